"""Documentation a user reaches (issue 24): runtime docstrings for every public callable, the
stub's text as their one source, the stub's signatures checked against the built module
(stubtest), affcorr.solvers as an attribute, the API reference built, the licence and the
changelog."""

from __future__ import annotations

import ast
import inspect
import os
import subprocess
import sys
from pathlib import Path

import affcorr
import pytest
from affcorr import _docs, _native

ROOT = Path(__file__).resolve().parents[1]


def public_callables():
    for name in affcorr.__all__:
        obj = getattr(affcorr, name)
        if callable(obj):
            yield name, obj
    for mod in (affcorr.solvers, affcorr.opencv):
        for name in mod.__all__:
            obj = getattr(mod, name)
            if callable(obj):
                yield f"{mod.__name__}.{name}", obj


@pytest.mark.parametrize("name,obj", list(public_callables()), ids=lambda x: str(x)[:40])
def test_every_public_callable_has_a_docstring(name, obj):
    assert (obj.__doc__ or "").strip(), f"{name} has no __doc__"
    if inspect.isclass(obj):
        for attr, member in vars(obj).items():
            if not attr.startswith("_") and inspect.isfunction(member):
                assert (member.__doc__ or "").strip(), f"{name}.{attr} has no __doc__"


def test_native_functions_carry_the_stubs_text_and_signature():
    tree = ast.parse((ROOT / "python/affcorr/_native.pyi").read_text())
    stub = {
        n.name: ast.get_docstring(n)
        for n in tree.body
        if isinstance(n, ast.FunctionDef) and ast.get_docstring(n)
    }
    # the native functions affcorr exposes as they are (the estimators have Python wrappers)
    wrapped = [n for n in affcorr.__all__ if _docs._wrappers.get(n) is getattr(affcorr, n)]
    assert len(wrapped) >= 28
    for name in wrapped:
        fn = getattr(affcorr, name)
        assert fn.__doc__ == stub[name], name
        assert inspect.signature(fn) == inspect.signature(getattr(_native, name)), name
        assert not hasattr(fn, "__wrapped__")  # pdoc would read the native's empty text
    # one wrapper per function, whichever module it is reached from
    assert affcorr.solvers.essential_2ac is affcorr.essential_2ac
    assert _docs.documented("homography_4pt") is affcorr.homography_4pt


def test_wrappers_return_and_raise_as_the_native_functions():
    import numpy as np

    A = np.array([[[2.0, 0.3], [0.1, 1.5]]])
    for got, want in zip(affcorr.decompose_affine(A), _native.decompose_affine(A)):
        np.testing.assert_array_equal(got, want)
    with pytest.raises(ValueError, match=r"A\[0\]: det A"):
        affcorr.decompose_affine([[[1, 0], [0, -1]]])


def test_solvers_is_an_attribute_after_import_affcorr():
    code = "import affcorr; print(affcorr.solvers.homography_4pt.__doc__.split()[0])"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "H"


def test_help_shows_the_text():
    assert "normalised DLT" in affcorr.homography_4pt.__doc__
    assert "(x1, x2)" in str(inspect.signature(affcorr.homography_4pt))


def test_the_stub_matches_the_built_module():
    pytest.importorskip("mypy")
    out = subprocess.run(
        [sys.executable, "-m", "mypy.stubtest", "affcorr._native", "--allowlist",
         str(ROOT / "scripts/stubtest_allowlist.txt")],
        capture_output=True, text=True, timeout=600, cwd=ROOT,
    )  # fmt: skip
    assert out.returncode == 0, out.stdout[-4000:]


def test_the_api_reference_builds(tmp_path):
    pytest.importorskip("pdoc")
    env = {**os.environ, "AFFCORR_DOCS_RUST": "0"}
    subprocess.run(
        ["bash", str(ROOT / "scripts/docs.sh"), str(tmp_path)],
        env=env, check=True, timeout=600, capture_output=True,
    )  # fmt: skip
    top = (tmp_path / "python/affcorr.html").read_text()
    assert "Inverse of synthesize_affine" in top  # a native function's text
    for page in ("solvers", "opencv", "estimation", "pipeline", "shape", "cli"):
        assert (tmp_path / f"python/affcorr/{page}.html").is_file(), page
    assert "acs_from_keypoints" in (tmp_path / "python/affcorr/opencv.html").read_text()


def test_licence_and_changelog():
    licence = (ROOT / "LICENSE").read_text()
    assert "Apache License" in licence and "Version 2.0, January 2004" in licence
    assert "END OF TERMS AND CONDITIONS" in licence
    changelog = (ROOT / "CHANGELOG.md").read_text()
    assert f"## [{affcorr.__version__}]" in changelog or "## [Unreleased]" in changelog
    assert "Versioning" in changelog and "v0." in changelog


def test_no_placeholder_project_url():
    text = (ROOT / "pyproject.toml").read_text()
    assert "example.invalid" not in text and "example.com" not in text


def test_logging_is_silent_by_default():
    import logging

    log = logging.getLogger("affcorr")
    assert any(isinstance(h, logging.NullHandler) for h in log.handlers)
