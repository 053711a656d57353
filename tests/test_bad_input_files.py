"""Bad-input battery for files: images, ONNX models and the ONNX Runtime library.

Every image-taking entry point (``read_gray_image``, ``extract_patches``,
``ShapeEstimator.estimate``, ``Pipeline.match_pair``) gets the same files: truncated PNG/JPEG,
zero-sized and huge headers, 16-bit, RGBA and grayscale. Bad files are ``ValueError`` naming the
file; a missing file is ``FileNotFoundError`` (the one documented exception to "ValueError or
RuntimeError": it is what ``open()`` raises, and an ``OSError``). Models that are missing,
corrupt or break their contract, and ONNX Runtime libraries that are missing, not ONNX Runtime,
too old or broken, are ``RuntimeError`` (``FileNotFoundError`` when missing), never a panic: the
library cases run in a fresh interpreter, because ONNX Runtime loads once per process.
"""

from __future__ import annotations

import io
import os
import re
import shutil
import struct
import subprocess
import sys
import textwrap
import zlib
from pathlib import Path

import affcorr
import numpy as np
import pytest
from affcorr.data import data_dir
from PIL import Image

SHAPE_DATA = Path(__file__).resolve().parent / "data" / "shape"
MODELS = Path(affcorr.__file__).resolve().parent / "models"


def png(width: int, height: int, depth: int = 8, colour: int = 0, data: bytes = b"\0" * 4):
    """A PNG whose header says width x height over `data` (compressed) as its pixel stream."""

    def chunk(kind: bytes, body: bytes) -> bytes:
        crc = zlib.crc32(kind + body) & 0xFFFFFFFF
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", crc)

    ihdr = struct.pack(">IIBBBBB", width, height, depth, colour, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", zlib.compress(data))
        + chunk(b"IEND", b"")
    )


