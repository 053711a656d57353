"""Small real test data shipped inside the package (affcorr/sample_data/; the repository's
data/graffiti links to it), and readers for it."""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

#: The bundled data: graffiti 1 and 3 with their ground-truth H (1.9 MB, see its README.md).
PACKAGE_DATA = Path(__file__).resolve().parent / "sample_data"


def data_dir() -> Path:
    """The folder that holds ``graffiti/``: $AFFCORR_DATA when set, else the copy bundled in the
    package (so that ``affcorr demo`` runs from any directory and from a wheel)."""
    env = os.environ.get("AFFCORR_DATA")
    if env:
        return Path(env)
    if (PACKAGE_DATA / "graffiti" / "H1to3p.xml").is_file():
        return PACKAGE_DATA
    raise FileNotFoundError(
        f"affcorr's bundled data is missing ({PACKAGE_DATA}): reinstall affcorr or set AFFCORR_DATA"
    )


def read_opencv_matrix(path: Path) -> np.ndarray:
    """Reads the first matrix of an OpenCV XML storage file (rows, cols, data)."""
    text = Path(path).read_text()
    rows = int(re.search(r"<rows>\s*(\d+)\s*</rows>", text).group(1))
    cols = int(re.search(r"<cols>\s*(\d+)\s*</cols>", text).group(1))
    data = re.search(r"<data>(.*?)</data>", text, re.S).group(1).split()
    return np.array([float(v) for v in data]).reshape(rows, cols)


def read_gray(path: Path) -> np.ndarray:
    """An image as float64 grayscale in [0, 1], shape (H, W)."""
    from PIL import Image

    return np.asarray(Image.open(path).convert("L"), dtype=np.float64) / 255.0


def graffiti_files() -> tuple[Path, Path, np.ndarray]:
    """(image 1 path, image 3 path, H 1→3) of the bundled graffiti pair; needs no Pillow."""
    d = data_dir() / "graffiti"
    return d / "graf1.png", d / "graf3.png", read_opencv_matrix(d / "H1to3p.xml")


def importable(module: str) -> bool:
    """Whether ``module`` imports (an optional dependency: installed and working)."""
    import importlib

    try:
        importlib.import_module(module)
    except ImportError:
        return False
    return True


def picture_note() -> str | None:
    """None when matplotlib is installed; else the one line the demos print instead of a
    picture."""
    if importable("matplotlib"):
        return None
    return "picture skipped: it needs matplotlib: pip install 'affcorr[plot]'"


def graffiti() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(image 1, image 3, H 1→3) of the Oxford graffiti sequence."""
    d = data_dir() / "graffiti"
    return (
        read_gray(d / "graf1.png"),
        read_gray(d / "graf3.png"),
        read_opencv_matrix(d / "H1to3p.xml"),
    )


def graffiti_grid(step: int = 20) -> tuple[Path, Path, np.ndarray]:
    """(image 1 path, image 3 path, ground-truth ACs (N, 8)) of graffiti 1→3 on a grid.

    x1 runs over a ``step``-pixel grid of image 1 (60..580 × 60..740 px); x2 and A come from
    H1to3p (``affcorr.correspondences_from_homography``); points whose x2 falls within 40 px of
    image 3's border are dropped. The exact ground truth the shape tests and benches use.
    """
    from . import _native

    d = data_dir() / "graffiti"
    H = read_opencv_matrix(d / "H1to3p.xml")
    ys, xs = np.mgrid[60:580:step, 60:740:step]
    x1 = np.c_[xs.ravel(), ys.ravel()].astype(np.float64)
    gt = _native.correspondences_from_homography(H, x1)
    inside = (gt[:, 2] > 40) & (gt[:, 3] > 40) & (gt[:, 2] < 760) & (gt[:, 3] < 600)
    return d / "graf1.png", d / "graf3.png", gt[inside]
