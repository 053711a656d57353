"""Fixed training and validation sets of patch pairs, generated once and cached as .npz.

Patches are stored as uint8 (1 KiB each); the generation is seeded, so a dataset is the same
on every machine. Rebuilt only when missing (delete the file to regenerate).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .sources import textures
from .views import Texture, plane_pairs, similarity_pairs

# Pairs per texture and split. Training draws from 34 images, validation from 6 others.
SIMILARITY_PER_TEXTURE = {"train": 8000, "val": 1000}
PLANE_PER_TEXTURE = {"train": 4000, "val": 1000}
PLANE_MATCHES_PER_SCENE = 100
MIN_PATCH_STD = 0.02  # textureless patches carry no orientation, scale or shape


def _progress(it, desc: str):
    try:
        from tqdm import tqdm

        return tqdm(it, desc=desc, leave=False)
    except ImportError:
        return it


def _u8(p: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(p * 255.0), 0, 255).astype(np.uint8)


def _textured(pa: np.ndarray, pb: np.ndarray) -> np.ndarray:
    return (pa.std(axis=(1, 2)) > MIN_PATCH_STD) & (pb.std(axis=(1, 2)) > MIN_PATCH_STD)


def similarity_dataset(
    path: Path, split: str, seed: int = 0, *, centre_jitter: float = 0.0
) -> dict[str, np.ndarray]:
    """E_os pairs: ``patch_a``, ``patch_b`` (N, 32, 32) uint8, ``angle``, ``scale`` (N,)."""
    if path.exists():
        return dict(np.load(path))
    rng = np.random.default_rng([seed, 0 if split == "train" else 1])
    parts = []
    for _, img in _progress(textures(split), f"similarity pairs ({split})"):
        sp = similarity_pairs(
            rng, Texture(img), SIMILARITY_PER_TEXTURE[split], centre_jitter=centre_jitter
        )
        k = _textured(sp.patch_a, sp.patch_b)
        parts.append((_u8(sp.patch_a[k]), _u8(sp.patch_b[k]), sp.angle[k], sp.scale[k]))
    out = {
        name: np.concatenate([p[i] for p in parts])
        for i, name in enumerate(["patch_a", "patch_b", "angle", "scale"])
    }
    np.savez(path, **out)
    return out


def plane_dataset(
    path: Path, split: str, seed: int = 0, *, max_tilt_deg: float = 60.0, centre_jitter: float = 0.5
) -> dict[str, np.ndarray]:
    """E_aff pairs: ``patch_a``, ``patch_b`` uint8, ``corrs`` (N, 8), ``F`` (N, 3, 3) per row."""
    if path.exists():
        return dict(np.load(path))
    rng = np.random.default_rng([seed, 2 if split == "train" else 3])
    parts = []
    for _, img in _progress(textures(split), f"plane pairs ({split})"):
        tex = Texture(img)
        got, tries = 0, 0
        while got < PLANE_PER_TEXTURE[split] and tries < 400:
            tries += 1
            pp = plane_pairs(
                rng,
                tex,
                PLANE_MATCHES_PER_SCENE,
                max_tilt_deg=max_tilt_deg,
                centre_jitter=centre_jitter,
            )
            if pp is None:
                continue
            k = _textured(pp.patch_a, pp.patch_b)
            n = int(k.sum())
            parts.append(
                (
                    _u8(pp.patch_a[k]),
                    _u8(pp.patch_b[k]),
                    pp.corrs[k],
                    np.broadcast_to(pp.F, (n, 3, 3)),
                )
            )
            got += n
    out = {
        name: np.concatenate([p[i] for p in parts])
        for i, name in enumerate(["patch_a", "patch_b", "corrs", "F"])
    }
    np.savez(path, **out)
    return out
