"""affcorr.Pipeline: images -> XFeat matches -> ACs -> H / pose, on graffiti 1->3 (ground truth H).

- Parity: the Rust matchers against the numpy reference (affcorr.export.xfeat_reference, which
  reproduces upstream XFeat) on the same float32 images: >= 99 % of the reference's matches
  reproduced within 0.01 px, and the count of correct matches within 1 %.
- Accuracy (from the image files, decoded in Rust): correct matches within 3 px, and the mean
  corner error of the homography estimated from the ACs, under the bounds below.
- Bad inputs raise FileNotFoundError / RuntimeError / ValueError naming the problem.

Bounds (measured 2026-11-22 with the committed models, ONNX Runtime 1.31.1, 2 threads; set with
margin for other CPUs' kernels; benches/results/pipeline_timing.md has the run):

=================== ============================ ===================================
matcher             correct within 3 px / ACs    H corner error (threshold 2 / 3 px)
=================== ============================ ===================================
xfeat               711 / 1533   (bound >= 650)  0.67 / 1.02 px  (bound < 2.5 px)
xfeat-star          564 / 913    (bound >= 500)  1.12 / 1.21 px  (bound < 4 px)
xfeat-lighterglue   1094 / 1474  (bound >= 1000) 0.81 / 0.64 px  (bound < 2 px)
=================== ============================ ===================================

(The numpy reference counts 718 / 562 / 1088 on PIL's 8-bit grayscale; the Rust decoder's float
BT.601 luma moves a few keypoints. xfeat-star re-measured 2026-12-01 with the PC-loss
fine-tuned refinement model, models/xfeat_refine.md; the wheel's gave 408 / 808, 1.77 px.)
"""

from __future__ import annotations

import shutil
from pathlib import Path

import affcorr
import numpy as np
import pytest
from affcorr.data import data_dir, graffiti
from affcorr.export import xfeat_reference as R
from affcorr.metrics import corner_error

GRAF = data_dir() / "graffiti"
A_PATH, B_PATH = GRAF / "graf1.png", GRAF / "graf3.png"
MODELS = Path(affcorr.__file__).resolve().parent / "models"

# matcher -> (reference method, min correct within 3 px, max H corner error at 3 px)
MATCHERS = {
    "xfeat": ("match_xfeat", 650, 2.5),
    "xfeat-star": ("match_xfeat_star", 500, 4.0),
    "xfeat-lighterglue": ("match_lighterglue", 1000, 2.0),
}


@pytest.fixture(scope="module")
def data():
    a, b, H = graffiti()
    return a.astype(np.float32), b.astype(np.float32), H


@pytest.fixture(scope="module")
def reference():
    return R.XFeatOnnx(threads=2)


_PIPELINES: dict[str, affcorr.Pipeline] = {}


def pipeline(matcher: str) -> affcorr.Pipeline:
    if matcher not in _PIPELINES:
        # Without the affine refinement (which moves x2) and the view cascade: the matcher's
        # own points, at the numpy reference's 4096 keypoints.
        _PIPELINES[matcher] = affcorr.Pipeline(
            matcher, max_keypoints=4096, threads=2, refine_affine=False, views="off"
        )
    return _PIPELINES[matcher]


# --- parity with the numpy reference -------------------------------------------------------------


@pytest.mark.parametrize("matcher", list(MATCHERS))
def test_matches_reproduce_the_numpy_reference(matcher, data, reference):
    a, b, H = data
    method = MATCHERS[matcher][0]
    ref = getattr(reference, method)(a, b)
    # The numpy reference specifies the full LighterGlue graph; the default adaptive loop
    # (early exit) is checked against the full graph in tests/test_lighterglue_adaptive.py.
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("AFFCORR_LIGHTERGLUE", "full")
        full = affcorr.Pipeline(
            matcher, max_keypoints=4096, threads=2, refine_affine=False, views="off"
        )
    res = full.match_pair(a, b)
    ours = (res.corrs[:, :2], res.corrs[:, 2:4])
    same = R.common_matches(ref, ours, tol=0.01)
    assert len(ref[0]) > 500
    assert same >= 0.99 * len(ref[0]), f"{same} of {len(ref[0])} reference matches reproduced"
    assert abs(len(res) - len(ref[0])) <= 0.01 * len(ref[0])
    c_ref = int(R.correct_within(*ref, H).sum())
    c_ours = int(R.correct_within(*ours, H).sum())
    assert abs(c_ours - c_ref) <= 0.01 * c_ref, (c_ours, c_ref)


