"""The driver of a batch: inputs and checksums, scheduling on local processes or Ray, retries,
the writers, the progress bar and the summary."""

from __future__ import annotations

import json
import logging
import multiprocessing
import os
import sys
import time
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from . import _outputs, _worker
from ._inputs import (
    Camera,
    PairsLike,
    digest,
    file_digest,
    image_names,
    names_to_pair,
    read_cameras,
    read_pairs,
)

logger = logging.getLogger("affcorr.batch")

#: The geometries a batch can estimate per pair.
GEOMETRIES = ("homography", "fundamental", "relative_pose")

#: The view cascade's relative budget in a batch (``view_relative_budget``; the pipeline's own
#: default is ``PIPELINE_DEFAULTS["view_relative_budget"]``): a pair list holds pairs that do
#: not overlap, and the cascade spends its whole budget on each of them. At 12 plain passes it
#: still runs the rotations, the zooms by ½ and ¼ and the first tilt groups, which solved
#: every rotated pair and 39 of 40 steep tilts, and gives up the magnified tiles of strong
#: zooms (benches/results/views_budget.md).
BATCH_VIEW_RELATIVE_BUDGET = 12.0

# Bump when the records' content changes: old outputs are then recomputed on resume.
_FORMAT = 1


@dataclass
class BatchSummary:
    """What a batch did.

    Attributes:
        pairs: pairs in the list (repeats and reversed repeats counted once).
        matched: pairs matched and written by this run.
        skipped: pairs already written with the same checksum (``resume``).
        failed: pairs that failed (each in ``failures`` and ``failures.jsonl``).
        retried: chunks resubmitted after their worker died.
        seconds: wall time of the run.
        pairs_per_second: ``matched / seconds``.
        workers: worker processes (local) or Ray's CPUs used.
        failures: ``(name0, name1, error)`` per failed pair.
        outputs: the files written, by kind.
    """

    pairs: int = 0
    matched: int = 0
    skipped: int = 0
    failed: int = 0
    retried: int = 0
    seconds: float = 0.0
    pairs_per_second: float = 0.0
    workers: int = 0
    executor: str = "local"
    failures: list[tuple[str, str, str]] = field(default_factory=list)
    outputs: dict[str, str] = field(default_factory=dict)

    def __str__(self) -> str:
        return (
            f"{self.matched} pairs matched, {self.skipped} already done, {self.failed} failed "
            f"of {self.pairs}; {self.seconds:.1f} s, {self.pairs_per_second:.2f} pairs/s on "
            f"{self.workers} {self.executor} worker(s); {self.retried} chunk(s) retried"
        )


def _model_digests(models: dict[str, Path]) -> dict[str, str]:
    return {k: file_digest(Path(v)) for k, v in sorted(models.items())}


