"""Type stubs of the Rust extension ``affcorr._native``.

Conventions (docs/design.md §2): float64 arrays (other dtypes and memory orders are converted);
ACs are ``(N, 8)`` rows ``[x1, y1, x2, y2, a11, a12, a21, a22]`` with ``A = dx2/dx1``;
``p2^T F p1 = 0``; motion ``X2 = R X1 + t``, ``E = [t]x R``; angles in radians.
Bad inputs raise ``ValueError`` naming the argument.
"""

import os
from collections.abc import Sequence
from typing import Any, final

import numpy as np
from numpy.typing import ArrayLike, NDArray

__version__: str

# --- geometry -------------------------------------------------------------------------------

def synthesize_affine(
    orientation: ArrayLike, scale: ArrayLike, residual_shape: ArrayLike
) -> NDArray[np.float64]:
    """A = scale · R(orientation) · A'(residual_shape) per row (paper eq. 11).

    orientation (N,) radians; scale (N,) > 0; residual_shape (N, 3) = (x0, x1, x2) with
    A' = B / sqrt(det B), B = [[1 + x0, 0], [x1, 1 + x2]], 1 + x0 > 0, 1 + x2 > 0.
    Returns (N, 2, 2).
    """

def decompose_affine(
    A: ArrayLike,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Inverse of synthesize_affine: A (N, 2, 2) with det A > 0 -> (orientation (N,), scale (N,),
    residual_shape (N, 3)). The residual shape is the canonical one with det B = 1."""

def affine_from_homography(H: ArrayLike, x1: ArrayLike) -> NDArray[np.float64]:
    """The affine maps A = dx2/dx1 (N, 2, 2) that H (3, 3) induces at the points x1 (N, 2)."""

def correspondences_from_homography(H: ArrayLike, x1: ArrayLike) -> NDArray[np.float64]:
    """The full ACs (N, 8) that H (3, 3) induces at the points x1 (N, 2):
    x2 = H(x1), A = dx2/dx1."""

def normalize_correspondences(
    corrs: ArrayLike, K1: ArrayLike, K2: ArrayLike
) -> NDArray[np.float64]:
    """ACs (N, 8) in pixels to normalised coordinates: x1 -> K1^-1 x1, x2 -> K2^-1 x2,
    A -> K2[:2,:2]^-1 A K1[:2,:2]. K must be upper triangular with positive focal lengths."""

def laf_to_affine(laf1: ArrayLike, laf2: ArrayLike) -> NDArray[np.float64]:
    """kornia LAF pairs (B, N, 2, 3) or (N, 2, 3) to ACs (B, N, 8) or (N, 8):
    x1, x2 are the LAF centres and A = L2 L1^-1."""

def affine_to_laf(
    corrs: ArrayLike, radius: float | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """ACs (N, 8) to kornia LAF pairs (1, N, 2, 3): L1 = radius·I at x1, L2 = radius·A at x2
    (radius None: 1.0)."""

def essential_from_pose(R: ArrayLike, t: ArrayLike) -> NDArray[np.float64]:
    """E = [t]x R (3, 3) for the motion X2 = R X1 + t."""

def fundamental_from_essential(E: ArrayLike, K1: ArrayLike, K2: ArrayLike) -> NDArray[np.float64]:
    """F = K2^-T E K1^-1."""

def decompose_essential(E: ArrayLike) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """The four (R, t) factorisations of E (unit t)."""

def pose_from_essential(
    E: ArrayLike, x1: ArrayLike, x2: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64], int]:
    """The (R, t) of E that puts the most normalised correspondences x1, x2 (N, 2) in front of
    both cameras, and that count."""

# --- Sampson distances (docs/design.md §3) --------------------------------------------------------
# F is (3, 3), shared by every row, or (N, 3, 3), one per row. Distances are in squared units of
# the coordinates (pixels^2 for a pixel F) and invariant to the scale of F. A zero denominator
# (only for special F) gives 0 when the residual is 0 too, else +inf, with zero gradient.

def sampson_point(F: ArrayLike, corrs: ArrayLike) -> NDArray[np.float64]:
    """Point Sampson distance per row (N,) of corrs (N, 4) or (N, 8) (A columns ignored):
    SD_P = (p2^T F p1)^2 / ((F p1)_1^2 + (F p1)_2^2 + (F^T p2)_1^2 + (F^T p2)_2^2),
    p = (x, y, 1)."""

def sampson_affine(F: ArrayLike, corrs: ArrayLike) -> NDArray[np.float64]:
    """Affine Sampson distances (N, 2) of ACs (N, 8), one per row k of the affine epipolar
    constraint A^T (F p1)[:2] + (F^T p2)[:2] = 0 (A = dx2/dx1):
    r_k = sum_i a_ik (F p1)_i + (F^T p2)_k, SD_A,k = r_k^2 / |dr_k/d(x1, y1, x2, y2, a1k, a2k)|^2.
    SD_A is the sum of the two columns."""

def sampson_point_grad(
    F: ArrayLike, corrs: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """sampson_point and its analytic gradient per row: (dist (N,), d_corrs (N, 4) or (N, 8),
    d_F (N, 3, 3)). d_corrs has the width of corrs (zero A columns for (N, 8)); d_F is per row
    (sum it over rows for a shared F)."""

def sampson_affine_grad(
    F: ArrayLike, corrs: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """sampson_affine and its analytic gradients per row and per constraint row k:
    (dist (N, 2), d_corrs (N, 2, 8), d_F (N, 2, 3, 3)), d_corrs[n, k] = dSD_A,k/d corrs[n]."""

# --- homography / fundamental solvers -------------------------------------------------------------
# Inputs are pixels (normalised internally). Each solver returns a list of candidate models, each
# a (3, 3) array with unit Frobenius norm and arbitrary sign: p2 ~ H p1 for homographies,
# p2^T F p1 = 0 for fundamental matrices. A degenerate sample (collinear or coincident points,
# all correspondences on one plane for F, det A <= 0, a rank-deficient system) gives []. Bad
# shapes and NaN/infinity raise ValueError naming the argument. ACs are (N, 8) rows
# [x1, y1, x2, y2, a11, a12, a21, a22] with A = dx2/dx1.

def homography_4pt(x1: ArrayLike, x2: ArrayLike) -> list[NDArray[np.float64]]:
    """H from 4 point correspondences x1, x2 (4, 2): normalised DLT, closed-form null space.
    [] if three of the points are collinear in either image."""

def homography_2ac(corrs: ArrayLike) -> list[NDArray[np.float64]]:
    """H from 2 ACs (2, 8): 2 point + 4 affine linear equations each, least squares (12 x 9)."""

def homography_1ac_given_f(corrs: ArrayLike, F: ArrayLike) -> list[NDArray[np.float64]]:
    """H from 1 AC (1, 8) and the fundamental matrix F (3, 3): H = -[e2]x F + e2 v^T with v from
    6 linear equations (Barath & Hajder 2017). [] if F has rank < 2."""

def homography_1ac2pt(corr: ArrayLike, x1: ArrayLike, x2: ArrayLike) -> list[NDArray[np.float64]]:
    """H from one AC corr (1, 8) and 2 point correspondences x1, x2 (2, 2), the hybrid sample:
    10 linear equations of rank 8 (one AC fixes H up to 2 parameters, each point one more),
    least squares. [] if a point repeats the AC's or the other."""

def homography_lsq(x1: ArrayLike, x2: ArrayLike) -> list[NDArray[np.float64]]:
    """Non-minimal normalised DLT on N >= 4 point correspondences x1, x2 (N, 2) (least squares)."""

def homography_ac_lsq(corrs: ArrayLike) -> list[NDArray[np.float64]]:
    """Non-minimal H from N >= 2 ACs (N, 8): the homography_2ac system over all ACs, least
    squares; affine rows weighted as an AC's points at 8 px from its centre."""

def fundamental_7pt(x1: ArrayLike, x2: ArrayLike) -> list[NDArray[np.float64]]:
    """F from 7 point correspondences x1, x2 (7, 2): 2-dim null space + cubic det constraint.
    Up to 3 candidates, each of rank 2."""

def fundamental_8pt(x1: ArrayLike, x2: ArrayLike) -> list[NDArray[np.float64]]:
    """Normalised 8-point algorithm on N >= 8 point correspondences x1, x2 (N, 2);
    rank 2 enforced."""

def fundamental_3ac(corrs: ArrayLike) -> list[NDArray[np.float64]]:
    """F from 3 ACs (3, 8): 1 epipolar + 2 affine epipolar equations each (9 x 9, rank 8
    generically), least-squares null vector, rank 2 enforced. One model generically (up to 3
    from the cubic if the null space is 2-dim); [] if all 3 ACs come from one plane."""

def fundamental_1ac4pt(corr: ArrayLike, x1: ArrayLike, x2: ArrayLike) -> list[NDArray[np.float64]]:
    """F from one AC corr (1, 8) and 4 point correspondences x1, x2 (4, 2), the hybrid sample:
    the AC's 3 equations and the points' 4, solved as 7 points (2-dim null space + cubic).
    Up to 3 candidates, each of rank 2."""

def fundamental_ac_lsq(corrs: ArrayLike) -> list[NDArray[np.float64]]:
    """Non-minimal F from N >= 3 ACs (N, 8): the fundamental_3ac system over all ACs, least
    squares, rank 2 enforced."""

# --- robust estimation ----------------------------------------------------------------------------
# The raw bindings; affcorr.estimation wraps them into (model, RansacInfo) pairs and documents
# the options. `options` are keyword options (see ESTIMATOR_OPTIONS), validated in Rust: an
# unknown name or an invalid value raises ValueError naming it. Each info dict has the keys
# inliers ((N,) bool), num_inliers, num_iterations, score, lo_runs, refinements. When no model is
# found the model is NaN and num_inliers is 0 (no exception).

ESTIMATOR_OPTIONS: list[str]

def estimate_homography(
    corrs: ArrayLike, **options: Any
) -> tuple[NDArray[np.float64], dict[str, Any]]:
    """Robust H (3, 3), p2 ~ H p1, from (N, 8) ACs or (N, 4) points; GIL released."""

def estimate_fundamental(
    corrs: ArrayLike, **options: Any
) -> tuple[NDArray[np.float64], dict[str, Any]]:
    """Robust F (3, 3), p2^T F p1 = 0, from (N, 8) ACs or (N, 4) points; GIL released."""

def estimate_relative_pose(
    corrs: ArrayLike, K1: ArrayLike, K2: ArrayLike, **options: Any
) -> tuple[
    tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]],
    dict[str, Any],
]:
    """Robust X2 = R X1 + t: ((R, t, E, F), info); |t| = 1; GIL released."""

