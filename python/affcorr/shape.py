"""The shape network: affine correspondences from two images and matched points.

For each match ``x1 <-> x2``, a 32x32 grayscale patch is cut around ``x1`` in image A and around
``x2`` in image B (bilinear; pixel ``(r, c)`` of the patch is the image at
``(x + c - 15.5, y + r - 15.5)``, with pixel centres at integer coordinates and edge replication
outside). The network gives each patch an orientation ``O`` and a scale ``S`` (softmax-mean
decoding over the bins in its metadata) and the pair a residual shape ``A'' = (x0, x1, x2)``;
the affine map of the AC is (docs/design.md §2, paper eq. 11)::

    A = S_AB * R(O_AB) * A'(A''),   O_AB = O_B - O_A,   S_AB = S_B / S_A.

Inference runs in Rust through ONNX Runtime: the library is taken from ``ORT_DYLIB_PATH`` if set,
else from the installed ``onnxruntime`` wheel (``onnxruntime/capi/libonnxruntime.so*``). The
GIL is released while images are decoded, patches cut and the network run.

Errors: bad arguments raise ``ValueError`` naming the argument; a missing image or model file
raises ``FileNotFoundError``; ONNX Runtime and model problems (library missing, not ONNX,
contract violations) raise ``RuntimeError``.
"""

from __future__ import annotations

import importlib.util
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _native
from ._images import as_rgb, as_xy

__all__ = [
    "AffineRefinement",
    "ShapeEstimate",
    "ShapeEstimator",
    "REFINE_STATUSES",
    "bundled_shape_model",
    "confidence_model",
    "extract_patches",
    "find_ort_library",
    "read_gray_image",
    "refine_affine",
]

#: An image: a PNG/JPEG file path, or an array (H, W) / (H, W, C), C in 1..4, of dtype uint8
#: (divided by 255), uint16 (divided by 65535) or float (values in [0, 1]).
ImageLike = Union[str, "os.PathLike[str]", np.ndarray]

#: Native runners a forked child inherited from its parent. They are kept, never dropped:
#: dropping one would wait for its ONNX Runtime and rayon threads, which did not survive the
#: fork (docs/reliability.md, "Fork").
_INHERITED: list[Any] = []


class _PerProcess:
    """A native object (ONNX Runtime sessions, thread pools) that belongs to the process that
    built it: after ``fork()`` the child's first use builds its own from the same arguments,
    instead of waiting forever on the parent's threads (the child has none of them)."""

    def __init__(self, make: Callable[[], Any]) -> None:
        self._make = make
        self._obj = make()
        self._pid = os.getpid()

    def get(self) -> Any:
        if self._pid != os.getpid():
            _INHERITED.append(self._obj)
            self._obj = self._make()
            self._pid = os.getpid()
        return self._obj


_LIBRARY_PATTERNS = ("libonnxruntime.so*", "libonnxruntime*.dylib", "onnxruntime.dll")


def bundled_shape_model() -> Path:
    """The shape network shipped in the package (``affcorr/models/shape.onnx``)."""
    return Path(__file__).resolve().parent / "models" / "shape.onnx"


def find_ort_library() -> Path | None:
    """The ONNX Runtime library to load, or ``None`` to let ``ORT_DYLIB_PATH`` decide.

    With ``ORT_DYLIB_PATH`` set (non-empty) this returns ``None`` and the Rust side loads that
    library. Otherwise it returns the library inside the installed ``onnxruntime`` package
    (found without importing it) and raises ``RuntimeError`` when there is none.
    """
    if os.environ.get("ORT_DYLIB_PATH"):
        return None
    spec = importlib.util.find_spec("onnxruntime")
    roots = list(spec.submodule_search_locations or []) if spec is not None else []
    for root in roots:
        capi = Path(root) / "capi"
        for pattern in _LIBRARY_PATTERNS:
            found = sorted(capi.glob(pattern), key=lambda p: (len(p.name), p.name))
            if found:
                # The most specific name (libonnxruntime.so.1.31.1 over libonnxruntime.so).
                return found[-1]
    raise RuntimeError(
        "ONNX Runtime library not found: `pip install onnxruntime` (its wheel ships "
        "onnxruntime/capi/libonnxruntime.so.<version>), or set ORT_DYLIB_PATH to a "
        "libonnxruntime >= 1.20"
    )


