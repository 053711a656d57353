"""The wheel as a new user gets it: built from this checkout, installed with its dependencies
only into a fresh virtualenv (no system site-packages, so no Pillow, matplotlib or torch), and
its commands run from a directory outside the repository.

It costs a wheel build (mostly cached after scripts/setup.sh's) and a pip install of numpy,
onnxruntime and tqdm (from pip's cache when warm): about 2 minutes. AFFCORR_SKIP_WHEEL_TEST=1
skips it.
"""

from __future__ import annotations

import os
import subprocess
import sys
import venv
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.skipif(
    os.environ.get("AFFCORR_SKIP_WHEEL_TEST") == "1", reason="AFFCORR_SKIP_WHEEL_TEST=1"
)


def _maturin() -> list[str]:
    exe = Path(sys.executable).with_name("maturin")
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "maturin"]


@pytest.fixture(scope="module")
def clean_venv(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("wheel")
    wheels = tmp / "wheels"
    lock = ROOT / ".venv" / ".build.lock"
    build = [*_maturin(), "build", "--release", "-q", "-o", str(wheels)]
    if lock.parent.is_dir():  # scripts/dev.sh's lock: one cargo build of the extension at a time
        build = ["flock", str(lock), *build]
    subprocess.run(build, cwd=ROOT, check=True, timeout=1500)
    [wheel] = wheels.glob("affcorr-*.whl")
    import zipfile

    names = zipfile.ZipFile(wheel).namelist()
    assert "affcorr/sample_data/graffiti/graf1.png" in names  # the demo's data
    assert any(n.endswith(".dist-info/licenses/LICENSE") for n in names)
    assert "affcorr/_native.pyi" in names and "affcorr/py.typed" in names
    env_dir = tmp / "venv"
    venv.EnvBuilder(with_pip=True, system_site_packages=False).create(env_dir)
    pip = [str(env_dir / "bin" / "python"), "-m", "pip", "install", "-q"]
    subprocess.run(
        [*pip, "--disable-pip-version-check", "-c", str(ROOT / "scripts/constraints.txt"),
         str(wheel)],
        check=True, timeout=900,
    )  # fmt: skip
    return env_dir


def run(env_dir: Path, *args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "AFFCORR_DATA")}
    return subprocess.run(
        [str(env_dir / "bin" / "affcorr"), *args],
        cwd=cwd, env=env, capture_output=True, text=True, timeout=600,
    )  # fmt: skip


def test_the_clean_venv_has_no_optional_extras(clean_venv):
    python = str(clean_venv / "bin" / "python")
    for module in ("PIL", "matplotlib", "torch"):
        r = subprocess.run([python, "-c", f"import {module}"], capture_output=True)
        assert r.returncode != 0, f"{module} is in the clean venv"


def test_version_and_api_from_the_wheel(clean_venv, tmp_path):
    r = run(clean_venv, "--version", cwd=tmp_path)
    assert r.returncode == 0 and r.stdout.startswith("affcorr "), r.stderr
    code = (
        "import affcorr, affcorr.data; assert affcorr.solvers.homography_4pt.__doc__; "
        "assert affcorr.decompose_affine.__doc__; print(affcorr.data.data_dir())"
    )
    r = subprocess.run(
        [str(clean_venv / "bin" / "python"), "-c", code],
        cwd=tmp_path, capture_output=True, text=True, check=True,
    )  # fmt: skip
    assert "site-packages/affcorr/sample_data" in r.stdout


def test_demo_runs_anywhere_from_the_wheel(clean_venv, tmp_path):
    r = run(clean_venv, "demo", "--max-keypoints", "512", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "homography mean corner error vs ground truth" in r.stdout
    assert "picture skipped: it needs matplotlib: pip install 'affcorr[plot]'" in r.stdout
    r = run(clean_venv, "demo", "--geometry", cwd=tmp_path)
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr


def test_commands_that_need_an_extra_say_which_in_one_line(clean_venv, tmp_path):
    d = Path(__file__).resolve().parent  # any .npz path: the extra is checked first
    r = run(clean_venv, "show", str(d / "x.npz"), cwd=tmp_path)
    assert r.returncode == 2
    assert r.stderr.strip().splitlines() == [
        "affcorr show: this command needs matplotlib: pip install 'affcorr[plot]'"
    ]


def test_match_and_homography_from_the_wheel(clean_venv, tmp_path):
    from affcorr.data import data_dir

    g = data_dir() / "graffiti"
    a, b = str(g / "graf1.png"), str(g / "graf3.png")
    fast = ["--matcher", "xfeat", "--max-keypoints", "256"]
    r = run(clean_venv, "match", a, b, "-o", "acs.npz", *fast, cwd=tmp_path)
    assert r.returncode == 0 and (tmp_path / "acs.npz").is_file(), r.stderr
    r = run(clean_venv, "homography", a, b, "-o", "h.json", *fast, cwd=tmp_path)
    assert r.returncode == 0 and (tmp_path / "h.json").is_file(), r.stderr
