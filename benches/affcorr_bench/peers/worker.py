"""Runs one group of methods (methods.GROUPS) on a scene file, in the venv of that group.

    PYTHONPATH=benches VENV/bin/python -m affcorr_bench.peers.worker \
        GROUP PROBLEM THRESHOLD scenes.npz out.npz [METHOD ...]

(run.run_group starts it so, with common.child_env(): the package need not be installed in the
group's venv; this module and what it imports need only numpy and the group's library.)

Each method runs on each scene PEERS_REPEAT times back to back (environment, default 1), after
one untimed warm-up call on the first scene; scene by scene, all methods of the group in turn.
The time is the wall-clock time of the fastest call alone (data already in memory, in the
library's layout).
out.npz holds, for method m and scene i: ``m/i/time``, ``m/i/ok``, and the model and ``inliers``
when ok; errors go to ``m/i/error``.
"""

from __future__ import annotations

import os
import sys
import time
import traceback

import numpy as np

from . import methods
from . import scenes as scene_io


def versions() -> str:
    """Versions of the libraries importable here."""
    found = []
    for mod in ("affcorr", "kornia", "torch", "poselib", "cv2", "pycolmap", "pygcransac", "numpy"):
        try:
            m = __import__(mod)
        except Exception:
            continue
        found.append(f"{mod} {getattr(m, '__version__', '?')}")
    return ", ".join(found)


def main(argv: list[str]) -> int:
    group, problem, thr, src, dst, *only = argv
    thr = float(thr)
    # PEERS_REPEAT calls per scene, back to back; the time is the fastest (the result is the
    # last call's: every method here is seeded or deterministic on these inputs).
    repeat = max(1, int(os.environ.get("PEERS_REPEAT", "1")))
    data = scene_io.load(src)
    try:
        factories = methods.GROUPS[group]()
    except Exception as e:  # an unavailable library: report it for every method of the group
        np.savez(dst, group_error=f"{type(e).__name__}: {e}")
        return 0
    out: dict[str, np.ndarray] = {"versions": np.str_(versions())}
    funcs = {}
    for name, make in factories.items():
        if only and name not in only:
            continue
        funcs[name] = make(problem)
        try:
            funcs[name](data[0], thr)  # warm-up (imports, lazy initialisation, caches)
        except Exception:
            pass
    # Scene-major, so that every method of the group meets the machine in the same state (run
    # method by method, two identical affcorr configurations differed by 1.3x: the first one
    # was always slower).
    for i, s in enumerate(data):
        for name, f in funcs.items():
            key = f"{name}/{i}/"
            best = np.inf
            for _ in range(repeat):
                t0 = time.perf_counter()
                try:
                    r = f(s, thr)
                    best = min(best, time.perf_counter() - t0)
                except Exception:
                    best = min(best, time.perf_counter() - t0)
                    out[key + "error"] = np.str_(traceback.format_exc(limit=2)[-500:])
                    r = None
                    break
            out[key + "time"] = np.float64(best)
            out[key + "ok"] = np.bool_(r is not None)
            for k, v in (r or {}).items():
                out[key + k] = np.asarray(v)
    print(f"  {group}: done", file=sys.stderr, flush=True)
    np.savez(dst, **out)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
