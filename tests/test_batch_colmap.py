"""affcorr batch's COLMAP database (issue 25): pycolmap reads back the right counts (cameras,
images, keypoints, matches, verified two-view geometries), and COLMAP's incremental mapper
imports it and registers every view."""

from __future__ import annotations

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
