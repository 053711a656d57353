"""The batch's outputs, written by the driver only (one writer), pair by pair as results come:

- ``features.h5`` (hloc's layout): a group per image name with ``keypoints`` (N, 2) float32
  (pixel centres at integers, as hloc stores them), ``scores`` (N,), ``descriptors`` (D, N)
  float16 and ``image_size`` (W, H).
- ``matches.h5`` (hloc's layout): a group ``names_to_pair(name0, name1)`` per pair with
  ``matches0`` (N0,) int16 (the index of the matched keypoint of image 1, -1 for none) and
  ``matching_scores0`` (N0,) float16, as hloc's ``match_features`` writes them; beside them
  ``acs`` (N, 8), ``certainty``, ``reliable`` / ``affine_confidence`` (when the pipeline gives
  them), ``ac_keypoints`` (N, 2) (each AC's keypoint in image 0 and 1, -1 for none), and the
  models with their inlier masks over the ACs (``H``, ``H_inliers``, ``F``, ``F_inliers``,
  ``R``, ``t``, ``E``, ``pose_inliers``) and, when the pose's inliers lie on one plane and the
  other motion of that plane is physically valid too, that motion and the plane's homography
  (``twin_R``, ``twin_t``, ``twin_normal``, ``planar_share``, ``planar_H``:
  ``affcorr.planar_twin``); attributes ``checksum`` (of the inputs and options,
  for ``resume``), ``worker``, ``seconds``, ``view``, ``peak_rss_mb`` (the worker's peak
  memory so far).
- ``failures.jsonl``: one line per failed pair (names, error), appended.
- ``database.db`` (optional, pycolmap): cameras, images, keypoints (+0.5: COLMAP's pixel
  corners), matches and verified two-view geometries (F, E or H with their inlier matches;
  a pose with a planar twin is ``PLANAR_OR_PANORAMIC`` with E, F and the plane's H, as
  COLMAP's own verification marks a calibrated pair whose inliers a homography explains).

The HDF5 files are opened, written and closed for every group of results, so that between
writes they are complete files: a crash of a worker costs nothing written, a crash of the
driver at most the results not yet written (the pairs in flight). They are written without
``libver="latest"``, whose file-consistency flags would make a file left open by a killed
driver unreadable until ``h5clear``. A pair's ``checksum`` attribute is written last and an
image group counts once its four datasets are there, so a group cut short by a crash is
redone on resume. SQLite commits each pair.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from ._inputs import Camera, names_to_pair

FEATURES_FILE = "features.h5"
MATCHES_FILE = "matches.h5"
FAILURES_FILE = "failures.jsonl"
DATABASE_FILE = "database.db"
SUMMARY_FILE = "summary.json"

_IMAGE_KEYS = {"keypoints", "scores", "descriptors", "image_size"}

_ARRAYS = (
    "matches0",
    "matching_scores0",
    "acs",
    "certainty",
    "reliable",
    "affine_confidence",
    "ac_keypoints",
    "num_keypoints",
)


def _h5py() -> Any:
    try:
        import h5py
    except ImportError:
        raise RuntimeError(
            "affcorr batch writes HDF5 through h5py, which is not installed: "
            "pip install 'affcorr[batch]'"
        ) from None
    return h5py


def written_checksums(output: Path) -> dict[str, str]:
    """``{pair key: checksum}`` of the pairs in ``matches.h5`` (for ``resume``)."""
    path = output / MATCHES_FILE
    if not path.exists():
        return {}
    h5py = _h5py()
    out: dict[str, str] = {}
    with h5py.File(path, "r") as fd:

        def visit(name: str, obj: Any) -> None:
            if isinstance(obj, h5py.Group) and "checksum" in obj.attrs:
                out[name] = str(obj.attrs["checksum"])

        fd.visititems(visit)
    return out


class HdfWriter:
    """features.h5 and matches.h5 (see the module docs)."""

    def __init__(self, output: Path) -> None:
        self.h5py = _h5py()
        self.features = output / FEATURES_FILE
        self.matches = output / MATCHES_FILE
        self.images: set[str] = set()
        if self.features.exists():
            with self.h5py.File(self.features, "r") as fd:

                def visit(name: str, obj: Any) -> None:
                    # An image group counts once all of it is there (image_size is written
                    # last): a crash in the middle of a group rewrites it.
                    if isinstance(obj, self.h5py.Group) and _IMAGE_KEYS <= set(obj.keys()):
                        self.images.add(name)

                fd.visititems(visit)

    def write(self, records: list[dict[str, Any]]) -> None:
        new_images = [
            (name, feat)
            for r in records
            for name, feat in r.get("images", {}).items()
            if name not in self.images
        ]
        if new_images:
            with self.h5py.File(self.features, "a") as fd:
                for name, feat in new_images:
                    if name in self.images:
                        continue
                    if name in fd:
                        del fd[name]
                    g = fd.create_group(name)
                    for k in ("keypoints", "scores", "descriptors", "image_size"):
                        g.create_dataset(k, data=feat[k])
                    self.images.add(name)
        ok = [r for r in records if "error" not in r]
        if not ok:
            return
        with self.h5py.File(self.matches, "a") as fd:
            for r in ok:
                key = names_to_pair(r["name0"], r["name1"])
                if key in fd:
                    del fd[key]
                g = fd.create_group(key)
                for k in _ARRAYS:
                    if k in r:
                        g.create_dataset(k, data=r[k])
                for k, v in r["models"].items():
                    g.create_dataset(k, data=v)
                g.attrs["worker"] = r["worker"]
                g.attrs["seconds"] = r["seconds"]
                g.attrs["view"] = r.get("view", "")
                g.attrs["peak_rss_mb"] = r.get("peak_rss_mb", 0.0)
                # Last: a group without its checksum (a crash while writing it) is redone.
                g.attrs["checksum"] = r["checksum"]


class FailureLog:
    """failures.jsonl: a line per failed pair."""

    def __init__(self, output: Path) -> None:
        self.path = output / FAILURES_FILE

    def write(self, records: list[dict[str, Any]]) -> None:
        bad = [r for r in records if "error" in r]
        if not bad:
            return
        with open(self.path, "a") as f:
            for r in bad:
                line = {k: r[k] for k in ("name0", "name1", "error", "checksum", "worker")}
                f.write(json.dumps(line) + "\n")
            f.flush()
            os.fsync(f.fileno())


class ColmapWriter:
    """A COLMAP database through pycolmap (see the module docs). Image ids follow the order
    of first appearance of each image in the pair list, so that they do not depend on
    scheduling."""

    def __init__(
        self, path: Path, image_order: list[str], cameras: dict[str, Camera], min_inliers: int
    ) -> None:
        try:
            import pycolmap
        except ImportError:
            raise RuntimeError(
                "colmap output needs pycolmap, which is not installed: pip install 'affcorr[batch]'"
            ) from None
        self.pycolmap = pycolmap
        self.path = path
        self.order = {name: i + 1 for i, name in enumerate(image_order)}
        self.cameras = cameras
        self.min_inliers = min_inliers
        self.db = pycolmap.Database.open(str(path))
        self.ids: dict[str, int] = {im.name: im.image_id for im in self.db.read_all_images()}

    def close(self) -> None:
        self.db.close()

    def _image(self, name: str, feat: dict[str, Any] | None) -> int | None:
        if name in self.ids:
            return self.ids[name]
        if feat is None:
            return None
        pc = self.pycolmap
        w, h = (int(x) for x in feat["image_size"])
        cam = self.cameras.get(name)
        if cam is None:
            f = 1.2 * max(w, h)
            camera = pc.Camera(model="SIMPLE_PINHOLE", width=w, height=h, params=[f, w / 2, h / 2])
            camera.has_prior_focal_length = False
        else:
            camera = pc.Camera(
                model=cam.model, width=cam.width, height=cam.height, params=list(cam.params)
            )
            camera.has_prior_focal_length = True
        image_id = self.order[name]
        camera.camera_id = image_id
        camera_id = self.db.write_camera(camera, use_camera_id=True)
        rig = pc.Rig(rig_id=image_id)
        rig.add_ref_sensor(camera.sensor_id)
        rig_id = self.db.write_rig(rig, use_rig_id=True)
        image = pc.Image(name=name, camera_id=camera_id, image_id=image_id)
        image_id = self.db.write_image(image, use_image_id=True)
        frame = pc.Frame(frame_id=image_id, rig_id=rig_id)
        sensor = pc.sensor_t(type=pc.SensorType.CAMERA, id=camera_id)
        frame.add_data_id(pc.data_t(sensor_id=sensor, id=image_id))
        self.db.write_frame(frame, use_frame_id=True)
        kp = np.asarray(feat["keypoints"], dtype=np.float32) + 0.5  # COLMAP: corner at 0
        self.db.write_keypoints(image_id, kp)
        self.ids[name] = image_id
        return image_id

    def write(self, records: list[dict[str, Any]], features: Any) -> None:
        for r in records:
            for name, feat in r.get("images", {}).items():
                self._image(name, feat)
        for r in records:
            if "error" in r:
                continue
            ids = [self._image(n, features(n)) for n in (r["name0"], r["name1"])]
            if None in ids:
                continue
            i0, i1 = ids
            m0 = np.asarray(r["matches0"])
            q = np.flatnonzero(m0 >= 0)
            matches = np.stack([q, m0[q]], axis=1).astype(np.uint32)
            if self.db.exists_matches(i0, i1):
                self.db.delete_matches(i0, i1)
            if self.db.exists_two_view_geometry(i0, i1):
                self.db.delete_two_view_geometry(i0, i1)
            self.db.write_matches(i0, i1, matches)
            self.db.write_two_view_geometry(i0, i1, self._geometry(r, matches))

    def _geometry(self, r: dict[str, Any], matches: np.ndarray) -> Any:
        """The verified geometry: the relative pose (CALIBRATED, E) when estimated, else F
        (UNCALIBRATED), else H (PLANAR); the inlier matches are the keypoint matches whose
        AC is an inlier of that model. A pose with a planar twin (its motion is ambiguous) is
        PLANAR_OR_PANORAMIC with the plane's H, as COLMAP's own verification marks a
        calibrated pair whose inliers a homography explains."""
        pc = self.pycolmap
        models = r["models"]
        ack = np.asarray(r["ac_keypoints"])
        keyed = {(int(a), int(b)) for a, b in matches}
        tvg = pc.TwoViewGeometry()
        for key, mask, config in (
            ("E", "pose_inliers", pc.TwoViewGeometryConfiguration.CALIBRATED),
            ("F", "F_inliers", pc.TwoViewGeometryConfiguration.UNCALIBRATED),
            ("H", "H_inliers", pc.TwoViewGeometryConfiguration.PLANAR),
        ):
            if key not in models or not np.isfinite(models[key]).all():
                continue
            inl = np.asarray(models[mask], dtype=bool)
            pairs = [
                (int(a), int(b)) for (a, b), ok in zip(ack, inl) if ok and (int(a), int(b)) in keyed
            ]
            if len(pairs) < self.min_inliers:
                continue
            tvg.config = config
            if key == "E":
                tvg.E = models["E"]
                tvg.F = models["pose_F"]
            elif key == "F":
                tvg.F = models["F"]
            else:
                tvg.H = models["H"]
            if "H" in models and np.isfinite(models["H"]).all():
                tvg.H = models["H"]
            if key == "E" and "planar_H" in models:
                tvg.config = pc.TwoViewGeometryConfiguration.PLANAR_OR_PANORAMIC
                tvg.H = models["planar_H"]
            tvg.inlier_matches = np.asarray(sorted(pairs), dtype=np.uint32).reshape(-1, 2)
            return tvg
        tvg.config = pc.TwoViewGeometryConfiguration.UNDEFINED
        return tvg
