"""affcorr batch's COLMAP database (issue 25): pycolmap reads back the right counts (cameras,
images, keypoints, matches, verified two-view geometries), and COLMAP's incremental mapper
imports it and registers every view."""

from __future__ import annotations

import affcorr
import numpy as np
import pytest

pycolmap = pytest.importorskip("pycolmap", reason="the COLMAP database is written by pycolmap")
h5py = pytest.importorskip("h5py", reason="affcorr batch writes HDF5 through h5py")

from affcorr import batch  # noqa: E402
from test_batch import OPTIONS, good_pairs, images  # noqa: E402, F401 (the fixture)


def test_colmap_database_reads_back_and_maps(images, tmp_path) -> None:  # noqa: F811
    folder, names = images
    pairs = [*good_pairs(names), (names[0], "broken.png")]
    cams = tmp_path / "cameras.txt"
    cams.write_text(f"{names[0]} PINHOLE 320 256 400 400 160 128\n")
    out = tmp_path / "out"
    s = batch.run(
        pairs, folder, out, colmap=True, cameras=cams, geometry=["homography", "fundamental"],
        workers=2, progress=False, **OPTIONS,
    )  # fmt: skip
    assert (s.matched, s.failed) == (len(pairs) - 1, 1), s
    db = pycolmap.Database.open(str(out / "database.db"))
    try:
        assert db.num_cameras() == db.num_images() == len(names)  # not the broken image
        by_name = {im.name: im for im in db.read_all_images()}
        assert sorted(by_name) == sorted(names)
        # Ids follow the pair list, whatever the scheduling.
        assert [by_name[n].image_id for n in names] == list(range(1, len(names) + 1))
        cam0 = db.read_camera(by_name[names[0]].camera_id)
        assert cam0.model.name == "PINHOLE" and list(cam0.params) == [400, 400, 160, 128]
        with h5py.File(out / "features.h5", "r") as ff, h5py.File(out / "matches.h5") as fm:
            for n in names:
                kp = db.read_keypoints(by_name[n].image_id)
                np.testing.assert_allclose(kp[:, :2], ff[n]["keypoints"][()] + 0.5)
            assert db.num_matched_image_pairs() == len(pairs) - 1
            assert db.num_verified_image_pairs() == len(pairs) - 1
            for a, b in pairs[:-1]:
                ia, ib = by_name[a].image_id, by_name[b].image_id
                m = db.read_matches(ia, ib)
                m0 = fm[batch.names_to_pair(a, b)]["matches0"][()]
                assert len(m) == (m0 >= 0).sum()
                np.testing.assert_array_equal(m[:, 1], m0[m[:, 0]])
                tvg = db.read_two_view_geometry(ia, ib)
                assert tvg.config == pycolmap.TwoViewGeometryConfiguration.UNCALIBRATED
                assert len(tvg.inlier_matches) >= 15 and tvg.F is not None
    finally:
        db.close()
    # COLMAP imports it: the incremental mapper registers every view of the (planar) scene.
    recs = pycolmap.incremental_mapping(str(out / "database.db"), str(folder), str(tmp_path))
    assert recs, "COLMAP made no reconstruction"
    best = max(recs.values(), key=lambda r: r.num_reg_images())
    assert best.num_reg_images() == len(names) and best.num_points3D() > 50


def _plane_acs(t, n_points: int = 150) -> tuple[np.ndarray, np.ndarray]:
    """Exact ACs of the plane z = 4 seen by K, K with X2 = R X1 + t (R: 0.1 rad about y)."""
    K = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])
    c, s = np.cos(0.1), np.sin(0.1)
    R = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    H = K @ (R + np.outer(t, [0.0, 0.0, 1.0]) / 4.0) @ np.linalg.inv(K)
    x1 = np.random.default_rng(3).uniform(0, 480, (n_points, 2))
    return affcorr.correspondences_from_homography(H, x1), K


def test_a_planar_pose_is_planar_or_panoramic_with_its_twin(tmp_path) -> None:
    from affcorr.batch import _outputs, _worker

    config = dict(seed=0, geometries=["relative_pose"], thresholds={"relative_pose": 1.0})
    plane, K = _plane_acs([-1.0, 0.0, 0.3])
    task = dict(K0=K.tolist(), K1=K.tolist())
    models = _worker._models(plane, np.ones(len(plane)), task, config)
    assert models["planar_share"] == 1.0
    np.testing.assert_allclose(models["twin_R"] @ models["twin_R"].T, np.eye(3), atol=1e-9)
    p = np.c_[plane[:, :2], np.ones(len(plane))] @ models["planar_H"].T
    np.testing.assert_allclose(p[:, :2] / p[:, 2:], plane[:, 2:4], atol=1e-6)
    # The same motion seen on two planes (z = 4 and a plane tilted by 37 degrees): no twin.
    c, s = np.cos(0.1), np.sin(0.1)
    R = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    n2 = np.array([0.6, 0.0, 0.8])
    H2 = K @ (R + np.outer([-1.0, 0.0, 0.3], n2) / 6.0) @ np.linalg.inv(K)
    x1 = np.random.default_rng(4).uniform(0, 480, (150, 2))
    two = np.vstack([plane, affcorr.correspondences_from_homography(H2, x1)])
    models_two = _worker._models(two, np.ones(len(two)), task, config)
    assert "twin_R" not in models_two and "planar_H" not in models_two
    # COLMAP: PLANAR_OR_PANORAMIC with the plane's H; CALIBRATED without a twin.
    db = _outputs.ColmapWriter(tmp_path / "database.db", ["a", "b"], {}, min_inliers=15)
    try:
        for acs, m, want in (
            (plane, models, pycolmap.TwoViewGeometryConfiguration.PLANAR_OR_PANORAMIC),
            (two, models_two, pycolmap.TwoViewGeometryConfiguration.CALIBRATED),
        ):
            n = len(acs)
            record = dict(models=m, ac_keypoints=np.c_[np.arange(n), np.arange(n)])
            tvg = db._geometry(record, np.c_[np.arange(n), np.arange(n)].astype(np.uint32))
            assert tvg.config == want
            assert len(tvg.inlier_matches) == m["pose_inliers"].sum()
            if "planar_H" in m:
                np.testing.assert_allclose(tvg.H, m["planar_H"])
    finally:
        db.close()
