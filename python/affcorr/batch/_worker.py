"""The worker side of a batch: one pipeline per process (built on its first task and kept), the
per-image feature cache (in memory, and on disk when the batch has a cache folder), and a
chunk of pairs in, one plain record per pair out (arrays and numbers only, cheap to pickle).

A worker never raises for a pair: a pair that fails is a record with its error. The models
reach a worker as paths (a shared file system, the local executor) or, under Ray, as bytes in
the object store, fetched once per worker process and written to a folder named by their
digest (:func:`shipped_models_dir`), so that workers and batches with the same models share one
folder instead of leaving one behind per process.
"""

from __future__ import annotations

import hashlib
import os
import socket
import tempfile
import time
from collections import OrderedDict
from pathlib import Path
from typing import Any

import numpy as np

from ._inputs import default_camera

# One pipeline per process, for the configuration of the running batch.
_STATE: dict[str, Any] = {}


def _set_threads(threads: int) -> None:
    # rayon's global pool (the estimators) reads this when it starts; the pipeline's own pool
    # and ONNX Runtime get `threads` from the Pipeline.
    os.environ["RAYON_NUM_THREADS"] = str(threads)


class _State:
    def __init__(self, config: dict[str, Any], models: dict[str, Path]) -> None:
        from affcorr.pipeline import Pipeline

        _set_threads(config["threads"])
        kwargs = dict(config["pipeline"])
        if "shape" in models:
            kwargs["shape_model"] = models["shape"]
        if config.get("models_dir_shipped"):
            kwargs["models_dir"] = models["_dir"]
        elif config.get("models_dir"):
            kwargs["models_dir"] = config["models_dir"]
        self.pipeline = Pipeline(threads=config["threads"], **kwargs)
        self.config = config
        self.features: OrderedDict[str, Any] = OrderedDict()
        self.reported: set[str] = set()
        # {image name: Ray object reference of its file's bytes} of the chunk in hand.
        self.shipped_images: dict[str, Any] = {}
        self.worker = f"{socket.gethostname()}:{os.getpid()}"

    # ------------------------------------------------------------------ features

    def image_features(self, name: str, image_digest: str) -> Any:
        """The features of image `name`: from memory, the disk cache, or extracted (then
        stored in both)."""
        from affcorr.pipeline import Features

        if name in self.features:
            self.features.move_to_end(name)
            return self.features[name]
        cache = self.config.get("cache_dir")
        path = None
        f = None
        if cache and not image_digest.startswith("missing:"):
            path = Path(cache) / f"{self.config['features_key'][:16]}-{image_digest[:32]}.afcf"
            if path.is_file():
                try:
                    f = Features.from_bytes(path.read_bytes())
                except (OSError, ValueError):
                    f = None  # a damaged entry is recomputed and replaced
        if f is None:
            f = self._extract(name)
            if path is not None:
                tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
                try:
                    tmp.write_bytes(f.to_bytes())
                    os.replace(tmp, path)  # atomic: readers see all of it or nothing
                except OSError:
                    tmp.unlink(missing_ok=True)
        self.features[name] = f
        while len(self.features) > self.config["memory_images"]:
            self.features.popitem(last=False)
        return f

    def _extract(self, name: str) -> Any:
        """Features of image `name`, read from the image folder or, when the driver ships the
        images (``ship_images``), from its bytes in Ray's object store."""
        ref = self.shipped_images.get(name)
        if ref is None:
            if self.config["image_dir"] is None:
                raise RuntimeError(f"image {name!r} was not shipped to this worker")
            return self.pipeline.extract(Path(self.config["image_dir"]) / name)
        import ray

        # The file's own bytes under its own suffix: the same decoder as for a path, so the
        # features are identical to those read from the folder.
        with tempfile.NamedTemporaryFile(suffix=Path(name).suffix) as tmp:
            tmp.write(ray.get(ref))
            tmp.flush()
            return self.pipeline.extract(tmp.name)

    def feature_record(self, name: str, f: Any) -> dict[str, Any]:
        """What features.h5 holds of an image (hloc's layout)."""
        return {
            "keypoints": np.asarray(f.keypoints, dtype=np.float32),
            "scores": np.asarray(f.scores, dtype=np.float32),
            "descriptors": np.ascontiguousarray(np.asarray(f.descriptors).T, dtype=np.float16),
            "image_size": np.asarray(f.image_size, dtype=np.int64),
        }

    # ------------------------------------------------------------------ one pair

    def pair(self, task: dict[str, Any]) -> dict[str, Any]:
        t0 = time.perf_counter()
        n0, n1 = task["name0"], task["name1"]
        rec: dict[str, Any] = {
            "index": task["index"],
            "name0": n0,
            "name1": n1,
            "checksum": task["checksum"],
            "worker": self.worker,
        }
        try:
            f0 = self.image_features(n0, task["digest0"])
            f1 = self.image_features(n1, task["digest1"])
            m = self.pipeline.match_features(f0, f1)
            rec.update(_pair_arrays(m, f0, f1, self.config["snap_px"]))
            if "relative_pose" in self.config["geometries"]:
                task = dict(task)
                for k, f in (("K0", f0), ("K1", f1)):
                    if task.get(k) is None:
                        task[k] = default_camera(*f.image_size).K()
            rec["models"] = _models(m.corrs, m.certainty, task, self.config)
            rec["images"] = {}
            for name, f in ((n0, f0), (n1, f1)):
                if name not in self.reported:
                    rec["images"][name] = self.feature_record(name, f)
                    self.reported.add(name)
        except KeyboardInterrupt:
            raise
        except Exception as e:  # noqa: BLE001 (a bad pair is recorded, never fatal)
            rec = {k: rec[k] for k in ("index", "name0", "name1", "checksum", "worker")}
            rec["error"] = f"{type(e).__name__}: {e}"
        rec["seconds"] = time.perf_counter() - t0
        rec["peak_rss_mb"] = _peak_rss_mb()
        return rec