# --- accuracy from the files ------------------------------------------------------------------


@pytest.mark.parametrize("matcher", list(MATCHERS))
def test_correct_matches_and_homography_on_graffiti(matcher, data):
    _, _, H_gt = data
    _, min_correct, max_err = MATCHERS[matcher]
    H, info, res = pipeline(matcher).homography(A_PATH, B_PATH, threshold=3.0, return_matches=True)
    correct = R.correct_within(res.corrs[:, :2], res.corrs[:, 2:4], H_gt)
    assert correct.sum() >= min_correct, f"{correct.sum()} / {len(res)} correct"
    err = corner_error(H, H_gt, 800, 640)
    assert err < max_err, f"mean corner error {err:.2f} px"
    # info describes the ACs returned; the inliers are mostly correct matches.
    assert isinstance(info, affcorr.RansacInfo) and len(info.inliers) == len(res)
    assert correct[info.inliers].mean() > 0.7
    assert res.timings["ransac"] > 0 and res.timings["total"] >= res.timings["ransac"]


def test_affine_refinement_in_the_pipeline(data):
    """The default refine_affine=True is refine_affine on the network's ACs (full resolution:
    the working images are the originals), and improves A at the correct matches. Views off:
    the view cascade verifies with the ACs, so with it the two pipelines' matches may differ."""
    _, _, H_gt = data
    kw = dict(max_keypoints=1024, threads=2, views="off")
    plain = affcorr.Pipeline("xfeat", refine_affine=False, **kw).match_pair(A_PATH, B_PATH)
    assert plain.timings["affine_refine"] == 0
    res = affcorr.Pipeline("xfeat", **kw).match_pair(A_PATH, B_PATH)
    expected = affcorr.refine_affine(A_PATH, B_PATH, plain.corrs)
    # To the last bits but for rounding: the pipeline refines on its own decoded images.
    np.testing.assert_allclose(res.corrs, expected.corrs, rtol=0, atol=1e-9)
    assert res.timings["affine_refine"] > 0
    correct = R.correct_within(plain.corrs[:, :2], plain.corrs[:, 2:4], H_gt)
    gt = affcorr.affine_from_homography(H_gt, plain.corrs[correct, :2]).reshape(-1, 4)
    before = np.linalg.norm(plain.corrs[correct, 4:] - gt, axis=1)
    after = np.linalg.norm(res.corrs[correct, 4:] - gt, axis=1)
    assert np.median(after) < 0.5 * np.median(before), (np.median(after), np.median(before))


