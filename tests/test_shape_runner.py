"""The shape-network runner (affcorr.ShapeEstimator) against independent references.

- image decoding vs PIL + numpy's BT.601 luma;
- patch extraction vs a numpy bilinear reference (and scipy's map_coordinates when installed);
- Rust inference vs Python's onnxruntime.InferenceSession on the same patches;
- the softmax-mean decoding vs numpy, and the ACs vs synthesize_affine(O_B - O_A, S_B / S_A, A'');
- every bad input gives ValueError / FileNotFoundError / RuntimeError naming the problem.

The fixture models in tests/data/shape/ are written by make_fixtures.py there: echo.onnx's outputs
are slices of the flattened patches (angle logits = pixels 0..8, scale logits = 8..13, residual
shape = 16..19 of patch A).
"""

from __future__ import annotations

import doctest
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import affcorr
import affcorr.shape
import numpy as np
import pytest
from PIL import Image

DATA = Path(__file__).resolve().parent / "data" / "shape"
LUMA = np.array([0.299, 0.587, 0.114])


@pytest.fixture(scope="module")
def bundled():
    return affcorr.ShapeEstimator(threads=2)


@pytest.fixture(scope="module")
def echo():
    return affcorr.ShapeEstimator(DATA / "echo.onnx", threads=1)


def random_image(h=61, w=83, seed=0):
    return np.random.default_rng(seed).random((h, w))


# --- numpy references ------------------------------------------------------------------------


