"""Image inputs from other libraries: the channel order of OpenCV arrays and torch tensors.

affcorr's readers (Rust) take a path, or an array ``(H, W)`` / ``(H, W, 3|4)`` of uint8,
uint16 or float in [0, 1] whose colour channels are **RGB(A)**. :func:`as_rgb` turns what a
user has into that.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

#: The accepted values of ``channel_order``.
CHANNEL_ORDERS = ("rgb", "bgr")


def _from_torch(image: Any) -> np.ndarray:
    """A torch tensor as numpy, channels last: ``(C, H, W)`` or ``(1, C, H, W)`` with C in
    {1, 3, 4} become ``(H, W, C)`` (``(H, W)`` for one channel); ``(H, W)`` stays."""
    a = image.detach().cpu().numpy()
    if a.ndim == 4 and a.shape[0] == 1:
        a = a[0]
    if a.ndim == 3 and a.shape[0] in (1, 3, 4) and a.shape[-1] not in (3, 4):
        a = np.moveaxis(a, 0, -1)
    if a.ndim == 3 and a.shape[-1] == 1:
        a = a[..., 0]
    return a


def as_rgb(image: Any, channel_order: str = "rgb") -> Any:
    """``image`` as affcorr's readers take it.

    - a path (``str`` / ``os.PathLike``) is returned unchanged: files are decoded by their own
      format, whatever ``channel_order`` says;
    - a torch tensor is moved to numpy, channels last (``(C, H, W)`` and ``(1, C, H, W)``, as
      torchvision and kornia hold images, become ``(H, W, C)``);
    - ``channel_order="bgr"`` (``cv2.imread``'s order) reverses the colour channels of
      ``(H, W, 3)`` and ``(H, W, 4)`` arrays (BGRA → RGBA); gray ``(H, W)`` is unaffected.

    Raises ``ValueError`` for another ``channel_order``.
    """
    if channel_order not in CHANNEL_ORDERS:
        raise ValueError(f"channel_order must be 'rgb' or 'bgr', got {channel_order!r}")
    if isinstance(image, (str, os.PathLike)):
        return image
    if type(image).__module__.startswith("torch"):
        image = _from_torch(image)
    if channel_order == "bgr":
        a = np.asarray(image)
        if a.ndim == 3 and a.shape[-1] == 3:
            return np.ascontiguousarray(a[..., ::-1])
        if a.ndim == 3 and a.shape[-1] == 4:
            return np.ascontiguousarray(a[..., [2, 1, 0, 3]])
        return a
    return image


def as_xy(points: Any) -> Any:
    """OpenCV's point forms as ``(N, 2)``: ``(N, 1, 2)`` arrays and ``cv2.KeyPoint`` lists (their
    ``pt``); anything else is returned unchanged, for the readers' own checks and messages."""
    if isinstance(points, (list, tuple)) and len(points) and hasattr(points[0], "pt"):
        return np.array([k.pt for k in points], dtype=np.float64).reshape(-1, 2)
    if isinstance(points, np.ndarray) and points.ndim == 3 and points.shape[1:] == (1, 2):
        return points[:, 0, :]
    return points