def planar_twin(
    corrs: ArrayLike,
    K1: ArrayLike,
    K2: ArrayLike,
    R: ArrayLike,
    t: ArrayLike,
    inliers: ArrayLike,
    threshold: float,
) -> (
    tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], float, NDArray[np.float64]]
    | None
):
    """The twin of a planar relative pose: (R, t, normal, planar_share, H) or None; GIL
    released."""

def estimate_homography_batch(
    corrs: Sequence[ArrayLike], **options: Any
) -> list[tuple[NDArray[np.float64], dict[str, Any]] | ValueError]:
    """estimate_homography over many pairs in parallel (rayon); quality is one array per pair.
    A pair with invalid input is its ValueError ("pair i: ...") in its place; too few rows is a
    no-model result; Ctrl-C raises KeyboardInterrupt."""

def estimate_fundamental_batch(
    corrs: Sequence[ArrayLike], **options: Any
) -> list[tuple[NDArray[np.float64], dict[str, Any]] | ValueError]:
    """estimate_fundamental over many pairs in parallel (rayon); per-pair errors as
    estimate_homography_batch."""

def estimate_relative_pose_batch(
    corrs: Sequence[ArrayLike], K1: ArrayLike, K2: ArrayLike, **options: Any
) -> list[
    tuple[
        tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]],
        dict[str, Any],
    ]
    | ValueError
]:
    """estimate_relative_pose over many pairs in parallel; K1, K2: one (3, 3) or one per pair."""

