"""Bad-input battery over every array-taking function of the Python API.

One table (``SPECS``) lists each public function with valid arguments; every input class of the
issue is applied to every array argument in turn:

- NaN / infinity in the last row: ``ValueError`` naming the argument;
- a wrong shape (one column short, an extra leading axis, a scalar): ``ValueError`` naming it
  (or, where numpy's conversion makes it a valid shape of another length, the row counts);
- zero rows: either an empty result or ``ValueError`` (each spec says which, with its message);
- int, float32, non-contiguous and Fortran-ordered arrays: the same answer, bit for bit, as the
  float64 C-ordered copy (they are converted, never rejected);
- scalar options of the wrong type: ``ValueError`` naming them.

Degenerate data (duplicate or collinear points, det A <= 0, singular K) and N = 10^7 have their
own tests below. docs/reliability.md's table is checked against the test names here.
"""

from __future__ import annotations

import functools
import re
from collections.abc import Callable
from dataclasses import dataclass, field, fields, is_dataclass
from pathlib import Path
from typing import Any

import affcorr
import affcorr.solvers
import numpy as np
import pytest

SHAPE_DATA = Path(__file__).resolve().parent / "data" / "shape"
RNG = np.random.default_rng(8)
H = np.array([[1.1, 0.05, 12.0], [-0.02, 0.95, -7.0], [2e-4, -1e-4, 1.0]])
K1 = np.array([[500.0, 0, 320], [0, 520, 240], [0, 0, 1]])
K2 = np.array([[610.0, 0, 300], [0, 590, 250], [0, 0, 1]])
X1 = RNG.uniform(0, 640, (40, 2))
CORRS = affcorr.correspondences_from_homography(H, X1)
R = np.array([[np.cos(0.2), 0, np.sin(0.2)], [0, 1, 0], [-np.sin(0.2), 0, np.cos(0.2)]])
T = np.array([1.0, 0.1, -0.2])
E = affcorr.essential_from_pose(R, T)
F = affcorr.fundamental_from_essential(E, K1, K2)
NORM = affcorr.normalize_correspondences(CORRS, K1, K2)
LAF1, LAF2 = affcorr.affine_to_laf(CORRS[:6], 3.0)


@dataclass
class Spec:
    """A public function, valid keyword arguments, and what zero rows give."""

    name: str
    fun: Callable[..., Any]
    args: dict[str, Any]
    #: Argument names that hold arrays (the battery mutates each).
    arrays: tuple[str, ...]
    #: Per array argument: the message fragment of ValueError for zero rows; absent: allowed.
    empty: dict[str, str] = field(default_factory=dict)
    #: Argument name -> the name the messages use, when they differ (e.g. "pair 0").
    named: dict[str, str] = field(default_factory=dict)

    def __call__(self, **override: Any) -> Any:
        return self.fun(**{**self.args, **override})


def est(name: str) -> Callable[..., Any]:
    f = getattr(affcorr, name)
    return lambda **kw: f(**kw, max_iterations=50)


def batch(name: str) -> Callable[..., Any]:
    # on_error="raise": a bad pair is otherwise returned as its PairError (issue 23), and this
    # battery checks the message of the error itself.
    f = getattr(affcorr, name)
    return lambda corrs, **kw: f([corrs], **kw, max_iterations=50, on_error="raise")


@functools.cache
def echo() -> affcorr.ShapeEstimator:
    """The echo fixture model (tests/data/shape), loaded on first use."""
    return affcorr.ShapeEstimator(SHAPE_DATA / "echo.onnx", threads=1)


