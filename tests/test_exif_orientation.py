"""EXIF orientation: image files are matched turned upright by their tag's turn, and every
coordinate comes back in their stored pixels (docs/pipeline.md, "Photographs taken in
portrait").

Graffiti 3 is stored turned a quarter turn counter-clockwise and tagged by PIL (an EXIF writer
independent of affcorr) as a camera held in portrait tags it: "turn 90 degrees clockwise to
show" (6). Turned upright it is graffiti 3 again, so the plain pass solves the pair; the ACs
are checked against the plane-induced ACs of the homography into the stored pixels.
"""

from __future__ import annotations

import affcorr
import numpy as np
import pytest
from affcorr import cli
from affcorr.data import data_dir, read_opencv_matrix
from affcorr.pipeline import PIPELINE_DEFAULTS

Image = pytest.importorskip("PIL.Image")

GRAF = data_dir() / "graffiti"


def _stored_portrait(tmp_path, tag: int, suffix: str = ".jpg"):
    """graf3 stored turned 90 degrees counter-clockwise (640 x 800), tagged ``tag`` by PIL; the
    homography from graf1 into the stored pixels."""
    b = (affcorr.read_gray_image(GRAF / "graf3.png") * 255).round().astype(np.uint8)
    stored = np.ascontiguousarray(np.rot90(b, 1))
    exif = Image.Exif()
    exif[0x0112] = tag
    path = tmp_path / f"graf3-{tag}{suffix}"
    Image.fromarray(stored).save(path, exif=exif, **({"quality": 95} if suffix == ".jpg" else {}))
    # Upright (turned 90 degrees clockwise): (x, y) stored -> (H_stored - 1 - y, x) shown.
    h_stored = stored.shape[0]
    shown_from_stored = np.array([[0, -1, h_stored - 1], [1, 0, 0], [0, 0, 1.0]])
    H = read_opencv_matrix(GRAF / "H1to3p.xml")
    return path, np.linalg.inv(shown_from_stored) @ H


def _plane_errors(corrs: np.ndarray, H: np.ndarray) -> tuple[float, float]:
    """Median |H(x1) - x2| and median ||A - dH/dx1||_F over ``corrs``."""
    p = np.c_[corrs[:, :2], np.ones(len(corrs))] @ H.T
    x2 = p[:, :2] / p[:, 2:]
    jac = (H[None, :2, :2] - x2[:, :, None] * H[None, 2:3, :2]) / p[:, 2, None, None]
    dx = np.linalg.norm(corrs[:, 2:4] - x2, axis=1)
    da = np.linalg.norm(corrs[:, 4:].reshape(-1, 2, 2) - jac, axis=(1, 2))
    return float(np.median(dx)), float(np.median(da))


@pytest.fixture(scope="module")
def pipes():
    return {
        exif: affcorr.Pipeline(max_keypoints=1024, threads=2, exif_orientation=exif)
        for exif in (True, False)
    }


@pytest.mark.parametrize("suffix", [".jpg", ".png"])
def test_a_portrait_file_is_matched_upright_and_reported_in_its_stored_pixels(
    tmp_path, pipes, suffix
):
    path, H = _stored_portrait(tmp_path, 6, suffix)
    pipe = pipes[True]
    assert pipe.exif_orientation and PIPELINE_DEFAULTS["exif_orientation"] is True
    f = pipe.extract(path)
    assert (f.orientation, f.image_size, f.working_size) == (6, (640, 800), (800, 640))
    k = f.keypoints
    assert k[:, 0].max() <= 639.5 and k[:, 1].max() <= 799.5 and k[:, 1].max() > 640

    H_est, info, res = pipe.homography(GRAF / "graf1.png", path, return_matches=True)
    assert [v["label"] for v in res.views] == ["plain"]
    dx, da = _plane_errors(res.corrs[info.inliers], H)
    assert info.num_inliers > 100 and dx < 1.0 and da < 0.1, (info.num_inliers, dx, da)

    # As stored, the same pixels meet a quarter turn: the view cascade has to undo it, and
    # the coordinates are the same stored pixels.
    off = pipes[False]
    assert not off.exif_orientation and off.extract(path).orientation == 1
    H_off, info, res = off.homography(GRAF / "graf1.png", path, return_matches=True)
    assert len(res.views) > 1
    dx, da = _plane_errors(res.corrs[info.inliers], H)
    assert dx < 1.0 and da < 0.1, (dx, da)


def test_a_mirrored_tag_is_turned_but_not_mirrored(tmp_path, pipes):
    # Tag 5: a quarter turn clockwise and a mirror (a front camera's preview). The stored
    # pixels are the camera's; only the turn is applied.
    path, H = _stored_portrait(tmp_path, 5)
    pipe = pipes[True]
    assert pipe.extract(path).orientation == 6
    H_est, info, res = pipe.homography(GRAF / "graf1.png", path, return_matches=True)
    assert [v["label"] for v in res.views] == ["plain"]
    dx, da = _plane_errors(res.corrs[info.inliers], H)
    assert dx < 1.0 and da < 0.1, (dx, da)


def test_arrays_are_taken_as_they_are(tmp_path, pipes):
    path, _ = _stored_portrait(tmp_path, 6)
    stored = affcorr.read_gray_image(path)
    assert stored.shape == (800, 640)  # the reader gives the stored pixels
    f = pipes[True].extract(stored)
    assert (f.orientation, f.image_size, f.working_size) == (1, (640, 800), (640, 800))


def test_the_cli_takes_the_option():
    args = cli.build_parser().parse_args(["match", "a.png", "b.png", "-o", "out.npz"])
    assert args.exif_orientation is True
    args = cli.build_parser().parse_args(
        ["match", "a.png", "b.png", "-o", "out.npz", "--no-exif-orientation"]
    )
    assert args.exif_orientation is False
