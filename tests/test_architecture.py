"""The crates' layering (docs/design.md §1): each workspace crate depends only on the crates
below it, so that data flows one way and no arrow runs back up. A new dependency between our
crates must be added here on purpose."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: Our crates each crate may depend on (normal dependencies; dev-dependencies are the tests').
ALLOWED = {
    "affcorr-geom": set(),
    "affcorr-solvers": {"affcorr-geom"},
    "affcorr-ransac": {"affcorr-geom", "affcorr-solvers"},
    "affcorr-image": {"affcorr-geom"},
    "affcorr-runner": {"affcorr-geom", "affcorr-image"},
    "affcorr-pipeline": {"affcorr-geom", "affcorr-image", "affcorr-ransac", "affcorr-runner"},
    "affcorr": {
        "affcorr-geom",
        "affcorr-solvers",
        "affcorr-ransac",
        "affcorr-image",
        "affcorr-runner",
        "affcorr-pipeline",
    },
    "affcorr-devtools": set(),
    "affcorr-py": {"affcorr"},
    "affcorr-benches": {"affcorr"},
}


@pytest.fixture(scope="module")
def metadata():
    cargo = shutil.which("cargo")
    if cargo is None:
        pytest.fail("cargo is needed to read the workspace's crate graph")
    out = subprocess.run(
        [cargo, "metadata", "--no-deps", "--format-version", "1", "--offline"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(out.stdout)


def test_every_crate_depends_only_on_the_crates_below_it(metadata):
    ours = {p["name"] for p in metadata["packages"]}
    assert ours == set(ALLOWED), "a crate was added or removed: update ALLOWED and docs/design.md"
    for p in metadata["packages"]:
        deps = {d["name"] for d in p["dependencies"] if d["kind"] is None and d["name"] in ours}
        assert deps <= ALLOWED[p["name"]], f"{p['name']} depends on {deps - ALLOWED[p['name']]}"


def test_the_runner_holds_no_estimation_and_the_image_crate_no_onnx(metadata):
    by_name = {p["name"]: p for p in metadata["packages"]}
    names = {n: {d["name"] for d in p["dependencies"] if d["kind"] is None} for n, p in
             by_name.items()}  # fmt: skip
    assert "affcorr-ransac" not in names["affcorr-runner"]
    assert "ort" not in names["affcorr-image"] and "ort" in names["affcorr-runner"]
