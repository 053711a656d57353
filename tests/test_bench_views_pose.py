"""The rotated-pair benchmark's geometry (benches/affcorr_bench/views_pose.py): ACs found against
a turned image B map back to B's own pixels exactly, and ``--board-only`` blanks exactly the
pixels outside the board's grown outline."""

from __future__ import annotations

import affcorr
import numpy as np
import pytest
from affcorr_bench.views import rotated
from affcorr_bench.views_pose import BOARD_MARGIN, back_to_original, board_only


@pytest.mark.parametrize("deg", [30.0, 90.0, 135.0, 180.0])
def test_acs_seen_in_a_turned_b_map_back_to_the_plane_induced_acs(deg):
    h = np.array([[0.9, -0.1, 20.0], [0.12, 1.05, -8.0], [2e-4, -1e-4, 1.0]])
    rng = np.random.default_rng(0)
    x1 = rng.uniform([0, 0], [320, 240], size=(40, 2))
    truth = affcorr.correspondences_from_homography(h, x1)
    _, m = rotated(np.zeros((240, 320), np.uint8), np.eye(3), deg)
    # What the pipeline reports against the turned B: the ACs of M H.
    seen = affcorr.correspondences_from_homography(m @ h, x1)
    assert not np.allclose(seen, truth)
    np.testing.assert_allclose(back_to_original(seen, m), truth, rtol=0, atol=1e-9)


def test_board_only_keeps_the_board_and_its_margin_and_greys_the_rest():
    img = (np.arange(120 * 160).reshape(120, 160) % 251).astype(np.uint8)
    poly = np.array([[40.0, 30.0], [120.0, 30.0], [120.0, 90.0], [40.0, 90.0]])
    out = board_only(img, poly)
    grey = round(float(img.mean()))
    # Inside the outline, and outside it up to the grown corners' sides (the corner (40, 30)
    # moves along (-4, -3) / 5, so the left side moves by 0.8 of the margin): untouched. Far
    # outside: the image's mean grey.
    assert np.array_equal(out[30:91, 40:121], img[30:91, 40:121])
    m = int(0.8 * BOARD_MARGIN)
    assert np.array_equal(out[60, 40 - m : 40], img[60, 40 - m : 40])
    assert out[60, 40 - m - 2] == grey
    assert (out[:10] == grey).all() and (out[:, :20] == grey).all() and (out[110:] == grey).all()
    assert out.dtype == img.dtype and out.shape == img.shape


def test_the_pair_summary_names_each_dataset_with_its_count():
    from collections import Counter

    from affcorr_bench.views_pose import pair_summary

    assert pair_summary(Counter({"synthetic": 12})) == (
        "12 rendered multi-plane scenes with parallax"
    )
    text = pair_summary(Counter({"synthetic": 3, "chessboard-stereo": 13, "other": 2}))
    assert text == (
        "3 rendered multi-plane scenes with parallax, 13 chessboard pairs of experiment 3's "
        "stereo rig and 2 other"
    )