# --- essential solvers

def essential_5pt(x1: ArrayLike, x2: ArrayLike) -> list[NDArray[np.float64]]:
    """Essential matrices from five point correspondences (Nistér 2004 / Stewénius 2006).

    x1, x2 (5, 2) in normalised coordinates (x = K^-1 p; use ``normalize_correspondences``).
    Returns up to 10 matrices (3, 3) with unit Frobenius norm (sign arbitrary) and
    x2^T E x1 = 0; an empty list for a degenerate sample (e.g. repeated points)."""

def essential_1ac2pt(corr: ArrayLike, x1: ArrayLike, x2: ArrayLike) -> list[NDArray[np.float64]]:
    """Essential matrices from one affine correspondence corr (1, 8) and two point
    correspondences x1, x2 (2, 2), all normalised (``normalize_correspondences``): the hybrid
    sample. Five linear equations (the AC's 3, one per point), then the five-point machinery.
    Returns up to 10 unit-norm (3, 3) matrices."""

def essential_2ac(corrs: ArrayLike) -> list[NDArray[np.float64]]:
    """Essential matrices from two affine correspondences (Barath & Hajder 2018).

    corrs (2, 8) normalised ACs [x1, y1, x2, y2, a11, a12, a21, a22]
    (``normalize_correspondences``).
    Returns up to 10 unit-norm (3, 3) matrices, best first (ranked by the AC equation the
    minimal sub-problem drops); ACs of two planes give the true E first, ACs of one plane leave
    several solutions (the homography's two-fold ambiguity among them). Empty for det A <= 0 or
    a degenerate sample."""