def truncated(kind: str) -> bytes:
    """A 64x64 PNG or JPEG cut in the middle."""
    img = Image.fromarray((np.arange(64 * 64) % 251).astype(np.uint8).reshape(64, 64))
    buf = io.BytesIO()
    img.save(buf, format=kind)
    data = buf.getvalue()
    return data[: len(data) // 2]


# name -> (file bytes, message fragment of the ValueError)
BAD_FILES = {
    "truncated.png": (truncated("PNG"), "truncated.png"),
    "truncated.jpg": (truncated("JPEG"), "truncated JPEG"),
    "empty.png": (b"", "unrecognised format"),
    "text.png": (b"hello", "unrecognised format"),
    "zero_width.png": (png(0, 10), "Invalid image dimensions"),
    "zero_height.png": (png(10, 0), "Invalid image dimensions"),
    "huge_rgb.png": (png(20_000, 20_000, 8, 2), "the image is 20000×20000 pixels, over the"),
    "huge_rgba16.png": (png(100_000, 100_000, 16, 6), "Memory limit exceeded: the image is"),
    "huge_gray_short.png": (png(20_000, 20_000), "not have enough data"),
}


@pytest.fixture(scope="module")
def echo():
    return affcorr.ShapeEstimator(SHAPE_DATA / "echo.onnx", threads=1)


@pytest.fixture(scope="module")
def pipe():
    return affcorr.Pipeline("xfeat", max_keypoints=256, threads=1)


def entry_points(echo, pipe):
    good = np.random.default_rng(0).random((64, 64))
    xy = np.array([[30.0, 30.0]])
    return {
        "read_gray_image": lambda img: affcorr.read_gray_image(img),
        "extract_patches": lambda img: affcorr.extract_patches(img, xy),
        "ShapeEstimator.estimate": lambda img: echo.estimate(good, img, xy, xy),
        "Pipeline.match_pair": lambda img: pipe.match_pair(img, good),
    }


ENTRY_IDS = ["read_gray_image", "extract_patches", "ShapeEstimator.estimate", "Pipeline.match_pair"]


@pytest.mark.parametrize("entry", ENTRY_IDS)
@pytest.mark.parametrize("name", list(BAD_FILES))
def test_bad_image_files_raise_value_error_naming_the_file(tmp_path, echo, pipe, entry, name):
    data, fragment = BAD_FILES[name]
    path = tmp_path / name
    path.write_bytes(data)
    with pytest.raises(ValueError) as info:
        entry_points(echo, pipe)[entry](path)
    msg = str(info.value)
    assert name in msg and fragment in msg, msg


@pytest.mark.parametrize("entry", ENTRY_IDS)
def test_a_missing_image_is_file_not_found_and_a_directory_a_value_error(
    tmp_path, echo, pipe, entry
):
    call = entry_points(echo, pipe)[entry]
    with pytest.raises(FileNotFoundError, match="nope.png"):
        call(tmp_path / "nope.png")
    with pytest.raises(ValueError, match="Is a directory"):
        call(tmp_path)


@pytest.mark.parametrize(
    "mode, dtype",
    [("L", np.uint8), ("I;16", np.uint16), ("RGB", np.uint8), ("RGBA", np.uint8)],
    ids=["gray8", "gray16", "rgb", "rgba"],
)
def test_16_bit_rgba_and_gray_files_decode_like_their_arrays(tmp_path, mode, dtype):
    rng = np.random.default_rng(1)
    channels = {"L": None, "I;16": None, "RGB": 3, "RGBA": 4}[mode]
    shape = (37, 53) if channels is None else (37, 53, channels)
    top = 65535 if dtype == np.uint16 else 255
    arr = rng.integers(0, top + 1, shape).astype(dtype)
    path = tmp_path / "img.png"
    img = Image.fromarray(arr)
    assert img.mode == mode
    img.save(path)
    from_file = affcorr.read_gray_image(path)
    assert from_file.shape == (37, 53)
    np.testing.assert_array_equal(from_file, affcorr.read_gray_image(arr))
    if dtype == np.uint16:
        # 16-bit precision is kept: the values are not those of an 8-bit copy.
        assert not np.array_equal(from_file, np.round(from_file * 255) / 255)


def test_the_matcher_refuses_images_too_small_or_too_large_for_it(pipe):
    """Under 32 px, or over 64 MP at the working resolution (≈160 MB per MP: an out-of-memory
    abort otherwise), the matcher says so before running; max_side brings a large one in."""
    with pytest.raises(ValueError, match="too small"):
        pipe.match_pair(np.zeros((20, 20)), np.zeros((20, 20)))
    huge = np.zeros((8200, 8200), np.uint8)
    with pytest.raises(ValueError, match=r"image_a: 8200×8200 pixels is over .* set max_side"):
        pipe.match_pair(huge, np.zeros((64, 64)))
    small = affcorr.Pipeline("xfeat", max_keypoints=64, max_side=512, threads=1)
    assert small.match_pair(huge, huge).corrs.shape[1] == 8  # runs (at 512 px)


# --- models ----------------------------------------------------------------------------------


def bad_models(tmp_path: Path) -> dict[str, tuple[Path, type, str]]:
    """name -> (model path, exception, message fragment)."""
    (tmp_path / "empty.onnx").write_bytes(b"")
    (tmp_path / "junk.onnx").write_bytes(b"\x08\x07 not a protobuf")
    cut = MODELS / "shape.onnx"
    (tmp_path / "cut.onnx").write_bytes(cut.read_bytes()[:4000])
    (tmp_path / "a_dir.onnx").mkdir()
    return {
        "missing": (tmp_path / "missing.onnx", FileNotFoundError, "missing.onnx"),
        "directory": (tmp_path / "a_dir.onnx", RuntimeError, "a_dir.onnx"),
        "empty": (tmp_path / "empty.onnx", RuntimeError, "empty.onnx"),
        "junk": (tmp_path / "junk.onnx", RuntimeError, "not a valid ONNX model"),
        "truncated": (tmp_path / "cut.onnx", RuntimeError, "cut.onnx"),
        "wrong contract": (SHAPE_DATA / "wrong_contract.onnx", RuntimeError, "shape-v1"),
        "a matcher": (MODELS / "xfeat_refine.onnx", RuntimeError, "violates the shape-v1"),
    }


MODEL_CASES = ["missing", "directory", "empty", "junk", "truncated", "wrong contract", "a matcher"]


@pytest.mark.parametrize("case", MODEL_CASES)
@pytest.mark.parametrize("where", ["ShapeEstimator", "Pipeline shape_model", "Pipeline backbone"])
def test_bad_models_raise_naming_the_file_and_problem(tmp_path, case, where):
    path, exc, fragment = bad_models(tmp_path)[case]
    if where == "Pipeline backbone":
        if case == "wrong contract":
            pytest.skip("a shape-v1 fixture as backbone is the 'a matcher' case reversed")
        d = tmp_path / "models"
        d.mkdir()
        if path.is_dir():
            (d / "xfeat_backbone.onnx").mkdir()
        elif path.exists():
            shutil.copy(path, d / "xfeat_backbone.onnx")
        if case == "a matcher":
            fragment = "features-backbone-v1"
        elif case != "junk":
            fragment = "xfeat_backbone.onnx"
        with pytest.raises(exc, match=fragment):
            affcorr.Pipeline("xfeat", models_dir=d, threads=1)
        return
    with pytest.raises(exc, match=fragment):
        if where == "ShapeEstimator":
            affcorr.ShapeEstimator(path, threads=1)
        else:
            affcorr.Pipeline("xfeat", shape_model=path, threads=1)


def test_missing_files_are_also_os_errors():
    """FileNotFoundError is an OSError: `except OSError` and `except FileNotFoundError` work."""
    with pytest.raises(OSError):
        affcorr.read_gray_image("/nonexistent/dir/x.png")
    assert issubclass(FileNotFoundError, OSError)


# --- the ONNX Runtime library ------------------------------------------------------------------

CHILD = """
    import affcorr
    try:
        affcorr.ShapeEstimator()
        print("OK")
    except BaseException as e:
        print(type(e).__name__ + ":", e)
    """


def fake_ort(tmp_path: Path, version: str) -> Path:
    """tests/data/fake_ort/fake_ort.c built as a library reporting `version` (an old build, or a
    broken one: its GetApi returns NULL)."""
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        pytest.skip("no C compiler for the fake ONNX Runtime library")
    src = Path(__file__).resolve().parent / "data" / "fake_ort" / "fake_ort.c"
    lib = tmp_path / f"libonnxruntime.so.{version}"
    define = f'-DFAKE_ORT_VERSION="{version}"'
    subprocess.run([cc, "-shared", "-fPIC", define, "-o", str(lib), str(src)], check=True)
    return lib


def libc() -> Path:
    for line in Path("/proc/self/maps").read_text().splitlines():
        parts = line.split()
        if len(parts) >= 6 and ("/libc.so" in parts[5] or "/libc-" in parts[5]):
            return Path(parts[5])
    pytest.skip("libc not found in /proc/self/maps")


@pytest.mark.parametrize(
    "kind, fragment",
    [
        ("missing", "does not exist"),
        ("libc", "does not export `OrtGetApiBase`"),
        ("too old", "expected version >= '1.20"),
        ("null api", "could not load the ONNX Runtime library"),
    ],
)
def test_a_bad_ort_library_is_a_runtime_error_in_a_fresh_process(tmp_path, kind, fragment):
    lib = {
        "missing": lambda: tmp_path / "libonnxruntime.so.1.31.1",
        "libc": libc,
        "too old": lambda: fake_ort(tmp_path, "1.10.0"),
        "null api": lambda: fake_ort(tmp_path, "1.31.0"),
    }[kind]()
    out = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(CHILD)],
        env={**os.environ, "ORT_DYLIB_PATH": str(lib)},
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("RuntimeError:"), out.stdout + out.stderr
    assert str(lib) in out.stdout and fragment in out.stdout, out.stdout
    assert "PanicException" not in out.stdout