#: What :func:`refine_affine` can report per AC: ``"refined"``, or why the input came back
#: (a flat window, a fit that diverged, a ZNCC under ``min_zncc``, no better than the input's,
#: or an ill-determined shift along a lone edge).
REFINE_STATUSES = ("refined", "flat", "diverged", "low_zncc", "not_improved", "aperture")


def confidence_model(name: str) -> tuple[NDArray[np.float64], float, list[str]]:
    """The calibrated logistic model behind ``affine_confidence``: ``(weights, threshold,
    feature names)``; ``name`` is ``"network"`` (the network's ACs alone), ``"refinement"``
    (:func:`refine_affine` on any ACs) or ``"network_refinement"`` (the default output).

    ``affine_confidence = 1 / (1 + exp(-features @ weights))`` and ``reliable =
    affine_confidence >= threshold``, with the ``confidence_features`` every result carries
    (docs/shape_network.md, "Confidence").
    """
    if not isinstance(name, str):
        raise ValueError(f"name must be a str, got {name!r}")
    weights, threshold, names = _native.confidence_model(name)
    return weights, float(threshold), list(names)


@dataclass(frozen=True)
class ShapeEstimate:
    """ACs with the per-patch quantities they were built from (all float64), and how far each
    AC can be trusted."""

    #: (N, 8) rows [x1, y1, x2, y2, a11, a12, a21, a22], A = dx2/dx1.
    corrs: NDArray[np.float64]
    #: (N,) orientation O of each patch of image A, radians in (-pi, pi].
    orientation_a: NDArray[np.float64]
    #: (N,) orientation O of each patch of image B, radians in (-pi, pi].
    orientation_b: NDArray[np.float64]
    #: (N,) scale S of each patch of image A.
    scale_a: NDArray[np.float64]
    #: (N,) scale S of each patch of image B.
    scale_b: NDArray[np.float64]
    #: (N, 3) residual shape A'' = (x0, x1, x2) of each pair.
    residual_shape: NDArray[np.float64]
    #: (N,) in [0, 1]: the calibrated probability that the AC's A is good (cosine similarity
    #: with the true A >= 0.9), from the network's spread, the refinement (with ``refine``)
    #: and the neighbouring ACs (docs/shape_network.md, "Confidence").
    affine_confidence: NDArray[np.float64]
    #: (N,) bool: ``affine_confidence`` at least the model's calibrated threshold.
    reliable: NDArray[np.bool_]
    #: (N,) the network's angular spread, sum over both patches of 1 - R (R the mean
    #: resultant length of the angle distribution; 0 = certain).
    angle_spread: NDArray[np.float64]
    #: (N,) the network's log-scale spread, sqrt(Var_a ln S + Var_b ln S).
    scale_spread: NDArray[np.float64]
    #: (N, F) the confidence's inputs (:func:`confidence_model` names them).
    confidence_features: NDArray[np.float64]
    #: ``"network"`` or ``"network_refinement"``: the model the confidence came from.
    confidence_model: str
    #: (N,) str: the refinement's outcome per AC (:data:`REFINE_STATUSES`); None without
    #: ``refine``.
    status: NDArray[np.str_] | None = None
    #: (N,) the refinement's final ZNCC per AC (the input's where it failed); None without
    #: ``refine``.
    zncc: NDArray[np.float64] | None = None


