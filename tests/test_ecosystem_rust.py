"""The Rust facade as a dependency (issue 24): `default-features = false` is geometry, solvers
and ransac without ONNX Runtime or image decoding; the default pulls the whole pipeline. The
worked examples themselves are doctests (`cargo test -p affcorr --doc`, run by scripts/test.sh's
`cargo test`)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.skipif(shutil.which("cargo") is None, reason="no cargo")


def crates(*args: str) -> set[str]:
    out = subprocess.run(
        ["cargo", "tree", "--locked", "-p", "affcorr", "-e", "normal", "--prefix", "none", *args],
        cwd=ROOT, capture_output=True, text=True, check=True, timeout=300,
    )  # fmt: skip
    return {line.split()[0] for line in out.stdout.splitlines() if line.strip()}


def test_without_default_features_there_is_no_onnx_runtime_or_image_decoding():
    lean, full = crates("--no-default-features"), crates()
    assert {"affcorr-geom", "affcorr-solvers", "affcorr-ransac"} <= lean
    for heavy in ("ort", "ort-sys", "image", "png", "zune-jpeg", "affcorr-image", "affcorr-runner",
                  "affcorr-pipeline"):  # fmt: skip
        assert heavy not in lean, heavy
    assert {"ort", "image", "affcorr-pipeline"} <= full
    assert len(lean) < len(full) * 0.7


@pytest.mark.parametrize("features", [["--no-default-features"], ["--features", "image"]])
def test_the_facade_builds_with_fewer_features(features):
    subprocess.run(
        ["cargo", "check", "--locked", "-q", "-p", "affcorr", *features],
        cwd=ROOT, check=True, timeout=1200,
    )  # fmt: skip


def test_the_facade_guide_has_a_doctest_per_estimator():
    text = (ROOT / "crates/affcorr/src/lib.rs").read_text()
    for fn in ("estimate_homography", "estimate_fundamental", "estimate_relative_pose"):
        assert f"//! use affcorr::ransac::{{Correspondences, EstimatorOptions, {fn}}};" in text, fn
