"""Writes the seed inputs of the image_decode and shape_model fuzz targets (README.md).

Run from the repository root: `.venv/bin/python fuzz/seeds.py`. Seeds are tiny files of each
pixel type the decoder maps (gray, gray + alpha, RGB, RGBA, 16-bit, palette, 1-bit;
interlaced PNG; baseline, progressive, gray and CMYK JPEG) and the shape-contract fixtures of
tests/data/shape.
"""

from __future__ import annotations

import io
import shutil
from pathlib import Path

import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parent.parent
CORPUS = ROOT / "fuzz" / "corpus"


def images() -> dict[str, bytes]:
    rng = np.random.default_rng(0)
    rgba = rng.integers(0, 256, size=(5, 7, 4), dtype=np.uint8)
    out: dict[str, bytes] = {}

    def save(name: str, img: Image.Image, fmt: str, **kw: object) -> None:
        buf = io.BytesIO()
        img.save(buf, fmt, **kw)
        out[name] = buf.getvalue()

    save("gray.png", Image.fromarray(rgba[..., 0], "L"), "PNG")
    save("gray_alpha.png", Image.fromarray(rgba[..., :2], "LA"), "PNG")
    save("rgb.png", Image.fromarray(rgba[..., :3], "RGB"), "PNG")
    save("rgba.png", Image.fromarray(rgba, "RGBA"), "PNG")
    save("rgb_interlaced.png", Image.fromarray(rgba[..., :3], "RGB"), "PNG", interlace=1)
    gray16 = (rgba[..., 0].astype(np.uint16) * 257).astype(np.uint16)
    save("gray16.png", Image.fromarray(gray16), "PNG")
    save("palette.png", Image.fromarray(rgba[..., :3], "RGB").convert("P"), "PNG")
    save("bits.png", Image.fromarray(rgba[..., 0] > 127), "PNG")
    save("rgb.jpg", Image.fromarray(rgba[..., :3], "RGB"), "JPEG", quality=80)
    save("gray.jpg", Image.fromarray(rgba[..., 0], "L"), "JPEG")
    save("progressive.jpg", Image.fromarray(rgba[..., :3], "RGB"), "JPEG", progressive=True)
    save("cmyk.jpg", Image.fromarray(rgba, "RGBA").convert("CMYK"), "JPEG")
    return out


def main() -> None:
    for sub in ("image_decode", "shape_model"):
        (CORPUS / sub).mkdir(parents=True, exist_ok=True)
    for name, data in images().items():
        (CORPUS / "image_decode" / name).write_bytes(data)
    for model in sorted((ROOT / "tests" / "data" / "shape").glob("*.onnx")):
        shutil.copy(model, CORPUS / "shape_model" / model.name)


if __name__ == "__main__":
    main()