class ShapeEstimator:
    """The shape network, ready to turn matches into affine correspondences.

    Args:
        model: path of a ``.onnx`` file with the ``shape-v1`` contract (docs/design.md §6); ``None``
            for the bundled model (:func:`bundled_shape_model`).
        threads: ONNX Runtime intra-op threads; ``None`` for every core.
        batch_size: patch pairs per inference run.

    The model's contract (input/output names, metadata, logit widths) is checked on loading.

    >>> import numpy as np, affcorr
    >>> est = affcorr.ShapeEstimator(threads=1)
    >>> img = np.random.default_rng(0).random((64, 80))
    >>> corrs = est.estimate(img, img, [[40.0, 30.0]], [[41.5, 29.0]])
    >>> corrs.shape
    (1, 8)
    """

    def __init__(
        self,
        model: str | os.PathLike[str] | None = None,
        *,
        threads: int | None = None,
        batch_size: int = 512,
    ) -> None:
        path = bundled_shape_model() if model is None else Path(os.fspath(model))
        # threads and batch_size (Python or numpy ints) are checked in Rust: 1 to 1024 threads,
        # 1 to 65536 pairs per run; each error names the option and the bound.
        self._model_path = path
        library = find_ort_library()
        self._native = _PerProcess(
            lambda: _native.ShapeRunner(
                str(path), ort_library=library, threads=threads, batch_size=batch_size
            )
        )

    @property
    def _runner(self) -> Any:
        """The native runner of this process (rebuilt in a forked child)."""
        return self._native.get()

    @property
    def model_path(self) -> Path:
        """The model file."""
        return self._model_path

    @property
    def angle_bins(self) -> NDArray[np.float64]:
        """Angle bin centres (radians) from the model's metadata."""
        return self._runner.angle_bins

    @property
    def scale_bins(self) -> NDArray[np.float64]:
        """Scale bin centres (linear factors) from the model's metadata."""
        return self._runner.scale_bins

    @property
    def metadata(self) -> dict[str, str]:
        """All custom metadata of the model (e.g. ``trained``)."""
        return self._runner.metadata

    @property
    def threads(self) -> int:
        """ONNX Runtime intra-op threads."""
        return self._runner.threads

    @property
    def batch_size(self) -> int:
        """Patch pairs per inference run."""
        return self._runner.batch_size

    def estimate(
        self,
        image_a: ImageLike,
        image_b: ImageLike,
        x1: ArrayLike,
        x2: ArrayLike,
        *,
        refine: bool = True,
        channel_order: str = "rgb",
    ) -> NDArray[np.float64]:
        """ACs ``(N, 8)`` of the matches ``x1 (N, 2)`` in image A <-> ``x2 (N, 2)`` in image B.

        By default the network's ACs are then refined against the images by affine
        Lucas-Kanade (:func:`refine_affine` with its defaults, which also moves ``x2``): at a
        matcher's real matches it takes the median ||A - A_gt||_F from ~0.2 to ~0.01
        (benches/results/eval/affine.md). ``refine=False`` returns the network's ACs alone
        (several times faster); :func:`refine_affine` gives the refinement's options and
        per-AC report. ``channel_order``: ``"bgr"`` for ``cv2.imread`` arrays (files are
        decoded by their own format); ``x1``, ``x2`` may be OpenCV's ``(N, 1, 2)`` arrays or
        ``cv2.KeyPoint`` lists.
        """
        a, b = as_rgb(image_a, channel_order), as_rgb(image_b, channel_order)
        return self._runner.estimate(a, b, as_xy(x1), as_xy(x2), bool(refine))[0]

    def estimate_detailed(
        self,
        image_a: ImageLike,
        image_b: ImageLike,
        x1: ArrayLike,
        x2: ArrayLike,
        *,
        refine: bool = False,
        channel_order: str = "rgb",
    ) -> ShapeEstimate:
        """Like :meth:`estimate`, with the per-patch orientations, scales and residual shapes,
        and each AC's ``affine_confidence`` and ``reliable`` flag.

        ``refine=False`` (the default here, unlike :meth:`estimate`) gives the network's ACs
        alone, scored by the network's own spread and the agreement of neighbouring ACs;
        ``refine=True`` refines them (:func:`refine_affine`, defaults) and scores them with
        the refinement's outcome as well (``status`` and ``zncc`` per AC): an AC whose
        refinement failed keeps the network's A and is flagged unreliable.
        """
        a, b = as_rgb(image_a, channel_order), as_rgb(image_b, channel_order)
        *arrays, report = self._runner.estimate(a, b, as_xy(x1), as_xy(x2), bool(refine))
        status = report.get("status")
        return ShapeEstimate(
            *arrays,
            affine_confidence=report["affine_confidence"],
            reliable=report["reliable"],
            angle_spread=report["angle_spread"],
            scale_spread=report["scale_spread"],
            confidence_features=report["confidence_features"],
            confidence_model=report["confidence_model"],
            status=None if status is None else np.asarray(status, dtype=str),
            zncc=report.get("zncc"),
        )

    def predict(
        self, patches_a: ArrayLike, patches_b: ArrayLike, *, return_logits: bool = False
    ) -> dict[str, np.ndarray]:
        """Run the network on patch pairs ``(N, 1, 32, 32)`` (gray in [0, 1]).

        Returns ``orientation_a``, ``orientation_b``, ``scale_a``, ``scale_b`` (N,) and
        ``residual_shape`` (N, 3), float64. With ``return_logits`` also the raw float32 outputs
        ``angle_logits_a/b`` (N, K_theta), ``scale_logits_a/b`` (N, K_s) and
        ``residual_shape_raw`` (N, 3).
        """
        return self._runner.predict(patches_a, patches_b, return_logits)

    def extract_patches(
        self, image: ImageLike, xy: ArrayLike, *, channel_order: str = "rgb"
    ) -> NDArray[np.float32]:
        """The network's input patches ``(N, 1, 32, 32)`` around ``xy (N, 2)``; see
        :func:`extract_patches`."""
        return extract_patches(image, xy, channel_order=channel_order)

    def __repr__(self) -> str:
        return (
            f"ShapeEstimator(model={str(self._model_path)!r}, threads={self.threads}, "
            f"batch_size={self.batch_size})"
        )


