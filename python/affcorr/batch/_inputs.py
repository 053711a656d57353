"""The batch's inputs: pair lists, camera files, checksums, and hloc's pair names."""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Union

import numpy as np

#: A pair list: a text file (one ``name0 name1`` pair per line, ``#`` comments, hloc's
#: pairs format) or a sequence of ``(name0, name1)``.
PairsLike = Union[str, "os.PathLike[str]", Sequence[Sequence[str]]]


def names_to_pair(name0: str, name1: str, separator: str = "/") -> str:
    """hloc's key of a pair in ``matches.h5`` (``hloc.utils.parsers.names_to_pair``): the two
    names with ``/`` replaced by ``-``, joined by ``/`` (so each pair is a group ``name0`` with
    a subgroup ``name1``)."""
    return separator.join((name0.replace("/", "-"), name1.replace("/", "-")))


def read_pairs(pairs: PairsLike) -> list[tuple[str, str]]:
    """The pairs, in order, without repeats: a pair given twice, or also reversed, is kept
    once (in its first direction), as hloc's ``find_unique_new_pairs`` does."""
    if isinstance(pairs, (str, os.PathLike)):
        path = Path(pairs)
        if not path.is_file():
            raise FileNotFoundError(f"pairs: no such file {str(path)!r}")
        raw: list[tuple[str, str]] = []
        for lineno, line in enumerate(path.read_text().splitlines(), 1):
            line = line.split("#", 1)[0].strip()
            if not line:
                continue
            parts = line.split()
            if len(parts) < 2:
                raise ValueError(f"pairs: line {lineno} of {str(path)!r} is not 'name0 name1'")
            raw.append((parts[0], parts[1]))
    else:
        raw = []
        for i, p in enumerate(pairs):
            if isinstance(p, (str, bytes)) or len(p) != 2:
                raise ValueError(f"pairs[{i}] must be a pair (name0, name1), got {p!r}")
            raw.append((os.fspath(p[0]), os.fspath(p[1])))
    seen: set[tuple[str, str]] = set()
    out = []
    for a, b in raw:
        if (a, b) in seen or (b, a) in seen:
            continue
        seen.add((a, b))
        out.append((a, b))
    return out


@dataclass(frozen=True)
class Camera:
    """A pinhole camera: COLMAP's model name and parameters (distortion is kept for the
    COLMAP database; the relative pose uses the pinhole part)."""

    model: str
    width: int
    height: int
    params: tuple[float, ...]

    def K(self) -> np.ndarray:  # noqa: N802 (intrinsics are capitals by convention)
        """The (3, 3) intrinsics of the pinhole part."""
        p = self.params
        if self.model in ("SIMPLE_PINHOLE", "SIMPLE_RADIAL", "RADIAL"):
            fx = fy = p[0]
            cx, cy = p[1], p[2]
        else:  # PINHOLE, OPENCV, FULL_OPENCV: fx fy cx cy ...
            fx, fy, cx, cy = p[:4]
        return np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]], dtype=np.float64)

    def as_list(self) -> list[Any]:
        return [self.model, self.width, self.height, list(self.params)]


_PARAMS = {
    "SIMPLE_PINHOLE": 3,
    "PINHOLE": 4,
    "SIMPLE_RADIAL": 4,
    "RADIAL": 5,
    "OPENCV": 8,
    "FULL_OPENCV": 12,
}


def default_camera(width: int, height: int) -> Camera:
    """The EXIF-free default: SIMPLE_PINHOLE with f = 1.2 max(W, H) and the principal point at
    the centre (COLMAP's prior when nothing is known)."""
    f = 1.2 * max(width, height)
    return Camera("SIMPLE_PINHOLE", width, height, (f, width / 2.0, height / 2.0))


def read_cameras(path: str | os.PathLike[str]) -> dict[str, Camera]:
    """A camera file: one image per line, ``name MODEL width height params...`` (COLMAP's
    ``cameras.txt`` columns after the image name; hloc's query lists with intrinsics), with
    MODEL one of SIMPLE_PINHOLE (f cx cy), PINHOLE (fx fy cx cy), SIMPLE_RADIAL (f cx cy k),
    RADIAL (f cx cy k1 k2), OPENCV (fx fy cx cy k1 k2 p1 p2), FULL_OPENCV; ``#`` comments."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"cameras: no such file {str(path)!r}")
    out: dict[str, Camera] = {}
    for lineno, line in enumerate(path.read_text().splitlines(), 1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        parts = line.split()
        where = f"cameras: line {lineno} of {str(path)!r}"
        if len(parts) < 4 or parts[1].upper() not in _PARAMS:
            raise ValueError(
                f"{where} must be 'name MODEL width height params...' with MODEL one of "
                f"{sorted(_PARAMS)}"
            )
        model = parts[1].upper()
        try:
            w, h = int(parts[2]), int(parts[3])
            params = tuple(float(x) for x in parts[4:])
        except ValueError as e:
            raise ValueError(f"{where}: {e}") from None
        if len(params) != _PARAMS[model]:
            raise ValueError(
                f"{where}: {model} takes {_PARAMS[model]} parameters, got {len(params)}"
            )
        if w < 1 or h < 1 or params[0] <= 0:
            raise ValueError(f"{where}: the size and focal length must be positive")
        out[parts[0]] = Camera(model, w, h, params)
    return out


def file_digest(path: Path) -> str:
    """sha256 of a file's bytes, or ``"missing:<path>"`` when it cannot be read (the pair then
    fails in the worker, with the worker's error)."""
    h = hashlib.sha256()
    try:
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
    except OSError:
        return f"missing:{path}"
    return h.hexdigest()


def digest(*parts: Any) -> str:
    """sha256 of the JSON of ``parts`` (the checksum of a pair's inputs and options)."""
    return hashlib.sha256(json.dumps(parts, sort_keys=True, default=str).encode()).hexdigest()


def image_names(pairs: Iterable[tuple[str, str]]) -> list[str]:
    """The images of the pairs, in order of first appearance."""
    seen: dict[str, None] = {}
    for a, b in pairs:
        seen.setdefault(a)
        seen.setdefault(b)
    return list(seen)
