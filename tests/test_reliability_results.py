"""Reliability, round two (issue 23): per-pair batch results, options that name themselves,
bounded resources, image files checked before they are read, and the documented invariances
at extreme magnitudes. (Fork safety and Ctrl-C: tests/test_reliability_process.py.)"""

from __future__ import annotations

import pickle

import affcorr
import numpy as np
import pytest
from affcorr.data import data_dir
from affcorr.estimation import PairError

RNG = np.random.default_rng(0)
X1 = RNG.uniform(0, 640, (100, 2))
GOOD = affcorr.correspondences_from_homography(np.diag([1.1, 1.1, 1.0]), X1)
K = np.array([[500.0, 0, 320], [0, 520, 240], [0, 0, 1]])
GRAF = data_dir() / "graffiti"


# --- one bad pair loses nothing else ---------------------------------------------------------


def batches():
    return {
        "homography": lambda pairs, **kw: affcorr.estimate_homography_batch(pairs, **kw),
        "fundamental": lambda pairs, **kw: affcorr.estimate_fundamental_batch(pairs, **kw),
        "relative_pose": lambda pairs, **kw: affcorr.estimate_relative_pose_batch(
            pairs, K, K, **kw
        ),
    }


@pytest.mark.parametrize("name", list(batches()))
def test_a_bad_pair_gets_its_own_error_and_the_others_their_results(name):
    run = batches()[name]
    nan = GOOD.copy()
    nan[4, 2] = np.nan
    pairs = [GOOD, GOOD[:, :3], nan, GOOD]
    out = run(pairs, max_iterations=200)
    assert len(out) == 4
    single = run([GOOD], max_iterations=200)[0]
    for i in (0, 3):
        model, info = out[i]
        assert info.num_inliers == single[1].num_inliers and info.score == single[1].score
    for i, text in ((1, "corrs must have shape"), (2, r"corrs\[4\] contains NaN")):
        e = out[i]
        assert isinstance(e, PairError) and e.index == i
        assert isinstance(e.error, ValueError)
        assert e.message.startswith(f"pair {i}: ")
        assert pytest.raises(ValueError, lambda e=e: (_ for _ in ()).throw(e.error)).match(text)
    with pytest.raises(ValueError, match=r"pair 1: corrs must have shape"):
        run(pairs, on_error="raise")


@pytest.mark.parametrize("name", list(batches()))
@pytest.mark.parametrize("rows", [0, 1])
def test_a_pair_with_too_few_matches_is_a_no_model_result_not_an_error(name, rows):
    out = batches()[name]([GOOD, GOOD[:rows]], max_iterations=100, on_error="raise")
    model, info = out[1]
    assert info.num_inliers == 0 and len(info.inliers) == rows and info.num_iterations == 0
    arrays = [model] if isinstance(model, np.ndarray) else [model.R, model.t, model.E, model.F]
    assert all(np.isnan(a).all() for a in arrays)
    assert not isinstance(out[0], PairError)


def test_per_pair_options_and_intrinsics_fail_only_their_pair():
    out = affcorr.estimate_homography_batch(
        [GOOD, GOOD, GOOD], pair_options=[None, {"scoring": "x"}, {"bogus": 1}]
    )
    assert not isinstance(out[0], PairError)
    assert "pair 1: scoring must be one of" in out[1].message
    assert "pair 2: unknown option bogus" in out[2].message
    bad = np.array([[500.0, 0, 320], [0, -500, 240], [0, 0, 1]])
    out = affcorr.estimate_relative_pose_batch([GOOD, GOOD], K, [K, bad], max_iterations=50)
    assert not isinstance(out[0], PairError)
    assert isinstance(out[1], PairError) and "K2" in out[1].message
    # Errors of the batch as a whole still raise.
    with pytest.raises(ValueError, match="unknown option foo"):
        affcorr.estimate_homography_batch([GOOD], foo=2)
    with pytest.raises(ValueError, match="pair_options must have one entry per pair"):
        affcorr.estimate_homography_batch([GOOD, GOOD], pair_options=[{}])
    with pytest.raises(ValueError, match='on_error must be "return" or "raise"'):
        affcorr.estimate_homography_batch([GOOD], on_error="ignore")


