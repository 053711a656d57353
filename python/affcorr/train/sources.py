"""Real images used as plane textures for training and validation (docs/design.md §7).

Two offline sources, both reachable from a fresh machine:

- scikit-image's bundled images (``pip install scikit-image``; BSD-3 and public-domain photos);
- Debian's ``opencv-doc`` samples (``apt-get download opencv-doc``, unpacked into the cache; the
  images carry the licences listed in the package's copyright file).

The split is by *source image*: validation textures are never seen in training. Images that
the evaluation suite uses with ground truth (graffiti, the chessboard stereo set, the motorcycle
stereo pair) are in neither split.
"""

from __future__ import annotations

import os
import subprocess
import tempfile
from pathlib import Path

import numpy as np

SKIMAGE_TRAIN = [
    "astronaut.png",
    "brick.png",
    "camera.png",
    "coffee.png",
    "coins.png",
    "grass.png",
    "hubble_deep_field.jpg",
    "ihc.png",
    "moon.png",
    "page.png",
    "retina.jpg",
    "rocket.jpg",
    "text.png",
    "clock_motion.png",
]
SKIMAGE_VAL = ["chelsea.png", "gravel.png"]
OPENCV_TRAIN = [
    "aero1.jpg",
    "aloeL.jpg",
    "apple.jpg",
    "baboon.jpg",
    "basketball1.png",
    "blox.jpg",
    "board.jpg",
    "box_in_scene.png",
    "butterfly.jpg",
    "fruits.jpg",
    "HappyFish.jpg",
    "home.jpg",
    "lena.jpg",
    "messi5.jpg",
    "orange.jpg",
    "rubberwhale1.png",
    "squirrel_cls.jpg",
    "stuff.jpg",
    "Blender_Suzanne1.jpg",
    "ela_original.jpg",
    "sudoku.png",
    "pic1.png",
    "pic3.png",
    "pic5.png",
]
OPENCV_VAL = ["building.jpg", "leuvenA.jpg", "starry_night.jpg", "smarties.png"]
MIN_SIDE = 200


def cache_dir() -> Path:
    """``$AFFCORR_CACHE`` or ``~/.cache/affcorr``: downloaded packages, datasets, checkpoints."""
    root = Path(os.environ.get("AFFCORR_CACHE", Path.home() / ".cache" / "affcorr"))
    root.mkdir(parents=True, exist_ok=True)
    return root


def opencv_doc_data() -> Path:
    """The ``examples/data`` folder of Debian's opencv-doc, fetched with apt on first use."""
    target = cache_dir() / "opencv-doc"
    data = target / "usr/share/doc/opencv-doc/examples/data"
    if data.is_dir():
        return data
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run(["apt-get", "download", "opencv-doc"], cwd=tmp, check=True)
        deb = next(Path(tmp).glob("opencv-doc_*.deb"))
        subprocess.run(["dpkg-deb", "-x", str(deb), str(target)], check=True)
    return data


def _gray(img: np.ndarray) -> np.ndarray:
    img = np.asarray(img)
    scale = 255.0 if img.dtype == np.uint8 else float(np.max(img) or 1.0)
    img = img.astype(np.float32) / scale
    if img.ndim == 3:
        img = img[..., :3] @ np.array([0.299, 0.587, 0.114], dtype=np.float32)
    return np.ascontiguousarray(img)


def load_image(path: Path) -> np.ndarray:
    """A grayscale float32 image in [0, 1]."""
    from skimage import io

    return _gray(io.imread(str(path)))


def textures(split: str) -> list[tuple[str, np.ndarray]]:
    """``(name, gray image)`` pairs of the ``split`` ('train' or 'val')."""
    if split not in ("train", "val"):
        raise ValueError(f"split must be 'train' or 'val', got {split!r}")
    import skimage

    sk_root = Path(skimage.__file__).parent / "data"
    sk_names, cv_names = (
        (SKIMAGE_TRAIN, OPENCV_TRAIN) if split == "train" else (SKIMAGE_VAL, OPENCV_VAL)
    )
    out = [(name, load_image(sk_root / name)) for name in sk_names]
    root = opencv_doc_data()
    out += [(name, load_image(root / name)) for name in cv_names if (root / name).exists()]
    return [(n, im) for n, im in out if min(im.shape) >= MIN_SIDE]
