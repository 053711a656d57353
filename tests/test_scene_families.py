"""The scene-family benchmark's generator (affcorr_bench.scene_families): exact geometry before
noise, the requested outlier share, and the errors it reports."""

from __future__ import annotations

import numpy as np
import pytest
from affcorr_bench import scene_families as sf


def skew(t):
    return np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0.0]])


@pytest.mark.parametrize("problem", sf.PROBLEMS)
@pytest.mark.parametrize("over", [{}, {"narrow": True, "aniso": False}, {"planes": 8}])
def test_noise_free_scenes_are_exact(problem, over):
    s = {**sf.BASE, **over, "px": 0.0, "aff": 0.0, "outliers": 0.3}
    sc = sf.make_scene(np.random.default_rng(3), problem, 500, s)
    c, inl = sc["corrs"], sc["inlier"]
    assert c.shape == (500, 8) and abs(inl.mean() - 0.7) < 0.01
    assert np.allclose(sc["R"] @ sc["R"].T, np.eye(3)) and np.isclose(np.linalg.norm(sc["t"]), 1)
    f = np.linalg.inv(sc["K2"]).T @ skew(sc["t"]) @ sc["R"] @ np.linalg.inv(sc["K1"])
    p1, p2 = np.c_[c[:, :2], np.ones(500)], np.c_[c[:, 2:4], np.ones(500)]
    l1, l2 = p1 @ f.T, p2 @ f
    scale = np.abs(l1[:, :2]).max()
    # p2^T F p1 = 0 and the affine constraint A^T (F p1)_12 + (F^T p2)_12 = 0 on the inliers
    e = np.sum(p2 * l1, axis=1)
    a = c[:, 4:].reshape(-1, 2, 2)
    r = np.einsum("nik,ni->nk", a, l1[:, :2]) + l2[:, :2]
    assert np.abs(e[inl]).max() < 1e-9 * scale * 640
    assert np.abs(r[inl]).max() < 1e-9 * scale
    assert np.median(np.abs(e[~inl])) > 1e-3 * scale * 640
    if problem == "homography":
        q = p1[inl] @ sc["H"].T
        assert np.abs(q[:, :2] / q[:, 2:] - c[inl, 2:4]).max() < 1e-9
        # A is the Jacobian of H: a finite difference of H agrees
        x, h = c[inl][0, :2], 1e-4
        hx = lambda x: (sc["H"] @ np.r_[x, 1])[:2] / (sc["H"] @ np.r_[x, 1])[2]  # noqa: E731
        jac = np.c_[
            (hx(x + [h, 0]) - hx(x - [h, 0])) / 2 / h, (hx(x + [0, h]) - hx(x - [0, h])) / 2 / h
        ]
        assert np.allclose(jac.reshape(4), c[inl][0, 4:], atol=1e-6)


def test_noise_has_the_requested_scale():
    s = {**sf.BASE, "px": 1.0, "aff": 0.05, "outliers": 0.0}
    exact = sf.make_scene(
        np.random.default_rng(4), "homography", 2000, {**s, "px": 0.0, "aff": 0.0}
    )
    noisy = sf.make_scene(np.random.default_rng(4), "homography", 2000, s)
    q = np.c_[noisy["corrs"][:, :2], np.ones(2000)] @ noisy["H"].T
    d = q[:, :2] / q[:, 2:] - noisy["corrs"][:, 2:4]
    # x1 and x2 both carry 1 px: the transfer residual is ~ sqrt(1 + |A|^2) px per coordinate
    assert 0.9 < np.std(d) / np.sqrt(1 + np.mean(np.abs(exact["corrs"][:, 4:]) ** 2) * 2) < 1.4


def test_errors_of_the_truth_are_zero_and_failures_count_as_the_worst():
    sc = sf.make_scene(np.random.default_rng(5), "relpose", 300, sf.BASE)
    assert sf.errors("relpose", dict(R=sc["R"], t=sc["t"]), sc) == pytest.approx((0, 0), abs=1e-5)
    assert sf.errors("relpose", None, sc) == (180.0, 180.0)
    h = sf.make_scene(np.random.default_rng(5), "homography", 300, sf.BASE)
    assert sf.errors("homography", dict(H=h["H"] * 3.0), h)[0] < 1e-9


def test_the_paired_ratio_compares_methods_scene_by_scene():
    def row(method, seed, e1, e2):
        return dict(problem="relpose", family="base", method=method, seed=seed, err1=e1, err2=e2)

    rows = [
        row("ac-auto", 0, 0.1, 0.4),  # score 0.2
        row("pts-auto", 0, 0.4, 0.4),  # 0.4: ratio 0.5
        row("ac-auto", 1, 2.0, 2.0),  # 2.0
        row("pts-auto", 1, 1.0, 1.0),  # 1.0: ratio 2
        row("ac-auto", 2, 1.0, 1.0),  # no partner: left out
        row("ac-auto", 0, 9.0, 9.0) | dict(family="narrow"),  # another family
    ]
    gm, below, n = sf.paired_ratio(rows, "relpose", "base", "ac-auto", "pts-auto")
    assert (below, n) == (1, 2)
    assert gm == pytest.approx(1.0)  # sqrt(0.5 * 2)
    assert sf.paired_ratio(rows, "relpose", "hard", "ac-auto", "pts-auto") is None