def test_pair_errors_pickle_and_raise():
    e = affcorr.estimate_homography_batch([GOOD[:, :3]])[0]
    back = pickle.loads(pickle.dumps(e))
    assert (back.index, back.message, type(back.error)) == (0, e.message, ValueError)
    with pytest.raises(PairError, match="pair 0: corrs must have shape"):
        raise e


@pytest.fixture(scope="module")
def pipe():
    return affcorr.Pipeline("xfeat", threads=2, max_keypoints=256)


def test_match_pairs_keeps_the_readable_pairs(pipe, tmp_path):
    text = tmp_path / "text.png"
    text.write_text("not an image")
    good = (GRAF / "graf1.png", GRAF / "graf3.png")
    pairs = [good, (GRAF / "graf1.png", text), (tmp_path / "missing.png", good[1]), good]
    out = pipe.match_pairs(pairs)
    assert len(out) == 4
    single = pipe.match_pair(*good)
    for i in (0, 3):
        assert np.array_equal(out[i].corrs, single.corrs)
    assert isinstance(out[1], PairError) and isinstance(out[1].error, ValueError)
    assert out[1].message.startswith("pairs[1]: ") and "unrecognised format" in out[1].message
    assert isinstance(out[2], PairError) and isinstance(out[2].error, FileNotFoundError)
    # An array that is not an image is its pair's error too.
    out = pipe.match_pairs([good, (np.zeros((4, 4, 7)), good[1])])
    assert not isinstance(out[0], PairError) and isinstance(out[1], PairError)
    with pytest.raises(ValueError, match=r"pairs\[1\]: "):
        pipe.match_pairs(pairs, on_error="raise")


# --- options: Python and numpy integers, named in every error, bounded ------------------------


INTS = [np.int64(3), np.int32(3), np.uint8(3), 3]


@pytest.mark.parametrize("value", INTS, ids=lambda v: type(v).__name__)
def test_every_integer_option_takes_python_and_numpy_integers(value):
    base = affcorr.estimate_homography(GOOD, seed=3, max_iterations=30)
    for kw in ({"seed": value}, {"max_iterations": 30, "min_iterations": value}):
        opts = {"seed": 3, "max_iterations": 30, **kw}
        h, info = affcorr.estimate_homography(GOOD, **opts)
        assert info.num_inliers == base[1].num_inliers
    est = affcorr.ShapeEstimator(threads=value, batch_size=value)
    assert (est.threads, est.batch_size) == (3, 3)


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: affcorr.estimate_homography(GOOD, seed=2**70), "seed = 2**70"),
        (lambda: affcorr.estimate_homography(GOOD, max_iterations=2**70), "max_iterations = 2**70"),
        (lambda: affcorr.estimate_homography(GOOD, max_iterations=10**12), "limit of 1000000000"),
        (lambda: affcorr.estimate_homography(GOOD, lo_iterations=10**6), "lo_iterations = "),
        (lambda: affcorr.estimate_homography(GOOD, seed=-(2**70)), "seed must be a non-negative"),
        (lambda: affcorr.estimate_homography(GOOD, seed=1.5), "seed must be a non-negative"),
        (lambda: affcorr.estimate_homography(GOOD, seed=True), "seed must be a non-negative"),
        (
            lambda: affcorr.ShapeEstimator(threads=10**6),
            "threads = 1000000 is over the limit of 1024",
        ),
        (lambda: affcorr.ShapeEstimator(threads=2**70), "threads = 2**70"),
        (lambda: affcorr.ShapeEstimator(threads=0), "threads must be a positive int"),
        (lambda: affcorr.ShapeEstimator(threads=2.0), "threads must be a positive int"),
        (lambda: affcorr.ShapeEstimator(batch_size=10**9), "batch_size = 1000000000 is over"),
        (lambda: affcorr.Pipeline("xfeat", threads=10**6), "threads = 1000000 is over the limit"),
        (lambda: affcorr.Pipeline("xfeat", max_keypoints=2**70), "max_keypoints = 2**70"),
        (lambda: affcorr.Pipeline("xfeat", max_matches=2**70), "max_matches = 2**70"),
        (lambda: affcorr.Pipeline("xfeat", max_side=2**70), "max_side = 2**70"),
        (lambda: affcorr.Pipeline("xfeat", seed=2**70), "seed = 2**70"),
    ],
    ids=lambda v: v if isinstance(v, str) else "",
)
def test_option_errors_name_the_option_and_the_bound(call, message):
    message = message.replace("2**70", str(2**70))
    with pytest.raises(ValueError) as info:
        call()
    assert message in str(info.value)
    assert "int too big to convert" not in str(info.value)