def essential_8pt(x1: ArrayLike, x2: ArrayLike) -> list[NDArray[np.float64]]:
    """The least-squares essential matrix of N >= 8 normalised point correspondences (N, 2)
    (Hartley-normalised eight-point algorithm), projected to the essential manifold
    (singular values 1/sqrt2, 1/sqrt2, 0). One matrix, or none for coplanar/repeated points."""

def essential_lsq(
    x1: ArrayLike, x2: ArrayLike, corrs: ArrayLike | None = None
) -> list[NDArray[np.float64]]:
    """Like essential_8pt with the three equations of each normalised AC in corrs (M, 8) stacked
    under the point rows; needs N + 3M >= 8. x1, x2 may have zero rows."""

# --- shape network runner (docs/design.md §6; wrapped by affcorr.shape) ---------------------------

@final
class ShapeRunner:
    """The shape network loaded through ONNX Runtime (use ``affcorr.ShapeEstimator``).

    model_path: ``.onnx`` with the ``shape-v1`` contract (checked on loading: inputs patch_a,
    patch_b; outputs angle_logits_a/b, scale_logits_a/b, residual_shape; metadata
    affcorr.contract, patch_size, angle_bins, scale_bins, decode). ort_library: the
    libonnxruntime to load (``None``: ``ORT_DYLIB_PATH``); ignored once ONNX Runtime is loaded.
    Raises FileNotFoundError (no such model), RuntimeError (ONNX Runtime or the model),
    ValueError naming the option (threads not in 1..=1024, batch_size not in 1..=65536; Python
    or numpy ints)."""

    def __new__(
        cls,
        model_path: str | os.PathLike[str],
        *,
        ort_library: str | os.PathLike[str] | None = None,
        threads: int | None = None,
        batch_size: int | None = None,
    ) -> ShapeRunner: ...
    def predict(
        self, patches_a: ArrayLike, patches_b: ArrayLike, return_logits: bool = False
    ) -> dict[str, np.ndarray]:
        """patches (N, 1, 32, 32) -> orientation_a/b, scale_a/b (N,), residual_shape (N, 3);
        with return_logits also the float32 outputs angle_logits_a/b, scale_logits_a/b and
        residual_shape_raw."""
    def estimate(
        self, image_a: Any, image_b: Any, x1: ArrayLike, x2: ArrayLike, refine: bool = False
    ) -> tuple[
        NDArray[np.float64],
        NDArray[np.float64],
        NDArray[np.float64],
        NDArray[np.float64],
        NDArray[np.float64],
        NDArray[np.float64],
        dict[str, Any],
    ]:
        """Images (path or array) and matches x1, x2 (N, 2) -> (corrs (N, 8), orientation_a,
        orientation_b, scale_a, scale_b (N,), residual_shape (N, 3), report), with
        A = (S_B / S_A) R(O_B - O_A) A'(A''); with refine, corrs refined (default options).
        report: affine_confidence, reliable (N,), confidence_features (N, F),
        confidence_model, angle_spread, scale_spread (N,); with refine also status (list of
        str), refined, zncc, shift_std, affine_std (N,)."""
    @property
    def angle_bins(self) -> NDArray[np.float64]: ...
    @property
    def scale_bins(self) -> NDArray[np.float64]: ...
    @property
    def metadata(self) -> dict[str, str]: ...
    @property
    def threads(self) -> int: ...
    @property
    def batch_size(self) -> int: ...