def test_the_interval_of_the_ratio_to_the_best_peer_resamples_the_seeds():
    def row(method, seed, e1, e2, problem="relpose"):
        return dict(problem=problem, family="base", method=method, seed=seed, err1=e1, err2=e2)

    # Exactly twice the best peer on every scene: no resample can move the ratio; the worse
    # peer does not count.
    rows = [row("ac-auto", k, 0.2 * (k + 1), 0.2 * (k + 1)) for k in range(10)]
    rows += [row("poselib", k, 0.1 * (k + 1), 0.1 * (k + 1)) for k in range(10)]
    rows += [row("opencv-USAC_MAGSAC", k, 0.5 * (k + 1), 0.5 * (k + 1)) for k in range(10)]
    lo, hi = sf.best_peer_interval(rows, "relpose", "base", "ac-auto")
    assert lo == pytest.approx(2.0) and hi == pytest.approx(2.0)
    # Scenes that disagree: the interval holds the full sample's ratio and has width.
    rng = np.random.default_rng(1)
    noisy = [
        row(m, k, *rng.lognormal(0.0, 0.8, 2)) for k in range(24) for m in ("ac-auto", "poselib")
    ]
    lo, hi = sf.best_peer_interval(noisy, "relpose", "base", "ac-auto")
    med = sf.medians([r | dict(ms=0.0, failed=False) for r in noisy])
    point = sf.score(med[("relpose", "base", "ac-auto")], "relpose") / sf.score(
        med[("relpose", "base", "poselib")], "relpose"
    )
    assert lo < point < hi and hi / lo > 1.2
    # H: the transfer error alone.
    h = [row("ac-auto", k, 3.0, 100.0, "homography") for k in range(5)]
    h += [row("poselib", k, 1.0, 1.0, "homography") for k in range(5)]
    assert sf.best_peer_interval(h, "homography", "base", "ac-auto") == pytest.approx((3.0, 3.0))
    # No peer on the family's scenes: no interval.
    assert sf.best_peer_interval(rows[:10], "relpose", "base", "ac-auto") is None


def test_the_auc_difference_on_real_pairs_comes_with_its_interval():
    inf = float("inf")
    a = [1.0, 2.0, 3.0, inf]
    # The same errors: no difference in any resample.
    assert sf.auc_difference(a, a, 10) == (0.0, 0.0, 0.0)
    # Halved errors and a failure turned into 4 deg: the point difference is the AUCs', and the
    # resamples spread around it.
    b = [0.5, 1.0, 1.5, 4.0]
    diff, lo, hi = sf.auc_difference(b, a, 10)
    assert diff == pytest.approx(sf._auc(b, 10) - sf._auc(a, 10)) and diff > 0
    assert lo < diff < hi
    with pytest.raises(ValueError, match="the same pairs, got 4 and 3"):
        sf.auc_difference(a, a[:3], 10)


def test_the_plot_of_the_default_against_the_best_peer_needs_a_peer(tmp_path):
    rows = [
        dict(problem="relpose", family=f, method=m, seed=k, err1=e, err2=e, ms=1.0, failed=False)
        for f in ("base", "narrow")
        for k in range(6)
        for m, e in (("ac-auto", 0.1 * (k + 1)), ("poselib", 0.12 * (k + 1)))
    ]
    fams = [f for f in sf.FAMILIES if f[0] in ("base", "narrow")]
    path = tmp_path / "vs_peer.png"
    assert sf.plot_vs_peer(sf.medians(rows), rows, ["relpose"], fams, path)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    alone = [r for r in rows if r["method"] == "ac-auto"]
    other = tmp_path / "none.png"
    assert not sf.plot_vs_peer(sf.medians(alone), alone, ["relpose"], fams, other)
    assert not other.exists()


def test_a_selection_of_families_gets_the_scenes_of_the_full_run():
    # Scenes are seeded by the family's place in FAMILIES, so `--families` reproduces the
    # full run's scenes and its rows can be compared with the full table.
    full = sf.make_jobs(["fundamental"], sf.FAMILIES, 2, 50)
    some = sf.make_jobs(["fundamental"], [f for f in sf.FAMILIES if f[0] == "A 10%"], 2, 50)
    same = [j for j in full if j["family"] == "A 10%"]
    assert [j["seed"] for j in some] == [0, 1] and len(same) == 2
    for a, b in zip(some, same):
        np.testing.assert_array_equal(a["scene"]["corrs"], b["scene"]["corrs"])
    other = [j for j in full if j["family"] == "A 3%"][0]
    assert not np.array_equal(some[0]["scene"]["corrs"], other["scene"]["corrs"])