def extract_patches(
    image: ImageLike, xy: ArrayLike, *, channel_order: str = "rgb"
) -> NDArray[np.float32]:
    """32x32 patches ``(N, 1, 32, 32)`` float32 around the sub-pixel centres ``xy (N, 2)``.

    Pixel ``(r, c)`` of a patch is the image read bilinearly at ``(x + c - 15.5, y + r - 15.5)``;
    reads outside the image replicate its border (``scipy.ndimage.map_coordinates(order=1,
    mode="nearest")``). Colour images are converted to gray first (:func:`read_gray_image`;
    ``channel_order="bgr"`` for ``cv2.imread`` arrays).
    """
    return _native.extract_patches(as_rgb(image, channel_order), as_xy(xy))


def read_gray_image(image: ImageLike, *, channel_order: str = "rgb") -> NDArray[np.float32]:
    """An image as the network sees it: ``(H, W)`` float32 gray in [0, 1].

    Files (PNG, JPEG; 8 or 16 bits) are decoded in Rust. Colour becomes
    ``0.299 R + 0.587 G + 0.114 B``; alpha is ignored. ``channel_order``: ``"bgr"`` for
    ``cv2.imread`` arrays (files are decoded by their own format); torch tensors
    ``(C, H, W)`` are accepted.
    """
    return _native.read_gray_image(as_rgb(image, channel_order))


@dataclass(frozen=True)
class AffineRefinement:
    """The result of :func:`refine_affine`."""

    #: (N, 8) ACs: refined where ``refined``, else the input rows.
    corrs: NDArray[np.float64]
    #: (N,) bool: whether each AC passed the checks and was refined.
    refined: NDArray[np.bool_]
    #: (N,) weighted ZNCC of each returned AC's windows at the finest level (NaN if flat).
    zncc: NDArray[np.float64]
    #: (N,) str: ``"refined"``, or why the input came back (:data:`REFINE_STATUSES`).
    status: NDArray[np.str_]
    #: (N,) the fitted shift's standard deviation (px, worst direction) from the Gauss-Newton
    #: covariance; inf for a flat window.
    shift_std: NDArray[np.float64]
    #: (N,) the expected ||dA||_F of the returned A from the same covariance.
    affine_std: NDArray[np.float64]
    #: (N,) in [0, 1]: the calibrated probability that the returned A is good (cosine with
    #: the true A >= 0.9), from the refinement's outcome and the neighbouring ACs; low for a
    #: returned input.
    affine_confidence: NDArray[np.float64]
    #: (N,) bool: ``affine_confidence`` at least the calibrated threshold.
    reliable: NDArray[np.bool_]
    #: (N, F) the confidence's inputs (:func:`confidence_model` ``("refinement")``).
    confidence_features: NDArray[np.float64]


