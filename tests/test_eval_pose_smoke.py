"""Experiment 3's core (affcorr_bench.eval.pose, pose_data) and the report generator
(affcorr_bench.eval.report) on tiny inputs: the metrics have their textbook values, a rendered
synthetic pair agrees with its own ground truth, the estimators recover an exact scene's pose
through the peer worker and cache their rows, and the report says "not run yet" for missing
experiments. No matcher, peer venv or downloaded data is needed."""

from __future__ import annotations

import numpy as np
import pytest
from affcorr_bench.common import rotation
from affcorr_bench.eval import pose, pose_data, report
from affcorr_bench.peers import scenes


def test_metrics():
    R = rotation(np.array([0.3, -1.0, 0.2]), np.radians(10.0))
    assert pose.rotation_error(R, np.eye(3)) == pytest.approx(10.0)
    t = np.array([0.2, -0.5, 1.0])
    assert pose.translation_error(-t, t) == pytest.approx(0.0, abs=1e-6)  # E fixes t up to sign
    assert pose.translation_error(np.array([1.0, 0, 0]), np.array([0, 1.0, 0])) == 90.0
    # one pair at 2.5 deg: the recall curve rises linearly to 1 at 2.5 (SuperGlue's
    # trapezoids), so AUC = (th - 2.5 / 2) / th
    assert pose.pose_auc([2.5]) == pytest.approx([0.75, 0.875, 0.9375])
    assert pose.pose_auc([0.0, np.inf]) == pytest.approx([0.5, 0.5, 0.5])  # a failure counts
    square = np.array([[0, 0], [10, 0], [10, 10], [0, 10.0]])
    inside = pose_data.inside_convex(square, np.array([[5, 5], [11, 5], [0.5, 9.5]]))
    assert inside.tolist() == [True, False, True]
    assert pose_data.inside_convex(square[::-1], np.array([[5.0, 5.0]]))[0]  # either winding


def test_synthetic_pair_agrees_with_its_ground_truth(monkeypatch):
    pytest.importorskip("torch")
    import torch
    from affcorr.train.views import Texture, _gaussian_blur

    rng = np.random.default_rng(0)
    noise = torch.from_numpy(rng.random((1, 1, 400, 400)).astype(np.float32))
    tex = _gaussian_blur(noise, 3.0)[0, 0].numpy()
    tex = (tex - tex.min()) / (tex.max() - tex.min())
    monkeypatch.setattr(pose_data, "_textures", lambda: [("noise", Texture(tex))])
    d = pose_data.render_pair(0, seed=7, with_depth=True)
    assert d["img1"].shape == (480, 640) and d["img1"].dtype == np.uint8
    R, t = d["R"], d["t"] * d["baseline"]
    assert np.allclose(R @ R.T, np.eye(3)) and d["covisible"] >= pose_data.MIN_COVISIBLE
    # lift view 1's pixels with their depth, move them by (R, t), project into view 2
    ys, xs = np.mgrid[10:470:7, 10:630:7]
    z1 = d["depth1"][ys, xs].ravel()
    ok = np.isfinite(z1)
    p1 = np.c_[xs.ravel(), ys.ravel(), np.ones(xs.size)][ok]
    X2 = (z1[ok, None] * p1 @ np.linalg.inv(d["K1"]).T) @ R.T + t
    p2 = X2 @ d["K2"].T
    x2 = p2[:, :2] / p2[:, 2:]
    c = np.rint(x2).astype(int)
    vis = (c[:, 0] >= 0) & (c[:, 0] < 640) & (c[:, 1] >= 0) & (c[:, 1] < 480)
    vis[vis] &= np.abs(d["depth2"][c[vis, 1], c[vis, 0]] - X2[vis, 2]) < 0.01 * X2[vis, 2]
    assert vis.sum() > 1000
    a = d["img1"][p1[vis, 1].astype(int), p1[vis, 0].astype(int)].astype(float)
    b = d["img2"][c[vis, 1], c[vis, 0]].astype(float)
    assert np.corrcoef(a, b)[0, 1] > 0.9  # same texture points (photometric change aside)