def test_match_result_layout_and_certainty(data):
    a, b, H_gt = data
    res = pipeline("xfeat").match_pair(A_PATH, B_PATH)
    n = len(res)
    assert res.corrs.shape == (n, 8) and res.corrs.dtype == np.float64
    assert res.certainty.shape == (n,)
    assert np.all(np.diff(res.certainty) <= 0), "sorted by decreasing certainty"
    assert np.all((res.certainty > 0) & (res.certainty <= 1 + 1e-6))  # cosine similarities
    assert res.num_keypoints == (4096, 4096)
    assert set(res.timings) == {
        "decode",
        "matcher",
        "detection",
        "matching",
        "patches",
        "shape_net",
        "affine_refine",
        "views",
        "guided",
        "ransac",
        "total",
    }
    assert res.timings["decode"] > 0 and res.timings["ransac"] == 0
    assert res.timings["affine_refine"] == 0
    assert res.timings["total"] >= sum(v for k, v in res.timings.items() if k != "total") * 0.99
    # The A of each AC is the shape network's at those points: the same as ShapeEstimator's.
    est = affcorr.ShapeEstimator(threads=2)
    np.testing.assert_allclose(
        est.estimate(A_PATH, B_PATH, res.corrs[:, :2], res.corrs[:, 2:4], refine=False),
        res.corrs,
        atol=1e-9,
    )
    # Certainty is informative: the most certain half is more often correct.
    correct = R.correct_within(res.corrs[:, :2], res.corrs[:, 2:4], H_gt)
    assert correct[: n // 2].mean() > correct[n // 2 :].mean()


def test_arrays_paths_and_batches_agree():
    p = pipeline("xfeat")
    from PIL import Image

    rgb_a = np.asarray(Image.open(A_PATH).convert("RGB"))
    rgb_b = np.asarray(Image.open(B_PATH).convert("RGB"))
    from_files = p.match_pair(str(A_PATH), B_PATH)
    from_arrays = p.match_pair(rgb_a, rgb_b)
    np.testing.assert_array_equal(from_files.corrs, from_arrays.corrs)
    batch = p.match_pairs([(A_PATH, B_PATH), (rgb_b, rgb_a)])
    assert len(batch) == 2
    np.testing.assert_array_equal(batch[0].corrs, from_files.corrs)
    swapped = p.match_pair(B_PATH, A_PATH)
    np.testing.assert_array_equal(batch[1].corrs, swapped.corrs)


def test_max_matches_and_max_side():
    _, _, H_gt = graffiti()
    p = affcorr.Pipeline("xfeat", max_matches=300, max_side=400, threads=2)
    assert (p.max_matches, p.max_side) == (300, 400)
    assert p.max_keypoints == affcorr.PIPELINE_DEFAULTS["max_keypoints"]
    res = p.match_pair(A_PATH, B_PATH)
    assert len(res) == 300
    # Results are in the original 800x640 pixels although matching ran at 400x320.
    assert res.corrs[:, [0, 2]].max() > 500
    correct = R.correct_within(res.corrs[:, :2], res.corrs[:, 2:4], H_gt, px=6.0)
    assert correct.sum() >= 170, correct.sum()


def test_a_detection_threshold_keeps_only_the_stronger_keypoints():
    default = affcorr.Pipeline("xfeat", max_keypoints=512, threads=2, views="off")
    assert default.detection_threshold == 0.05  # XFeat's metadata, on its heatmap
    strict = affcorr.Pipeline(
        "xfeat", max_keypoints=512, threads=2, views="off", detection_threshold=0.5
    )
    assert strict.detection_threshold == 0.5
    every, few = default.extract(A_PATH), strict.extract(A_PATH)
    # (not a subset: XFeat ranks the budget by heatmap × reliability, the threshold is on the
    # heatmap alone)
    assert len(every) == 512 and 0 < len(few) < 512
    # features of one threshold do not match under another
    with pytest.raises(ValueError, match="features_a: .*detection_threshold"):
        strict.match_features(every, every)
    assert affcorr.Pipeline("xfeat-star", threads=1).detection_threshold is None


def test_relative_pose_returns_the_estimator_types():
    K = np.array([[800.0, 0, 400], [0, 800, 320], [0, 0, 1]])
    pose, info, res = pipeline("xfeat").relative_pose(
        A_PATH, B_PATH, K, K, threshold=2.0, return_matches=True
    )
    assert isinstance(pose, affcorr.RelativePose) and isinstance(info, affcorr.RansacInfo)
    assert pose.R.shape == (3, 3) and abs(np.linalg.norm(pose.t) - 1) < 1e-9
    assert len(info.inliers) == len(res) and info.num_inliers > 100
    np.testing.assert_allclose(pose.R @ pose.R.T, np.eye(3), atol=1e-9)
    # The same as estimating from the ACs directly.
    pose2, info2 = affcorr.estimate_relative_pose(res.corrs, K, K, threshold=2.0)
    np.testing.assert_array_equal(pose.E, pose2.E)
    np.testing.assert_array_equal(info.inliers, info2.inliers)


def test_prosac_defaults_to_the_certainty():
    H, info = pipeline("xfeat").homography(A_PATH, B_PATH, threshold=3.0, sampler="prosac")
    assert info.num_inliers > 500
    with pytest.raises(ValueError, match="unknown option"):
        pipeline("xfeat").homography(A_PATH, B_PATH, no_such_option=1)


# --- bad inputs ----------------------------------------------------------------------------------


def test_bad_images(tmp_path):
    p = pipeline("xfeat")
    with pytest.raises(FileNotFoundError, match="nonexistent.png"):
        p.match_pair(tmp_path / "nonexistent.png", B_PATH)
    (tmp_path / "text.png").write_text("not an image")
    with pytest.raises(ValueError, match="text.png"):
        p.match_pair(A_PATH, tmp_path / "text.png")
    with pytest.raises(ValueError, match="too small"):
        p.match_pair(np.zeros((20, 20)), np.zeros((20, 20)))
    with pytest.raises(ValueError, match="image_a"):
        p.match_pair(np.zeros((40, 40, 7)), B_PATH)
    with pytest.raises(ValueError, match="image_b"):
        p.match_pair(A_PATH, 3.5)
    with pytest.raises(ValueError, match=r"pairs\[1\]"):
        p.match_pairs([(A_PATH, B_PATH), (A_PATH,)])
    # A failing pair is its own error (issue 23); on_error="raise" raises it as before.
    with pytest.raises(FileNotFoundError, match=r"pairs\[0\].*missing.png"):
        p.match_pairs([(A_PATH, tmp_path / "missing.png")], on_error="raise")
    (failed,) = p.match_pairs([(A_PATH, tmp_path / "missing.png")])
    assert isinstance(failed.error, FileNotFoundError) and failed.index == 0


def test_bad_intrinsics_are_rejected_before_matching():
    p = pipeline("xfeat")
    with pytest.raises(ValueError, match=r"K1 must have shape \(3, 3\)"):
        p.relative_pose(A_PATH, B_PATH, np.eye(2), np.eye(3))
    with pytest.raises(ValueError, match="K2 is not a valid intrinsic matrix.*NaN"):
        p.relative_pose(A_PATH, B_PATH, np.eye(3), np.full((3, 3), np.nan))
    with pytest.raises(ValueError, match="K1 is not a valid intrinsic matrix"):
        p.relative_pose(A_PATH, B_PATH, -np.eye(3), np.eye(3))


def test_bad_options():
    with pytest.raises(ValueError, match="matcher must be one of"):
        affcorr.Pipeline("sift")
    for kw in ({"max_keypoints": 0}, {"max_side": -1}, {"threads": 0}, {"max_matches": 1.5}):
        with pytest.raises(ValueError, match=next(iter(kw))):
            affcorr.Pipeline("xfeat", **kw)
    with pytest.raises(ValueError, match="max_side"):
        affcorr.Pipeline("xfeat", max_side=16)
    for bad in (float("nan"), float("inf"), True, "0.1"):
        with pytest.raises(ValueError, match="detection_threshold must be a finite number"):
            affcorr.Pipeline("xfeat", detection_threshold=bad)
    with pytest.raises(ValueError, match="detection_threshold: the xfeat-star matcher keeps no"):
        affcorr.Pipeline("xfeat-star", detection_threshold=0.1)


def test_missing_models(tmp_path):
    with pytest.raises(FileNotFoundError, match="models_dir"):
        affcorr.Pipeline("xfeat", models_dir=tmp_path / "nope")
    # A directory without the backbone.
    with pytest.raises(FileNotFoundError, match="xfeat_backbone.onnx"):
        affcorr.Pipeline("xfeat", models_dir=tmp_path)
    # With the backbone but without the model the matcher needs.
    shutil.copy(MODELS / "xfeat_backbone.onnx", tmp_path)
    with pytest.raises(FileNotFoundError, match="xfeat_lighterglue.onnx"):
        affcorr.Pipeline("xfeat-lighterglue", models_dir=tmp_path)
    with pytest.raises(FileNotFoundError, match="xfeat_refine.onnx"):
        affcorr.Pipeline("xfeat-star", models_dir=tmp_path)
    with pytest.raises(FileNotFoundError, match="no_shape.onnx"):
        affcorr.Pipeline("xfeat", models_dir=tmp_path, shape_model=tmp_path / "no_shape.onnx")
    # The directory's backbone with the bundled shape network works.
    assert affcorr.Pipeline("xfeat", models_dir=tmp_path).models["backbone"].parent == tmp_path


def test_wrong_contracts(tmp_path):
    # The refinement MLP where the backbone should be: the contract mismatch is named.
    shutil.copy(MODELS / "xfeat_refine.onnx", tmp_path / "xfeat_backbone.onnx")
    with pytest.raises(RuntimeError, match="features-backbone-v1.*features-refine-v1"):
        affcorr.Pipeline("xfeat", models_dir=tmp_path)
    # The backbone where LighterGlue should be.
    shutil.copy(MODELS / "xfeat_backbone.onnx", tmp_path / "xfeat_backbone.onnx")
    shutil.copy(MODELS / "xfeat_backbone.onnx", tmp_path / "xfeat_lighterglue.onnx")
    with pytest.raises(RuntimeError, match="matcher-lighterglue-v1"):
        affcorr.Pipeline("xfeat-lighterglue", models_dir=tmp_path)
    # A matcher where the shape network should be.
    with pytest.raises(RuntimeError, match="shape-v1"):
        affcorr.Pipeline("xfeat", shape_model=MODELS / "xfeat_refine.onnx")
    # Not ONNX at all.
    (tmp_path / "xfeat_backbone.onnx").write_bytes(b"garbage")
    with pytest.raises(RuntimeError, match="not a valid ONNX model"):
        affcorr.Pipeline("xfeat", models_dir=tmp_path)


def test_broken_metadata_is_named(tmp_path):
    onnx = pytest.importorskip("onnx")
    m = onnx.load(str(MODELS / "xfeat_backbone.onnx"))
    props = [(p.key, p.value) for p in m.metadata_props]
    del m.metadata_props[:]
    for k, v in props:
        if k == "affcorr.detection.threshold":
            continue
        e = m.metadata_props.add()
        e.key, e.value = k, ("16" if k == "affcorr.stride" else v)
    onnx.save(m, str(tmp_path / "xfeat_backbone.onnx"))
    with pytest.raises(RuntimeError, match="affcorr.detection.threshold is missing"):
        affcorr.Pipeline("xfeat", models_dir=tmp_path)


def test_docstring_example():
    import doctest

    import affcorr.pipeline

    result = doctest.testmod(affcorr.pipeline, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0 and result.failed == 0


def test_a_pair_without_matches_gives_no_model_rather_than_an_error():
    """Too few matches for a minimal sample is a normal outcome of matching: like a RANSAC
    that finds no model, a NaN model with no inliers, and the (few) matches."""
    flat = np.full((240, 320), 0.5)
    pipe = affcorr.Pipeline("xfeat", max_keypoints=256, threads=1, views="off")
    for estimate in (pipe.homography, pipe.fundamental):
        model, info, res = estimate(flat, flat, return_matches=True)
        assert np.isnan(model).all() and info.num_inliers == 0
        assert len(info.inliers) == len(res) < 3
    K = np.array([[300.0, 0, 160], [0, 300, 120], [0, 0, 1]])
    pose, info = pipe.relative_pose(flat, flat, K, K)
    assert np.isnan(pose.R).all() and info.num_inliers == 0


def test_a_too_small_image_is_named_by_the_users_size():
    """max_side shrinks a 1000x60 image to 400x24: the message gives the user's size first."""
    p = affcorr.Pipeline("xfeat", max_keypoints=64, max_side=400, threads=1, views="off")
    thin = np.full((60, 1000), 0.5)
    with pytest.raises(ValueError, match=r"image_a: 1000×60 pixels \(400×24 at the working"):
        p.match_pair(thin, np.full((240, 320), 0.5))