def refine_affine(
    image_a: ImageLike,
    image_b: ImageLike,
    corrs: ArrayLike,
    *,
    radius: int = 16,
    blur_sigmas: tuple[float, ...] = (3.0, 1.5, 0.75),
    iterations: int = 6,
    min_zncc: float = 0.8,
    move_points: bool = True,
    try_identity: bool = True,
    try_neighbours: bool = True,
    max_shift_std: float = 0.5,
    channel_order: str = "rgb",
) -> AffineRefinement:
    """Refine ACs ``(N, 8)`` against the two images by affine Lucas-Kanade (Rust, parallel,
    the GIL released).

    For each AC, the ``(2 radius + 1)^2`` window of image A around ``x1`` is matched to image B
    at ``x2 + t + A d`` by Gauss-Newton over ``t``, ``A`` and a gain and bias, coarse to fine
    over Gaussian blurs ``blur_sigmas`` (px), at most ``iterations`` steps per level. A result
    is kept when det A > 0, ``|t| < radius / 2``, its ZNCC both beats the input's and reaches
    ``min_zncc``, and the fitted translation's standard deviation (from the Gauss-Newton
    matrix and the residual; pixels, worst direction) is at most ``max_shift_std``, which
    rejects windows on a lone edge, where any shift along it fits (the aperture problem);
    otherwise the input row is returned, with ``status`` saying which check failed and a low
    ``affine_confidence`` (never ``reliable``). With ``move_points`` x2 becomes
    ``x2 + t`` (A and t are fitted together); otherwise only A changes. With ``try_identity``
    the iterations start from A = I instead of the input's A wherever the identity matches
    better at the coarsest level (most image pairs are roughly upright). With
    ``try_neighbours`` they start, where it matches better still, from the similarity that the
    AC's 8 nearest ACs (in image A) agree on: the median scale ratio and rotation of their
    displacements ``x2_j - x2_i`` against ``x1_j - x1_i``. The shape network's scale is poor
    beyond about 1.5x zoom; the points' displacements know it. ``channel_order``: ``"bgr"``
    for ``cv2.imread`` arrays.

    On graffiti 1->3 at SIFT's correct matches the median ||A - A_gt||_F goes from 0.369 (the
    shape network) to 0.023, against SIFT's own 0.311 (benches/results/shape_accuracy.md).

    >>> import numpy as np, affcorr
    >>> y, x = np.mgrid[:120, :120]
    >>> img = 0.5 + 0.2 * np.sin(0.3 * x + 0.1 * y) * np.cos(0.05 * x - 0.25 * y)
    >>> c = np.array([[60.0, 60.0, 60.0, 60.0, 1.1, 0.05, 0.0, 0.95]])  # A 0.1 off
    >>> r = affcorr.refine_affine(img, img, c)
    >>> bool(r.refined[0]), np.abs(r.corrs[0, 4:] - [1, 0, 0, 1]).max() < 0.01
    (True, True)
    """
    if not isinstance(radius, int) or isinstance(radius, bool) or not 1 <= radius <= 64:
        raise ValueError(f"radius must be an int in 1..64 (pixels), got {radius!r}")
    if not isinstance(iterations, int) or isinstance(iterations, bool) or iterations < 1:
        raise ValueError(f"iterations must be a positive int, got {iterations!r}")
    try:
        sigmas = [float(s) for s in blur_sigmas]
    except (TypeError, ValueError):
        raise ValueError(
            f"blur_sigmas must be a sequence of numbers, got {blur_sigmas!r}"
        ) from None
    out, report = _native.refine_affine(
        as_rgb(image_a, channel_order),
        as_rgb(image_b, channel_order),
        corrs,
        radius=radius,
        blur_sigmas=sigmas,
        iterations=iterations,
        min_zncc=float(min_zncc),
        move_points=bool(move_points),
        max_shift_std=float(max_shift_std),
        try_identity=bool(try_identity),
        try_neighbours=bool(try_neighbours),
    )
    return AffineRefinement(
        out,
        report["refined"],
        report["zncc"],
        status=np.asarray(report["status"], dtype=str),
        shift_std=report["shift_std"],
        affine_std=report["affine_std"],
        affine_confidence=report["affine_confidence"],
        reliable=report["reliable"],
        confidence_features=report["confidence_features"],
    )