IMAGE = RNG.random((48, 64))
NEEDS = "needs at least"
SPECS = [
    Spec(
        "synthesize_affine",
        affcorr.synthesize_affine,
        dict(
            orientation=RNG.uniform(-3, 3, 6),
            scale=RNG.uniform(0.5, 2, 6),
            residual_shape=RNG.uniform(-0.2, 0.2, (6, 3)),
        ),
        ("orientation", "scale", "residual_shape"),
    ),
    Spec(
        "decompose_affine", affcorr.decompose_affine, dict(A=CORRS[:, 4:].reshape(-1, 2, 2)), ("A",)
    ),
    Spec("affine_from_homography", affcorr.affine_from_homography, dict(H=H, x1=X1), ("H", "x1")),
    Spec(
        "correspondences_from_homography",
        affcorr.correspondences_from_homography,
        dict(H=H, x1=X1),
        ("H", "x1"),
    ),
    Spec(
        "normalize_correspondences",
        affcorr.normalize_correspondences,
        dict(corrs=CORRS, K1=K1, K2=K2),
        ("corrs", "K1", "K2"),
    ),
    Spec("laf_to_affine", affcorr.laf_to_affine, dict(laf1=LAF1, laf2=LAF2), ("laf1", "laf2")),
    Spec("affine_to_laf", affcorr.affine_to_laf, dict(corrs=CORRS, radius=2.0), ("corrs",)),
    Spec("essential_from_pose", affcorr.essential_from_pose, dict(R=R, t=T), ("R", "t")),
    Spec(
        "fundamental_from_essential",
        affcorr.fundamental_from_essential,
        dict(E=E, K1=K1, K2=K2),
        ("E", "K1", "K2"),
    ),
    Spec("decompose_essential", affcorr.decompose_essential, dict(E=E), ("E",)),
    Spec(
        "pose_from_essential",
        affcorr.pose_from_essential,
        dict(E=E, x1=NORM[:, :2], x2=NORM[:, 2:4]),
        ("E", "x1", "x2"),
    ),
    *[
        Spec(n, getattr(affcorr, n), dict(F=F, corrs=CORRS), ("F", "corrs"))
        for n in ("sampson_point", "sampson_affine", "sampson_point_grad", "sampson_affine_grad")
    ],
    *[
        Spec(
            n,
            getattr(affcorr.solvers, n),
            dict(x1=CORRS[:k, :2], x2=CORRS[:k, 2:4]),
            ("x1", "x2"),
            empty={"x1": "must have shape", "x2": "must have shape"},
        )
        for n, k in (("homography_4pt", 4), ("fundamental_7pt", 7), ("essential_5pt", 5))
    ],
    *[
        Spec(
            n,
            getattr(affcorr.solvers, n),
            dict(x1=CORRS[:, :2], x2=CORRS[:, 2:4]),
            ("x1", "x2"),
            empty={"x1": NEEDS, "x2": "x2"},
        )
        for n in ("homography_lsq", "fundamental_8pt", "essential_8pt")
    ],
    *[
        Spec(
            n,
            getattr(affcorr.solvers, n),
            dict(corrs=CORRS[:k]),
            ("corrs",),
            empty={"corrs": "must have shape"},
        )
        for n, k in (("homography_2ac", 2), ("fundamental_3ac", 3), ("essential_2ac", 2))
    ],
    *[
        Spec(n, getattr(affcorr.solvers, n), dict(corrs=CORRS), ("corrs",), empty={"corrs": NEEDS})
        for n in ("homography_ac_lsq", "fundamental_ac_lsq")
    ],
    Spec(
        "homography_1ac_given_f",
        affcorr.solvers.homography_1ac_given_f,
        dict(corrs=CORRS[:1], F=F),
        ("corrs", "F"),
        empty={"corrs": "must have shape"},
    ),
    Spec(
        "essential_lsq",
        affcorr.solvers.essential_lsq,
        dict(x1=NORM[:4, :2], x2=NORM[:4, 2:4], corrs=NORM[4:6]),
        ("x1", "x2", "corrs"),
        empty={"x2": "same length"},
    ),
    *[
        Spec(n, est(n), dict(corrs=CORRS), ("corrs",), empty={"corrs": "need at least"})
        for n in ("estimate_homography", "estimate_fundamental")
    ],
    Spec(
        "estimate_relative_pose",
        est("estimate_relative_pose"),
        dict(corrs=CORRS, K1=K1, K2=K2),
        ("corrs", "K1", "K2"),
        empty={"corrs": "need at least"},
    ),
    *[
        Spec(
            n,
            batch(n),
            dict(corrs=CORRS),
            ("corrs",),
            empty={"corrs": "pair 0: "},
            named={"corrs": "pair 0: corrs"},
        )
        for n in ("estimate_homography_batch", "estimate_fundamental_batch")
    ],
    Spec(
        "estimate_relative_pose_batch",
        batch("estimate_relative_pose_batch"),
        dict(corrs=CORRS, K1=K1, K2=K2),
        ("corrs", "K1", "K2"),
        empty={"corrs": "pair 0: "},
        named={"corrs": "pair 0: corrs"},
    ),
    Spec(
        "extract_patches",
        affcorr.extract_patches,
        dict(image=IMAGE, xy=X1[:5] / 10),
        ("image", "xy"),
        empty={"image": "empty"},
    ),
    Spec(
        "ShapeEstimator.estimate",
        lambda **kw: echo().estimate_detailed(IMAGE, IMAGE, **kw),
        dict(x1=X1[:5] / 10, x2=X1[5:10] / 10),
        ("x1", "x2"),
    ),
    Spec(
        "ShapeEstimator.predict",
        lambda **kw: echo().predict(**kw),
        dict(patches_a=RNG.random((3, 1, 32, 32)), patches_b=RNG.random((3, 1, 32, 32))),
        ("patches_a", "patches_b"),
    ),
    Spec(
        "read_gray_image",
        affcorr.read_gray_image,
        dict(image=RNG.random((20, 30, 3))),
        ("image",),
        empty={"image": "empty"},
    ),
]
CASES = [(s, a) for s in SPECS for a in s.arrays]
CASE_IDS = [f"{s.name}-{a}" for s, a in CASES]


