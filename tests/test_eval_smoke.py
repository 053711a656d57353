"""Smoke test of the evaluation suite (affcorr_bench.eval): every experiment's core on one small
pair with a known homography, for each matcher of the registry that runs here (a peer that is
not installed, see benches/eval/setup.sh, is skipped with its reason)."""

from __future__ import annotations

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2", reason="opencv not installed (benches/eval/setup.sh)")

from affcorr_bench.eval import affine, data, extreme, matchers, matching  # noqa: E402

KEYPOINTS = 256


@pytest.fixture(scope="module")
def pair() -> data.Pair:
    """A 192x256 crop of graffiti 1 and its warp by a strength-1 random homography."""
    from affcorr.data import graffiti

    g1 = graffiti()[0][200:392, 250:506]
    ref = np.clip(np.rint(g1 * 255), 0, 255).astype(np.uint8)
    h, w = ref.shape
    H = data.random_homography(np.random.default_rng(3), w, h, 1)
    tgt = cv2.warpPerspective(ref, H, (w, h), flags=cv2.INTER_LINEAR)
    return data.Pair("smoke", "viewpoint", ref, tgt, H, {"tilt": 0})


_RUNS: dict[str, matchers.Matches] = {}


def run(name: str, pair: data.Pair) -> matchers.Matches:
    why = matchers.available()[name]
    if why:
        pytest.skip(f"{name} unavailable: {why}")
    if name not in _RUNS:
        _RUNS[name] = matchers.run(name, pair.img1, pair.img2, max_keypoints=KEYPOINTS)
    return _RUNS[name]


def test_available_names_every_method():
    av = matchers.available()
    assert list(av) == matchers.NAMES
    assert all(isinstance(v, str) for v in av.values())
    with pytest.raises(ValueError, match="name"):
        matchers.run("nope", np.zeros((8, 8), np.uint8), np.zeros((8, 8), np.uint8))


def test_mma_score_weights():
    assert matching.mma_score(np.ones(10)) == pytest.approx(1.0)
    curve = np.r_[np.zeros(5), np.ones(5)]  # correct only from 6 px on
    w = 2 - 0.1 * np.arange(1, 11)
    assert matching.mma_score(curve) == pytest.approx(w[5:].sum() / w.sum())


@pytest.mark.parametrize("name", matchers.NAMES)
def test_matching_core(name, pair):
    m = run(name, pair)
    n = len(m)
    assert m.x1.shape == m.x2.shape == (n, 2) and m.score.shape == (n,)
    assert (m.A is None) == (name.startswith(("xfeat", "disk", "aliked")))
    assert m.A is None or m.A.shape == (n, 2, 2)
    curve = matching.mma_curve(m, pair.H)
    assert np.all(np.diff(curve) >= 0)
    # A mild homography of a textured crop: most matches of any working method are right.
    assert n >= 20 and curve[-1] > 0.5, (n, curve)


@pytest.mark.parametrize("name", ["sift", "hesaff", "asift", "affcorr", "xfeat"])
def test_affine_core(name, pair):
    m = run(name, pair)
    r = affine.evaluate_pair(pair, name, m, per_pair=100)
    assert r is not None and 0 < r["n"] <= 100
    for key in ("own", "os", "full") if m.A is not None else ("os", "full"):
        assert np.all(np.isfinite(r[f"fro_{key}"])) and np.all(np.abs(r[f"cos_{key}"]) <= 1 + 1e-9)
    # SIFT's similarity of a near-similarity warp is close to the truth.
    if name == "sift":
        assert np.median(r["fro_own"]) < 0.5


def test_with_affcorr_shapes_fills_A(pair):
    m = run("sift", pair)
    if matchers.available()["affcorr"]:
        pytest.skip("affcorr unavailable")
    s = matchers.with_affcorr_shapes(m.subset(np.arange(min(len(m), 50))), pair.img1, pair.img2)
    assert s.A.shape == (len(s), 2, 2) and np.all(np.isfinite(s.A))
    assert np.array_equal(s.x1, m.x1[: len(s)])


@pytest.mark.parametrize("name", ["sift", "affcorr"])
def test_extreme_core(name, pair):
    m = run(name, pair)
    r = extreme.score_pair(pair, name, m, extreme.opencv_homography)
    assert r["matched"] and r["correct_inliers"] > 10, r
    if name == "affcorr":
        r = extreme.score_pair(pair, name, m, extreme.affcorr_homography)
        assert r["matched"], r


