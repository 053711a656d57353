"""Matching at SfM scale: ``affcorr batch`` and :func:`run`.

A pair list (hloc's pairs file, or a list of ``(name0, name1)``) and an image folder in; per
pair the ACs ``(N, 8)``, the matcher's certainty, the reliability flags (``reliable``,
``affine_confidence``) and, optionally, the homography, the fundamental matrix and the relative
pose with their inlier masks; out hloc's ``features.h5`` and ``matches.h5`` (which hloc's
``triangulation`` / ``reconstruction`` and other hloc-reading tools take) and, optionally, a
COLMAP database (``colmap=True``) that ``colmap mapper`` imports. :mod:`affcorr.batch._outputs`
documents the layout.

- **Features once per image**: each image's keypoints and descriptors
  (:meth:`affcorr.Pipeline.extract`) are computed once and kept, in each worker's memory and in
  ``<output>/cache`` (shared by the workers when it is on a shared file system); every pair is
  then :meth:`affcorr.Pipeline.match_features`, whose result equals ``match_pair``'s bit for bit.
- **Pairs that do not overlap** cost the view cascade's whole budget (it finds nothing to
  stop at), so a batch runs it at ``view_relative_budget=BATCH_VIEW_RELATIVE_BUDGET`` (12
  plain passes of work; a single pair's default is 30): every rotated pair and nearly every
  steep tilt still solved, the strong zooms that only magnified tiles solve given up
  (benches/results/views_budget.md, docs/scale.md).
- **Local or Ray**: by default a process per core (``workers``), each running the pipeline with
  ``threads_per_worker`` threads (ONNX Runtime and rayon); with ``ray_address`` (``--ray``) the
  chunks of ``chunk_size`` pairs are Ray tasks on an existing cluster, the model files shipped
  once through the object store, the images read from the shared file system or, with
  ``ship_images=True`` (``--ship-images``) for workers that cannot see the image folder, sent
  once each through the object store as their files' bytes (decoded by the same decoder, so the
  results are identical).
- **Resumable**: each pair's group carries a checksum of its inputs (both images' bytes, the
  cameras) and options (pipeline, models, geometry); ``resume=True`` skips the pairs written
  with the same checksum and redoes the others.
- **Fault tolerant**: a bad pair (unreadable image, too small, ...) is recorded with its
  error (``failures.jsonl``, :attr:`BatchSummary.failures`) and never stops the batch; a chunk
  whose worker dies is resubmitted (``retries`` times, then pair by pair, then recorded).
- **Deterministic**: a pair's results depend on its inputs and options only, never on the
  scheduling, the worker count or retries.
- **Incremental**: results are written as they arrive, by the driver alone; the HDF5 files are
  closed between writes, so a crash loses only the pairs in flight.

>>> from affcorr.batch import run  # doctest: +SKIP
>>> summary = run("pairs.txt", "images/", "out/", geometry=["fundamental"], colmap=True)
... # doctest: +SKIP
"""

from ._inputs import Camera, default_camera, names_to_pair, read_cameras, read_pairs
from ._run import BATCH_VIEW_RELATIVE_BUDGET, GEOMETRIES, BatchSummary, run

__all__ = [
    "BATCH_VIEW_RELATIVE_BUDGET",
    "GEOMETRIES",
    "BatchSummary",
    "Camera",
    "default_camera",
    "names_to_pair",
    "read_cameras",
    "read_pairs",
    "run",
]
