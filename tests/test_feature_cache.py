"""The per-image feature cache (issue 21): Pipeline.extract + Pipeline.match_features give
match_pair's results bit for bit, Features pickle and round-trip through bytes, and
match_pairs extracts an image shared by several pairs once."""

from __future__ import annotations

import pickle

import affcorr
import numpy as np
import pytest
from affcorr.data import data_dir
from affcorr.pipeline import Features

G = data_dir() / "graffiti"
A, B = G / "graf1.png", G / "graf3.png"


def _same(x: affcorr.MatchResult, y: affcorr.MatchResult) -> None:
    np.testing.assert_array_equal(x.corrs, y.corrs)
    np.testing.assert_array_equal(x.certainty, y.certainty)
    assert x.num_keypoints == y.num_keypoints
    assert [v["label"] for v in x.views] == [v["label"] for v in y.views]
    for name in ("reliable", "affine_confidence"):
        if hasattr(x, name):
            np.testing.assert_array_equal(getattr(x, name), getattr(y, name))


@pytest.fixture(scope="module")
def pipe() -> affcorr.Pipeline:
    return affcorr.Pipeline("xfeat", max_keypoints=256, max_side=320, threads=2)


@pytest.mark.parametrize("matcher", ["xfeat", "xfeat-lighterglue"])
def test_match_features_equals_match_pair(matcher: str) -> None:
    p = affcorr.Pipeline(matcher, max_keypoints=256, max_side=320, threads=2)
    want = p.match_pair(A, B)
    fa, fb = p.extract(A), p.extract(B)
    assert isinstance(fa, Features)
    assert fa.matcher == matcher and fa.image_size == (800, 640) and fa.working_size == (320, 256)
    assert fa.keypoints.shape == (len(fa), 2) and fa.descriptors.shape == (len(fa), 64)
    assert fa.scores.shape == (len(fa),) and fa.seconds > 0
    _same(p.match_features(fa, fb), want)
    # The same features again, after pickling (a process boundary) and after bytes.
    _same(p.match_features(fa, fb), want)
    _same(p.match_features(pickle.loads(pickle.dumps(fa)), fb), want)
    _same(p.match_features(fa, Features.from_bytes(fb.to_bytes())), want)


def test_keypoints_are_the_acs_points(pipe: affcorr.Pipeline) -> None:
    """Without views every AC's x1 is a keypoint of A exactly (the batch's hloc indices)."""
    p = affcorr.Pipeline("xfeat", max_keypoints=256, max_side=320, threads=2, views="off")
    fa, fb = p.extract(A), p.extract(B)
    m = p.match_features(fa, fb)
    kp = {tuple(k) for k in fa.keypoints}
    assert len(m) > 20 and all((x, y) in kp for x, y in m.corrs[:, :2])


def test_match_pairs_shares_images_and_equals_match_pair(pipe: affcorr.Pipeline) -> None:
    img_a = affcorr.read_gray_image(A)
    img_b = affcorr.read_gray_image(B)
    pairs = [(A, B), (B, A), (A, A), (img_a, img_b), (img_b, img_a), (A, G / "missing.png")]
    got = pipe.match_pairs(pairs)
    for (x, y), r in zip(pairs[:5], got[:5]):
        _same(r, pipe.match_pair(x, y))
    assert isinstance(got[5], affcorr.PairError) and "missing.png" in str(got[5].error)


def test_bad_features_arguments_raise_value_error(pipe: affcorr.Pipeline) -> None:
    f = pipe.extract(A)
    with pytest.raises(ValueError, match="features_b must be the Features"):
        pipe.match_features(f, "graf3.png")
    other = affcorr.Pipeline("xfeat", max_keypoints=128, max_side=320, threads=1)
    with pytest.raises(ValueError, match="features_a: extracted with matcher xfeat, max_key"):
        other.match_features(f, f)
    with pytest.raises(ValueError, match="^data: "):
        Features.from_bytes(b"AFCF but not really")
    with pytest.raises(ValueError, match="data"):
        Features.from_bytes(f.to_bytes()[:-3])
    with pytest.raises(FileNotFoundError):
        pipe.extract(G / "missing.png")