def init_ort(path: str | os.PathLike[str] | None = None) -> str:
    """Loads ONNX Runtime from path (else ``ORT_DYLIB_PATH``) and returns the library in use;
    a no-op once loaded. RuntimeError when the library is missing or unusable (< 1.20)."""

def ort_library() -> str | None:
    """The loaded ONNX Runtime library, or None."""

def extract_patches(image: Any, xy: ArrayLike) -> NDArray[np.float32]:
    """Patches (N, 1, 32, 32) float32: pixel (r, c) is the gray image read bilinearly at
    (x + c - 15.5, y + r - 15.5), edges replicated. image: PNG/JPEG path or array (H, W) /
    (H, W, C) of uint8, uint16 or float in [0, 1]."""

def read_gray_image(image: Any) -> NDArray[np.float32]:
    """(H, W) float32 gray in [0, 1]; colour is 0.299 R + 0.587 G + 0.114 B, alpha ignored."""

def refine_affine(
    image_a: Any,
    image_b: Any,
    corrs: ArrayLike,
    *,
    radius: int,
    blur_sigmas: list[float],
    iterations: int,
    min_zncc: float,
    move_points: bool,
    try_identity: bool,
    try_neighbours: bool,
    max_shift_std: float,
) -> tuple[NDArray[np.float64], dict[str, Any]]:
    """Affine Lucas-Kanade refinement of ACs (wrapped by affcorr.refine_affine): (corrs (N, 8),
    report): refined (N,) bool, status (list of str), zncc, shift_std, affine_std,
    affine_confidence (N,), reliable (N,) bool, confidence_features (N, F), confidence_model."""

# --- end-to-end pipeline (wrapped by affcorr.pipeline) -------------------------------------------

_MatchTuple = tuple[
    NDArray[np.float64],
    NDArray[np.float64],
    dict[str, float],
    tuple[int, int],
    list[dict[str, Any]],
    NDArray[np.float64],
    NDArray[np.bool_],
]

def confidence_model(name: str) -> tuple[NDArray[np.float64], float, list[str]]:
    """(weights (F,), threshold, feature names) of the calibrated confidence model "network",
    "refinement" or "network_refinement"."""

#: The pipeline's one set of defaults (affcorr-pipeline's `defaults` module).
PIPELINE_DEFAULTS: dict[str, Any]
#: Matcher names, the default first.
PIPELINE_MATCHERS: list[str]
#: The model roles each matcher runs.
PIPELINE_MATCHER_MODELS: dict[str, list[str]]
#: The model roles of the view cascade's screen where another matcher screens (XFeat's
#: backbone for DISK, ALIKED and XFeat*), by matcher.
PIPELINE_SCREEN_MODELS: dict[str, list[str]]
#: Model file names in a models directory, by role.
PIPELINE_MODEL_FILES: dict[str, str]

@final
class PipelineFeatures:
    """One image's features (PipelineRunner.extract); immutable, picklable (as its bytes)."""

    @property
    def matcher(self) -> str: ...
    @property
    def image_size(self) -> tuple[int, int]: ...
    @property
    def working_size(self) -> tuple[int, int]: ...
    @property
    def orientation(self) -> int:
        """The EXIF orientation (1-8) the image was turned upright by before extraction."""
    @property
    def keypoints(self) -> NDArray[np.float64]:
        """(N, 2) in the original (stored) pixels (empty for a dense matcher)."""
    @property
    def scores(self) -> NDArray[np.float32]: ...
    @property
    def descriptors(self) -> NDArray[np.float32]:
        """(N, D)."""
    @property
    def seconds(self) -> float: ...
    def to_bytes(self) -> bytes: ...
    @staticmethod
    def from_bytes(data: bytes) -> PipelineFeatures:
        """Features from to_bytes; anything else raises ValueError naming data."""
    def __reduce__(self) -> tuple[Any, tuple[bytes]]: ...
    def __len__(self) -> int: ...

