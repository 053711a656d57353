"""What the evaluation suite's experiments share: cached matching, fast BLAS for the torch peers,
and the generated tables' header (command, date, machine load, versions). The CSV and markdown
helpers are affcorr_bench.common's."""

from __future__ import annotations

import datetime
import functools
import hashlib
import os
import platform
import sys
from pathlib import Path

import numpy as np

from .. import common
from . import matchers

RESULTS = common.RESULTS / "eval"
#: The match cache and the unpacked OpenBLAS (benches/eval/.cache/, git-ignored).
CACHE = common.EVAL_STATE / ".cache"
#: Bump when a matcher of the registry changes, so cached matches are recomputed.
MATCHES_VERSION = 1
#: Counts changes of affcorr's pipeline that alter its matches (the view cascade's steps, the
#: refinement): affcorr's cached matches carry it, so bumping it re-runs affcorr's rows and
#: keeps the peers'. 2: third-size tiles magnified by 3 in the cascade. 3: the cascade's
#: budget counts work, not time (default 30 plain passes of work). 4: a plain pass verified by fewer
#: than CONFIDENT_VIEW x min_inliers is rivalled by every view (its AC-guided one after the
#: rotations); tilts of 4 before the tiles. 5: a kept pass verified with a weak yield is grown by
#: guided re-matching. 6: the verification's F refined as before 5 (only H's points-only
#: refinement starts undamped). 7: a weak plain pass with enough inliers to be kept is rivalled
#: by its AC-guided view too, after the rotations. 8: the tilt-4 groups hold the tilts zoomed by
#: 1/2 too. 9: the warps' directional blur computes its taps once away from the edges (the same
#: views to float rounding). 10: a plain pass whose matches' median certainty is low is rivalled
#: by the rotations however well it verifies (views::uncertain). 11: A's tilt-4 groups meet B's
#: 45° rotations too. 12: a rival short of the margin wins by one plane's support
#: (views::planar_rival). 13: a view verified weakly before the rotations ran is rivalled by
#: them (views::rivalled_by_rotations). 14: the homography's local optimisation runs its
#: widening and threshold tracks from each hypothesis, and every raw record gets one
#: (LoSchedule::Both). 15: XFeat's mutual nearest neighbours verify strongly by 0.4 of their
#: matches (defaults::weak_ratio). 16: the cascade screens its groups on shrunk images while
#: nothing is kept (views::screen_warps).
AFFCORR_PIPELINE_REVISION = 16
#: The Rust sources that make affcorr's matches, Cargo.lock (which pins ONNX Runtime's
#: bindings and the rest) and the matcher's models (the shape model is in its own tag): their
#: digest is in affcorr's cache keys too, so an experiment on the cascade that is not landed (or
#: a revision number used twice) never serves stale matches.
PIPELINE_SOURCES = ("crates/*/src/**/*.rs", "Cargo.lock", "python/affcorr/models/xfeat_*.onnx")
#: Debian's OpenBLAS, unpacked by setup.sh (not installed: the machine's libblas stays as is).
OPENBLAS = CACHE / "openblas" / "usr/lib/x86_64-linux-gnu/openblas-pthread"


def use_openblas() -> None:
    """Re-executes this experiment with OpenBLAS in front of Debian's reference libblas (which
    Debian's torch links): LightGlue's matrix products run ~15x faster, and every peer then runs
    as a user would run it. No-op without setup.sh's unpacked OpenBLAS."""
    if not OPENBLAS.is_dir() or os.environ.get("AFFCORR_EVAL_BLAS") == str(OPENBLAS):
        return
    env = dict(os.environ, AFFCORR_EVAL_BLAS=str(OPENBLAS), OPENBLAS_NUM_THREADS="1")
    env["LD_LIBRARY_PATH"] = os.pathsep.join(
        p for p in (str(OPENBLAS), env.get("LD_LIBRARY_PATH", "")) if p
    )
    # sys.argv[0] is the module's file under ``python -m``: rerun it as the same module.
    spec = getattr(sys.modules.get("__main__"), "__spec__", None)
    argv = ["-m", spec.name] if spec is not None else [sys.argv[0]]
    os.execve(sys.executable, [sys.executable, *argv, *sys.argv[1:]], common.child_env(env))


@functools.cache
def pipeline_source_digest() -> str:
    """10 hex digits of the SHA-1 of PIPELINE_SOURCES (paths and contents, in path order); ""
    outside a checkout."""
    files = sorted({f for pattern in PIPELINE_SOURCES for f in common.ROOT.glob(pattern)})
    if not files:
        return ""
    h = hashlib.sha1()
    for f in files:
        h.update(str(f.relative_to(common.ROOT)).encode() + b"\0" + f.read_bytes())
    return h.hexdigest()[:10]


def pipeline_tag() -> str:
    """The part of affcorr's cache keys that names its pipeline: the revision and the source
    digest (``-p<revision>-src<digest>``)."""
    return f"-p{AFFCORR_PIPELINE_REVISION}-src{pipeline_source_digest()}"


def _key(pair, name: str, max_keypoints: int) -> Path:
    h = hashlib.sha1(pair.img1.tobytes() + pair.img2.tobytes()).hexdigest()[:10]
    folder = CACHE / "matches" / f"v{MATCHES_VERSION}" / f"{pair.id}-{h}"
    # affcorr's matches depend on its shape model and on its pipeline's code too.
    tag = ""
    if name == "affcorr":
        tag = f"-shape{matchers.shape_model_tag()}{pipeline_tag()}"
    return folder / f"{name}-k{max_keypoints}{tag}.npz"


def matches(name: str, pair, max_keypoints: int) -> matchers.Matches:
    """``matchers.run`` on a data.Pair, cached on disk by the images' content."""
    path = _key(pair, name, max_keypoints)
    if path.exists():
        z = np.load(path)
        A = z["A"] if z["A"].ndim == 3 else None
        return matchers.Matches(z["x1"], z["x2"], A, z["score"], float(z["seconds"]))
    m = matchers.run(name, pair.img1, pair.img2, max_keypoints=max_keypoints)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")
    A = np.zeros(0) if m.A is None else m.A
    np.savez(tmp, x1=m.x1, x2=m.x2, A=A, score=m.score, seconds=m.seconds)
    tmp.replace(path)
    return m


def header(title: str, command: str, notes: list[str]) -> list[str]:
    """Markdown lines: title, command, date, machine and load, library versions, notes."""
    load = " / ".join(f"{x:.1f}" for x in os.getloadavg())
    vers = ", ".join(f"{k} {v}" for k, v in matchers.versions().items())
    blas = "OpenBLAS" if os.environ.get("AFFCORR_EVAL_BLAS") else "Debian reference BLAS"
    return [
        f"# {title}",
        "",
        f"Command: `{command}`",
        "",
        f"Date: {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC. Machine: "
        f"{platform.machine()}, {os.cpu_count()} cores shared with other jobs, load average "
        f"(1/5/15 min) at the end {load}; every method single-threaded ({matchers.THREADS}), "
        f"torch on {blas}.",
        "",
        f"Versions: {vers}.",
        "",
        *[line for n in notes for line in (n, "")],
    ]


def unavailable_note(names: list[str]) -> list[str]:
    """'unavailable' lines for methods that do not run here."""
    av = matchers.available()
    return [f"- {matchers.LABELS[n]}: unavailable ({av[n]})" for n in names if av[n]]
