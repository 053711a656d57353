"""The end-to-end pipeline: two images in, affine correspondences (and H or a pose) out.

``affcorr.Pipeline`` runs in Rust through ONNX Runtime, with the GIL released:

1. **decode**: files are decoded (PNG, JPEG) to gray; arrays are taken as
   :func:`affcorr.read_gray_image` takes them. With ``max_side``, an image whose longer side
   exceeds it is downscaled (antialiased) to that working resolution.
2. **matcher**: the XFeat backbone (``models/xfeat_backbone.onnx``; twice per image for XFeat*),
   or a dense matcher (``"dense"``: a ``dense-warp-v1`` model such as a DKM or RoMa export,
   given as ``dense_model``; it sees files and (H, W, 3 | 4) arrays in colour).
3. **detection** and **matching**: sparse keypoints + mutual nearest neighbours (``"xfeat"``),
   semi-dense cells + mutual nearest neighbours + sub-pixel refinement (``"xfeat-star"``,
   ``models/xfeat_refine.onnx``), or sparse keypoints + LighterGlue (``"xfeat-lighterglue"``,
   ``models/xfeat_lighterglue.onnx``). The post-processing follows
   ``affcorr.export.xfeat_reference`` (docs/matchers.md). A dense matcher's matches are drawn
   by DKM's balanced sampling from its certainty map (seeded: ``seed``).
4. **patches** and **shape_net**: 32x32 patches around the matched points and the shape network's
   affine map ``A = dx2/dx1`` at each (``models/shape.onnx``, see :class:`affcorr.ShapeEstimator`).

5. **affine_refine**: affine Lucas-Kanade refinement of the ACs against the images (on by
   default, see :func:`affcorr.refine_affine`).

Results are in the original images' pixels, sorted by decreasing certainty (MNN: cosine
similarity of the descriptors; XFeat*: refinement confidence; LighterGlue: match score).
:meth:`Pipeline.homography`, :meth:`Pipeline.fundamental` and :meth:`Pipeline.relative_pose` add
the robust estimation of :func:`affcorr.estimate_homography` / :func:`affcorr.estimate_fundamental`
/ :func:`affcorr.estimate_relative_pose` on the ACs, with the same keyword options and return
types (``ransac`` in the timings).

This module is a thin layer over the Rust crate ``affcorr-pipeline``: every step runs there, and
the matcher names, model file names and defaults are read from it (:data:`PIPELINE_DEFAULTS`),
so the Rust API, this API and the CLI share one set (docs/pipeline.md says why each value).

Errors: bad arguments and undecodable images raise ``ValueError``; missing image or model files
``FileNotFoundError``; models that break their ONNX contract and ONNX Runtime problems
``RuntimeError``.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _native
from ._images import as_rgb
from .estimation import (
    PairError,
    RansacInfo,
    RelativePose,
    _check_on_error,
    _info,
    _per_pair,
    _pose,
)
from .shape import _PerProcess, bundled_shape_model, find_ort_library

__all__ = [
    "DEFAULT_DENSE_MATCHES",
    "MATCHERS",
    "Features",
    "PIPELINE_DEFAULTS",
    "MatchResult",
    "Pipeline",
    "bundled_models_dir",
]

#: The pipeline's defaults, one set for Rust, Python and the CLI (from ``affcorr-pipeline``):
#: ``matcher``, ``max_keypoints``, ``aliked_detection_threshold``, ``dense_matches``,
#: ``refine_affine``, ``views``, ``seed``, ``homography_threshold``, ``fundamental_threshold``,
#: ``pose_threshold`` (pixels).
PIPELINE_DEFAULTS: dict[str, Any] = dict(_native.PIPELINE_DEFAULTS)

#: The matcher names :class:`Pipeline` takes, the default first.
MATCHERS: tuple[str, ...] = tuple(_native.PIPELINE_MATCHERS)

#: Matches a dense matcher draws by default (``max_matches=None``).
DEFAULT_DENSE_MATCHES: int = PIPELINE_DEFAULTS["dense_matches"]

#: An image: a PNG/JPEG file path, or an array (H, W) / (H, W, C), C in 1..4, of dtype uint8
#: (divided by 255), uint16 (divided by 65535) or float (values in [0, 1]).
ImageLike = Union[str, "os.PathLike[str]", np.ndarray]

#: Model file names in a models directory, by role, and the roles each matcher needs.
_FILES: dict[str, str] = dict(_native.PIPELINE_MODEL_FILES)
_NEEDS: dict[str, list[str]] = {k: list(v) for k, v in _native.PIPELINE_MATCHER_MODELS.items()}
_SCREEN: dict[str, list[str]] = {k: list(v) for k, v in _native.PIPELINE_SCREEN_MODELS.items()}

_D = PIPELINE_DEFAULTS


#: One image's features (:meth:`Pipeline.extract`), immutable: ``matcher``, ``image_size``
#: (W, H) as stored, ``working_size`` (upright), ``orientation`` (the EXIF orientation 1-8 the
#: image was turned upright by; 1 for arrays), ``keypoints`` (N, 2) in the original (stored)
#: pixels, ``scores`` (N,),
#: ``descriptors`` (N, D), ``seconds`` (extraction time), ``len()``; ``to_bytes()`` and
#: ``Features.from_bytes(data)`` store them (a versioned binary format), and they pickle.
Features = _native.PipelineFeatures


def bundled_models_dir() -> Path:
    """The models shipped in the package (``affcorr/models``)."""
    return Path(__file__).resolve().parent / "models"


@dataclass(frozen=True, eq=False)
class MatchResult:
    """The ACs of one image pair.

    Attributes:
        corrs: ``(N, 8)`` float64 rows ``[x1, y1, x2, y2, a11, a12, a21, a22]``, ``A = dx2/dx1``,
            in the original images' pixels, most certain first.
        certainty: ``(N,)`` the matcher's certainty of each match (higher is better).
        timings: seconds per stage: ``decode``, ``matcher``, ``detection``, ``matching``,
            ``patches``, ``shape_net``, ``affine_refine`` (0 unless enabled), ``views`` (the
            view cascade: verification and synthetic views, whose own stages are counted in
            the stages above too), ``guided`` (guided re-matching, 0 unless it ran),
            ``ransac`` (0 unless estimated), ``total``.
        num_keypoints: keypoints (or semi-dense cells) found in image A and in image B.
        affine_confidence: ``(N,)`` float64 in [0, 1], the calibrated probability that each
            AC's A is good (cosine with the true A >= 0.9), from the shape network's spread,
            the refinement's outcome and the neighbouring ACs (docs/shape_network.md,
            "Confidence").
        reliable: ``(N,)`` bool, ``affine_confidence`` at least the calibrated threshold; an
            AC whose refinement failed is never reliable. ``drop_unreliable=True`` keeps only
            these.
        views: the view cascade's report, one dict per view tried, the plain pair first
            (``label``, ``image`` "A" / "B" / None, ``rotation`` and ``tilt_angle`` in
            radians, ``scale``, ``tilt``, ``guided``, ``window`` (the tile matched, as
            fractions ``[x0, y0, x1, y1]``, or None), ``other_scale`` and
            ``other_rotation`` (radians; the other image's zoom and in-plane rotation),
            ``matches``, ``inliers``, ``verified``, ``screen`` (the view's rank score in a
            screened group of tilts or tiles, else None),
            ``seconds``, ``work`` (what it took from ``view_relative_budget``, in plain
            passes: counted, not timed, so the same pair runs the same views on any machine;
            the views' work sums to the pair's, the last view's including any extractions
            after it whose screens the budget cut), ``started`` (the cascade's work when the
            view started, its group's screen included: what the budget was compared with, so
            the view runs under any ``view_relative_budget`` above it; 0 for the plain pass),
            ``screen_extraction`` (the part of ``started`` and ``work`` that its group's
            screen spent extracting the group's images; 0 for a view with no screen before
            it: a smaller budget skips the screen when these extractions would reach it, and
            stops after them when only the screens would: no screen is paid for without a
            view after it),
            ``used``: whether its ACs are the result's); empty when the cascade did not run
            (``views="off"``, dense matchers).
    """

    corrs: NDArray[np.float64]
    certainty: NDArray[np.float64]
    timings: dict[str, float]
    num_keypoints: tuple[int, int]
    views: list[dict[str, Any]] = field(default_factory=list)
    affine_confidence: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    reliable: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, bool))

    @property
    def view(self) -> dict[str, Any] | None:
        """The view that produced the ACs (the report marked ``used``, as the Rust pipeline
        chose it: the verified view with the most inliers, else the plain pair); None when the
        cascade did not run."""
        return next((v for v in self.views if v["used"]), None)

    def view_summary(self) -> str:
        """One line on the view cascade: whose ACs these are, how many synthetic views it
        tried and the work it took, in plain passes (the plain pass's 1 included); "" when it
        did not run (``views="off"``, dense matchers). Graffiti 1→3 with B upside down gives
        ``views: ACs of B rot 180° (249 of 277 matches agree); 1 synthetic view tried, 3.0
        plain passes of work`` (on one line); the pair upright ``views: the plain pair
        verified (249 of 277 matches agree); no synthetic view needed``.
        """
        if not self.views:
            return ""
        used, tried = self.view, len(self.views) - 1
        work = sum(v["work"] for v in self.views)
        agree = (
            f"{used['inliers']} of {used['matches']} matches agree"
            if used["matches"]
            else "no matches"
        )
        cost = (
            f"{tried} synthetic view{'s' if tried != 1 else ''} tried, "
            f"{work:.1f} plain passes of work"
        )
        if tried == 0:
            if used["verified"]:
                return f"views: the plain pair verified ({agree}); no synthetic view needed"
            return f"views: the plain pair did not verify ({agree}); no synthetic view run"
        if not used["verified"]:
            return f"views: no view verified, the plain pair's ACs kept ({agree}); {cost}"
        return f"views: ACs of {used['label']} ({agree}); {cost}"

    def __len__(self) -> int:
        return len(self.corrs)

    def __repr__(self) -> str:
        return (
            f"MatchResult({len(self)} ACs, keypoints {self.num_keypoints}, "
            f"total {1e3 * self.timings.get('total', 0.0):.1f} ms)"
        )


def _positive(value: Any, name: str, *, optional: bool = True) -> int | None:
    if value is None and optional:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        what = "a positive int" + (" or None" if optional else "")
        raise ValueError(f"{name} must be {what}, got {value!r}")
    return int(value)


class Pipeline:
    """Images in, affine correspondences out (matcher + shape network), plus H or pose.

    Args:
        matcher: ``"xfeat-lighterglue"`` (XFeat keypoints matched by LighterGlue: the most
            correct matches, but its cost grows with ``max_keypoints`` squared), ``"xfeat"``
            (mutual nearest neighbours, fastest), ``"xfeat-star"`` (semi-dense XFeat* with
            sub-pixel refinement), ``"disk-lightglue"`` (DISK keypoints matched by LightGlue,
            with its adaptive depth and width), ``"aliked-lightglue"`` (ALIKED keypoints
            matched by LightGlue, the same loop; for both the models are not shipped but made
            at setup time by ``python -m affcorr.export.lightglue_models -o
            python/affcorr/models``, docs/matchers.md) or ``"dense"`` (a ``dense-warp-v1``
            model, ``dense_model``).
            ``None``: ``"dense"`` when ``dense_model`` is given, else the default
            (``PIPELINE_DEFAULTS["matcher"]``).
        max_keypoints: keypoints per image (semi-dense cells for ``"xfeat-star"``; unused by
            ``"dense"``).
        detection_threshold: the score a keypoint needs in the detector's map (the sparse
            matchers: XFeat's heatmap, DISK's logits, ALIKED's scores); over ``max_keypoints``
            the highest scores are kept either way. ``None``: the model's (XFeat 0.05, DISK 0),
            and for ALIKED ``PIPELINE_DEFAULTS["aliked_detection_threshold"]`` (0: the top
            ``max_keypoints``, as for DISK; upstream's 0.2 leaves texture-poor images a few
            dozen keypoints, docs/matchers.md). Not for ``"xfeat-star"`` or ``"dense"``.
        max_matches: keep at most this many matches, the most certain; ``None``: all. A dense
            matcher draws this many (``None``: ``DEFAULT_DENSE_MATCHES``, 2000).
        max_side: downscale images whose longer side exceeds this (pixels) before matching;
            ``None``: full resolution. Results are in the original pixels either way.
        exif_orientation: match image files as their EXIF orientation shows them (upright),
            so that a photograph taken in portrait meets one taken in landscape without a
            turn. The ACs and keypoints are in the files' *stored* pixels either way (their
            width and height as the file stores them; what COLMAP, PIL and
            :func:`affcorr.read_gray_image` give, not ``cv2.imread``, which turns them):
            only the images the matcher sees differ. Arrays are taken as they are. On by
            default; :attr:`Features.orientation` says how an image was turned.
        threads: ONNX Runtime and Rust threads; ``None``: every core.
        shape_model: the shape network (``shape-v1``); ``None``: the bundled one, or
            ``shape.onnx`` of ``models_dir`` when that has one.
        models_dir: a directory with ``xfeat_backbone.onnx``, ``xfeat_refine.onnx`` and
            ``xfeat_lighterglue.onnx`` (the ones the matcher needs; ``disk_backbone.onnx`` and
            ``disk_lightglue_{encode,layer,assign}.onnx`` for ``"disk-lightglue"``;
            ``aliked_backbone.onnx``, ``aliked_sddh.onnx`` and
            ``aliked_lightglue_{encode,layer,assign}.onnx`` for ``"aliked-lightglue"``;
            ``dense.onnx`` for ``"dense"`` without ``dense_model``); ``None``: the bundled models
            (``affcorr/models``).
        dense_model: a ``dense-warp-v1`` ONNX file (docs/matchers.md says how to export DKM or
            RoMa to it; none is shipped).
        seed: seed of the dense matcher's balanced sampling (the same seed gives the same
            matches).
        views: the view cascade for pairs the plain matcher cannot solve (large in-plane
            rotation, zoom, tilt): ``"auto"`` (the default) verifies the plain pair's matches
            with a fundamental matrix and, when too few agree, matches synthetic views
            (rotations, zooms, ASIFT tilts) until one verifies, mapping every AC back through
            the view's warp; ``"full"`` tries every view and keeps the best; ``"off"`` the
            plain pair only. Easy pairs cost one verification. When the pass it keeps
            verifies with few inliers for the keypoint budget (under a tenth: a steep tilt's or
            a zoom's), its matches are grown as by ``guided_matching``, so that they cover the
            overlap. See :attr:`MatchResult.views`.
        view_budget: seconds after which the cascade starts no new view (None: no limit).
        view_relative_budget: the cascade starts no new view once it has done this many
            times the plain pass's work (the default: ``PIPELINE_DEFAULTS["view_relative_budget"]``;
            None: no limit), nor a screened group's screen that would reach it. It bounds
            what a pair that no view solves costs, on any image size; the work is counted
            (pixels extracted, keypoints matched, ACs made), not timed, so which views run
            does not depend on the machine or its load.
        max_views: at most this many synthetic views (None: the default, 256).
        channel_order: ``"bgr"`` for ``cv2.imread`` arrays (files are decoded by their own
            format; torch tensors ``(C, H, W)`` are accepted).
        refine_affine: refine the network's ACs against the images by affine Lucas-Kanade
            (:func:`affcorr.refine_affine` with its defaults; x2 moves too). On by default; its
            effect is measured in benches/results/eval/affine.md and
            benches/results/pose_refine.md. It costs a few times the shape network (timed as
            ``affine_refine``); ``False`` gives the network's ACs alone (the view cascade then
            weighs their A less when it verifies a pass; for repetitive patterns at large
            rotations keep it on: docs/pipeline.md, "Without the refinement").
        drop_unreliable: return only the ACs flagged reliable (:attr:`MatchResult.reliable`),
            for callers that need trustworthy A (default False: every AC, each flagged).
        guided_matching: when the pair's matches verify, predict every unmatched keypoint of
            image A in image B from its nearest verified AC (x2 + A (p - x1)), fit it by the
            affine refinement and keep it when it is reliable and agrees with the verifying
            fundamental matrix; the new ACs follow the matcher's (timed as ``guided``). More
            matches where the images overlap, without descriptors (docs/pipeline.md). Off (the
            default), it still runs after a view cascade that kept a weakly verified pass
            (``views``).

    Every model's ONNX contract is checked on loading.

    >>> import affcorr
    >>> from affcorr.data import data_dir
    >>> d = data_dir() / "graffiti"
    >>> pipe = affcorr.Pipeline("xfeat", max_keypoints=1024, threads=2)
    >>> res = pipe.match_pair(d / "graf1.png", d / "graf3.png")
    >>> res.corrs.shape[1], len(res.certainty) == len(res.corrs) > 100
    (8, True)
    """

    def __init__(
        self,
        matcher: str | None = None,
        *,
        max_keypoints: int = _D["max_keypoints"],
        detection_threshold: float | None = None,
        max_matches: int | None = None,
        max_side: int | None = None,
        threads: int | None = None,
        shape_model: str | os.PathLike[str] | None = None,
        models_dir: str | os.PathLike[str] | None = None,
        dense_model: str | os.PathLike[str] | None = None,
        seed: int = _D["seed"],
        refine_affine: bool = _D["refine_affine"],
        drop_unreliable: bool = False,
        exif_orientation: bool = _D["exif_orientation"],
        guided_matching: bool = _D["guided_matching"],
        views: str = _D["views"],
        view_budget: float | None = None,
        view_relative_budget: float | None = PIPELINE_DEFAULTS["view_relative_budget"],
        max_views: int | None = None,
        channel_order: str = "rgb",
    ) -> None:
        as_rgb("", channel_order)  # validates it
        self._channel_order = channel_order
        if matcher is None:
            matcher = "dense" if dense_model is not None else _D["matcher"]
        if not isinstance(matcher, str) or matcher.lower() not in MATCHERS:
            raise ValueError(f"matcher must be one of {list(MATCHERS)}, got {matcher!r}")
        matcher = matcher.lower()
        if dense_model is not None and matcher != "dense":
            raise ValueError(f'dense_model is only used with matcher="dense", not {matcher!r}')
        max_keypoints = _positive(max_keypoints, "max_keypoints", optional=False)
        if detection_threshold is not None and (
            isinstance(detection_threshold, bool)
            or not isinstance(detection_threshold, (int, float, np.integer, np.floating))
            or not np.isfinite(detection_threshold)
        ):
            raise ValueError(
                f"detection_threshold must be a finite number or None, got {detection_threshold!r}"
            )
        max_matches = _positive(max_matches, "max_matches")
        max_side = _positive(max_side, "max_side")
        threads = _positive(threads, "threads")
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValueError(f"seed must be a non-negative int, got {seed!r}")
        directory = bundled_models_dir() if models_dir is None else Path(os.fspath(models_dir))
        if models_dir is not None and not directory.is_dir():
            raise FileNotFoundError(f"models_dir {str(directory)!r} is not a directory")
        if shape_model is not None:
            shape = Path(os.fspath(shape_model))
        elif models_dir is not None and (directory / "shape.onnx").is_file():
            shape = directory / "shape.onnx"
        else:
            shape = bundled_shape_model()
        paths = {k: directory / f for k, f in _FILES.items() if k != "shape"}
        if dense_model is not None:
            paths["dense"] = Path(os.fspath(dense_model))
        elif matcher == "dense" and not paths["dense"].is_file():
            raise ValueError(
                'matcher="dense" needs dense_model= (a dense-warp-v1 ONNX file; none is shipped, '
                f"docs/matchers.md says how to export DKM or RoMa) or {_FILES['dense']} in "
                "models_dir"
            )
        needs = _NEEDS[matcher]
        # The view cascade's screen (XFeat's backbone for DISK, ALIKED and XFeat*) where its
        # model is there; without it the matcher's own features screen the views.
        if views != "off":
            screen = _SCREEN.get(matcher, [])
            needs = needs + [k for k in screen if k not in needs and paths[k].is_file()]
        self._models = {**{k: paths[k] for k in needs}, "shape": shape}
        model_args = {f"{k}_model": str(paths[k]) for k in needs}
        args = dict(
            matcher=matcher,
            shape_model=str(shape),
            **model_args,
            ort_library=find_ort_library(),
            max_keypoints=max_keypoints,
            detection_threshold=None if detection_threshold is None else float(detection_threshold),
            max_matches=max_matches,
            max_side=max_side,
            threads=threads,
            seed=int(seed),
            refine_affine=bool(refine_affine),
            drop_unreliable=bool(drop_unreliable),
            exif_orientation=bool(exif_orientation),
            guided_matching=bool(guided_matching),
            views=views,
            view_budget=view_budget,
            view_relative_budget=view_relative_budget,
            max_views=_positive(max_views, "max_views"),
        )
        # The models and thread pools belong to this process; a forked child (multiprocessing
        # "fork", DataLoader workers) loads its own on first use.
        self._native = _PerProcess(lambda: _native.PipelineRunner(**args))

    @property
    def _runner(self) -> Any:
        """The native pipeline of this process (rebuilt in a forked child)."""
        return self._native.get()

    # ----------------------------------------------------------------- properties

    @property
    def matcher(self) -> str:
        """``"xfeat"``, ``"xfeat-star"``, ``"xfeat-lighterglue"``, ``"disk-lightglue"``,
        ``"aliked-lightglue"`` or ``"dense"``."""
        return self._runner.matcher

    @property
    def max_keypoints(self) -> int:
        """Keypoints (or semi-dense cells) per image; for ``"dense"`` the matches drawn."""
        return self._runner.max_keypoints

    @property
    def detection_threshold(self) -> float | None:
        """The score a keypoint needs in the detector's map; ``None`` for ``"xfeat-star"`` and
        ``"dense"``, which keep no keypoints by score."""
        return self._runner.detection_threshold

    @property
    def seed(self) -> int:
        """The seed of a dense matcher's balanced sampling."""
        return self._runner.seed

    @property
    def exif_orientation(self) -> bool:
        """Whether image files are matched upright, as their EXIF orientation shows them
        (coordinates stay in their stored pixels)."""
        return self._runner.exif_orientation

    @property
    def views(self) -> str:
        """The view cascade's mode: ``"off"``, ``"auto"`` or ``"full"``."""
        return self._runner.views

    @property
    def view_screen(self) -> str:
        """The matcher whose features rank the view cascade's synthetic views before any is
        matched: ``"xfeat"`` for ``"disk-lightglue"`` and ``"aliked-lightglue"`` (whose own
        extractions cost 10–30× XFeat's) and for ``"xfeat-star"`` (whose semi-dense cells have
        no keypoint descriptors; docs/pipeline.md, "Screening with XFeat"), else the
        pipeline's own matcher."""
        return self._runner.view_screen

    @property
    def matcher_metadata(self) -> dict[str, str]:
        """The matcher model's custom ONNX metadata (the XFeat backbone's or the dense
        matcher's), e.g. ``affcorr.contract``."""
        return dict(self._runner.matcher_metadata)

    @property
    def max_matches(self) -> int | None:
        """The cap on matches, or None."""
        return self._runner.max_matches

    @property
    def max_side(self) -> int | None:
        """The working resolution's longer side, or None (full resolution)."""
        return self._runner.max_side

    @property
    def threads(self) -> int:
        """ONNX Runtime intra-op threads and Rust threads."""
        return self._runner.threads

    @property
    def models(self) -> dict[str, Path]:
        """The model files in use (``backbone``, ``refine`` / ``lighterglue``, or ``dense``;
        the DISK or ALIKED matcher's, with XFeat's ``backbone`` for the view cascade's screen
        when the cascade is on; ``shape``)."""
        return dict(self._models)

    @property
    def shape_model(self) -> Path:
        """The shape network's file."""
        return self._models["shape"]

    # ----------------------------------------------------------------- matching

    def _image(self, x: Any) -> Any:
        x = as_rgb(x, self._channel_order)
        return os.fspath(x) if isinstance(x, os.PathLike) else x

    def match_pair(self, image_a: ImageLike, image_b: ImageLike) -> MatchResult:
        """The ACs of an image pair (paths or arrays)."""
        return MatchResult(*self._runner.match_pair(self._image(image_a), self._image(image_b)))

    def match_pairs(
        self, pairs: Iterable[Sequence[ImageLike]], *, on_error: str = "return"
    ) -> list[MatchResult | PairError]:
        """:meth:`match_pair` over many ``(image_a, image_b)`` pairs, in Rust with the GIL
        released. With ``threads > 1`` the pairs run in parallel, one per thread (at most one
        per core), each on a single-threaded copy of the models (loaded on the first call and
        kept): 12-20 % more pairs per second than one pair after the other with every thread
        (benches/results/pipeline_timing.md). Results equal :meth:`match_pair`'s.

        Each pair gets its result: a :class:`MatchResult`, or a :class:`affcorr.PairError` in
        its place when that pair fails (an unreadable or missing image, an image too large for
        the matcher): ``error`` is the exception :meth:`match_pair` would raise, its message
        prefixed ``pairs[i]: ``. The other pairs are kept. ``on_error="raise"`` raises the first
        failing pair's exception instead. An item that is not a pair raises either way. Ctrl-C
        starts no further pair and raises ``KeyboardInterrupt`` once the running ones end.

        A pair that does not overlap runs the view cascade until ``view_relative_budget`` is
        spent (about 31 plain passes at the default 30). For a list with many such pairs,
        give the pipeline the batch's budget, as ``affcorr batch`` does:
        ``view_relative_budget=affcorr.batch.BATCH_VIEW_RELATIVE_BUDGET`` (12: every rotated
        pair and nearly every steep tilt still solved, about 12.4 passes on a pair without
        overlap; benches/results/views_budget.md)."""
        _check_on_error(on_error)
        items = []
        # One conversion per distinct image object, so that Rust sees one buffer per image and
        # extracts its features once (paths are shared by name there).
        converted: dict[int, Any] = {}

        def image(x: Any) -> Any:
            if id(x) not in converted:
                converted[id(x)] = self._image(x)
            return converted[id(x)]

        for i, p in enumerate(pairs):
            if isinstance(p, (str, bytes, os.PathLike, np.ndarray)) or len(p) != 2:
                raise ValueError(f"pairs[{i}] must be a pair (image_a, image_b)")
            items.append((image(p[0]), image(p[1])))
        return _per_pair(self._runner.match_pairs(items), lambda r: MatchResult(*r), on_error)

    def extract(self, image: ImageLike) -> Features:
        """The features of one image, to match with many others (:meth:`match_features`): it is
        decoded, downscaled to ``max_side``, and the matcher's keypoints and descriptors are
        computed (a dense matcher, which runs on the pair, keeps the colour image). In Rust with
        the GIL released. :class:`Features` pickle (as :meth:`Features.to_bytes`), so they can
        be cached on disk or sent to other processes."""
        return self._runner.extract(self._image(image))

    def match_features(self, features_a: Features, features_b: Features) -> MatchResult:
        """The ACs of two images from their :meth:`extract` features: :meth:`match_pair`'s
        result bit for bit (the view cascade included), without extracting again. The timings
        count each image's extraction too. Features of another matcher, ``max_keypoints``,
        ``detection_threshold`` or ``max_side`` raise ``ValueError`` naming the argument."""
        return MatchResult(*self._runner.match_features(features_a, features_b))

    # ----------------------------------------------------------------- estimation

    def _estimated(
        self, out: tuple[Any, ...], model: Any, return_matches: bool
    ) -> tuple[Any, RansacInfo] | tuple[Any, RansacInfo, MatchResult]:
        (_, info), match = out
        res = MatchResult(*match)
        return (model, _info(info), res) if return_matches else (model, _info(info))

    def homography(
        self,
        image_a: ImageLike,
        image_b: ImageLike,
        *,
        threshold: float = _D["homography_threshold"],
        seed: int = _D["seed"],
        return_matches: bool = False,
        **options: Any,
    ) -> (
        tuple[NDArray[np.float64], RansacInfo] | tuple[NDArray[np.float64], RansacInfo, MatchResult]
    ):
        """The homography ``p2 ~ H p1`` (original pixels) of an image pair.

        :meth:`match_pair`, then :func:`affcorr.estimate_homography` on the ACs (2-AC samples by
        default) with ``threshold`` (transfer error, pixels; the default is
        ``PIPELINE_DEFAULTS["homography_threshold"]``), ``seed`` and ``**options`` (see
        :mod:`affcorr.estimation`; with ``sampler="prosac"`` and no ``quality``, the
        certainties), all in Rust with the GIL released. ``info.inliers`` indexes the ACs of
        the match result, which ``return_matches=True`` appends (its timings include
        ``ransac``).

        Returns:
            ``(H, info)`` as :func:`affcorr.estimate_homography`, or ``(H, info, matches)``.
        """
        out = self._runner.estimate(
            "homography", self._image(image_a), self._image(image_b), threshold=threshold,
            seed=seed, **options
        )  # fmt: skip
        return self._estimated(out, out[0][0], return_matches)

    def fundamental(
        self,
        image_a: ImageLike,
        image_b: ImageLike,
        *,
        threshold: float = _D["fundamental_threshold"],
        seed: int = _D["seed"],
        return_matches: bool = False,
        **options: Any,
    ) -> (
        tuple[NDArray[np.float64], RansacInfo] | tuple[NDArray[np.float64], RansacInfo, MatchResult]
    ):
        """The fundamental matrix ``p2^T F p1 = 0`` (original pixels) of an image pair.

        :meth:`match_pair`, then :func:`affcorr.estimate_fundamental` (3-AC samples by default)
        with ``threshold`` (Sampson distance, pixels; default
        ``PIPELINE_DEFAULTS["fundamental_threshold"]``), ``seed`` and ``**options``, as
        :meth:`homography`. The scene must not be a single plane.

        Returns:
            ``(F, info)`` as :func:`affcorr.estimate_fundamental`, or ``(F, info, matches)``.
        """
        out = self._runner.estimate(
            "fundamental", self._image(image_a), self._image(image_b), threshold=threshold,
            seed=seed, **options
        )  # fmt: skip
        return self._estimated(out, out[0][0], return_matches)

    def relative_pose(
        self,
        image_a: ImageLike,
        image_b: ImageLike,
        K1: ArrayLike,  # noqa: N803 (intrinsics are capitals by convention)
        K2: ArrayLike,  # noqa: N803
        *,
        threshold: float = _D["pose_threshold"],
        seed: int = _D["seed"],
        return_matches: bool = False,
        **options: Any,
    ) -> tuple[RelativePose, RansacInfo] | tuple[RelativePose, RansacInfo, MatchResult]:
        """The relative pose ``X2 = R X1 + t`` of two calibrated images.

        ``K1``, ``K2``: ``(3, 3)`` intrinsics of the original images (checked before matching:
        upper triangular, positive focal lengths).
        :meth:`match_pair`, then :func:`affcorr.estimate_relative_pose` with ``threshold``
        (Sampson distance, pixels; default ``PIPELINE_DEFAULTS["pose_threshold"]``), ``seed``
        and ``**options``, as :meth:`homography`.

        Returns:
            ``(pose, info)`` as :func:`affcorr.estimate_relative_pose`, or
            ``(pose, info, matches)``.
        """
        out = self._runner.estimate(
            "relative_pose", self._image(image_a), self._image(image_b), K1=K1, K2=K2,
            threshold=threshold, seed=seed, **options
        )  # fmt: skip
        return self._estimated(out, _pose(out[0][0]), return_matches)

    def __repr__(self) -> str:
        return (
            f"Pipeline(matcher={self.matcher!r}, max_keypoints={self.max_keypoints}, "
            f"max_matches={self.max_matches}, max_side={self.max_side}, threads={self.threads})"
        )