@final
class PipelineRunner:
    """Matcher (XFeat backbone + MNN / XFeat* refinement / LighterGlue, or a dense-warp-v1
    model with DKM's balanced sampling) and shape network in Rust (use ``affcorr.Pipeline``).
    Every model's contract is checked on loading.
    Raises ValueError (unknown matcher, option < 1, descriptor sizes that disagree),
    FileNotFoundError (no such model), RuntimeError (contract violation, ONNX Runtime)."""

    def __new__(
        cls,
        *,
        matcher: str,
        shape_model: str | os.PathLike[str],
        backbone_model: str | os.PathLike[str] | None = None,
        refine_model: str | os.PathLike[str] | None = None,
        lighterglue_model: str | os.PathLike[str] | None = None,
        disk_backbone_model: str | os.PathLike[str] | None = None,
        disk_lightglue_model: str | os.PathLike[str] | None = None,
        aliked_backbone_model: str | os.PathLike[str] | None = None,
        aliked_lightglue_model: str | os.PathLike[str] | None = None,
        dense_model: str | os.PathLike[str] | None = None,
        ort_library: str | os.PathLike[str] | None = None,
        max_keypoints: int | None = None,
        detection_threshold: float | None = None,
        max_matches: int | None = None,
        max_side: int | None = None,
        threads: int | None = None,
        seed: int | None = None,
        refine_affine: bool = ...,
        drop_unreliable: bool = False,
        exif_orientation: bool = ...,
        guided_matching: bool = ...,
        views: str | None = None,
        view_budget: float | None = None,
        view_relative_budget: float | None = ...,
        max_views: int | None = None,
    ) -> PipelineRunner: ...
    def estimate(
        self,
        geometry: str,
        image_a: Any,
        image_b: Any,
        *,
        K1: Any = None,  # noqa: N803
        K2: Any = None,  # noqa: N803
        threshold: float | None = None,
        **options: Any,
    ) -> tuple[tuple[Any, dict[str, Any]], _MatchTuple]:
        """((model, info), match tuple) for geometry "homography" (H), "fundamental" (F) or
        "relative_pose" ((R, t, E, F); K1, K2 checked before matching): the Rust Pipeline's
        estimators with estimate_*'s keyword options; threshold None is the pipeline's default;
        GIL released."""
    def match_pair(self, image_a: Any, image_b: Any) -> _MatchTuple:
        """Images (path or array) -> (corrs (N, 8), certainty (N,), timings {stage: seconds},
        (keypoints in A, keypoints in B), views [report per view]); GIL released."""
    def match_pairs(self, pairs: Sequence[tuple[Any, Any]]) -> list[_MatchTuple | Exception]:
        """match_pair over the pairs, in parallel on single-threaded copies of the models when
        threads > 1; a failing pair is its exception ("pairs[i]: ...") in its place. An image
        in several pairs (the same path or object) has its features extracted once."""
    def extract(self, image: Any) -> PipelineFeatures:
        """One image's features (decoded, max_side, keypoints and descriptors); GIL released."""
    def match_features(self, features_a: Any, features_b: Any) -> _MatchTuple:
        """The match tuple of two images' features (bit-identical to match_pair's); features of
        another matcher or options raise ValueError naming the argument; GIL released."""
    @property
    def matcher(self) -> str: ...
    @property
    def exif_orientation(self) -> bool: ...
    @property
    def views(self) -> str: ...
    @property
    def view_screen(self) -> str: ...
    @property
    def max_keypoints(self) -> int: ...
    @property
    def detection_threshold(self) -> float | None: ...
    @property
    def max_matches(self) -> int | None: ...
    @property
    def max_side(self) -> int | None: ...
    @property
    def threads(self) -> int: ...
    @property
    def seed(self) -> int: ...
    @property
    def matcher_metadata(self) -> dict[str, str]: ...
