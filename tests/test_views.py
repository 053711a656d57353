"""The view cascade from Python: a pair the plain matcher cannot solve (graffiti 1→3 with
image B turned upside down, exactly, by numpy) is solved through a synthetic view, its ACs are
in the original pixels with A composed with the view's warp, and the report says which view.
The Rust tests (crates/affcorr-pipeline/tests/views.rs) cover 135° and a 4x zoom; here also a
steep tilt of a rotated pair (B turned by 200° and foreshortened 4x), which only a tilt view
against a rotated view of B solves, a 4x zoom whose kept view, verified with few inliers, is
grown by guided re-matching, and a chessboard matched a quarter turn off, whose strongly verified
but uncertain plain pass is rivalled by the rotated views."""

from __future__ import annotations

import affcorr
import numpy as np
import pytest
from affcorr.data import data_dir, graffiti
from affcorr.metrics import corner_error

GRAF = data_dir() / "graffiti"


@pytest.fixture(scope="module")
def upside_down():
    a = affcorr.read_gray_image(GRAF / "graf1.png")
    b = affcorr.read_gray_image(GRAF / "graf3.png")
    h, w = b.shape
    # x' = (w - 1 - x, h - 1 - y): the homography of the pair becomes R H.
    R = np.array([[-1.0, 0, w - 1], [0, -1.0, h - 1], [0, 0, 1]])  # noqa: N806
    return a, np.ascontiguousarray(b[::-1, ::-1]), R @ graffiti()[2]


def _pipe(views: str, refine_affine: bool = True) -> affcorr.Pipeline:
    return affcorr.Pipeline(max_keypoints=1024, threads=2, views=views, refine_affine=refine_affine)


# Without the refinement the ACs are the shape network's: verification weighs their A less
# (VERIFY_AFFINE_WEIGHT_NETWORK in crates/affcorr-pipeline/src/views.rs), and still tells the
# wrong plain pass of a turned pair from a right one.
@pytest.mark.parametrize("refine_affine", [True, False])
def test_an_upside_down_pair_is_solved_through_a_rotated_view(upside_down, refine_affine):
    a, b, gt = upside_down
    H_off, info_off = _pipe("off", refine_affine).homography(a, b)
    assert not np.isfinite(H_off).all() or corner_error(H_off, gt, *a.shape[::-1]) > 20

    H, info, res = _pipe("auto", refine_affine).homography(a, b, return_matches=True)
    err = corner_error(H, gt, a.shape[1], a.shape[0])
    assert err < 5.0, err
    assert res.view["verified"] and res.view["label"] != "plain", res.views
    assert res.views[0]["label"] == "plain" and not res.views[0]["verified"]
    assert [v["used"] for v in res.views].count(True) == 1 and res.view["used"]
    assert res.timings["views"] > 0
    used, tried = res.view, len(res.views) - 1
    assert res.view_summary().startswith(
        f"views: ACs of {used['label']} ({used['inliers']} of {used['matches']} matches agree);"
        f" {tried} synthetic view"
    ), res.view_summary()
    # The inliers' A against the plane's: the view's 180° turn is composed into A (without
    # it, A would be -A_gt, off by twice its norm; the network's A alone is off by ~0.2).
    c = res.corrs[info.inliers]
    A_gt = affcorr.correspondences_from_homography(gt, c[:, :2])[:, 4:]  # noqa: N806
    assert np.median(np.linalg.norm(c[:, 4:] - A_gt, axis=1)) < (0.1 if refine_affine else 0.4)


@pytest.mark.parametrize("refine_affine", [True, False])
def test_an_easy_pair_tries_no_synthetic_view(refine_affine):
    res = _pipe("auto", refine_affine).match_pair(GRAF / "graf1.png", GRAF / "graf3.png")
    assert [v["label"] for v in res.views] == ["plain"] and res.views[0]["verified"]
    off = _pipe("off", refine_affine).match_pair(GRAF / "graf1.png", GRAF / "graf3.png")
    np.testing.assert_array_equal(off.corrs, res.corrs)
    assert off.views == [] and off.view is None
    n, agree = res.views[0]["matches"], res.views[0]["inliers"]
    assert res.view_summary() == (
        f"views: the plain pair verified ({agree} of {n} matches agree); no synthetic view needed"
    )
    assert off.view_summary() == ""