def test_pipeline_threads_take_numpy_integers():
    assert affcorr.Pipeline("xfeat", threads=np.int64(2), max_keypoints=np.int32(128)).threads == 2


# --- image files: format first, size bounded --------------------------------------------------


def test_a_device_or_non_image_is_refused_from_its_first_bytes(tmp_path):
    with pytest.raises(ValueError, match="unrecognised format.*00 00 00 00"):
        affcorr.read_gray_image("/dev/zero")
    big = tmp_path / "big.bin"
    with open(big, "wb") as f:  # 600 MiB on paper, a sparse hole on disk
        f.truncate(600 << 20)
    with pytest.raises(ValueError, match="unrecognised format"):
        affcorr.read_gray_image(big)


def test_an_image_file_over_the_size_limit_is_refused(tmp_path):
    big = tmp_path / "big.png"
    with open(big, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n")
        f.truncate(300 << 20)
    with pytest.raises(ValueError, match="over the 256 MiB limit on image files"):
        affcorr.read_gray_image(big)


# --- extreme magnitudes -----------------------------------------------------------------------


@pytest.mark.parametrize("exp", [-300, -160, -100, 0, 100, 155, 300])
def test_documented_invariances_hold_at_extreme_magnitudes(exp):
    c = 10.0**exp
    scene_f = np.array([[1e-7, -2e-5, 0.01], [3e-5, 1e-7, -0.02], [-0.012, 0.018, 1.0]])
    rows = RNG.uniform(0, 640, (50, 8))
    rows[:, 4:] = [1.0, 0.1, -0.05, 0.9]
    p, pc = affcorr.sampson_point(scene_f, rows), affcorr.sampson_point(scene_f * c, rows)
    np.testing.assert_allclose(pc, p, rtol=1e-9)
    a, ac = affcorr.sampson_affine(scene_f, rows), affcorr.sampson_affine(scene_f * c, rows)
    np.testing.assert_allclose(ac, a, rtol=1e-9, atol=1e-12)
    A = np.array([[[1.2, 0.3], [-0.2, 0.8]]])
    o, s, r = affcorr.decompose_affine(A)
    oc, sc, rc = affcorr.decompose_affine(A * c)
    np.testing.assert_allclose(sc, s * c, rtol=1e-12)
    np.testing.assert_allclose(oc, o, atol=1e-12)
    np.testing.assert_allclose(rc, r, atol=1e-12)


def test_the_issue_examples_of_silent_nonsense():
    _, s, _ = affcorr.decompose_affine(np.eye(2)[None] * 1e155)
    assert np.isfinite(s).all() and s[0] == pytest.approx(1e155)
    F = np.array([[0.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    c = np.array([[3.0, 2, 7, 3]])
    assert affcorr.sampson_point(F * 1e155, c)[0] == pytest.approx(0.5)
    assert affcorr.sampson_point(F * 1e-160, c)[0] == pytest.approx(0.5)
    # A huge residual shape: an A with det s², not A = 0.
    a = affcorr.synthesize_affine([0.3], [2.0], [[1e200, 0.0, 1e200]])
    assert np.linalg.det(a[0]) == pytest.approx(4.0)
    # An A that overflows f64 is an error naming the row.
    with pytest.raises(ValueError, match=r"A\[0\]: the result overflows f64"):
        affcorr.synthesize_affine([0.0], [1e300], [[1e20, 0.0, 0.0]])


@pytest.mark.parametrize("exp", [-300, -200, 200, 300])
def test_essential_factorisation_is_finite_at_any_scale(exp):
    R = np.array([[0.8, -0.6, 0.0], [0.6, 0.8, 0.0], [0.0, 0.0, 1.0]])
    E = affcorr.essential_from_pose(R, np.array([1.0, 0.2, -0.1]))

    def rotations(e):  # the four (R, t), as a set: sorted by their entries
        return sorted(np.concatenate([np.ravel(r), np.ravel(t)]).tolist() for r, t in e)

    scaled = rotations(affcorr.decompose_essential(E * 10.0**exp))
    assert np.isfinite(scaled).all()
    np.testing.assert_allclose(scaled, rotations(affcorr.decompose_essential(E)), atol=1e-9)