def arrays_of(result: Any) -> list[np.ndarray]:
    """Every array in a result (tuples, lists, dicts and dataclasses), in a fixed order."""
    if isinstance(result, np.ndarray):
        return [result]
    if isinstance(result, dict):
        return [x for k in sorted(result) for x in arrays_of(result[k])]
    if isinstance(result, (list, tuple)):
        return [x for r in result for x in arrays_of(r)]
    if is_dataclass(result):
        return [x for f in fields(result) for x in arrays_of(getattr(result, f.name))]
    return [np.asarray(result)]


def assert_identical(a: Any, b: Any) -> None:
    xs, ys = arrays_of(a), arrays_of(b)
    assert len(xs) == len(ys)
    for x, y in zip(xs, ys):
        # NaN equals NaN in float arrays; str and object fields (names, None) compare as they are.
        assert x.shape == y.shape and np.array_equal(x, y, equal_nan=x.dtype.kind in "fc")


def message_name(spec: Spec, arg: str) -> str:
    return spec.named.get(arg, arg)


def poisoned(value: np.ndarray, bad: float) -> np.ndarray:
    """`value` with its last row's first entry set to `bad` (every row must be checked)."""
    out = np.array(value, dtype=np.float64)
    out.reshape(-1, out.shape[-1])[-1, 0] = bad
    return out


# --- NaN and infinity --------------------------------------------------------------------------


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf], ids=["nan", "inf", "-inf"])
@pytest.mark.parametrize("spec, arg", CASES, ids=CASE_IDS)
def test_non_finite_values_raise_value_error_naming_the_argument(spec, arg, bad):
    with pytest.raises(ValueError) as info:
        spec(**{arg: poisoned(spec.args[arg], bad)})
    msg = str(info.value)
    assert message_name(spec, arg) in msg, msg
    assert any(w in msg for w in ("NaN", "nan", "finite", "inf")), msg


# --- shapes ------------------------------------------------------------------------------------