def _peak_rss_mb() -> float:
    """The process's peak resident memory so far, MB (Linux reports kB; 0 where unknown)."""
    try:
        import resource
    except ImportError:  # not on Windows
        return 0.0
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _pair_arrays(m: Any, f0: Any, f1: Any, snap_px: float) -> dict[str, Any]:
    """The ACs and hloc's matches0 / matching_scores0: each AC's x1 is a keypoint of image 0
    (the matcher's point, exactly); its x2 is snapped to the nearest keypoint of image 1 within
    ``snap_px`` (the affine refinement moves x2 by sub-pixel amounts). ACs of synthetic views
    (the view cascade) or without a keypoint near x2 are in ``acs`` but not in ``matches0``;
    each keypoint is matched once (the most certain AC wins)."""
    corrs = np.asarray(m.corrs, dtype=np.float64)
    n = len(corrs)
    k0 = np.asarray(f0.keypoints, dtype=np.float64)
    k1 = np.asarray(f1.keypoints, dtype=np.float64)
    idx = np.full((n, 2), -1, dtype=np.int32)
    if n and len(k0) and len(k1):
        lookup = {(float(x), float(y)): i for i, (x, y) in enumerate(k0)}
        idx[:, 0] = [lookup.get((float(x), float(y)), -1) for x, y in corrs[:, :2]]
        # Nearest keypoint of image 1, in blocks to bound memory.
        for s in range(0, n, 1024):
            d = corrs[s : s + 1024, None, 2:4] - k1[None, :, :]
            d2 = np.einsum("ijk,ijk->ij", d, d)
            j = np.argmin(d2, axis=1)
            ok = d2[np.arange(len(j)), j] <= snap_px * snap_px
            idx[s : s + 1024, 1] = np.where(ok, j, -1)
    dtype = np.int16 if len(k1) < np.iinfo(np.int16).max else np.int32
    matches0 = np.full(len(k0), -1, dtype=dtype)
    scores0 = np.zeros(len(k0), dtype=np.float16)
    used1 = np.zeros(len(k1), dtype=bool)
    certainty = np.asarray(m.certainty, dtype=np.float64)
    for a in range(n):  # most certain first
        i, j = idx[a]
        if i < 0 or j < 0 or matches0[i] >= 0 or used1[j]:
            continue
        matches0[i] = j
        scores0[i] = certainty[a]
        used1[j] = True
    out = {
        "acs": corrs,
        "certainty": certainty.astype(np.float32),
        "ac_keypoints": idx,
        "matches0": matches0,
        "matching_scores0": scores0,
        "num_keypoints": np.asarray(m.num_keypoints, dtype=np.int64),
    }
    for name in ("reliable", "affine_confidence"):
        v = getattr(m, name, None)
        if v is not None and len(v) == n:
            out[name] = np.asarray(v)
    view = getattr(m, "view", None)
    out["view"] = view["label"] if view else ""
    return out