class _Progress:
    """tqdm with pairs/s and failures on a terminal (stderr), else a line per 10%."""

    def __init__(self, total: int, enabled: bool) -> None:
        self.total, self.n, self.failed = total, 0, 0
        self.enabled = enabled
        self.bar = None
        self.next_line = 0
        self.start = time.perf_counter()
        if enabled and sys.stderr.isatty():
            try:
                from tqdm import tqdm

                self.bar = tqdm(total=total, desc="affcorr batch", unit="pair")
            except ImportError:
                pass

    def update(self, done: int, failed: int) -> None:
        self.n += done
        self.failed += failed
        if self.bar is not None:
            self.bar.set_postfix(failed=self.failed, refresh=False)
            self.bar.update(done)
        elif self.enabled and (self.n >= self.next_line or self.n == self.total):
            rate = self.n / max(time.perf_counter() - self.start, 1e-9)
            print(
                f"affcorr batch: {self.n}/{self.total} pairs, {rate:.2f} pairs/s, "
                f"{self.failed} failed",
                file=sys.stderr,
                flush=True,
            )
            self.next_line = self.n + max(self.total // 10, 1)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def run(
    pairs: PairsLike,
    image_dir: str | os.PathLike[str],
    output: str | os.PathLike[str],
    *,
    matcher: str | None = None,
    max_keypoints: int | None = None,
    detection_threshold: float | None = None,
    max_matches: int | None = None,
    max_side: int | None = None,
    views: str | None = None,
    view_relative_budget: float | None = BATCH_VIEW_RELATIVE_BUDGET,
    refine_affine: bool | None = None,
    seed: int = 0,
    models_dir: str | os.PathLike[str] | None = None,
    shape_model: str | os.PathLike[str] | None = None,
    geometry: Sequence[str] = ("fundamental",),
    thresholds: dict[str, float] | None = None,
    cameras: str | os.PathLike[str] | dict[str, Camera] | None = None,
    colmap: bool = False,
    min_inliers: int = 15,
    workers: int | None = None,
    threads_per_worker: int = 1,
    ray_address: str | None = None,
    ship_images: bool = False,
    chunk_size: int = 4,
    cache: bool = True,
    memory_images: int = 32,
    resume: bool = False,
    overwrite: bool = False,
    retries: int = 2,
    snap_px: float = 2.0,
    progress: bool = True,
    on_result: Callable[[dict[str, Any]], None] | None = None,
) -> BatchSummary:
    """Matches every pair of a list, writes hloc's HDF5 files (and a COLMAP database), and
    returns a :class:`BatchSummary`; see :mod:`affcorr.batch`."""
    from affcorr import __version__
    from affcorr.pipeline import PIPELINE_DEFAULTS, Pipeline

    t_start = time.perf_counter()
    image_dir = Path(image_dir)
    output = Path(output)
    if not image_dir.is_dir():
        raise FileNotFoundError(f"image_dir: {str(image_dir)!r} is not a directory")
    for g in geometry:
        if g not in GEOMETRIES:
            raise ValueError(f"geometry: {g!r} is not one of {list(GEOMETRIES)}")
    for name, v, low in (
        ("chunk_size", chunk_size, 1),
        ("threads_per_worker", threads_per_worker, 1),
        ("memory_images", memory_images, 2),
        ("retries", retries, 0),
        ("min_inliers", min_inliers, 0),
    ):
        if isinstance(v, bool) or not isinstance(v, int) or v < low:
            raise ValueError(f"{name} must be an int >= {low}, got {v!r}")
    if workers is not None and (
        isinstance(workers, bool) or not isinstance(workers, int) or workers < 1
    ):
        raise ValueError(f"workers must be a positive int or None, got {workers!r}")
    if not snap_px > 0:
        raise ValueError(f"snap_px must be positive, got {snap_px!r}")
    if ship_images and ray_address is None:
        raise ValueError(
            "ship_images: sending images as bytes is for Ray workers (ray_address / --ray); "
            "local workers read image_dir"
        )
    if output.exists() and not output.is_dir():
        raise ValueError(f"output: {str(output)!r} exists and is not a directory")
    existing = [
        f
        for f in (_outputs.MATCHES_FILE, _outputs.FEATURES_FILE, _outputs.DATABASE_FILE)
        if (output / f).exists()
    ]
    if existing and not (resume or overwrite):
        raise ValueError(
            f"output: {str(output)!r} already holds {', '.join(existing)}; pass resume=True "
            "(--resume) to skip the pairs written there, or overwrite=True (--overwrite)"
        )
    output.mkdir(parents=True, exist_ok=True)
    if overwrite and not resume:
        for f in (*existing, _outputs.FAILURES_FILE, _outputs.SUMMARY_FILE):
            (output / f).unlink(missing_ok=True)

    pair_list = read_pairs(pairs)
    names = image_names(pair_list)
    if isinstance(cameras, (str, os.PathLike)):
        cameras = read_cameras(cameras)
    cameras = dict(cameras or {})

    # The pipeline's configuration, checked here (bad options raise before any work).
    pipeline_kwargs: dict[str, Any] = {"seed": seed}
    for k, v in (
        ("matcher", matcher),
        ("max_keypoints", max_keypoints),
        ("detection_threshold", detection_threshold),
        ("max_matches", max_matches),
        ("max_side", max_side),
        ("views", views),
        ("refine_affine", refine_affine),
        ("shape_model", None if shape_model is None else os.fspath(shape_model)),
    ):
        if v is not None:
            pipeline_kwargs[k] = v
    # Always given (None is "no limit", not "the default"): the batch's default differs from
    # the pipeline's (BATCH_VIEW_RELATIVE_BUDGET).
    pipeline_kwargs["view_relative_budget"] = view_relative_budget
    probe = Pipeline(threads=1, models_dir=models_dir, **pipeline_kwargs)
    models = {k: Path(v) for k, v in probe.models.items()}
    # The effective options, not the given ones: the checksum (and so resume) must not depend
    # on whether a default was spelled out (the CLI passes them all).
    pipeline_kwargs.update(
        matcher=probe.matcher,
        max_keypoints=probe.max_keypoints,
        detection_threshold=probe.detection_threshold,
        max_matches=probe.max_matches,
        max_side=probe.max_side,
        views=probe.views,
        exif_orientation=probe.exif_orientation,
        refine_affine=(
            PIPELINE_DEFAULTS["refine_affine"] if refine_affine is None else bool(refine_affine)
        ),
    )
    pipeline_kwargs.pop("shape_model", None)  # its file's digest is in model_digests
    del probe
    thr = {
        "homography": PIPELINE_DEFAULTS["homography_threshold"],
        "fundamental": PIPELINE_DEFAULTS["fundamental_threshold"],
        "relative_pose": PIPELINE_DEFAULTS["pose_threshold"],
    }
    thr.update(thresholds or {})
    model_digests = _model_digests(models)
    options_key = digest(
        _FORMAT, __version__, pipeline_kwargs, model_digests, list(geometry),
        {g: thr[g] for g in geometry}, snap_px,
    )  # fmt: skip
    # The features do not depend on how far the view cascade may go.
    features_key = digest(
        _FORMAT,
        {k: v for k, v in pipeline_kwargs.items() if k != "view_relative_budget"},
        model_digests,
    )

    # Checksums of every image and pair.
    digests = {n: file_digest(image_dir / n) for n in names}

    def camera_of(name: str) -> Camera | None:
        return cameras.get(name)

    tasks: list[dict[str, Any]] = []
    for i, (a, b) in enumerate(pair_list):
        ca, cb = camera_of(a), camera_of(b)
        t: dict[str, Any] = {
            "index": i,
            "name0": a,
            "name1": b,
            "digest0": digests[a],
            "digest1": digests[b],
            "checksum": digest(
                options_key,
                digests[a],
                digests[b],
                ca.as_list() if ca else None,
                cb.as_list() if cb else None,
            ),  # fmt: skip
        }
        if "relative_pose" in geometry:
            # None: the worker takes default_camera of the image's size.
            t["K0"] = ca.K().tolist() if ca else None
            t["K1"] = cb.K().tolist() if cb else None
        tasks.append(t)

    done_before = _outputs.written_checksums(output) if resume else {}
    todo = [
        t for t in tasks if done_before.get(names_to_pair(t["name0"], t["name1"])) != t["checksum"]
    ]
    summary = BatchSummary(pairs=len(tasks), skipped=len(tasks) - len(todo))
    # Locality: pairs sorted by their first image, then chunks of consecutive pairs, so that a
    # worker's memory cache serves the image shared by a chunk.
    order = {n: i for i, n in enumerate(names)}
    todo.sort(key=lambda t: (order[t["name0"]], order[t["name1"]]))
    chunks = [todo[i : i + chunk_size] for i in range(0, len(todo), chunk_size)]

    cache_dir = output / "cache" if cache else None
    if cache_dir is not None:
        cache_dir.mkdir(exist_ok=True)
    config: dict[str, Any] = {
        "key": digest(
            options_key,
            os.fspath(image_dir),
            os.fspath(cache_dir) if cache_dir else "",
            threads_per_worker,
        ),
        "pipeline": {k: v for k, v in pipeline_kwargs.items() if k != "shape_model"},
        "models_dir": None if models_dir is None else os.fspath(models_dir),
        "threads": threads_per_worker,
        "image_dir": os.fspath(image_dir.resolve()),
        "cache_dir": None if cache_dir is None else os.fspath(cache_dir.resolve()),
        "features_key": features_key,
        "memory_images": memory_images,
        "geometries": list(geometry),
        "thresholds": {g: thr[g] for g in geometry},
        "seed": seed,
        "snap_px": snap_px,
    }
    if shape_model is not None:
        config["pipeline"]["shape_model"] = os.fspath(shape_model)

    hdf = _outputs.HdfWriter(output)
    failures_log = _outputs.FailureLog(output)
    db = (
        _outputs.ColmapWriter(output / _outputs.DATABASE_FILE, names, cameras, min_inliers)
        if colmap
        else None
    )
    feature_cache: dict[str, dict[str, Any]] = {}

    def features_of(name: str) -> dict[str, Any] | None:
        # The COLMAP writer needs an image's keypoints if a pair names an image whose
        # record arrived in an earlier run (resume): read back from features.h5.
        if name in feature_cache:
            return feature_cache[name]
        import h5py

        if not hdf.features.exists():
            return None
        with h5py.File(hdf.features, "r") as fd:
            if name not in fd:
                return None
            g = fd[name]
            return {"keypoints": g["keypoints"][()], "image_size": g["image_size"][()]}

    bar = _Progress(len(todo), progress)

    def handle(records: list[dict[str, Any]]) -> None:
        hdf.write(records)
        failures_log.write(records)
        if db is not None:
            for r in records:
                for n, f in r.get("images", {}).items():
                    feature_cache[n] = f
            db.write(records, features_of)
            feature_cache.clear()
        bad = [r for r in records if "error" in r]
        summary.matched += len(records) - len(bad)
        summary.failed += len(bad)
        summary.failures.extend((r["name0"], r["name1"], r["error"]) for r in bad)
        bar.update(len(records), len(bad))
        if on_result is not None:
            for r in records:
                on_result(
                    {k: r[k] for k in ("index", "name0", "name1", "worker") if k in r}
                    | {"error": r.get("error")}
                )

    try:
        if ray_address is not None:
            summary.executor = "ray"
            summary.workers, summary.retried = _run_ray(
                ray_address, config, models, chunks, retries, handle,
                image_dir if ship_images else None,
            )  # fmt: skip
        else:
            n = workers or max(1, (os.cpu_count() or 1) // threads_per_worker)
            n = max(1, min(n, len(chunks)))
            summary.workers = n
            summary.retried = _run_local(n, config, chunks, retries, handle)
    finally:
        bar.close()
        if db is not None:
            db.close()
    summary.seconds = time.perf_counter() - t_start
    summary.pairs_per_second = summary.matched / summary.seconds if summary.seconds else 0.0
    summary.outputs = {
        "features": os.fspath(hdf.features),
        "matches": os.fspath(hdf.matches),
        "failures": os.fspath(failures_log.path),
        **({"colmap": os.fspath(output / _outputs.DATABASE_FILE)} if colmap else {}),
    }
    (output / _outputs.SUMMARY_FILE).write_text(json.dumps(asdict(summary), indent=1) + "\n")
    logger.info("affcorr batch: %s", summary)
    return summary


def _died(chunk: list[dict[str, Any]], attempts: int) -> list[dict[str, Any]]:
    return [
        {
            "index": t["index"],
            "name0": t["name0"],
            "name1": t["name1"],
            "checksum": t["checksum"],
            "worker": "",
            "error": f"WorkerDied: the worker matching this pair died {attempts} time(s) "
            "(killed, out of memory, or crashed)",
            "seconds": 0.0,
        }
        for t in chunk
    ]


def _requeue(chunk: list[dict[str, Any]], attempt: int, retries: int, queue: list, handle) -> int:
    """A chunk whose worker died: again (up to ``retries`` times), then pair by pair, then
    each pair recorded as failed. Returns the number of resubmissions."""
    if attempt < retries:
        queue.append((chunk, attempt + 1))
        return 1
    if len(chunk) > 1:
        queue.extend(([t], attempt) for t in chunk)  # isolate the pair that kills workers
        return len(chunk)
    handle(_died(chunk, attempt + 1))
    return 0


def _run_local(
    n: int, config: dict[str, Any], chunks: list[list[dict]], retries: int, handle
) -> int:
    """Chunks on ``n`` local processes (spawned: no inherited threads or ONNX Runtime state),
    at most 2 chunks in flight per process. A process that dies breaks the pool: it is
    replaced and the chunks in flight are resubmitted."""
    queue: list[tuple[list[dict], int]] = [(c, 0) for c in reversed(chunks)]
    retried = 0
    ctx = multiprocessing.get_context("spawn")
    while queue:
        pool = ProcessPoolExecutor(
            n, mp_context=ctx, initializer=_worker.worker_init, initargs=(config["threads"],)
        )
        inflight: dict[Future, tuple[list[dict], int]] = {}
        broken = False
        try:
            while (queue or inflight) and not broken:
                while queue and len(inflight) < 2 * n:
                    chunk, attempt = queue.pop()
                    try:
                        fut = pool.submit(_worker.process_chunk, config, chunk)
                    except BrokenProcessPool:
                        # The pool broke between two results (a worker died while the
                        # last result was handled): this chunk never ran, so it goes
                        # back unchanged, without spending one of its retries.
                        queue.append((chunk, attempt))
                        broken = True
                        break
                    inflight[fut] = (chunk, attempt)
                if broken:
                    break
                finished, _ = wait(list(inflight), return_when=FIRST_COMPLETED)
                for fut in finished:
                    chunk, attempt = inflight.pop(fut)
                    try:
                        records = fut.result()
                    except BrokenProcessPool:
                        broken = True
                        retried += _requeue(chunk, attempt, retries, queue, handle)
                        continue
                    handle(records)
            if broken:
                # Every chunk still in flight was lost with the pool.
                for fut, (chunk, attempt) in inflight.items():
                    try:
                        handle(fut.result(timeout=0))
                    except Exception:  # noqa: BLE001 (lost with the pool)
                        retried += _requeue(chunk, attempt, retries, queue, handle)
                logger.warning("affcorr batch: a worker process died; restarting the pool")
        finally:
            pool.shutdown(wait=not broken, cancel_futures=True)
    return retried


def _run_ray(
    address: str,
    config: dict[str, Any],
    models: dict[str, Path],
    chunks,
    retries: int,
    handle,
    ship_from: Path | None = None,
) -> tuple[int, int]:
    """Chunks as Ray tasks (``config["threads"]`` CPUs each) on the cluster at ``address``
    (``"auto"``, ``"ray://host:port"`` or ``"host:port"``; ``"local"`` starts one). The model
    files go to the object store once; each worker process fetches them on its first task.
    With ``ship_from`` (``ship_images``) every image's file bytes go to the object store once
    too, and the workers never read an image folder: a task carries the references of its
    chunk's images and fetches only those its worker has no features for.
    Ray retries a task whose worker dies (``retries`` times); after that its pairs are tried
    one by one, and recorded as failed if they still kill their worker."""
    try:
        import ray
    except ImportError:
        raise RuntimeError(
            "--ray needs Ray, which is not installed: pip install 'affcorr[ray]'"
        ) from None
    started = False
    if not ray.is_initialized():
        if address == "local":
            ray.init(include_dashboard=False, log_to_driver=False)
        else:
            ray.init(address=address, include_dashboard=False, log_to_driver=False)
        started = True
    try:
        files = {role: path.read_bytes() for role, path in models.items()}
        shipped = dict(config, models_dir_shipped=True, models_dir=None)
        shipped["pipeline"] = {k: v for k, v in config["pipeline"].items() if k != "shape_model"}
        box = [ray.put(files)]
        image_refs: dict[str, Any] = {}
        if ship_from is not None:
            shipped["image_dir"] = None
            for chunk in chunks:
                for t in chunk:
                    for n in (t["name0"], t["name1"]):
                        if n not in image_refs:
                            image_refs[n] = ray.put((ship_from / n).read_bytes())

        def refs_of(chunk: list[dict]) -> dict[str, Any] | None:
            if not image_refs:
                return None
            return {n: image_refs[n] for t in chunk for n in (t["name0"], t["name1"])}

        task = ray.remote(_worker.process_chunk_shipped).options(
            num_cpus=config["threads"], max_retries=retries, retry_exceptions=False
        )
        cpus = int(ray.cluster_resources().get("CPU", 1))
        limit = max(2, 2 * cpus // config["threads"])
        queue: list[tuple[list[dict], int]] = [(c, retries) for c in reversed(chunks)]
        inflight: dict[Any, tuple[list[dict], int]] = {}
        resubmitted = 0
        while queue or inflight:
            while queue and len(inflight) < limit:
                chunk, attempt = queue.pop()
                inflight[task.remote(shipped, box, chunk, refs_of(chunk))] = (chunk, attempt)
            ready, _ = ray.wait(list(inflight), num_returns=1)
            for ref in ready:
                chunk, attempt = inflight.pop(ref)
                try:
                    handle(ray.get(ref))
                except (
                    ray.exceptions.WorkerCrashedError,
                    ray.exceptions.NodeDiedError,
                    ray.exceptions.RayTaskError,
                    ray.exceptions.ObjectLostError,
                ):
                    # Ray's own retries are spent: split, then record.
                    resubmitted += _requeue(chunk, attempt, retries, queue, handle)
        return cpus, resubmitted
    finally:
        if started:
            ray.shutdown()