def test_estimation_cache_and_report(tmp_path, monkeypatch):
    monkeypatch.setenv("AFFCORR_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(pose, "ESTIMATORS", [e for e in pose.ESTIMATORS if e[0] == "affcorr"])
    s = scenes.make_scene(np.random.default_rng(1), "relpose", 300, 0.3)
    pair = pose_data.PosePair(
        "synthetic", "0000", s["K1"], s["K2"], s["R"], s["t"] / np.linalg.norm(s["t"]), load=None
    )
    jobs = [
        dict(
            matcher="affcorr",
            A_source="affcorr",
            pair=pair,
            corrs=s["corrs"],
            first=True,
            seconds=0.1,
        )
    ]
    notes, versions = [], set()
    rows = pose.estimate(jobs, tmp_path, notes, versions)
    assert {r["estimator"] for r in rows} == {"affcorr-points", "affcorr-AC"}, notes
    for r in rows:
        assert r["pose_err"] < 1.0 and r["inliers"] > 150, r
    # a second run reuses the cached rows and calls no worker
    monkeypatch.setattr(pose, "run_worker", lambda *a: pytest.fail("worker called again"))
    again = pose.estimate(jobs, tmp_path, notes, versions)
    assert [r["pose_err"] for r in again] == [r["pose_err"] for r in rows]
    # a new revision of affcorr's estimator re-estimates affcorr's rows instead of reusing them
    monkeypatch.setattr(pose, "AFFCORR_ESTIMATOR_REVISION", pose.AFFCORR_ESTIMATOR_REVISION + 1)
    with pytest.raises(pytest.fail.Exception, match="worker called again"):
        pose.estimate(jobs, tmp_path, notes, versions)

    results = tmp_path / "results"
    meta = dict(
        command="test",
        date="today",
        load="0",
        machine="test",
        seconds=1.0,
        versions=[],
        threshold=pose.THRESHOLD,
        grid=pose.PAIRS["quick"],
        pair_counts={"synthetic": {"affcorr": 1}, "chessboard": {}},
        matching_seconds={"affcorr": 0.1},
        common_pairs={"synthetic": 1, "chessboard": 0},
        cached=False,
        unavailable={},
        notes=[],
    )
    pose.write(results, rows, meta)
    assert (results / "pose.md").exists() and (results / "pose_summary.csv").exists()
    text = report.build(results, tmp_path / "evaluation.md")
    assert text.count("Not run yet") == 3  # experiments 1, 2 and 4
    assert "affcorr end to end" in text and "### Where affcorr stands" in text


def test_rows_cached_before_a_field_existed_are_written(tmp_path):
    rows = [dict(pair="a", rot_err=0.123456789), dict(pair="b", rot_err=1.0, shape_tag="x")]
    pose.write_rows_csv(tmp_path / "p.csv", rows)
    assert (tmp_path / "p.csv").read_text().splitlines() == [
        "pair,rot_err,shape_tag",
        "a,0.12346,",
        "b,1.0,x",
    ]


def test_cached_only_refuses_a_partial_table(monkeypatch):
    """`--cached` with matches missing (a new pipeline revision, another shape model) stops,
    naming them per matcher, before any result file is overwritten by a partial table."""
    pairs = [pose_data.PosePair.__new__(pose_data.PosePair) for _ in range(3)]
    monkeypatch.setattr(pose, "schedule", lambda names, data, grid: [("affcorr", p) for p in pairs])
    monkeypatch.setattr(pose, "get_matches", lambda name, p, cached_only=False: None)
    with pytest.raises(SystemExit, match="affcorr 3 of 3"):
        pose.collect_jobs(["affcorr"], {}, {}, lambda msg: None, cached_only=True)


def test_affcorr_matches_are_cached_per_pipeline_revision(tmp_path, monkeypatch):
    """affcorr's cached matches carry the suite's pipeline revision and source digest: after a
    change of the view cascade they are not served as they were."""
    from affcorr_bench.eval import matchers, suite

    pair = pose_data.PosePair.__new__(pose_data.PosePair)
    monkeypatch.setattr(pose, "match_path", lambda name, p: tmp_path / f"{name}.npz")
    monkeypatch.setattr(matchers, "shape_model_tag", lambda: "shape")
    stale = "shape-p0-srcold"
    np.savez(tmp_path / "affcorr.npz", x1=np.zeros((1, 2)), shape_tag=np.str_(stale))
    assert pose.get_matches("affcorr", pair, cached_only=True) is None
    current = f"shape-p{suite.AFFCORR_PIPELINE_REVISION}-src{suite.pipeline_source_digest()}"
    np.savez(tmp_path / "affcorr.npz", x1=np.zeros((1, 2)), shape_tag=np.str_(current))
    assert pose.get_matches("affcorr", pair, cached_only=True) is not None
    # another matcher's A depends on the shape model only
    np.savez(tmp_path / "sift.npz", x1=np.zeros((1, 2)), shape_tag=np.str_("shape"))
    assert pose.get_matches("sift", pair, cached_only=True) is not None