def _models(corrs: Any, certainty: Any, task: dict[str, Any], config: dict[str, Any]) -> dict:
    """H, F and the relative pose with their inlier masks over the ACs, and the pose's planar
    twin when it has one; a model that cannot be estimated (too few ACs, no consensus) is NaN
    with no inliers."""
    import affcorr

    out: dict[str, Any] = {}
    n = len(corrs)
    seed = config["seed"]
    for g in config["geometries"]:
        thr = config["thresholds"][g]
        try:
            if g == "homography":
                model, info = affcorr.estimate_homography(corrs, threshold=thr, seed=seed)
                out["H"], out["H_inliers"] = np.asarray(model), np.asarray(info.inliers)
            elif g == "fundamental":
                model, info = affcorr.estimate_fundamental(corrs, threshold=thr, seed=seed)
                out["F"], out["F_inliers"] = np.asarray(model), np.asarray(info.inliers)
            else:
                k0, k1 = np.asarray(task["K0"]), np.asarray(task["K1"])
                pose, info = affcorr.estimate_relative_pose(corrs, k0, k1, threshold=thr, seed=seed)
                out.update(R=pose.R, t=pose.t, E=pose.E, pose_F=pose.F)
                out["pose_inliers"] = np.asarray(info.inliers)
                # One plane: the other motion that explains every AC as well (see planar_twin).
                twin = affcorr.planar_twin(corrs, k0, k1, pose, info.inliers)
                if twin is not None:
                    out.update(twin_R=twin.R, twin_t=twin.t, twin_normal=twin.normal)
                    out.update(planar_share=np.float64(twin.planar_share), planar_H=twin.H)
        except ValueError:
            # Fewer ACs than a minimal sample: no model, as the pipeline reports it.
            key = {"homography": "H", "fundamental": "F"}.get(g, "E")
            out[key] = np.full((3, 3), np.nan)
            out[{"H": "H_inliers", "F": "F_inliers", "E": "pose_inliers"}[key]] = np.zeros(
                n, dtype=bool
            )
    return out


def _state(config: dict[str, Any], models: dict[str, Path] | None = None) -> _State:
    st = _STATE.get("state")
    if st is None or st.config["key"] != config["key"]:
        st = _State(config, models or {})
        _STATE["state"] = st
    return st


def process_chunk(config: dict[str, Any], chunk: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The records of a chunk of pairs (local executor: the models are paths)."""
    st = _state(config)
    return [st.pair(t) for t in chunk]


def shipped_models_dir(files: dict[str, bytes], root: Path | None = None) -> Path:
    """The folder holding `files` ({file name: bytes}) under `root` (the system's temporary
    folder by default), named by a digest of names and bytes, written once and then reused.

    Why a digest rather than a fresh temporary folder: Ray ends its workers without running
    their clean-up, so a private folder per worker process would stay behind after every
    batch. Each file is written to a temporary name and renamed, so a worker never loads a
    half-written file that another worker on the same machine is writing.
    """
    digest = hashlib.sha256()
    for name in sorted(files):
        digest.update(name.encode() + b"\0" + len(files[name]).to_bytes(8, "little"))
        digest.update(files[name])
    folder = Path(root or tempfile.gettempdir()) / f"affcorr-models-{digest.hexdigest()[:16]}"
    folder.mkdir(parents=True, exist_ok=True)
    for name, data in files.items():
        path = folder / name
        if path.is_file() and path.stat().st_size == len(data) and path.read_bytes() == data:
            continue
        fd, partial = tempfile.mkstemp(dir=folder, prefix=f".{name}.")
        try:
            with os.fdopen(fd, "wb") as handle:
                handle.write(data)
            os.replace(partial, path)
        except BaseException:
            Path(partial).unlink(missing_ok=True)  # a full disk leaves no partial file behind
            raise
    return folder


def process_chunk_shipped(
    config: dict[str, Any],
    box: list[Any],
    chunk: list[dict[str, Any]],
    images: dict[str, Any] | None = None,
) -> list[dict[str, Any]]:
    """:func:`process_chunk` under Ray: ``box`` holds the object-store reference of the model
    files' bytes, fetched only by a worker that has no pipeline for this batch yet; ``images``
    the references of the chunk's image files when the driver ships them."""
    st = _STATE.get("state")
    if st is None or st.config["key"] != config["key"]:
        import ray

        from affcorr.pipeline import _FILES

        files: dict[str, bytes] = ray.get(box[0])  # {role: bytes}
        names = {role: "shape.onnx" if role == "shape" else _FILES[role] for role in files}
        folder = shipped_models_dir({names[r]: data for r, data in files.items()})
        models: dict[str, Path] = {"_dir": folder}
        if "shape" in files:
            models["shape"] = folder / "shape.onnx"
        st = _state(config, models)
    st.shipped_images = images or {}
    return [st.pair(t) for t in chunk]


def worker_init(threads: int) -> None:
    """The local executor's process initializer."""
    _set_threads(threads)