def test_xfeat_star_ranks_its_views_by_xfeat_keypoints(upside_down):
    """XFeat*'s semi-dense cells have no keypoint descriptors: XFeat's keypoints screen its
    views (every view screened 0 before), and the best-screened rotation solves the pair."""
    p = affcorr.Pipeline("xfeat-star", threads=2)
    assert p.view_screen == "xfeat" and "backbone" in p.models
    assert affcorr.Pipeline("xfeat-star", views="off").view_screen == "xfeat-star"
    a, b, gt = upside_down
    H, _, res = p.homography(a, b, return_matches=True)
    screened = [v for v in res.views if v["screen"] is not None]
    best = max(screened, key=lambda v: v["screen"])
    assert best["screen"] > 0 and best["used"] and best["label"] == "B rot 180°", res.views
    assert corner_error(H, gt, *a.shape[::-1]) < 3


@pytest.mark.parametrize(
    ("kwargs", "fragment"),
    [
        ({"views": "sometimes"}, "views: unknown mode"),
        ({"view_budget": -1.0}, "view_budget"),
        ({"max_views": 0}, "max_views"),
        ({"view_relative_budget": 0.0}, "view_relative_budget"),
        ({"view_relative_budget": float("nan")}, "view_relative_budget"),
    ],
)
def test_bad_view_options_are_named(kwargs, fragment):
    with pytest.raises(ValueError, match=fragment):
        affcorr.Pipeline(threads=1, **kwargs)


def test_the_cli_takes_the_view_options(tmp_path, capsys):
    from affcorr import cli

    args = cli.build_parser().parse_args(["match", "a.png", "b.png", "-o", "x.npz"])
    assert args.views == affcorr.PIPELINE_DEFAULTS["views"] == "auto"
    assert args.view_budget is None
    assert args.view_relative_budget == affcorr.PIPELINE_DEFAULTS["view_relative_budget"] == 30
    none = ["match", "a.png", "b.png", "-o", "x.npz", "--view-relative-budget", "none"]
    assert cli.build_parser().parse_args(none).view_relative_budget is None
    out = tmp_path / "h.json"
    code = cli.main(
        ["homography", str(GRAF / "graf1.png"), str(GRAF / "graf3.png"), "--views", "off",
         "--max-keypoints", "512", "-o", str(out)]
    )  # fmt: skip
    assert code == 0 and out.is_file()
    assert "views:" not in capsys.readouterr().out  # views off: no cascade to report
    code = cli.main(
        ["match", str(GRAF / "graf1.png"), str(GRAF / "graf3.png"), "--max-keypoints", "512",
         "-o", str(tmp_path / "m.npz")]
    )  # fmt: skip
    assert code == 0
    assert "views: the plain pair verified (" in capsys.readouterr().out


def test_the_relative_budget_stops_the_cascade_of_a_pair_no_view_solves():
    # Graffiti against noise: nothing verifies. A budget of a millionth of the plain pass's
    # work is spent by the plain pair's verification, so no synthetic view starts; with
    # max_views=2 and no relative budget, exactly two are tried, and each reports its work.
    a = affcorr.read_gray_image(GRAF / "graf1.png")
    noise = np.random.default_rng(0).random((480, 640), dtype=np.float32)
    tiny = affcorr.Pipeline(max_keypoints=512, threads=2, view_relative_budget=1e-6)
    res = tiny.match_pair(a, noise)
    assert [v["label"] for v in res.views] == ["plain"] and not res.views[0]["verified"]
    assert res.view_summary().startswith("views: the plain pair did not verify (")
    assert res.view_summary().endswith("); no synthetic view run")
    two = affcorr.Pipeline(max_keypoints=512, threads=2, view_relative_budget=None, max_views=2)
    res = two.match_pair(a, noise)
    assert len(res.views) == 3 and not any(v["verified"] for v in res.views), res.views
    assert all(v["window"] is None and v["other_scale"] == 1.0 for v in res.views)
    # The first view carries its group's screen: seven rotated images of B and one of A
    # extracted at half their side (at full size the seven alone cost more than two plain
    # passes), then its own rotation of B at full size; the zoom by ½ one image of a quarter
    # of the pixels.
    work = [v["work"] for v in res.views]
    screen = res.views[1]["screen_extraction"]
    assert work[0] == 1.0 and 0.3 < screen < 1.0 and work[1] > screen + 0.3, res.views
    assert 0 < work[2] < 1.0, work
    assert res.view_summary().startswith("views: no view verified, the plain pair's ACs kept (")
    assert res.view_summary().endswith(
        f"); 2 synthetic views tried, {sum(work):.1f} plain passes of work"
    )


