"""affcorr: affine correspondences for relative pose, homography and fundamental estimation.

An affine correspondence (AC) is a point match ``x1 <-> x2`` that also carries the local affine
map ``A = dx2/dx1`` between the two images. Conventions (see docs/design.md §2):

- arrays are float64 (any input dtype or memory order is converted);
- ACs are ``(N, 8)`` rows ``[x1, y1, x2, y2, a11, a12, a21, a22]``; points alone are ``(N, 4)``;
- ``p2^T F p1 = 0``; the camera motion is ``X2 = R X1 + t`` and ``E = [t]x R``;
- angles are radians.

Every function raises ``ValueError`` naming the bad argument.

``ShapeEstimator`` runs the shape network (ONNX Runtime, from the ``onnxruntime`` wheel) to turn
two images and matched points into ACs; ``Pipeline`` runs the whole chain: two images → XFeat
matches (mutual nearest neighbours, XFeat* or LighterGlue) → ACs → homography or relative pose.
"""

from . import opencv, solvers  # affcorr.solvers, as the README names it; affcorr.opencv
from ._docs import document as _document
from ._logging import logger as _logger  # noqa: F401  (the "affcorr" logger, silent)
from ._native import (
    __version__,
    affine_from_homography,
    affine_to_laf,
    correspondences_from_homography,
    decompose_affine,
    decompose_essential,
    essential_1ac2pt,
    essential_2ac,
    essential_5pt,
    essential_8pt,
    essential_from_pose,
    essential_lsq,
    fundamental_1ac4pt,
    fundamental_3ac,
    fundamental_7pt,
    fundamental_8pt,
    fundamental_ac_lsq,
    fundamental_from_essential,
    homography_1ac2pt,
    homography_1ac_given_f,
    homography_2ac,
    homography_4pt,
    homography_ac_lsq,
    homography_lsq,
    laf_to_affine,
    normalize_correspondences,
    pose_from_essential,
    sampson_affine,
    sampson_affine_grad,
    sampson_point,
    sampson_point_grad,
    synthesize_affine,
)
from .estimation import (
    ESTIMATOR_OPTIONS,
    PairError,
    PlanarTwin,
    RansacInfo,
    RelativePose,
    estimate_fundamental,
    estimate_fundamental_batch,
    estimate_homography,
    estimate_homography_batch,
    estimate_relative_pose,
    estimate_relative_pose_batch,
    planar_twin,
)
from .pipeline import PIPELINE_DEFAULTS, MatchResult, Pipeline
from .shape import (
    AffineRefinement,
    ShapeEstimate,
    ShapeEstimator,
    extract_patches,
    read_gray_image,
    refine_affine,
)

__all__ = [
    "__version__",
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
    "MatchResult",
    "PIPELINE_DEFAULTS",
    "Pipeline",
    "AffineRefinement",
    "ShapeEstimate",
    "ShapeEstimator",
    "extract_patches",
    "read_gray_image",
    "refine_affine",
    "affine_from_homography",
    "affine_to_laf",
    "correspondences_from_homography",
    "decompose_affine",
    "decompose_essential",
    "essential_1ac2pt",
    "essential_2ac",
    "essential_5pt",
    "essential_8pt",
    "essential_from_pose",
    "essential_lsq",
    "fundamental_1ac4pt",
    "fundamental_3ac",
    "fundamental_7pt",
    "fundamental_8pt",
    "fundamental_ac_lsq",
    "fundamental_from_essential",
    "homography_1ac2pt",
    "homography_1ac_given_f",
    "homography_2ac",
    "homography_4pt",
    "homography_ac_lsq",
    "homography_lsq",
    "laf_to_affine",
    "normalize_correspondences",
    "pose_from_essential",
    "sampson_affine",
    "sampson_affine_grad",
    "sampson_point",
    "sampson_point_grad",
    "synthesize_affine",
    "solvers",
    "opencv",
]

# The native functions above carry their text from _native.pyi (affcorr._docs).
_document(globals(), __all__)