def wrong_shapes(value: np.ndarray) -> list[np.ndarray]:
    v = np.asarray(value, dtype=np.float64)
    return [v[..., :-1], v[None], np.float64(1.0)]


@pytest.mark.parametrize("which", [0, 1, 2], ids=["one column short", "extra axis", "scalar"])
@pytest.mark.parametrize("spec, arg", CASES, ids=CASE_IDS)
def test_wrong_shapes_raise_value_error_naming_the_argument(spec, arg, which):
    bad = wrong_shapes(spec.args[arg])[which]
    if arg == "image" and which == 0:
        pytest.skip("an image of any width (and 1 to 4 channels) is valid")
    if spec.name == "estimate_relative_pose_batch" and arg in ("K1", "K2") and which == 1:
        pytest.skip("(1, 3, 3) is one K per pair for this batch of one pair")
    with pytest.raises(ValueError) as info:
        spec(**{arg: bad})
    msg = str(info.value)
    # Either this argument's shape, or (numpy makes a scalar a 1-row array; a short 1-D array
    # is a row-count mismatch) the row counts that disagree, named by argument.
    shape = "shape" in msg or "a file path or a numpy array" in msg
    assert (message_name(spec, arg) in msg and shape) or "rows" in msg, msg


@pytest.mark.parametrize("spec, arg", CASES, ids=CASE_IDS)
def test_zero_rows_give_an_empty_result_or_a_value_error(spec, arg):
    value = np.asarray(spec.args[arg])
    if value.ndim == 2 and value.shape == (3, 3) or arg in ("t",):
        pytest.skip("a fixed-size matrix or vector has no rows to drop")
    empty = value[:0]
    if spec.name.endswith("_batch") and arg == "corrs":
        # A pair with no rows is a no-model result in a batch, not an error (issue 23).
        ((model, info),) = spec(**{arg: empty})
        assert info.num_inliers == 0 and len(info.inliers) == 0
        return
    if arg in spec.empty:
        with pytest.raises(ValueError, match=spec.empty[arg]):
            spec(**{arg: empty})
    else:
        # Every other array argument keeps its rows: a length mismatch, or an empty result.
        try:
            out = spec(**{arg: empty})
        except ValueError as e:
            assert message_name(spec, arg) in str(e) or "rows" in str(e), str(e)
        else:
            assert all(a.size == 0 or a.ndim == 0 for a in arrays_of(out)[:1]), out


# --- dtypes and memory orders --------------------------------------------------------------------


