"""OpenCV interop: keypoints, matches, point arrays and BGR images.

OpenCV and affcorr share the pixel convention (x right, y down, pixel centres at integers), so
coordinates pass unchanged. What differs:

- **channel order**: ``cv2.imread`` returns BGR, affcorr reads colour arrays as RGB. Pass
  ``channel_order="bgr"`` to :func:`as_rgb` (or convert with ``img[..., ::-1]``); gray images
  are unaffected, and so are files given by path (decoded by affcorr itself).
- **point arrays**: OpenCV's ``(N, 1, 2)`` arrays (``cv2.goodFeaturesToTrack``'s, what
  ``cv2.findHomography`` takes) and ``cv2.KeyPoint`` lists become ``(N, 2)`` with
  :func:`points`.
- **keypoint frames**: a SIFT / ORB / AKAZE keypoint has a scale (``size``, diameter in px) and
  an orientation (``angle``, degrees). Two matched keypoints give the similarity AC
  ``A = (size2 / size1) · R(angle2 − angle1)`` (:func:`acs_from_keypoints`), with
  ``R(θ) = [[cos θ, −sin θ], [sin θ, cos θ]]`` in y-down pixels: OpenCV's angle turns the same
  way as affcorr's orientation (checked on a rotated image in tests/test_opencv_interop.py;
  kornia's turns the other way). Such ACs carry no shear; affcorr's shape network and
  :func:`affcorr.refine_affine` give the full A.

Nothing here imports cv2: it works on anything with OpenCV's attributes (``pt``, ``size``,
``angle``; ``queryIdx``, ``trainIdx``).

>>> import numpy as np
>>> points(np.zeros((5, 1, 2), np.float32)).shape
(5, 2)
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ._images import CHANNEL_ORDERS, as_rgb

__all__ = ["CHANNEL_ORDERS", "acs_from_keypoints", "as_rgb", "keypoint_frames", "points"]


def _is_keypoint(x: Any) -> bool:
    return hasattr(x, "pt") and hasattr(x, "size") and hasattr(x, "angle")


def points(x: Any, what: str = "points") -> NDArray[np.float64]:
    """``(N, 2)`` float64 from ``(N, 2)``, OpenCV's ``(N, 1, 2)``, a list of ``cv2.KeyPoint``
    (their ``pt``) or a list of ``(x, y)``. Raises ``ValueError`` naming ``what``."""
    if isinstance(x, (list, tuple)) and len(x) and _is_keypoint(x[0]):
        return np.array([k.pt for k in x], dtype=np.float64).reshape(-1, 2)
    a = np.asarray(x, dtype=np.float64)
    if a.ndim == 3 and a.shape[1] == 1 and a.shape[2] == 2:
        a = a[:, 0, :]
    if a.ndim == 1 and a.size == 0:
        a = a.reshape(0, 2)
    if a.ndim != 2 or a.shape[1] != 2:
        raise ValueError(f"{what}: expected (N, 2) or (N, 1, 2) points, got shape {a.shape}")
    return np.ascontiguousarray(a)


def keypoint_frames(keypoints: Sequence[Any]) -> tuple[NDArray[np.float64], ...]:
    """``(xy (N, 2), size (N,), angle (N,) radians)`` of OpenCV keypoints; a keypoint without
    an orientation (``angle == -1``, e.g. FAST) gets angle 0."""
    if len(keypoints) and not _is_keypoint(keypoints[0]):
        raise ValueError("keypoints: expected cv2.KeyPoint objects (with pt, size, angle)")
    xy = np.array([k.pt for k in keypoints], dtype=np.float64).reshape(-1, 2)
    size = np.array([k.size for k in keypoints], dtype=np.float64)
    deg = np.array([k.angle for k in keypoints], dtype=np.float64)
    return xy, size, np.deg2rad(np.where(deg < 0, 0.0, deg))


def acs_from_keypoints(
    keypoints1: Sequence[Any],
    keypoints2: Sequence[Any],
    matches: Sequence[Any] | None = None,
) -> NDArray[np.float64]:
    """ACs ``(N, 8)`` from matched OpenCV keypoints: x1, x2 their centres, and the similarity
    ``A = (size2 / size1) · R(angle2 − angle1)`` their scales and orientations give.

    ``matches``: ``cv2.DMatch`` objects (``queryIdx`` into ``keypoints1``, ``trainIdx`` into
    ``keypoints2``, as ``cv2.BFMatcher.match(des1, des2)`` returns them; lists of k matches per
    query from ``knnMatch`` use their first), or ``(N, 2)`` index pairs; ``None``: the lists are
    already paired, ``keypoints1[i] ↔ keypoints2[i]``.

    >>> from types import SimpleNamespace as K
    >>> k1, k2 = [K(pt=(10.0, 20.0), size=4.0, angle=0.0)], [K(pt=(5.0, 6.0), size=8.0, angle=90.0)]
    >>> acs_from_keypoints(k1, k2).round(12).tolist()
    [[10.0, 20.0, 5.0, 6.0, 0.0, -2.0, 2.0, 0.0]]
    """
    xy1, s1, t1 = keypoint_frames(keypoints1)
    xy2, s2, t2 = keypoint_frames(keypoints2)
    if matches is None:
        if len(xy1) != len(xy2):
            raise ValueError(
                f"keypoints: without matches the lists must pair up, got {len(xy1)} and {len(xy2)}"
            )
        i = j = np.arange(len(xy1))
    else:
        i, j = _match_indices(matches)
        for name, idx, n in (("queryIdx", i, len(xy1)), ("trainIdx", j, len(xy2))):
            bad = np.flatnonzero((idx < 0) | (idx >= n))
            if len(bad):
                raise ValueError(
                    f"matches[{bad[0]}]: {name} {idx[bad[0]]} is outside the {n} keypoints"
                )
    if np.any(s1[i] <= 0) or np.any(s2[j] <= 0):
        raise ValueError("keypoints: every matched keypoint needs a positive size")
    scale = s2[j] / s1[i]
    d = t2[j] - t1[i]
    c, s = np.cos(d) * scale, np.sin(d) * scale
    return np.column_stack([xy1[i], xy2[j], c, -s, s, c])


def _match_indices(matches: Sequence[Any]) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    if len(matches) == 0:
        return np.zeros(0, np.intp), np.zeros(0, np.intp)
    first = matches[0]
    if isinstance(first, (list, tuple)) and first and hasattr(first[0], "queryIdx"):
        matches = [m[0] for m in matches if len(m)]  # knnMatch: the best of each query
        first = matches[0] if matches else None
    if first is not None and hasattr(first, "queryIdx"):
        return (
            np.array([m.queryIdx for m in matches], dtype=np.intp),
            np.array([m.trainIdx for m in matches], dtype=np.intp),
        )
    idx = np.asarray(matches)
    if idx.ndim != 2 or idx.shape[1] != 2 or not np.issubdtype(idx.dtype, np.integer):
        raise ValueError(
            f"matches: expected cv2.DMatch objects or (N, 2) integer index pairs, got {idx.shape}"
        )
    return idx[:, 0].astype(np.intp), idx[:, 1].astype(np.intp)