def bilinear_patches(img: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Pixel (r, c) = img read at (x + c - 15.5, y + r - 15.5), coordinates clamped to the image."""
    h, w = img.shape
    offs = np.arange(32) - 15.5
    u = np.clip(xy[:, 0, None, None] + offs[None, None, :], 0, w - 1)  # (N, 1, 32)
    v = np.clip(xy[:, 1, None, None] + offs[None, :, None], 0, h - 1)  # (N, 32, 1)
    u, v = np.broadcast_arrays(u, v)
    x0, y0 = np.floor(u).astype(int), np.floor(v).astype(int)
    x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
    fx, fy = u - x0, v - y0
    top = (1 - fx) * img[y0, x0] + fx * img[y0, x1]
    bottom = (1 - fx) * img[y1, x0] + fx * img[y1, x1]
    return ((1 - fy) * top + fy * bottom)[:, None]


def softmax_mean(logits: np.ndarray, bins: np.ndarray, angle: bool) -> np.ndarray:
    z = logits.astype(np.float64)
    p = np.exp(z - z.max(axis=1, keepdims=True))
    p /= p.sum(axis=1, keepdims=True)
    if angle:
        return np.arctan2(p @ np.sin(bins), p @ np.cos(bins))
    return np.exp(p @ np.log(bins))


def angle_diff(a, b):
    return np.abs(np.angle(np.exp(1j * (np.asarray(a) - np.asarray(b)))))


# --- ONNX Runtime library ---------------------------------------------------------------------


def test_the_library_comes_from_the_onnxruntime_wheel(monkeypatch):
    monkeypatch.delenv("ORT_DYLIB_PATH", raising=False)
    lib = affcorr.shape.find_ort_library()
    assert lib.is_file() and lib.name.startswith("libonnxruntime")
    assert lib.parent.name == "capi" and lib.parent.parent.name == "onnxruntime"
    monkeypatch.setenv("ORT_DYLIB_PATH", "/somewhere/libonnxruntime.so")
    assert affcorr.shape.find_ort_library() is None


def test_no_onnxruntime_package_is_a_runtime_error(monkeypatch):
    monkeypatch.delenv("ORT_DYLIB_PATH", raising=False)
    monkeypatch.setattr(affcorr.shape.importlib.util, "find_spec", lambda name: None)
    with pytest.raises(RuntimeError, match="pip install onnxruntime"):
        affcorr.shape.find_ort_library()


def run_fresh(code: str, **env: str) -> subprocess.CompletedProcess:
    """Runs code in a new interpreter (ONNX Runtime is loaded once per process)."""
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        env={**os.environ, **env},
        capture_output=True,
        text=True,
        timeout=120,
    )


@pytest.mark.parametrize("kind", ["missing", "not_a_library"])
def test_a_bad_ort_library_is_a_runtime_error_naming_it(tmp_path, kind):
    lib = tmp_path / "libonnxruntime.so.1.99.0"
    if kind == "not_a_library":
        lib.write_text("not a shared library")
    code = """
        import affcorr
        try:
            affcorr.ShapeEstimator()
        except RuntimeError as e:
            print("RuntimeError:", e)
        """
    out = run_fresh(code, ORT_DYLIB_PATH=str(lib))
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("RuntimeError:"), out.stdout + out.stderr
    assert str(lib) in out.stdout
    if kind == "missing":
        assert "does not exist" in out.stdout and "ORT_DYLIB_PATH" in out.stdout
    else:
        assert "could not load" in out.stdout
    assert "panicked" not in out.stderr


def test_init_ort_reports_the_loaded_library(bundled):
    lib = affcorr._native.ort_library()
    assert lib is not None and Path(lib).is_file()
    # Later calls keep the loaded library.
    assert Path(affcorr._native.init_ort()) == Path(lib)


# --- images -----------------------------------------------------------------------------------


def luma(rgb: np.ndarray) -> np.ndarray:
    return rgb[..., :3] @ LUMA


@pytest.mark.parametrize("mode", ["L", "LA", "RGB", "RGBA", "P", "I;16"])
def test_png_modes_decode_to_bt601_gray(tmp_path, mode):
    rng = np.random.default_rng(1)
    if mode == "I;16":
        raw = rng.integers(0, 65536, (13, 17), dtype=np.uint16)
        img = Image.fromarray(raw)
        want = raw / 65535.0
    elif mode == "P":
        rgb = rng.integers(0, 256, (13, 17, 3), dtype=np.uint8)
        img = Image.fromarray(rgb).quantize(16)
        want = luma(np.asarray(img.convert("RGB")) / 255.0)
    else:
        channels = {"L": 1, "LA": 2, "RGB": 3, "RGBA": 4}[mode]
        raw = rng.integers(0, 256, (13, 17, channels), dtype=np.uint8)
        img = Image.fromarray(raw[..., 0] if channels == 1 else raw, mode)
        want = raw[..., 0] / 255.0 if channels <= 2 else luma(raw / 255.0)
    path = tmp_path / "img.png"
    img.save(path)
    got = affcorr.read_gray_image(path)
    assert got.dtype == np.float32 and got.shape == (13, 17)
    np.testing.assert_allclose(got, want, atol=1e-6)
    np.testing.assert_array_equal(affcorr.read_gray_image(str(path)), got)


@pytest.mark.parametrize("mode", ["L", "RGB"])
def test_jpeg_decodes_close_to_pil(tmp_path, mode):
    yy, xx = np.mgrid[0:48, 0:64]
    rgb = np.stack([xx * 3 + 20, yy * 4 + 10, (xx + yy) * 2 + 5], axis=-1).astype(np.uint8)
    img = Image.fromarray(rgb).convert(mode)
    path = tmp_path / "img.jpg"
    img.save(path, quality=95)
    decoded = np.asarray(Image.open(path).convert("RGB")) / 255.0
    want = decoded[..., 0] if mode == "L" else luma(decoded)
    got = affcorr.read_gray_image(path)
    # Two JPEG decoders (zune-jpeg vs libjpeg) differ by rounding only.
    assert np.abs(got - want).max() < 4 / 255 and np.abs(got - want).mean() < 1 / 255


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32, np.float64])
@pytest.mark.parametrize("channels", [None, 1, 2, 3, 4])
def test_array_images(dtype, channels):
    rng = np.random.default_rng(2)
    shape = (9, 11) if channels is None else (9, 11, channels)
    unit = rng.random(shape)
    if dtype == np.uint8:
        arr = (unit * 255).round().astype(np.uint8)
        unit = arr / 255.0
    elif dtype == np.uint16:
        arr = (unit * 65535).round().astype(np.uint16)
        unit = arr / 65535.0
    else:
        arr = unit.astype(dtype)
    if channels is None:
        want = unit
    elif channels <= 2:
        want = unit[..., 0]
    else:
        want = luma(unit)
    np.testing.assert_allclose(affcorr.read_gray_image(arr), want, atol=1e-6)
    # Non-contiguous views are fine.
    np.testing.assert_allclose(affcorr.read_gray_image(arr[::2, ::-1]), want[::2, ::-1], atol=1e-6)


def test_bad_images(tmp_path):
    with pytest.raises(ValueError, match=r"image must have shape \(H, W\) or \(H, W, C\)"):
        affcorr.read_gray_image(np.zeros((4, 4, 5), np.uint8))
    with pytest.raises(ValueError, match=r"image must have shape"):
        affcorr.read_gray_image(np.zeros(4, np.uint8))
    with pytest.raises(ValueError, match="image has dtype int64"):
        affcorr.read_gray_image(np.zeros((4, 4), np.int64))
    nan = np.zeros((4, 4))
    nan[2, 3] = np.nan
    with pytest.raises(ValueError, match=r"image: .*x = 3, y = 2.*NaN"):
        affcorr.read_gray_image(nan)
    with pytest.raises(ValueError, match="empty"):
        affcorr.read_gray_image(np.zeros((0, 4), np.uint8))
    with pytest.raises(FileNotFoundError, match="missing.png"):
        affcorr.read_gray_image(tmp_path / "missing.png")
    junk = tmp_path / "junk.png"
    junk.write_bytes(b"\x89PNG but not really")
    with pytest.raises(ValueError, match="junk.png"):
        affcorr.read_gray_image(junk)
    good = tmp_path / "good.png"
    Image.fromarray(np.zeros((64, 64), np.uint8)).save(good)
    truncated = tmp_path / "truncated.png"
    truncated.write_bytes(good.read_bytes()[:60])
    with pytest.raises(ValueError, match="truncated.png"):
        affcorr.read_gray_image(truncated)
    with pytest.raises(ValueError, match="image must be a file path or a numpy array"):
        affcorr.read_gray_image(3.5)


# --- patches ----------------------------------------------------------------------------------


def centres(img, n=60, seed=3):
    h, w = img.shape
    rng = np.random.default_rng(seed)
    xy = np.c_[rng.uniform(-25, w + 25, n), rng.uniform(-25, h + 25, n)]
    edge = [[0, 0], [w - 1, h - 1], [15.5, 15.5], [w / 2, -0.25], [-1e5, 1e5], [40.0, 30.0]]
    return np.r_[xy, edge]


def test_patches_match_the_numpy_reference():
    img = random_image()
    xy = centres(img)
    got = affcorr.extract_patches(img, xy)
    assert got.dtype == np.float32 and got.shape == (len(xy), 1, 32, 32)
    assert got.flags.c_contiguous
    np.testing.assert_allclose(got, bilinear_patches(img, xy), atol=2e-6)
    # Many centres run in parallel and give the same values.
    many = np.tile(xy, (5, 1))
    np.testing.assert_array_equal(affcorr.extract_patches(img, many), np.tile(got, (5, 1, 1, 1)))


def test_patches_match_scipy_map_coordinates():
    ndimage = pytest.importorskip("scipy.ndimage")
    img = random_image(seed=4)
    xy = centres(img, seed=5)
    offs = np.arange(32) - 15.5
    for k, (x, y) in enumerate(xy):
        rows, cols = np.meshgrid(y + offs, x + offs, indexing="ij")
        want = ndimage.map_coordinates(img, [rows, cols], order=1, mode="nearest")
        got = affcorr.extract_patches(img, xy[k : k + 1])[0, 0]
        np.testing.assert_allclose(got, want, atol=2e-6, err_msg=f"centre {k}")


def test_patches_from_a_file_equal_patches_from_the_array(tmp_path, echo):
    arr = (random_image(seed=6) * 255).round().astype(np.uint8)
    Image.fromarray(arr).save(tmp_path / "a.png")
    xy = centres(arr, n=10)
    np.testing.assert_array_equal(
        echo.extract_patches(tmp_path / "a.png", xy), affcorr.extract_patches(arr, xy)
    )
    np.testing.assert_allclose(
        affcorr.extract_patches(arr, xy), bilinear_patches(arr / 255.0, xy), atol=2e-6
    )


def test_bad_centres():
    img = random_image()
    with pytest.raises(ValueError, match=r"xy must have shape \(N, 2\)"):
        affcorr.extract_patches(img, np.zeros((3, 3)))
    xy = np.zeros((4, 2))
    xy[2, 1] = np.inf
    with pytest.raises(ValueError, match=r"xy\[2\] contains NaN or infinity"):
        affcorr.extract_patches(img, xy)
    assert affcorr.extract_patches(img, np.zeros((0, 2))).shape == (0, 1, 32, 32)


# --- inference and decoding -------------------------------------------------------------------


def test_rust_inference_matches_python_onnxruntime(bundled):
    ort = pytest.importorskip("onnxruntime")
    rng = np.random.default_rng(7)
    a = rng.random((40, 1, 32, 32), dtype=np.float32)
    b = rng.random((40, 1, 32, 32), dtype=np.float32)
    ref = ort.InferenceSession(
        str(affcorr.shape.bundled_shape_model()), providers=["CPUExecutionProvider"]
    )
    names = [o.name for o in ref.get_outputs()]
    want = dict(zip(names, ref.run(None, {"patch_a": a, "patch_b": b})))
    got = bundled.predict(a, b, return_logits=True)
    for name in ["angle_logits_a", "angle_logits_b", "scale_logits_a", "scale_logits_b"]:
        assert got[name].dtype == np.float32
        np.testing.assert_allclose(got[name], want[name], atol=1e-5, rtol=1e-5, err_msg=name)
    np.testing.assert_allclose(got["residual_shape_raw"], want["residual_shape"], atol=1e-5)
    # Decoding vs numpy from Python's logits.
    for side in "ab":
        o = softmax_mean(want[f"angle_logits_{side}"], bundled.angle_bins, angle=True)
        s = softmax_mean(want[f"scale_logits_{side}"], bundled.scale_bins, angle=False)
        assert angle_diff(got[f"orientation_{side}"], o).max() < 1e-5
        np.testing.assert_allclose(got[f"scale_{side}"], s, rtol=1e-5)
    np.testing.assert_allclose(got["residual_shape"], want["residual_shape"], atol=1e-5)


def test_bins_come_from_the_metadata(bundled):
    import json

    ort = pytest.importorskip("onnxruntime")
    session = ort.InferenceSession(str(bundled.model_path), providers=["CPUExecutionProvider"])
    meta = session.get_modelmeta().custom_metadata_map
    np.testing.assert_array_equal(bundled.angle_bins, json.loads(meta["angle_bins"]))
    np.testing.assert_array_equal(bundled.scale_bins, json.loads(meta["scale_bins"]))
    assert bundled.metadata == meta


def test_softmax_mean_decoding_is_exact_on_the_echo_model(echo):
    rng = np.random.default_rng(8)
    a = np.full((25, 1, 32, 32), 0.5, np.float32)
    b = np.full((25, 1, 32, 32), 0.5, np.float32)
    for p in (a, b):
        p[:, 0, 0, :13] = rng.uniform(-6, 6, (25, 13))
    a[:, 0, 0, 16:19] = rng.uniform(-0.5, 0.5, (25, 3))
    got = echo.predict(a, b, return_logits=True)
    np.testing.assert_array_equal(got["angle_logits_b"], b[:, 0, 0, :8])
    np.testing.assert_array_equal(got["scale_logits_a"], a[:, 0, 0, 8:13])
    for side, p in (("a", a), ("b", b)):
        o = softmax_mean(p[:, 0, 0, :8], echo.angle_bins, angle=True)
        s = softmax_mean(p[:, 0, 0, 8:13], echo.scale_bins, angle=False)
        np.testing.assert_allclose(got[f"orientation_{side}"], o, atol=1e-12)
        np.testing.assert_allclose(got[f"scale_{side}"], s, rtol=1e-12)
    np.testing.assert_array_equal(got["residual_shape"], a[:, 0, 0, 16:19].astype(np.float64))
    np.testing.assert_array_equal(echo.scale_bins, [0.25, 0.5, 1.0, 2.0, 4.0])


def test_batches_do_not_change_the_result(bundled):
    rng = np.random.default_rng(9)
    a = rng.random((23, 1, 32, 32), dtype=np.float32)
    b = rng.random((23, 1, 32, 32), dtype=np.float32)
    small = affcorr.ShapeEstimator(threads=1, batch_size=5)
    assert small.batch_size == 5 and small.threads == 1
    one, many = small.predict(a, b), bundled.predict(a, b)
    for k in one:
        np.testing.assert_allclose(one[k], many[k], atol=1e-6, err_msg=k)
    empty = bundled.predict(np.zeros((0, 1, 32, 32)), np.zeros((0, 1, 32, 32)))
    assert empty["orientation_a"].shape == (0,) and empty["residual_shape"].shape == (0, 3)


@pytest.mark.parametrize("model", ["bundled", "echo"])
def test_acs_are_synthesised_from_orientation_scale_and_residual_shape(model, request):
    est = request.getfixturevalue(model)
    img_a, img_b = random_image(seed=10), random_image(seed=11)
    rng = np.random.default_rng(12)
    x1 = np.c_[rng.uniform(0, 83, 30), rng.uniform(0, 61, 30)]
    x2 = x1 + rng.normal(0, 3, x1.shape)
    d = est.estimate_detailed(img_a, img_b, x1, x2)
    assert d.corrs.shape == (30, 8) and d.residual_shape.shape == (30, 3)
    np.testing.assert_array_equal(d.corrs[:, :4], np.c_[x1, x2])
    a = affcorr.synthesize_affine(
        d.orientation_b - d.orientation_a, d.scale_b / d.scale_a, d.residual_shape
    )
    np.testing.assert_allclose(d.corrs[:, 4:], a.reshape(-1, 4), atol=1e-12)
    # The per-patch values are the network's on the extracted patches.
    p = est.predict(est.extract_patches(img_a, x1), est.extract_patches(img_b, x2))
    for k in ["orientation_a", "orientation_b", "scale_a", "scale_b", "residual_shape"]:
        np.testing.assert_allclose(getattr(d, k), p[k], atol=1e-12, err_msg=k)
    np.testing.assert_array_equal(est.estimate(img_a, img_b, x1, x2, refine=False), d.corrs)


def test_estimate_reads_files_like_arrays(tmp_path, bundled):
    rgb = (np.random.default_rng(13).random((50, 70, 3)) * 255).astype(np.uint8)
    Image.fromarray(rgb).save(tmp_path / "a.png")
    x = np.array([[10.0, 20.0], [35.5, 24.25], [69.0, 0.0]])
    from_file = bundled.estimate(tmp_path / "a.png", str(tmp_path / "a.png"), x, x + 0.5)
    from_array = bundled.estimate(rgb, rgb, x, x + 0.5)
    np.testing.assert_array_equal(from_file, from_array)


# --- bad inputs and bad models ----------------------------------------------------------------


def test_bad_estimate_arguments_are_value_errors_naming_them(echo):
    img = random_image()
    x = np.zeros((3, 2))
    with pytest.raises(ValueError, match=r"x1 must have shape \(N, 2\)"):
        echo.estimate(img, img, np.zeros((3, 3)), x)
    with pytest.raises(ValueError, match="x2 has 2 points, but x1 has 3"):
        echo.estimate(img, img, x, x[:2])
    bad = x.copy()
    bad[1, 0] = np.nan
    with pytest.raises(ValueError, match=r"x2\[1\] contains NaN or infinity"):
        echo.estimate(img, img, x, bad)
    with pytest.raises(ValueError, match=r"x1\[1\] contains NaN or infinity"):
        echo.estimate(img, img, bad, x)
    with pytest.raises(ValueError, match="image_b must have shape"):
        echo.estimate(img, np.zeros((3, 3, 7)), x, x)
    with pytest.raises(FileNotFoundError, match="image_a: .*nope.png"):
        echo.estimate("nope.png", img, x, x)


def test_bad_patches(echo):
    good = np.zeros((2, 1, 32, 32), np.float32)
    with pytest.raises(ValueError, match=r"patches_a must have shape \(N, 1, 32, 32\)"):
        echo.predict(np.zeros((2, 32, 32)), good)
    with pytest.raises(ValueError, match=r"patches_b must have shape \(N, 1, 32, 32\)"):
        echo.predict(good, np.zeros((2, 3, 32, 32)))
    with pytest.raises(ValueError, match="patches_b has 1 patches, but patches_a has 2"):
        echo.predict(good, good[:1])
    nan = good.copy()
    nan[1, 0, 5, 5] = np.nan
    with pytest.raises(ValueError, match=r"patches_a\[1\] contains NaN"):
        echo.predict(nan, good)


def test_bad_options():
    with pytest.raises(ValueError, match="threads"):
        affcorr.ShapeEstimator(threads=0)
    with pytest.raises(ValueError, match="batch_size"):
        affcorr.ShapeEstimator(batch_size=0)
    # Checked where the option is parsed, naming it (issue 23: every option names itself).
    with pytest.raises(ValueError, match="threads must be a positive int or None, got 0"):
        affcorr._native.ShapeRunner(str(DATA / "echo.onnx"), threads=0)


def test_unreadable_models(tmp_path, bundled):
    with pytest.raises(FileNotFoundError, match="missing.onnx"):
        affcorr.ShapeEstimator(tmp_path / "missing.onnx")
    junk = tmp_path / "junk.onnx"
    junk.write_bytes(b"not a protobuf at all")
    with pytest.raises(RuntimeError, match="junk.onnx.*not a valid ONNX model"):
        affcorr.ShapeEstimator(junk)
    truncated = tmp_path / "truncated.onnx"
    truncated.write_bytes(affcorr.shape.bundled_shape_model().read_bytes()[:5000])
    with pytest.raises(RuntimeError, match="truncated.onnx"):
        affcorr.ShapeEstimator(truncated)


@pytest.mark.parametrize(
    "name, fragments",
    [
        ("no_contract.onnx", ["affcorr.contract is missing", "angle_bins is missing"]),
        ("wrong_contract.onnx", ['affcorr.contract is "dense-v1", expected "shape-v1"']),
        ("bad_metadata.onnx", ['patch_size is "64"', 'decode is "argmax"', "scale_bins[1] = -2"]),
        ("wrong_input_name.onnx", ["input patch_a is missing", "unexpected input patch"]),
        ("wrong_input_shape.onnx", ["input patch_a: has shape (N, 3, 32, 32)"]),
        ("wrong_outputs.onnx", ["output residual_shape is missing", "output angle_logits_b"]),
        ("wrong_dtype.onnx", ["output residual_shape: has element type"]),
        ("width_mismatch.onnx", ["output angle_logits_a: has shape (N, 8), expected (N, 7)"]),
        ("width_mismatch_symbolic.onnx", ["output scale_logits_a on one patch pair"]),
    ],
)
def test_contract_violations_are_runtime_errors_saying_what_is_wrong(name, fragments, bundled):
    with pytest.raises(RuntimeError) as info:
        affcorr.ShapeEstimator(DATA / name)
    msg = str(info.value)
    assert name in msg and "violates the shape-v1 contract" in msg
    for f in fragments:
        assert f in msg, msg


def test_fixtures_are_what_the_script_writes(tmp_path):
    """The committed fixtures are reproducible (needs the onnx package)."""
    pytest.importorskip("onnx")
    import importlib.util

    spec = importlib.util.spec_from_file_location("make_fixtures", DATA / "make_fixtures.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    for name, make in module.FIXTURES.items():
        assert make().SerializeToString(deterministic=True) == (DATA / name).read_bytes(), name


def test_docstring_examples():
    result = doctest.testmod(affcorr.shape, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0 and result.failed == 0
