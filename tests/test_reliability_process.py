"""affcorr as a citizen of a Python process (issue 23): fork safety and Ctrl-C.

Every case runs in a fresh interpreter with a timeout, so that a hang fails the test instead of
hanging the suite (before the fix, each fork case hung forever in the child's first parallel
call, and each Ctrl-C case ran on for the whole estimate). No timing is asserted beyond a
generous bound; the measured latencies are in docs/reliability.md.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

TIMEOUT = 180  # seconds for a whole child: a hang fails, it does not block the suite

# Parallel work of every kind the bindings run: an estimation batch (rayon over pairs), Sampson
# distances of 10^4 rows (rayon over chunks), the shape network (ONNX Runtime threads, rayon
# patch extraction) and, optionally, the pipeline (its own pool and sessions).
PRELUDE = """
import multiprocessing as mp, sys
import numpy as np
import affcorr

RNG = np.random.default_rng(0)
X1 = RNG.uniform(0, 640, (300, 2))
PAIRS = [affcorr.correspondences_from_homography(np.diag([s, s, 1.0]), X1) for s in (0.9, 1.1)]
F = np.array([[0.0, -1e-4, 0.02], [1e-4, 0.0, -0.03], [-0.02, 0.03, 1.0]])
ROWS = RNG.uniform(0, 640, (10_000, 4))
IMG = RNG.random((96, 128))
EST = affcorr.ShapeEstimator(threads=2)
PIPE = affcorr.Pipeline("xfeat", threads=2, max_keypoints=256) if "pipeline" in sys.argv else None
GRAF = None
if PIPE is not None:
    from affcorr.data import data_dir
    GRAF = (data_dir() / "graffiti" / "graf1.png", data_dir() / "graffiti" / "graf3.png")


def work(_=None):
    hs = [float(h[0, 0] / h[2, 2]) for h, _ in affcorr.estimate_homography_batch(PAIRS)]
    sd = float(affcorr.sampson_point(F, ROWS).sum())
    acs = EST.estimate(IMG, IMG, [[60.0, 40.0]], [[61.0, 41.0]], refine=False)
    out = [round(h, 9) for h in hs] + [round(sd, 6), acs.shape[0]]
    if PIPE is not None:
        out.append(len(PIPE.match_pair(*GRAF)) > 50)
    return out


def child(q):
    q.put(work())
"""

FORK = (
    PRELUDE
    + """
if __name__ == "__main__":
    method, kind = sys.argv[1], sys.argv[2]
    expected = work()  # the parent's parallel calls come first: their pools exist at fork time
    ctx = mp.get_context(method)
    if kind == "pool":
        with ctx.Pool(2) as pool:
            got = pool.map(work, range(4))
        assert all(g == expected for g in got), (got, expected)
    else:
        q = ctx.Queue()
        p = ctx.Process(target=child, args=(q,))
        p.start()
        got = q.get(timeout=120)
        p.join(30)
        assert p.exitcode == 0 and got == expected, (p.exitcode, got, expected)
    assert work() == expected  # and the parent still works
    print("ok", expected)
"""
)


def run_child(script: str, *args: str, tmp_path, timeout: float = TIMEOUT):
    # A file, not -c: "spawn" children re-import the main module by its path.
    path = tmp_path / "child.py"
    path.write_text(script)
    env = {**os.environ, "RAYON_NUM_THREADS": "2"}
    return subprocess.run(
        [sys.executable, str(path), *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
    )


@pytest.mark.parametrize(
    "method, kind",
    [("fork", "process"), ("fork", "pool"), ("spawn", "process"), ("spawn", "pool")],
)
def test_parallel_calls_work_in_children_after_parallel_calls_in_the_parent(method, kind, tmp_path):
    r = run_child(FORK, method, kind, tmp_path=tmp_path)
    assert r.returncode == 0 and "ok" in r.stdout, r.stdout + r.stderr


def test_the_pipeline_works_in_a_forked_child_after_matching_in_the_parent(tmp_path):
    r = run_child(FORK, "fork", "process", "pipeline", tmp_path=tmp_path)
    assert r.returncode == 0 and "ok" in r.stdout, r.stdout + r.stderr


# --- Ctrl-C ---------------------------------------------------------------------------------

# Each long call would run for minutes: no model exists in pure outliers, so the estimators
# draw max_iterations samples; confidence 1 - 1e-15 keeps any adaptive bound from stopping.
LONG = {
    "relative_pose": """
K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
c = RNG.uniform(0, 640, (3000, 4))
call = lambda: affcorr.estimate_relative_pose(c, K, K, max_iterations=10**9,
                                              confidence=1 - 1e-15, sample="points")
""",
    "homography_batch": """
pairs = [RNG.uniform(0, 640, (3000, 4)) for _ in range(8)]
call = lambda: affcorr.estimate_homography_batch(pairs, max_iterations=10**9,
                                                 confidence=1 - 1e-15)
""",
    "fundamental_batch": """
pairs = [RNG.uniform(0, 640, (3000, 4)) for _ in range(8)]
call = lambda: affcorr.estimate_fundamental_batch(pairs, max_iterations=10**9,
                                                  confidence=1 - 1e-15)
""",
    "match_pairs": """
from affcorr.data import data_dir
g = data_dir() / "graffiti"
pipe = affcorr.Pipeline("xfeat", threads=2, max_keypoints=512)
pairs = [(g / "graf1.png", g / "graf3.png")] * 200
call = lambda: pipe.match_pairs(pairs)
""",
}

INTERRUPT = """
import sys, time
import numpy as np
import affcorr
RNG = np.random.default_rng(0)
{setup}
print("start", flush=True)
t0 = time.perf_counter()
try:
    call()
except KeyboardInterrupt:
    print("interrupted", time.perf_counter() - t0, flush=True)
else:
    print("finished", time.perf_counter() - t0, flush=True)
"""


def interrupt_latency(name: str) -> float:
    """Seconds from SIGINT to the child's KeyboardInterrupt handler (the child prints them)."""
    p = subprocess.Popen(
        [sys.executable, "-c", INTERRUPT.format(setup=textwrap.dedent(LONG[name]))],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "RAYON_NUM_THREADS": "2"},
    )
    try:
        assert p.stdout.readline().strip() == "start"
        time.sleep(1.5)  # well inside the call
        sent = time.perf_counter()
        p.send_signal(signal.SIGINT)
        out, err = p.communicate(timeout=60)
        latency = time.perf_counter() - sent
    finally:
        p.kill()
    assert out.startswith("interrupted"), out + err
    assert "ValueError" not in err, err
    return latency


@pytest.mark.parametrize("name", list(LONG))
def test_ctrl_c_stops_long_calls_with_keyboard_interrupt(name):
    # Generous: the child must also exit (the measured latency is ~0.02-0.2 s; see the docs).
    assert interrupt_latency(name) < 10


def test_a_keyboard_interrupt_in_an_arguments_array_method_is_not_rewrapped():
    import affcorr
    import numpy as np

    class Interrupting:
        def __array__(self, *args, **kwargs):
            raise KeyboardInterrupt

    x = np.random.default_rng(0).uniform(0, 640, (50, 8))
    calls = [
        lambda: affcorr.estimate_homography(Interrupting()),
        lambda: affcorr.estimate_homography_batch([x, Interrupting()]),
        lambda: affcorr.estimate_homography(x, quality=Interrupting(), sampler="prosac"),
        lambda: affcorr.sampson_point(Interrupting(), x),
        lambda: affcorr.decompose_affine(Interrupting()),
    ]
    for call in calls:
        with pytest.raises(KeyboardInterrupt):
            call()