def test_the_bundled_data_still_decodes():
    """The battery's reference: the real images decode (so the failures above are the files')."""
    img = affcorr.read_gray_image(data_dir() / "graffiti" / "graf1.png")
    assert img.shape == (640, 800) and 0.0 <= img.min() < img.max() <= 1.0


def test_the_reliability_table_names_tests_that_exist():
    """docs/reliability.md's bad-input table is checked against the tests it cites."""
    root = Path(__file__).resolve().parent.parent
    doc = (root / "docs" / "reliability.md").read_text()
    section = doc.split("## Bad-input battery")[1].split("\n## ")[0]
    rows = [r for r in section.splitlines() if r.startswith("| ") and "---" not in r][1:]
    files = [*(root / "tests").glob("test_*.py"), *(root / "crates/affcorr/tests").glob("*.rs")]
    sources = "\n".join(p.read_text() for p in files)
    cited = 0
    for row in rows:
        for name in re.findall(r"`([^`]+)`", row.rsplit("|", 2)[-2]):
            name = name.split("::")[-1].split("[")[0].rstrip("…").rstrip("_")
            if re.fullmatch(r"[a-z][a-z0-9_]*", name) and name.count("_") >= 2:
                assert re.search(rf"fn {name}|def {name}", sources), name
                cited += 1
    assert cited >= 25, cited