@pytest.mark.parametrize("seed", ["x", ",", "1,b"])
def test_extreme_names_a_bad_seed_list(seed, capsys):
    with pytest.raises(SystemExit) as e:
        extreme.main(["--seed", seed])
    assert e.value.code == 2
    assert f"--seed takes comma-separated integers, got {seed!r}" in capsys.readouterr().err


def _area_scale(H: np.ndarray) -> float:
    """|det| of the homography's Jacobian at image 1's centre (640 x 480): its local zoom²."""
    x = np.array([320.0, 240.0, 1.0])
    return float(abs(np.linalg.det(H / H[2, 2]) / ((H[2] / H[2, 2]) @ x) ** 3))


def test_extreme_pairs_zoom_only_when_asked():
    (plain,) = data.extreme_pairs(tilts=(60,), images=1)
    (same,) = data.extreme_pairs(tilts=(60,), images=1, scale_ratio=1.0)
    assert same.id == plain.id and np.array_equal(same.H, plain.H)
    assert np.array_equal(same.img2, plain.img2)
    (zoomed,) = data.extreme_pairs(tilts=(60,), images=1, scale_ratio=9.0)
    assert zoomed.id == plain.id + "-z9" and np.array_equal(zoomed.img1, plain.img1)
    # The same cameras but camera 2's distance: the local area scale moves by a factor
    # within 1/9..9 (the zoom's square), here by more than 2.
    r = _area_scale(zoomed.H) / _area_scale(plain.H)
    assert 2.0 < max(r, 1 / r) <= 9.0, r


@pytest.mark.parametrize("ratio", ["0.5", "nan"])
def test_extreme_names_a_bad_scale_ratio(ratio, capsys):
    with pytest.raises(SystemExit) as e:
        extreme.main(["--scale-ratio", ratio])
    assert e.value.code == 2
    assert "--scale-ratio must be at least 1" in capsys.readouterr().err


def test_a_steep_tilt_seen_from_farther_is_solved_through_a_zoomed_tilt_view():
    # Chelsea at 80° and 126° of roll, camera 2 farther away: the plane is shrunk about 2.6x
    # along the tilt's axis and 14x across it in B. No view of the cascade at A's size
    # matches it (0 matches before the zoomed tilts); A tilted by 4 and zoomed by 1/2, against
    # B turned, does.
    import affcorr

    (q,) = [
        p
        for p in data.extreme_pairs((80,), 11, 2, every_held_out=True, scale_ratio=9.0)
        if p.id == "x-chelsea-80-s11-z9"
    ]
    res = affcorr.Pipeline(threads=2).match_pair(q.img1, q.img2)
    assert "zoom 0.5 tilt 4" in res.view["label"] and res.view["verified"], res.views
    m = matchers.Matches(res.corrs[:, :2], res.corrs[:, 2:4], None, res.certainty, 0.0)
    H, _ = extreme.opencv_homography(m)
    assert extreme.overlap_error(H, q) < 10.0


def test_affcorrs_cached_matches_are_keyed_by_its_sources(tmp_path, monkeypatch):
    # A change to the Rust sources (an experiment not landed, a revision number reused) must
    # not serve the matches an earlier build cached; the peers' keys do not depend on them.
    from affcorr_bench.eval import suite

    (tmp_path / "crates/affcorr-x/src").mkdir(parents=True)
    source = tmp_path / "crates/affcorr-x/src/lib.rs"
    source.write_text("fn a() {}")
    (tmp_path / "Cargo.lock").write_text("lock")
    monkeypatch.setattr(suite.common, "ROOT", tmp_path)
    pair = data.Pair("p", "extreme", np.zeros((2, 2), np.uint8), np.ones((2, 2), np.uint8), None)

    def keys():
        suite.pipeline_source_digest.cache_clear()
        return suite._key(pair, "affcorr", 64).name, suite._key(pair, "sift", 64).name

    try:
        first = keys()
        assert first[0].endswith(f"-src{suite.pipeline_source_digest()}.npz")
        assert keys() == first
        source.write_text("fn a() { b() }")
        second = keys()
        assert second[0] != first[0] and second[1] == first[1] == "sift-k64.npz"
        # the matcher's models too
        (tmp_path / "python/affcorr/models").mkdir(parents=True)
        (tmp_path / "python/affcorr/models/xfeat_backbone.onnx").write_bytes(b"weights")
        assert keys()[0] not in (first[0], second[0])
    finally:
        suite.pipeline_source_digest.cache_clear()
