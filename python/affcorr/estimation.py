"""Robust estimation, PoseLib-like: each ``estimate_*`` returns ``(model, info)``.

The estimators run in Rust (``affcorr-ransac``) with the GIL released: a hypothesise-and-verify
loop with adaptive termination, local optimisation and a final refinement (docs/design.md §5).

- ``corrs`` is ``(N, 8)`` ACs ``[x1, y1, x2, y2, a11, a12, a21, a22]`` (``A = dx2/dx1``) or
  ``(N, 4)`` points ``[x1, y1, x2, y2]``, in pixels. ACs are sampled 2 at a time for H and E
  and 3 at a time for F; points 4, 7 and 5 at a time; hybrid samples (``sample="hybrid"``)
  take one AC and 2, 4 and 2 points.
- ``threshold`` is the inlier threshold in pixels: on the transfer error for homographies and on
  the Sampson distance for fundamental matrices and relative poses. About 3 sigma of the keypoint
  noise is a good value.
- Every other option is a keyword argument (all have defaults):

  ====================== ============ =========================================================
  option                 default      meaning
  ====================== ============ =========================================================
  ``sample``             ``None``     ``"affine"`` (minimal samples of ACs), ``"points"`` or
                                      ``"hybrid"`` (one AC and points: fewer affine
                                      equations than ACs, fewer data than points; ``(N, 8)``
                                      only); ``None``: ACs for ``(N, 8)`` data, points for
                                      ``(N, 4)``
  ``sampler``            ``"uniform"`` ``"uniform"`` or ``"prosac"`` (needs ``quality``)
  ``quality``            ``None``     ``(N,)`` per-correspondence quality for PROSAC, higher is
                                      better (e.g. matcher certainty); in the batch forms a
                                      list with one ``(N_i,)`` array per pair
  ``scoring``            ``"auto"``   the score of a model: ``"msac"`` (the truncated
                                      quadratic), ``"magsac"`` (MAGSAC++: the sigma-consensus++
                                      loss marginalised over noise scales up to
                                      ``threshold / 3.64``; also the loss of local optimisation
                                      and of the final refinement) or ``"auto"``: MSAC for every
                                      problem (the measured best on the scene families,
                                      docs/estimation.md)
  ``confidence``         ``0.9999``   confidence of the adaptive stopping rule, in (0, 1)
  ``sample_reliability`` ``1.0``      rho in ``(0, 1]`` in the stopping rule
                                      ``log(1 - confidence) / log(1 - rho w^m)``, where w is
                                      the fraction of data that can seed a good sample: for AC
                                      samples the inliers whose affine part is accurate too
                                      (point residual + 50 px^2 x affine residual within the
                                      threshold), so noisy ACs are searched longer; lower rho
                                      to search longer still
  ``min_iterations``     ``0``        never fewer iterations
  ``max_iterations``     ``10000``    never more iterations
  ``local_optimization`` ``True``     iterated least squares on the inliers of each new best
  ``lo``                 ``"irls"``   how each local-optimisation step picks the data it
                                      refits on: ``"irls"`` (those below the step's threshold)
                                      or ``"graph_cut"`` (GC-RANSAC: the minimum cut of data
                                      term + Potts spatial coherence on a grid neighbourhood
                                      of ``(x1, y1, x2, y2)``, so neighbours pull data just
                                      beyond the threshold in and push isolated ones out)
  ``lo_iterations``      ``10``       most refits in one local optimisation (per track)
  ``lo_schedule``        ``"auto"``   the thresholds local optimisation refits at:
                                      ``"widening"`` (8x the threshold down to it, so a rough
                                      minimal model still collects its inliers),
                                      ``"threshold"`` (the threshold alone: stays on the
                                      dominant structure when a second one lies a few pixels
                                      off it), ``"both"`` (both from the same hypothesis, the
                                      better score kept) or ``"auto"``: ``"both"`` for H,
                                      ``"widening"`` for F and the relative pose
                                      (docs/estimation.md)
  ``final_refinement``   ``True``     polish the final model on its inliers
  ``sprt``               ``True``     verify hypotheses with Wald's SPRT (random order, adaptive
                                      epsilon and delta): far fewer residuals for the same
                                      accuracy, slightly more iterations; ``False``: verify every
                                      hypothesis on all data
  ``affine_weight``      ``None``     weight (px^2) of the affine residual in scoring (``(N, 8)``
                                      only; 0: points only); ``None``: for F and the relative
                                      pose on ACs, 50 (points again, sampled, scored and
                                      refined, when it costs over 20% of the inliers or a
                                      points model explains 1.25x more: A too poor), else
                                      the lower weight
                                      that the noise of A measured on its inliers allows
                                      (its model polished at it; docs/estimation.md); 0
                                      otherwise. ``info.affine_weight`` is the weight used
  ``affine_refinement``  ``"final"``  where the affine terms of ACs enter the fits of H, F
                                      and the relative pose (``(N, 8)`` only): ``"off"``,
                                      ``"final"`` (the final refinement) or ``"all"`` (local
                                      optimisation too); the noise scale of A is estimated
                                      from the inliers and a poor A is down-weighted by a
                                      Cauchy loss (docs/estimation.md); H: A − A_H(x1) in its
                                      final refinement
  ``affine_confidence``  ``None``     ``(N,)`` per-AC confidence in ``[0, 1]`` scaling its
                                      affine terms (scoring with ``affine_weight``, and the
                                      refinements); 0 makes an AC a point; ``(N, 8)`` only; in
                                      the batch forms give it per pair in ``pair_options``
  ====================== ============ =========================================================

  ``affcorr.ESTIMATOR_OPTIONS`` lists the names. An unknown name raises ``ValueError``.
- Invalid input raises ``ValueError`` naming the argument or option: a bad shape, NaN or
  infinity, an invalid ``K``, ``threshold <= 0``, fewer correspondences than a minimal sample,
  PROSAC without ``quality`` or with the wrong length, ``sample="affine"`` with ``(N, 4)`` data,
  an ``affine_confidence`` of the wrong length, outside ``[0, 1]`` or with ``(N, 4)`` data.
- When no model is found (every sample degenerate, or no inlier at all), nothing is raised: as
  in PoseLib, ``info.num_inliers == 0`` and ``info.inliers`` is all ``False``
  (``info.num_iterations`` still counts the samples drawn); the model is filled with NaN so
  that it cannot be used by mistake. Check ``info.num_inliers``.
- The ``_batch`` forms take the options once for every pair, and ``pair_options``: a list with
  one dict per pair (or ``None``) whose entries override the shared options for that pair
  (``threshold``, ``seed`` and ``quality`` included).
- **Batches keep every pair's result.** The list has one item per pair, in order: its
  ``(model, info)``, or a :class:`PairError` (``index``, ``message``, and ``error``, the
  ``ValueError`` the single call would raise for that pair) in its place when that pair's
  input is invalid; the other pairs are estimated as usual. A pair with fewer
  correspondences than a minimal sample (0 or 1 matches, say) is not an error but a no-model
  result, as when no sample gives a model. ``on_error="raise"`` raises the first pair's error
  instead (the behaviour before). Errors of the whole batch (``corrs`` not a sequence, invalid
  shared options, a ``quality`` or ``pair_options`` list of the wrong length, ``K`` of the wrong
  shape) raise either way.
- Ctrl-C stops a long estimate or batch within a fraction of a second with
  ``KeyboardInterrupt`` (docs/reliability.md).
- Integer options (``seed``, ``max_iterations``, ...) take Python or numpy integers; errors
  name the option and, past a bound, give it (``max_iterations`` <= 10**9).
- The same data, options and ``seed`` give bit-identical results.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _native

__all__ = [
    "ESTIMATOR_OPTIONS",
    "PairError",
    "PlanarTwin",
    "RansacInfo",
    "RelativePose",
    "estimate_fundamental",
    "estimate_fundamental_batch",
    "estimate_homography",
    "estimate_homography_batch",
    "estimate_relative_pose",
    "estimate_relative_pose_batch",
    "planar_twin",
]

#: Names of the keyword options (besides ``threshold`` and ``seed``) that every estimator takes.
ESTIMATOR_OPTIONS: tuple[str, ...] = tuple(_native.ESTIMATOR_OPTIONS)


@dataclass(frozen=True, eq=False, repr=False)
class RansacInfo:
    """What a robust estimation did.

    Attributes:
        inliers: ``(N,)`` bool, the inliers of the returned model.
        num_inliers: their number (0 when no model was found).
        num_iterations: minimal samples drawn.
        score: the model's score (MSAC: the sum over data of ``max(0, 1 - r^2 / threshold^2)``;
            MAGSAC++: of ``1 - loss(r) / loss(threshold)``; higher is better). Relative poses
            count a correspondence whose point triangulates behind a camera as an outlier.
        lo_runs: local optimisations run.
        refinements: rounds of the final refinement that improved the model (0 to 4; each
            round refits on the inliers of the previous one while they change).
        residual_evaluations: residuals computed to verify and score models (what the SPRT
            saves).
        sprt_rejections: hypotheses rejected by the SPRT (0 without it).
        affine_weight: the weight (px^2) of the affine residual in scoring, 0 for points
            only. By default, for F and the relative pose on ``(N, 8)`` data, 50 px^2 or the
            lower weight that the noise of A measured on the data allows (0 when the estimate
            fell back to points).
    """

    inliers: NDArray[np.bool_]
    num_inliers: int
    num_iterations: int
    score: float
    lo_runs: int
    refinements: int
    residual_evaluations: int = 0
    sprt_rejections: int = 0
    affine_weight: float = 0.0

    @property
    def inlier_ratio(self) -> float:
        """num_inliers / N (0 for empty input)."""
        return self.num_inliers / len(self.inliers) if len(self.inliers) else 0.0

    def __repr__(self) -> str:
        return (
            f"RansacInfo(num_inliers={self.num_inliers}/{len(self.inliers)}, "
            f"num_iterations={self.num_iterations}, score={self.score:.4g}, "
            f"lo_runs={self.lo_runs}, refinements={self.refinements})"
        )


@dataclass(frozen=True, eq=False, repr=False)
class RelativePose:
    """A relative pose ``X2 = R X1 + t`` with ``|t| = 1``.

    Attributes:
        R: ``(3, 3)`` rotation.
        t: ``(3,)`` unit translation (the scale is unobservable).
        E: ``(3, 3)`` essential matrix ``[t]x R``.
        F: ``(3, 3)`` fundamental matrix ``K2^-T E K1^-1`` (pixels), ``p2^T F p1 = 0``.
    """

    R: NDArray[np.float64]
    t: NDArray[np.float64]
    E: NDArray[np.float64]
    F: NDArray[np.float64]

    @property
    def angle(self) -> float:
        """The rotation angle in radians."""
        return float(np.arccos(np.clip((np.trace(self.R) - 1.0) / 2.0, -1.0, 1.0)))

    def __repr__(self) -> str:
        t = np.array2string(self.t, precision=4, suppress_small=True, separator=", ")
        return f"RelativePose(angle={np.degrees(self.angle):.4g} deg, t={t})"


@dataclass(frozen=True, eq=False)
class PlanarTwin:
    """The other motion of a relative pose whose inliers lie on one plane (:func:`planar_twin`).

    Attributes:
        R: ``(3, 3)`` rotation of the twin.
        t: ``(3,)`` its unit translation.
        normal: ``(3,)`` the unit normal of its plane in camera 1 (``n^T X1 = d > 0``).
        planar_share: the share of the pose's inliers that one homography explains.
        H: ``(3, 3)`` that homography (pixels, ``p2 ~ H p1``, ``|H|_F = 1``), which the pose
            and its twin both induce.
    """

    R: NDArray[np.float64]
    t: NDArray[np.float64]
    normal: NDArray[np.float64]
    planar_share: float
    H: NDArray[np.float64]


class PairError(Exception):
    """The error of one pair of a batch, returned in that pair's place in the batch's list.

    A batch (``estimate_*_batch``, :meth:`affcorr.Pipeline.match_pairs`) gives every pair its
    result or its own error: ``[r if not isinstance(r, PairError) else ... for r in out]``.
    ``raise item`` (or ``on_error="raise"``) turns it back into an exception.

    Attributes:
        index: the pair's position in the batch.
        message: what went wrong, prefixed with the pair (``"pair 3: corrs[4] contains NaN or
            infinity"``, ``"pairs[1]: image_a: cannot decode image ..."``).
        error: the exception the single-pair call would have raised (``ValueError``,
            ``FileNotFoundError`` or ``RuntimeError``).
    """

    def __init__(self, index: int, error: BaseException) -> None:
        super().__init__(str(error))
        self.index = index
        self.message = str(error)
        self.error = error

    def __reduce__(self) -> tuple[Any, ...]:
        return (PairError, (self.index, self.error))

    def __repr__(self) -> str:
        return f"PairError(index={self.index}, message={self.message!r})"


_ON_ERROR = ("return", "raise")


def _check_on_error(on_error: str) -> None:
    if on_error not in _ON_ERROR:
        raise ValueError(f'on_error must be "return" or "raise", got {on_error!r}')


def _per_pair(items: list[Any], convert: Any, on_error: str) -> list[Any]:
    """Native batch items (a result, or the pair's exception object) as results and
    :class:`PairError` s; with ``on_error="raise"`` the first error raises."""
    out = []
    for i, item in enumerate(items):
        if isinstance(item, BaseException):
            if on_error == "raise":
                raise item
            out.append(PairError(i, item))
        else:
            out.append(convert(item))
    return out


def _info(d: dict[str, Any]) -> RansacInfo:
    return RansacInfo(**d)


def _pose(m: tuple[np.ndarray, ...]) -> RelativePose:
    return RelativePose(*m)


def estimate_homography(
    corrs: ArrayLike, *, threshold: float = 1.0, seed: int = 0, **options: Any
) -> tuple[NDArray[np.float64], RansacInfo]:
    """Robust homography ``p2 ~ H p1`` (pixels, ``|H|_F = 1``) from ACs or points.

    Args:
        corrs: ``(N, 8)`` ACs (2-AC samples by default) or ``(N, 4)`` points (4-point samples).
        threshold: inlier threshold on the transfer error ``|x2 - H(x1)|``, pixels.
        seed: seed of the random generator.
        **options: see the module docstring (``sample``, ``sampler``, ``quality``, ...).

    Returns:
        ``(H, info)``: the ``(3, 3)`` homography and a :class:`RansacInfo`.

    Example:
        >>> import numpy as np, affcorr
        >>> H = np.array([[1.1, 0.05, 12.0], [-0.02, 0.95, -7.0], [2e-4, -1e-4, 1.0]])
        >>> x1 = np.random.default_rng(0).uniform(0, 640, (200, 2))
        >>> corrs = affcorr.correspondences_from_homography(H, x1)  # exact ACs (200, 8)
        >>> corrs[150:, 2:4] += 50.0  # 50 outliers
        >>> H_est, info = affcorr.estimate_homography(corrs, threshold=2.0)
        >>> info.num_inliers, bool(info.inliers[:150].all())
        (150, True)
        >>> bool(np.allclose(H_est / H_est[2, 2], H, atol=1e-6))
        True
    """
    h, info = _native.estimate_homography(corrs, threshold=threshold, seed=seed, **options)
    return h, _info(info)


def estimate_fundamental(
    corrs: ArrayLike, *, threshold: float = 1.0, seed: int = 0, **options: Any
) -> tuple[NDArray[np.float64], RansacInfo]:
    """Robust fundamental matrix ``p2^T F p1 = 0`` (pixels, ``|F|_F = 1``, rank 2).

    The correspondences must not all lie on one plane (a plane makes F ambiguous).

    Args:
        corrs: ``(N, 8)`` ACs (3-AC samples by default) or ``(N, 4)`` points (7-point samples).
        threshold: inlier threshold on the Sampson distance, pixels.
        seed: seed of the random generator.
        **options: see the module docstring.

    Returns:
        ``(F, info)``: the ``(3, 3)`` fundamental matrix and a :class:`RansacInfo`.

    Example (two planes seen by two cameras, ``X2 = R X1 + t``):
        >>> import numpy as np, affcorr
        >>> K = np.array([[800.0, 0, 320], [0, 760, 240], [0, 0, 1]])
        >>> c, s = np.cos(0.1), np.sin(0.1)
        >>> R, t = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]), np.array([-1.0, 0.1, 0.2])
        >>> def plane(n, d):  # the homography induced by the plane n^T X1 = d
        ...     return K @ (R + np.outer(t, n) / d) @ np.linalg.inv(K)
        >>> rng = np.random.default_rng(0)
        >>> corrs = np.vstack([affcorr.correspondences_from_homography(
        ...     plane(n, d), rng.uniform(0, 480, (100, 2))) for n, d in
        ...     [((0, 0, 1.0), 5.0), ((0.6, 0, 0.8), 4.0), ((0, 0.6, 0.8), 6.0)]])
        >>> F, info = affcorr.estimate_fundamental(corrs, threshold=1.0)
        >>> p1, p2 = np.c_[corrs[:, :2], np.ones(300)], np.c_[corrs[:, 2:4], np.ones(300)]
        >>> info.num_inliers, bool(np.abs(np.sum(p2 * (p1 @ F.T), axis=1)).max() < 1e-6)
        (300, True)
    """
    f, info = _native.estimate_fundamental(corrs, threshold=threshold, seed=seed, **options)
    return f, _info(info)


def estimate_relative_pose(
    corrs: ArrayLike,
    K1: ArrayLike,  # noqa: N803 (intrinsics are capitals by convention)
    K2: ArrayLike,  # noqa: N803
    *,
    threshold: float = 1.0,
    seed: int = 0,
    **options: Any,
) -> tuple[RelativePose, RansacInfo]:
    """Robust calibrated relative pose ``X2 = R X1 + t`` from pixel correspondences.

    ACs are normalised with the full intrinsics (``A' = K2[:2,:2]^-1 A K1[:2,:2]``), so
    ``fx != fy`` is handled exactly. The pose is the factorisation of the final essential matrix
    with the most inliers in front of both cameras.

    Args:
        corrs: ``(N, 8)`` ACs (2-AC samples by default) or ``(N, 4)`` points (5-point samples).
        K1, K2: ``(3, 3)`` intrinsics of the two cameras (upper triangular).
        threshold: inlier threshold on the Sampson distance of ``F = K2^-T E K1^-1``, pixels.
        seed: seed of the random generator.
        **options: see the module docstring.

    Returns:
        ``(pose, info)``: a :class:`RelativePose` (``R``, unit ``t``, ``E``, ``F``) and a
        :class:`RansacInfo`.

    Example (two planes seen by two cameras):
        >>> import numpy as np, affcorr
        >>> K = np.array([[800.0, 0, 320], [0, 760, 240], [0, 0, 1]])
        >>> c, s = np.cos(0.1), np.sin(0.1)
        >>> R, t = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]), np.array([-1.0, 0.1, 0.2])
        >>> def plane(n, d):  # the homography induced by the plane n^T X1 = d
        ...     return K @ (R + np.outer(t, n) / d) @ np.linalg.inv(K)
        >>> rng = np.random.default_rng(0)
        >>> corrs = np.vstack([affcorr.correspondences_from_homography(
        ...     plane(n, d), rng.uniform(0, 480, (100, 2))) for n, d in
        ...     [((0, 0, 1.0), 5.0), ((0.6, 0, 0.8), 4.0)]])
        >>> pose, info = affcorr.estimate_relative_pose(corrs, K, K, threshold=1.0)
        >>> pose
        RelativePose(angle=5.73 deg, t=[-0.9759,  0.0976,  0.1952])
        >>> info.num_inliers, bool(np.allclose(pose.R, R, atol=1e-6))
        (200, True)
    """
    m, info = _native.estimate_relative_pose(
        corrs, K1, K2, threshold=threshold, seed=seed, **options
    )
    return _pose(m), _info(info)


def planar_twin(
    corrs: ArrayLike,
    K1: ArrayLike,  # noqa: N803
    K2: ArrayLike,  # noqa: N803
    pose: RelativePose,
    inliers: ArrayLike,
    *,
    threshold: float = 2.0,
) -> PlanarTwin | None:
    """The twin of a relative pose whose inliers lie on one plane, or ``None``.

    Two calibrated views of one plane have two motions (with their planes) that put the
    matches in front of both cameras and induce the same homography, hence the same points and
    the same ``A`` of every AC: the estimate is one of them by the noise alone
    (docs/estimation.md, "One plane"). This fits a homography to the pose's inliers (affcorr's
    RANSAC on their points, transfer error below ``threshold`` pixels); when it explains at
    least 80% of them (COLMAP's planar test), it decomposes the homography and returns the
    physically valid decomposition farther from ``pose``. ``None``: the pose is not planar,
    only one decomposition is valid, or fewer than 8 inliers.

    Args:
        corrs: the ``(N, 8)`` ACs or ``(N, 4)`` points the pose was estimated on (pixels).
        K1, K2: ``(3, 3)`` intrinsics of the two cameras.
        pose: the :class:`RelativePose` (``R`` and ``t`` are used).
        inliers: ``(N,)`` bool, its inliers (``info.inliers``).
        threshold: inlier threshold of the homography's transfer error, pixels.

    Returns:
        A :class:`PlanarTwin` or ``None``.

    Example (one plane: the estimate and its twin explain the matches equally):
        >>> import numpy as np, affcorr
        >>> K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
        >>> c, s = np.cos(0.1), np.sin(0.1)
        >>> R = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
        >>> t, n = np.array([-1.0, 0, 0.3]), np.array([0, 0, 1.0])
        >>> H = K @ (R + np.outer(t, n) / 4.0) @ np.linalg.inv(K)  # the plane z = 4
        >>> x1 = np.random.default_rng(0).uniform(0, 480, (100, 2))
        >>> corrs = affcorr.correspondences_from_homography(H, x1)
        >>> pose, info = affcorr.estimate_relative_pose(corrs, K, K)
        >>> twin = affcorr.planar_twin(corrs, K, K, pose, info.inliers)
        >>> twin.planar_share
        1.0
        >>> truth = [np.allclose(p.R, R, atol=1e-6) for p in (pose, twin)]
        >>> sorted(truth)  # one of the two is the true motion
        [False, True]
    """
    out = _native.planar_twin(corrs, K1, K2, pose.R, pose.t, np.asarray(inliers), float(threshold))
    return None if out is None else PlanarTwin(out[0], out[1], out[2], float(out[3]), out[4])


def estimate_homography_batch(
    corrs: Sequence[ArrayLike],
    *,
    threshold: float = 1.0,
    seed: int = 0,
    pair_options: Sequence[dict[str, Any] | None] | None = None,
    on_error: str = "return",
    **options: Any,
) -> list[tuple[NDArray[np.float64], RansacInfo] | PairError]:
    """:func:`estimate_homography` over many image pairs, in parallel in Rust (rayon; the GIL
    is released; ``RAYON_NUM_THREADS`` caps the threads). Each pair gets the same options and
    seed, so each result equals the single-pair call's, unless ``pair_options`` (one dict or
    ``None`` per pair) overrides some for a pair. ``quality`` is a list, one ``(N_i,)`` array per
    pair. A pair with invalid input gets a :class:`PairError` naming it in its place and the
    other pairs their results; ``on_error="raise"`` raises its ``ValueError`` instead. A pair
    with too few correspondences is a no-model result (``info.num_inliers == 0``, NaN model).

    Example:
        >>> import numpy as np, affcorr
        >>> x1 = np.random.default_rng(0).uniform(0, 640, (100, 2))
        >>> pairs = [affcorr.correspondences_from_homography(np.diag([s, s, 1.0]), x1)
        ...          for s in (0.9, 1.0, 1.1)]
        >>> out = affcorr.estimate_homography_batch(pairs)
        >>> [round(float(H[0, 0] / H[2, 2]), 6) for H, _ in out]
        [0.9, 1.0, 1.1]
        >>> out = affcorr.estimate_homography_batch(
        ...     pairs, pair_options=[{"seed": 1}, None, {"scoring": "magsac", "threshold": 3.0}])
        >>> [int(info.num_inliers) for _, info in out]
        [100, 100, 100]
    """
    _check_on_error(on_error)
    out = _native.estimate_homography_batch(
        corrs, threshold=threshold, seed=seed, pair_options=pair_options, **options
    )
    return _per_pair(out, lambda r: (r[0], _info(r[1])), on_error)


def estimate_fundamental_batch(
    corrs: Sequence[ArrayLike],
    *,
    threshold: float = 1.0,
    seed: int = 0,
    pair_options: Sequence[dict[str, Any] | None] | None = None,
    on_error: str = "return",
    **options: Any,
) -> list[tuple[NDArray[np.float64], RansacInfo] | PairError]:
    """:func:`estimate_fundamental` over many image pairs, in parallel in Rust (GIL released).

    Options (and ``pair_options``, ``on_error``, the per-pair results) as in
    :func:`estimate_homography_batch`.

    Example:
        >>> import numpy as np, affcorr
        >>> rng = np.random.default_rng(0)
        >>> pairs = [rng.uniform(0, 640, (50, 4)) for _ in range(2)]  # pure outliers
        >>> [len(info.inliers) for _, info in affcorr.estimate_fundamental_batch(pairs)]
        [50, 50]
    """
    _check_on_error(on_error)
    out = _native.estimate_fundamental_batch(
        corrs, threshold=threshold, seed=seed, pair_options=pair_options, **options
    )
    return _per_pair(out, lambda r: (r[0], _info(r[1])), on_error)


def estimate_relative_pose_batch(
    corrs: Sequence[ArrayLike],
    K1: ArrayLike,  # noqa: N803
    K2: ArrayLike,  # noqa: N803
    *,
    threshold: float = 1.0,
    seed: int = 0,
    pair_options: Sequence[dict[str, Any] | None] | None = None,
    on_error: str = "return",
    **options: Any,
) -> list[tuple[RelativePose, RansacInfo] | PairError]:
    """:func:`estimate_relative_pose` over many image pairs, in parallel in Rust (GIL released).

    Args:
        corrs: a sequence of ``(N_i, 8)`` or ``(N_i, 4)`` arrays.
        K1, K2: one ``(3, 3)`` for every pair, or a sequence (or ``(B, 3, 3)`` array) with one
            per pair.
        threshold, seed, **options: as in :func:`estimate_relative_pose`, shared by the pairs
            (``quality``: one array per pair).
        pair_options: one dict (or ``None``) per pair overriding the shared options.
        on_error: ``"return"`` (a :class:`PairError` in a failed pair's place, as in
            :func:`estimate_homography_batch`; an invalid per-pair K too) or ``"raise"``.

    Example:
        >>> import numpy as np, affcorr
        >>> K = np.array([[800.0, 0, 320], [0, 760, 240], [0, 0, 1]])
        >>> rng = np.random.default_rng(0)
        >>> def pair(t):  # two planes n^T X1 = d, X2 = X1 + t
        ...     hs = [K @ (np.eye(3) + np.outer(t, n) / d) @ np.linalg.inv(K)
        ...           for n, d in [((0, 0, 1.0), 5.0), ((0.6, 0, 0.8), 4.0)]]
        ...     x1 = rng.uniform(0, 480, (50, 2))
        ...     return np.vstack([affcorr.correspondences_from_homography(h, x1) for h in hs])
        >>> out = affcorr.estimate_relative_pose_batch([pair([1.0, 0, 0]), pair([0, 1.0, 0])], K, K)
        >>> [(pose.t.round(6) + 0.0).tolist() for pose, _ in out]
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
    """
    _check_on_error(on_error)
    out = _native.estimate_relative_pose_batch(
        corrs, K1, K2, threshold=threshold, seed=seed, pair_options=pair_options, **options
    )
    return _per_pair(out, lambda r: (_pose(r[0]), _info(r[1])), on_error)