def test_a_pair_no_view_solves_runs_the_same_views_however_long_they_take():
    # The relative budget counts work, not time: with one thread instead of two (slower, so a
    # wall-time budget would stop earlier) the cascade runs to the same views and the same
    # work, and stops at the budget.
    a = affcorr.read_gray_image(GRAF / "graf1.png")
    noise = np.random.default_rng(1).random((480, 640), dtype=np.float32)
    runs = [affcorr.Pipeline(max_keypoints=512, threads=t).match_pair(a, noise) for t in (2, 1)]
    labels = [[v["label"] for v in r.views] for r in runs]
    work = [[v["work"] for v in r.views] for r in runs]
    assert labels[0] == labels[1] and len(labels[0]) > 10, labels
    np.testing.assert_allclose(work[0], work[1], rtol=1e-12)
    budget = affcorr.PIPELINE_DEFAULTS["view_relative_budget"]
    # The budget stopped it (the plain pass's 1 is not the cascade's): every view started
    # under it, and most of it was spent (the cascade skips a screen that would reach it, so
    # it may stop short: tests/test_bench_views_budget.py reads where).
    started = [v["started"] for v in runs[0].views]
    assert max(started) < budget < sum(work[0][1:]) + 4.0, (started, work[0])
    assert not any(v["verified"] for v in runs[0].views)


def _rot(deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[c, -s], [s, c]])


def _tilted_b(t: float, direction_deg: float, turn_deg: float = 0.0, zoom: float = 1.0):
    """Graffiti's A and B' = W B with W = zoom R(turn) T(t, direction): B compressed t times
    along (sin direction, cos direction) after ASIFT's anti-aliasing blur, then turned (and
    scaled by ``zoom`` ≤ 1); and the homography A -> B'."""
    import cv2

    a = affcorr.read_gray_image(GRAF / "graf1.png")
    b = affcorr.read_gray_image(GRAF / "graf3.png")
    M = (
        zoom
        * _rot(turn_deg)
        @ _rot(direction_deg).T
        @ np.diag([1.0, 1.0 / t])
        @ _rot(direction_deg)
    )  # noqa: N806
    h, w = b.shape
    corners = np.array([[0, 0], [w - 1, 0], [0, h - 1], [w - 1, h - 1]], float) @ M.T
    W = np.c_[M, -corners.min(0)]  # noqa: N806
    size = tuple(int(v) for v in np.ceil(np.ptp(corners, axis=0)) + 1)
    blurred = cv2.GaussianBlur(b.astype(np.float32), (0, 0), 0.8 * np.sqrt((t / zoom) ** 2 - 1))
    tilted = cv2.warpAffine(blurred, W, size, flags=cv2.INTER_LINEAR)
    return a, tilted, np.vstack([W, [0, 0, 1]]) @ graffiti()[2]


def test_a_steep_tilt_of_a_rotated_pair_is_solved_through_a_screened_tilt_view():
    # B turned by 200° and foreshortened 4x along 20°.
    a, tilted, gt = _tilted_b(4.0, 20.0, 200.0)

    H_off, _ = _pipe("off").homography(a, tilted)
    assert not np.isfinite(H_off).all() or corner_error(H_off, gt, *a.shape[::-1]) > 20
    H, info, res = _pipe("auto").homography(a, tilted, return_matches=True)
    assert corner_error(H, gt, a.shape[1], a.shape[0]) < 5.0, res.views
    # A screened tilt view against B rotated found it (its screen is the group's best), and
    # the view its ACs guided refined it; either way the ACs are in the original pixels.
    screened = [v for v in res.views if v["screen"] is not None]
    assert screened and any(v["verified"] for v in res.views[1:]), res.views
    c = res.corrs[info.inliers]
    A_gt = affcorr.correspondences_from_homography(gt, c[:, :2])[:, 4:]  # noqa: N806
    assert len(c) > 100 and np.median(np.linalg.norm(c[:, 4:] - A_gt, axis=1)) < 0.1


def test_a_plain_pass_verified_by_too_few_inliers_is_rivalled_by_the_view_they_guide():
    # A tilt of 3.5 verifies the plain pair with a score of its matches, too few to end the
    # cascade on; after the rotations (its first rivals) the view that undoes their dominant
    # map finds hundreds.
    a, tilted, gt = _tilted_b(3.5, 0.0)
    H, info, res = _pipe("auto").homography(a, tilted, return_matches=True)
    plain, *rivals, guided = res.views
    assert plain["verified"] and plain["inliers"] < 2 * 12, res.views
    assert rivals and all(v["label"].startswith("B rot") for v in rivals), res.views
    assert guided["label"].endswith("guided") and guided["used"], res.views
    assert guided["inliers"] > 5 * plain["inliers"]
    assert corner_error(H, gt, a.shape[1], a.shape[0]) < 2.0


