"""Sizes the bad-input battery leaves out of its fast tests (docs/reliability.md).

Each case runs in a fresh interpreter, so its peak RSS is its own:

- ``nan-last-row``: 10^7 (N, 4) rows with a NaN in the last one: time to the ValueError;
- ``estimate-1e7``: ``estimate_homography`` on 10^7 exact ACs with 10 % outliers;
- ``decode-20000``: ``read_gray_image`` of a valid 20000 x 20000 8-bit gray PNG;
- ``pipeline-HxW``: ``Pipeline("xfeat").match_pair`` of a 12 MP and a 48 MP image at full
  resolution (no ``max_side``).

    .venv/bin/python -m affcorr_bench.bad_input_scale   # writes benches/results/bad_input_scale.md
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import textwrap

from . import common

CASES = {
    "nan-last-row": """
        corrs = np.ones((10**7, 4)); corrs[-1, 3] = np.nan
        t0 = time.perf_counter()
        try:
            affcorr.estimate_homography(corrs)
        except ValueError as e:
            note = str(e)
        seconds = time.perf_counter() - t0
    """,
    "estimate-1e7": """
        H = np.array([[1.1, 0.05, 12.0], [-0.02, 0.95, -7.0], [2e-4, -1e-4, 1.0]])
        rng = np.random.default_rng(0)
        corrs = affcorr.correspondences_from_homography(H, rng.uniform(0, 640, (10**7, 2)))
        corrs[: 10**6, 2:4] += rng.uniform(20, 200, (10**6, 2))
        t0 = time.perf_counter()
        _, info = affcorr.estimate_homography(corrs, threshold=2.0)
        seconds = time.perf_counter() - t0
        note = f"{info.num_inliers} inliers, {info.num_iterations} iterations"
    """,
    "decode-20000": """
        import struct, zlib
        def chunk(k, b):
            return struct.pack(">I", len(b)) + k + b + struct.pack(">I", zlib.crc32(k + b))
        raw = b"".join(b"\\0" + bytes([i % 256]) * 20000 for i in range(20000))
        path = os.path.join(tmp, "big.png")
        with open(path, "wb") as f:
            f.write(b"\\x89PNG\\r\\n\\x1a\\n"
                    + chunk(b"IHDR", struct.pack(">IIBBBBB", 20000, 20000, 8, 0, 0, 0, 0))
                    + chunk(b"IDAT", zlib.compress(raw, 1)) + chunk(b"IEND", b""))
        del raw
        t0 = time.perf_counter()
        img = affcorr.read_gray_image(path)
        seconds = time.perf_counter() - t0
        note = f"{img.shape}, {os.path.getsize(path) / 1e6:.1f} MB file"
    """,
    **{
        f"pipeline-{h}x{w}": f"""
        rng = np.random.default_rng(0)
        img = (rng.random(({h} // 8, {w} // 8)) * 255).astype(np.uint8).repeat(8, 0).repeat(8, 1)
        pipe = affcorr.Pipeline("xfeat", max_keypoints=2048, threads=2)
        t0 = time.perf_counter()
        res = pipe.match_pair(img, img)
        seconds = time.perf_counter() - t0
        note = f"xfeat at full resolution (no max_side), {{len(res)}} ACs"
    """
        for h, w in ((3000, 4000), (6000, 8000))
    },
}

PRELUDE = """
import os, resource, time, json
import numpy as np
import affcorr
tmp = {tmp!r}
note = ""
"""
EPILOGUE = """
rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(json.dumps({"seconds": seconds, "peak_rss_mb": rss, "note": note}))
"""


def main(argv=None) -> None:
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, body in CASES.items():
            code = PRELUDE.format(tmp=tmp) + textwrap.dedent(body) + EPILOGUE
            out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
            if out.returncode != 0:
                raise SystemExit(f"{name} failed:\n{out.stderr}")
            r = json.loads(out.stdout.strip().splitlines()[-1])
            rows.append((name, r))
            print(name, r)
    load = os.getloadavg()[0]
    lines = [
        "# Bad-input sizes (docs/reliability.md)",
        "",
        f"Command: `{common.command(__spec__.name, [])}` "
        f"({platform.machine()}, {os.cpu_count()} cores, load average {load:.1f}).",
        "",
        "| case | seconds | peak RSS (MB) | note |",
        "|---|---|---|---|",
        *[f"| {n} | {r['seconds']:.2f} | {r['peak_rss_mb']:.0f} | {r['note']} |" for n, r in rows],
        "",
    ]
    out = common.RESULTS / "bad_input_scale.md"
    common.write_report(out, lines, echo=False)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
