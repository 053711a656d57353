"""The benchmark package (benches/affcorr_bench): every module imports without doing any work,
every experiment answers --help, the peer worker imports without affcorr, and no Python or shell
file under benches/ or tests/ edits sys.path (the package is installed or on PYTHONPATH, never
patched in)."""

from __future__ import annotations

import importlib
import io
import json
import os
import pkgutil
import subprocess
import sys
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import affcorr_bench
import pytest
from affcorr_bench import common

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "benches" / "affcorr_bench"
MODULES = sorted(
    m.name for m in pkgutil.walk_packages(affcorr_bench.__path__, prefix="affcorr_bench.")
)
SUBPACKAGES = {"affcorr_bench.eval", "affcorr_bench.peers", "affcorr_bench.reliability"}
#: Modules that other modules use or start (no command line of their own, or positional
#: arguments only).
INTERNAL = {
    "affcorr_bench.common",
    "affcorr_bench.eval.data",
    "affcorr_bench.eval.matchers",
    "affcorr_bench.eval.pose_calib",
    "affcorr_bench.eval.suite",
    "affcorr_bench.peers.methods",
    "affcorr_bench.peers.scenes",
    "affcorr_bench.peers.worker",
}
EXPERIMENTS = [m for m in MODULES if m not in INTERNAL | SUBPACKAGES]


def test_the_package_is_the_one_in_this_checkout():
    assert Path(affcorr_bench.__file__).resolve().parent == PACKAGE
    assert common.ROOT == ROOT and common.RESULTS == ROOT / "benches" / "results"


def test_every_python_file_is_a_module_of_the_package():
    files = {
        ".".join(("affcorr_bench", *p.relative_to(PACKAGE).with_suffix("").parts)).removesuffix(
            ".__init__"
        )
        for p in PACKAGE.rglob("*.py")
    }
    assert files == {"affcorr_bench", *MODULES}
    assert SUBPACKAGES <= set(MODULES)
    # no Python left outside the package (benches/benches/*.rs and the shell scripts stay)
    loose = [
        p.relative_to(ROOT)
        for p in (ROOT / "benches").rglob("*.py")
        if PACKAGE not in p.parents and not any(s.startswith(".") for s in p.parts)
    ]
    assert loose == []


def test_importing_every_module_does_no_work(tmp_path):
    """A fresh interpreter imports them all, with arguments that would make any command line
    fail: nothing printed, nothing written, no exit."""
    code = (
        "import importlib, json, sys\n"
        "sys.argv = ['nothing-to-parse', '--not-an-option']\n"
        f"for name in {MODULES!r}:\n"
        "    importlib.import_module(name)\n"
        "print(json.dumps(sorted(m for m in sys.modules if m.startswith('affcorr_bench'))))\n"
    )
    p = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env=common.child_env(),
        timeout=300,
    )
    assert p.returncode == 0, p.stderr[-3000:]
    assert p.stderr == ""
    assert json.loads(p.stdout) == sorted({"affcorr_bench", *MODULES})
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name", EXPERIMENTS)
def test_experiment_answers_help(name, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    module = importlib.import_module(name)
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err), pytest.raises(SystemExit) as e:
        module.main(["--help"])
    assert e.value.code == 0, err.getvalue()
    assert out.getvalue().startswith("usage:")
    assert list(tmp_path.iterdir()) == []


def test_an_experiment_runs_as_a_module_from_anywhere(tmp_path):
    p = subprocess.run(
        [sys.executable, "-m", "affcorr_bench.solver_noise_hf", "--help"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env=common.child_env(),
    )
    assert p.returncode == 0 and "--trials" in p.stdout, p.stderr[-2000:]


def test_command_line_of_a_result_file():
    cmd = common.command("affcorr_bench.peers.run", ["--out", str(ROOT / "x y")], prefix="A=1 ")
    assert cmd == "A=1 .venv/bin/python -m affcorr_bench.peers.run --out 'x y'"


def test_the_peer_worker_imports_without_affcorr():
    """What a peer venv has: numpy and the peers' libraries, no affcorr, no installed package
    (the modules started there: the worker, pose_calib, pipeline_vs_sift's SIFT worker)."""
    code = (
        "import sys\n"
        "sys.modules['affcorr'] = None  # any import of affcorr fails\n"
        "from affcorr_bench.peers import methods, scenes, worker\n"
        "from affcorr_bench.eval import pose_calib\n"
        "import affcorr_bench.pipeline_vs_sift\n"
        "print(worker.versions())\n"
    )
    p = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=common.child_env()
    )
    assert p.returncode == 0, p.stderr[-2000:]
    assert "numpy" in p.stdout


def test_no_sys_path_edits_in_benches_or_tests():
    # spelled apart, so that this file does not match itself
    needles = ["sys.path." + "insert", "sys.path." + "append"]
    offenders = []
    for folder in ("benches", "tests"):
        for dirpath, dirnames, filenames in os.walk(ROOT / folder):
            dirnames[:] = [
                d for d in dirnames if not d.startswith(".") and d not in ("__pycache__", "target")
            ]
            for f in filenames:
                if not f.endswith((".py", ".sh")):
                    continue
                path = Path(dirpath) / f
                text = path.read_text(errors="replace")
                offenders += [f"{path.relative_to(ROOT)}: {n}" for n in needles if n in text]
    assert offenders == []