def test_a_weak_plain_pass_with_enough_inliers_to_keep_is_rivalled_by_its_guided_view_too():
    # B foreshortened 3x across: the plain pair verifies with a few dozen of its matches, enough
    # to be kept (at least 2 x min_inliers) but a weak yield for 1024 keypoints and under 60 %
    # of the matches; after the rotations the view that undoes their map finds many times more.
    a, tilted, gt = _tilted_b(3.0, 90.0)
    H, info, res = _pipe("auto").homography(a, tilted, return_matches=True)
    plain, *rivals, guided = res.views
    assert plain["verified"] and 2 * 12 <= plain["inliers"] < 0.1 * 1024, res.views
    assert rivals and all(v["label"].startswith("B rot") for v in rivals), res.views
    assert guided["label"].endswith("guided") and guided["used"], res.views
    assert guided["inliers"] > 5 * plain["inliers"]
    assert corner_error(H, gt, a.shape[1], a.shape[0]) < 2.0


def test_a_view_kept_with_a_weak_yield_is_grown_from_its_inliers():
    # A zoomed 4x into its centre: the zoom view that solves it verifies with a few dozen
    # inliers (a weak yield for 1024 keypoints), which guided re-matching grows, unasked.
    import cv2

    a = affcorr.read_gray_image(GRAF / "graf1.png")
    b = affcorr.read_gray_image(GRAF / "graf3.png")
    h, w = a.shape
    Z = np.array([[4.0, 0, -1.5 * (w - 1)], [0, 4.0, -1.5 * (h - 1)], [0, 0, 1]])  # noqa: N806
    zoomed = cv2.warpAffine(a, Z[:2], (w, h), flags=cv2.INTER_LINEAR)
    gt = graffiti()[2] @ np.linalg.inv(Z)
    H, info, res = _pipe("auto").homography(zoomed, b, return_matches=True)
    (kept,) = [v for v in res.views if v["used"]]
    assert kept["label"] != "plain" and kept["inliers"] < 0.1 * 1024, res.views
    n = kept["matches"]
    assert len(res) > 2 * n and res.timings["guided"] > 0
    d = np.linalg.norm(affcorr.metrics.transfer(gt, res.corrs[n:, :2]) - res.corrs[n:, 2:4], axis=1)
    assert np.mean(d < 3.0) >= 0.85
    assert corner_error(H, gt, w, h) < 2.0
    # A pair whose plain pass verifies with a strong yield is not grown.
    upright = _pipe("auto").match_pair(a, b)
    assert upright.views[0]["used"] and upright.timings["guided"] == 0


def _chessboard(nx: int = 9, ny: int = 6, square: int = 40, margin: int = 60) -> np.ndarray:
    """A chessboard of nx x ny squares on mid grey, uint8."""
    img = np.full((ny * square + 2 * margin, nx * square + 2 * margin), 128, np.uint8)
    for j in range(ny):
        for i in range(nx):
            y, x = margin + j * square, margin + i * square
            img[y : y + square, x : x + square] = 20 if (i + j) % 2 == 0 else 235
    return img


def test_a_board_matched_a_quarter_turn_off_is_rivalled_for_its_uncertain_matches():
    """A chessboard and the same board turned by 105°: the plain pass matches the squares a
    quarter turn off, and most of its matches agree with one F, more than a tenth of the keypoint
    budget (weak neither by share nor by yield). LighterGlue is unsure of them (a low median
    certainty), which sends the pass to the rotated rivals, and B turned by 270° registers the
    board (docs/pipeline.md, "Rotated pairs")."""
    cv2 = pytest.importorskip("cv2")
    a = _chessboard()
    h, w = a.shape
    angle = np.radians(105.0)
    c, s = np.cos(angle), np.sin(angle)
    centre = np.array([w / 2, h / 2])
    H = np.eye(3)  # noqa: N806
    H[:2, :2] = [[c, -s], [s, c]]
    H[:2, 2] = centre - H[:2, :2] @ centre
    b = cv2.warpPerspective(a, H, (w, h), borderValue=128)

    def correct(res) -> float:
        x = np.c_[res.corrs[:, :2], np.ones(len(res.corrs))] @ H.T
        return float(np.mean(np.linalg.norm(x[:, :2] / x[:, 2:] - res.corrs[:, 2:4], axis=1) < 3))

    off = _pipe("off").match_pair(a, b)
    assert correct(off) < 0.05
    res = _pipe("auto").match_pair(a, b)
    plain = res.views[0]
    assert plain["label"] == "plain" and plain["verified"]
    assert plain["inliers"] >= 0.6 * plain["matches"] and plain["inliers"] >= 0.1 * 1024
    assert np.median(off.certainty) < 0.35
    assert res.view["label"] == "B rot 270°"
    assert correct(res) > 0.7