def variants(value: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """name -> (variant, its float64 C-ordered equivalent)."""
    v = np.asarray(value)
    as_int = np.round(v * 4).astype(np.int32) if v.dtype.kind == "f" else v
    f32 = v.astype(np.float32)
    strided = np.repeat(v, 2, axis=0)[::2]
    return {
        "int32": (as_int, as_int.astype(np.float64)),
        "float32": (f32, f32.astype(np.float64)),
        "non-contiguous": (strided, np.ascontiguousarray(strided, dtype=np.float64)),
        "fortran": (np.asfortranarray(v), np.ascontiguousarray(v, dtype=np.float64)),
        "list": (v.tolist(), np.asarray(v.tolist(), dtype=np.float64)),
    }


@pytest.mark.parametrize("variant", ["int32", "float32", "non-contiguous", "fortran", "list"])
@pytest.mark.parametrize("spec, arg", CASES, ids=CASE_IDS)
def test_any_dtype_and_memory_order_gives_the_float64_answer(spec, arg, variant):
    value, reference = variants(spec.args[arg])[variant]
    if arg == "image" and variant in ("int32", "list"):
        # Documented: images are paths or arrays of uint8, uint16 or float.
        with pytest.raises(ValueError, match="image (has dtype int32|must be a file path)"):
            spec(**{arg: value})
        return
    if arg == "R" and variant == "int32":
        pytest.skip("a rounded rotation is not a rotation")
    try:
        expected = spec(**{arg: reference})
    except ValueError as e:
        # The variant changed the values into invalid ones (e.g. rounded K): same error either way.
        with pytest.raises(ValueError, match=None) as info:
            spec(**{arg: value})
        assert str(info.value) == str(e)
        return
    assert_identical(spec(**{arg: value}), expected)


@pytest.mark.parametrize(
    "call, fragment",
    [
        (lambda: affcorr.affine_to_laf(CORRS, radius="big"), "radius must be a number"),
        (lambda: affcorr.affine_to_laf(CORRS, radius=0.0), "radius"),
        (lambda: affcorr.affine_to_laf(CORRS, radius=np.nan), "radius"),
        (lambda: affcorr.estimate_homography(CORRS, threshold="1"), "threshold must be a number"),
        (lambda: affcorr.estimate_homography(CORRS, seed=-1), "seed must be a non-negative"),
        (lambda: affcorr.estimate_homography(CORRS, max_iterations=2**70), "max_iterations"),
        (
            lambda: affcorr.estimate_homography_batch([CORRS], pair_options={"seed": 1}),
            "pair_options must be a sequence with one dict",
        ),
        (
            lambda: affcorr.estimate_homography_batch([CORRS], pair_options="ab"),
            "pair_options must be a sequence with one dict",
        ),
        (
            lambda: affcorr.estimate_homography_batch(["abc"], on_error="raise"),
            "pair 0: corrs must be a numeric",
        ),
        (
            lambda: affcorr.estimate_homography(np.array([["a"] * 8] * 4)),
            "corrs must be a numeric array",
        ),
        (lambda: affcorr.decompose_affine(np.array([[[1 + 2j, 0], [0, 1]]])), None),
    ],
    ids=[
        "radius str",
        "radius 0",
        "radius nan",
        "threshold str",
        "seed < 0",
        "max_it huge",
        "pair_options dict",
        "pair_options str",
        "batch of str",
        "corrs of str",
        "complex",
    ],
)
def test_scalar_options_of_the_wrong_type_raise_value_error(call, fragment):
    if fragment is None:
        # numpy drops the imaginary part with a ComplexWarning; no crash, a real decomposition.
        with pytest.warns(Warning):
            theta, scale, _ = call()
        assert scale[0] == pytest.approx(1.0)
        return
    with pytest.raises(ValueError, match=fragment):
        call()


# --- degenerate data ---------------------------------------------------------------------------


def test_degenerate_samples_give_no_model_from_every_solver():
    s = affcorr.solvers
    dup = np.repeat(CORRS[:1], 8, axis=0)
    line = CORRS[:8].copy()
    line[:, 0] = np.arange(8) * 10.0
    line[:, 1] = line[:, 0] * 0.5
    reflected = CORRS[:3].copy()
    reflected[:, 4:] = [1.0, 0.0, 0.0, -1.0]
    singular = CORRS[:3].copy()
    singular[:, 4:] = [1.0, 1.0, 1.0, 1.0]
    for data in (dup, line):
        for name, k in (
            ("homography_4pt", 4),
            ("fundamental_7pt", 7),
            ("homography_lsq", 8),
            ("fundamental_8pt", 8),
        ):
            assert getattr(s, name)(data[:k, :2], data[:k, 2:4]) == [], name
    for data in (dup, reflected, singular):
        assert s.homography_2ac(data[:2]) == []
        assert s.fundamental_3ac(data[:3]) == []
        assert s.essential_2ac(data[:2]) == []
    # ... while the same solvers on the valid rows do find models (so [] is not vacuous).
    assert len(s.homography_4pt(CORRS[:4, :2], CORRS[:4, 2:4])) == 1
    assert len(s.homography_2ac(CORRS[:2])) == 1


@pytest.mark.parametrize("kind", ["duplicate", "det A < 0", "det A = 0"])
@pytest.mark.parametrize("problem", ["homography", "fundamental", "relative_pose"])
def test_degenerate_data_gives_no_model_and_nan(problem, kind):
    data = CORRS.copy()
    if kind == "duplicate":
        data[:] = data[0]
    else:
        data[:, 4:] = [1.0, 0.0, 0.0, -1.0] if kind == "det A < 0" else [1.0, 2.0, 2.0, 4.0]
    if problem == "relative_pose":
        model, info = affcorr.estimate_relative_pose(data, K1, K2, max_iterations=100)
        model = model.R
    else:
        model, info = getattr(affcorr, f"estimate_{problem}")(data, max_iterations=100)
    assert info.num_inliers == 0 and not info.inliers.any() and info.num_iterations == 100
    assert np.isnan(model).all()


@pytest.mark.parametrize(
    "K, fragment",
    [
        (np.zeros((3, 3)), "K[2,2] must be positive"),
        (np.diag([0.0, 500.0, 1.0]), "focal lengths"),
        (np.diag([500.0, -1.0, 1.0]), "focal lengths"),
        (np.diag([1e-200, 1e-200, 1.0]), "numerically singular"),
        (np.ones((3, 3)), "upper triangular"),
    ],
    ids=["zero", "fx = 0", "fy < 0", "tiny focal", "full"],
)
@pytest.mark.parametrize(
    "call",
    [
        lambda K: affcorr.normalize_correspondences(CORRS, K, K2),
        lambda K: affcorr.fundamental_from_essential(E, K, K2),
        lambda K: affcorr.estimate_relative_pose(CORRS, K, K2),
        lambda K: affcorr.estimate_relative_pose_batch([CORRS], K, K2),
    ],
    ids=["normalize", "fundamental_from_essential", "estimate", "estimate_batch"],
)
def test_singular_or_zero_focal_intrinsics_raise_value_error(call, K, fragment):
    with pytest.raises(
        ValueError, match="K1 is not a valid intrinsic matrix.*" + re.escape(fragment)
    ):
        call(K)


@pytest.mark.parametrize("t", [0.0, -2.0, np.nan, np.inf])
@pytest.mark.parametrize(
    "call",
    [
        lambda t: affcorr.estimate_homography(CORRS, threshold=t),
        lambda t: affcorr.estimate_fundamental_batch([CORRS], threshold=t),
        lambda t: affcorr.estimate_relative_pose(CORRS, K1, K2, threshold=t),
    ],
    ids=["homography", "fundamental_batch", "relative_pose"],
)
def test_threshold_must_be_positive_and_finite(call, t):
    with pytest.raises(ValueError, match="threshold = .* is invalid: must be positive"):
        call(t)


# --- N = 10^7 ----------------------------------------------------------------------------------


def test_ten_million_rows_are_validated_to_the_last_row():
    """Validation scans all 10^7 rows before any work (0.14 s measured; the full estimation at
    this size is measured once in docs/reliability.md, not here)."""
    corrs = np.zeros((10**7, 4))
    corrs[-1, 3] = np.nan
    with pytest.raises(ValueError, match=r"corrs\[9999999\] contains NaN"):
        affcorr.estimate_homography(corrs)
    with pytest.raises(ValueError, match=r"corrs\[9999999\] contains NaN"):
        affcorr.sampson_point(F, corrs)


# --- torch losses (optional) ---------------------------------------------------------------------


def test_losses_reject_nan_and_accept_float32():
    torch = pytest.importorskip("torch")
    from affcorr import losses

    c = torch.tensor(CORRS)
    f = torch.tensor(F)
    # float32 corrs give the answer of their float64 values.
    ref = losses.point_sampson(f, c.float().double())
    assert torch.equal(losses.point_sampson(f, c.float()), ref)
    bad = c.clone()
    bad[-1, 0] = float("nan")
    with pytest.raises(ValueError, match=r"corrs\[39\] contains NaN"):
        losses.point_sampson(f, bad)
    with pytest.raises(ValueError, match="reduction"):
        losses.PointSampsonLoss(reduction="max")