@pytest.mark.parametrize("flag", ["--repeat", "--timing-rounds"])
def test_a_count_below_one_is_named(flag, capsys):
    with pytest.raises(SystemExit) as e:
        sf.main([flag, "0"])
    assert e.value.code == 2
    assert f"{flag} must be at least 1, got 0" in capsys.readouterr().err


def test_the_sampson_threshold_follows_the_noise_above_its_floor():
    fams = [f for f in sf.FAMILIES if f[0] in ("px 0.25", "px 2")]
    jobs = sf.make_jobs(["relpose", "homography"], fams, 1, 50, sampson=(2.0, 0.75))
    thr = {(j["problem"], j["family"]): j["thr"] for j in jobs}
    assert thr[("relpose", "px 0.25")] == 0.75 and thr[("relpose", "px 2")] == 4.0
    assert thr[("homography", "px 2")] == 7.0  # H keeps its own rule
    default = sf.make_jobs(["relpose"], fams, 1, 50)
    assert [j["thr"] for j in default] == [1.5, 5.0]


@pytest.mark.parametrize("flag", ["--sampson-sigmas", "--sampson-floor"])
def test_a_threshold_that_is_not_positive_is_named(flag, capsys):
    with pytest.raises(SystemExit) as e:
        sf.main([flag, "0"])
    assert e.value.code == 2 and "--sampson-sigmas and --sampson-floor" in capsys.readouterr().err


def test_heavy_tails_widen_a_share_of_the_inliers_and_leave_the_others_alone():
    s = {**sf.BASE, "px": 1.0, "aff": 0.0, "outliers": 0.0}
    gauss = sf.make_scene(np.random.default_rng(4), "homography", 4000, s)
    tails = sf.make_scene(np.random.default_rng(4), "homography", 4000, {**s, "tails": 0.3})

    def transfer_residuals(sc):
        q = np.c_[sc["corrs"][:, :2], np.ones(len(sc["corrs"]))] @ sc["H"].T
        return q[:, :2] / q[:, 2:] - sc["corrs"][:, 2:4]

    # 70 % of the inliers at 1 px and 30 % at TAIL_SCALE px: 0.7 + 0.3 * 16 = 5.5 times the
    # Gaussian scene's variance, and residuals beyond 6 px (4 sigma of the Gaussian's ~1.5)
    ratio = np.var(transfer_residuals(tails)) / np.var(transfer_residuals(gauss))
    assert 4.8 < ratio < 6.2, ratio
    beyond = [np.mean(np.abs(transfer_residuals(sc)) > 4 * 1.5) for sc in (gauss, tails)]
    assert beyond[0] < 0.005 and beyond[1] > 0.05, beyond
    # A scene without tails draws nothing more: the same scene as before the option.
    again = sf.make_scene(np.random.default_rng(4), "homography", 4000, {**s, "tails": 0.0})
    np.testing.assert_array_equal(gauss["corrs"], again["corrs"])
    assert [f[0] for f in sf.EXTRA_FAMILIES][:2] == ["tails 10%", "tails 30%"]


def test_a_cluster_is_a_share_of_the_outliers_displaced_off_the_plane_by_one_shift():
    s = {**sf.BASE, "px": 0.5, "aff": 0.0, "outliers": 0.5}
    plain = sf.make_scene(np.random.default_rng(7), "homography", 1000, s)
    sc = sf.make_scene(np.random.default_rng(7), "homography", 1000, {**s, "cluster": 0.2})
    # The inliers are the same scene's (in another order: the cluster draws before the
    # shuffle); the cluster replaces 200 of the 500 outliers.
    inl = sc["inlier"]
    assert inl.sum() == 500
    np.testing.assert_array_equal(
        np.sort(plain["corrs"][plain["inlier"]], axis=0), np.sort(sc["corrs"][inl], axis=0)
    )
    q = np.c_[sc["corrs"][:, :2], np.ones(len(sc["corrs"]))] @ sc["H"].T
    off = sc["corrs"][:, 2:4] - q[:, :2] / q[:, 2:]
    # 200 outliers sit CLUSTER_SHIFT px off the plane, all in one direction (noise 0.5 px on
    # x1 and x2 around it), in one region of image 1; the other 300 are random.
    near = ~inl & (np.abs(np.linalg.norm(off, axis=1) - sf.CLUSTER_SHIFT) < 3.0)
    assert 195 <= near.sum() <= 205, near.sum()
    shift = np.median(off[near], axis=0)
    assert abs(np.linalg.norm(shift) - sf.CLUSTER_SHIFT) < 0.3
    assert np.all(np.linalg.norm(off[near] - shift, axis=1) < 4.0)
    extent = np.ptp(sc["corrs"][near, :2], axis=0)
    assert np.all(extent <= [sf.CLUSTER_SIDE * sf.W + 1, sf.CLUSTER_SIDE * sf.H + 1]), extent
    assert [f[0] for f in sf.EXTRA_FAMILIES][2:] == ["cluster 10%", "cluster 20%"]
