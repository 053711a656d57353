"""The peer benchmark harness (benches/peers): its scenes are exact, its metrics are zero on the
ground truth, and a one-scene run with the affcorr group writes its CSV, markdown and plots.
The peers themselves (their venvs) are not needed here."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import affcorr
import numpy as np
import pytest

PEERS = Path(__file__).resolve().parents[1] / "benches" / "peers"
sys.path.insert(0, str(PEERS))

import methods  # noqa: E402
import run  # noqa: E402
import scenes  # noqa: E402


@pytest.mark.parametrize("problem", ["homography", "relpose"])
def test_scenes_are_exact_before_noise(problem):
    s = scenes.make_scene(np.random.default_rng(3), problem, 400, 0.3)
    exact, truth = s["exact"], s["truth"]
    assert truth.sum() == 280 and exact.shape == (400, 8)
    F = np.linalg.inv(s["K2"]).T @ scenes.skew(s["t"]) @ s["R"] @ np.linalg.inv(s["K1"])
    F /= np.linalg.norm(F)
    assert np.sqrt(affcorr.sampson_point(F, exact)).max() < 1e-6
    assert np.sqrt(affcorr.sampson_affine(F, exact)).max() < 1e-6
    if problem == "homography":
        ref = affcorr.correspondences_from_homography(s["H"], exact[:, :2])
        assert np.abs(ref - exact).max() < 1e-6
    # noise only on x2 and A, outliers only where truth is False
    assert np.array_equal(s["corrs"][:, :2], exact[:, :2])
    assert np.abs(s["corrs"][truth, 2:4] - exact[truth, 2:4]).max() < 5 * scenes.SIGMA


def test_metrics_are_zero_on_the_ground_truth():
    s = scenes.make_scene(np.random.default_rng(4), "relpose", 300, 0.5)
    m = run.metrics("relpose", s, dict(R=s["R"], t=s["t"], inliers=s["truth"]))
    assert m["rot_err"] < 1e-6 and m["t_err"] < 1e-5 and m["epi_err"] < 1e-6
    assert m["precision"] == 1.0 and m["recall"] == 1.0
    F = np.linalg.inv(s["K2"]).T @ scenes.skew(s["t"]) @ s["R"] @ np.linalg.inv(s["K1"])
    m = run.metrics("fundamental", s, dict(F=F, inliers=s["truth"]))
    assert m["rot_err"] < 1e-5 and m["t_err"] < 1e-4
    h = scenes.make_scene(np.random.default_rng(5), "homography", 300, 0.5)
    m = run.metrics("homography", h, dict(H=h["H"], inliers=h["truth"]))
    assert m["h_err"] < 1e-8
    assert not run.metrics("homography", h, None)["ok"]


def test_pose_from_essential_picks_the_true_factorisation():
    s = scenes.make_scene(np.random.default_rng(6), "relpose", 200, 0.0)
    x1n = methods.normalize(s["K1"], s["exact"][:, :2])
    x2n = methods.normalize(s["K2"], s["exact"][:, 2:4])
    R, t = methods.pose_from_essential(scenes.skew(s["t"]) @ s["R"], x1n, x2n)
    assert run.rot_err(R, s["R"]) < 1e-6 and run.vec_err(t, s["t"]) < 1e-5


def test_smoke_run_writes_csv_markdown_and_plots(tmp_path):
    pytest.importorskip("matplotlib")
    cmd = [sys.executable, str(PEERS / "run.py"), "--smoke", "--groups", "affcorr"]
    p = subprocess.run([*cmd, "--out", str(tmp_path)], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr[-2000:]
    md = (tmp_path / "summary.md").read_text()
    assert "benches/peers/run.py --smoke" in md and "affcorr-AC" in md
    rows = (tmp_path / "results.csv").read_text().splitlines()
    # header + 3 problems x 5 affcorr methods (AC, AC-msac, AC-magsac, AC-graph_cut, points)
    assert len(rows) == 1 + 3 * 5
    assert "Load average" in md
    for problem in run.PROBLEMS:
        assert (tmp_path / f"{problem}_error_vs_outliers.png").stat().st_size > 1000
        assert (tmp_path / f"{problem}_time_vs_n.png").stat().st_size > 1000
    # re-rendering from the CSV gives the same report
    subprocess.run([*cmd, "--out", str(tmp_path), "--report-only"], check=True, capture_output=True)
    assert (tmp_path / "summary.md").read_text() == md
