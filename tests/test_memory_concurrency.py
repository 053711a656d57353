"""Memory and concurrency (docs/reliability.md, "Memory and concurrency").

- No leaks: 10^4 calls of each main API (2 x 10^3 of ShapeEstimator.estimate, whose ONNX
  Runtime run costs ~1 ms; python -m affcorr_bench.reliability.leak_check runs 10^4 of it) in a
  fresh
  subprocess, after a warm-up, grow its resident set by less than LEAK_BOUND_MIB: a leak of
  ~200 bytes per call would show, and the smallest result, a 3x3 matrix with its info dict,
  is larger.
- Concurrent calls from 4 Python threads give exactly the single-threaded results, with one
  ShapeEstimator shared by all threads.
- The GIL is released during long Rust calls: a pure-Python loop makes progress while one runs.
"""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor

import affcorr
import numpy as np
import pytest

CALLS = 10_000
SHAPE_CALLS = 2_000
LEAK_BOUND_MIB = 2.0

# Small inputs and few iterations: a leak of the bindings (arrays, dicts, errors) costs the same
# per call whatever the work, and 10^4 calls must stay within seconds. The ValueError path is
# included: errors built and dropped per call must not leak either.
LEAK_CHILD = r"""
import json, sys
import numpy as np
import affcorr

def rss_mib():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096 / 2**20

calls, shape_calls, warmup = (int(a) for a in sys.argv[1:4])
rng = np.random.default_rng(0)
H = np.array([[1.1, 0.05, 12.0], [-0.02, 0.95, -7.0], [2e-4, -1e-4, 1.0]])
c = affcorr.correspondences_from_homography(H, rng.uniform(0, 640, (16, 2)))
c[12:, 2:4] += 40.0
K = np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]])
F = np.array([[1e-6, -2e-5, 3e-3], [2.2e-5, 1e-7, -4e-3], [-3e-3, 4.1e-3, 1.0]])
fast = dict(threshold=2.0, max_iterations=5, local_optimization=False, final_refinement=False)
est = affcorr.ShapeEstimator(threads=1)
img = rng.random((64, 64))

def bad_input():
    try:
        affcorr.estimate_homography(c[:1], threshold=2.0)
    except ValueError:
        pass
    else:
        raise AssertionError("expected ValueError")

apis = {
    "estimate_homography": lambda: affcorr.estimate_homography(c, **fast),
    "estimate_fundamental": lambda: affcorr.estimate_fundamental(c, **fast),
    "estimate_relative_pose": lambda: affcorr.estimate_relative_pose(c, K, K, **fast),
    "sampson_point": lambda: affcorr.sampson_point(F, c),
    "sampson_affine": lambda: affcorr.sampson_affine(F, c),
    "ShapeEstimator.estimate": lambda: est.estimate(img, img, [[30.0, 30.0]], [[31.0, 29.0]]),
    "ValueError": bad_input,
}
growth = {}
for name, f in apis.items():
    for _ in range(warmup):
        f()
    before = rss_mib()
    for _ in range(shape_calls if name.startswith("ShapeEstimator") else calls):
        f()
    growth[name] = rss_mib() - before
print(json.dumps(growth))
"""


def test_ten_thousand_calls_do_not_leak():
    proc = subprocess.run(
        [sys.executable, "-c", LEAK_CHILD, str(CALLS), str(SHAPE_CALLS), "300"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    growth = json.loads(proc.stdout)
    assert len(growth) == 7
    leaking = {k: round(v, 2) for k, v in growth.items() if v >= LEAK_BOUND_MIB}
    assert not leaking, f"RSS growth (MiB) over {CALLS} calls each: {leaking}"


# --- concurrency ---------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def workload():
    """Tasks of every kind, their single-threaded results, and the shared ShapeEstimator."""
    rng = np.random.default_rng(3)
    H = np.array([[0.9, 0.1, 20.0], [-0.05, 1.05, -10.0], [1e-4, 2e-4, 1.0]])
    c = affcorr.correspondences_from_homography(H, rng.uniform(0, 640, (400, 2)))
    c[:, 2:4] += rng.normal(0, 0.5, (400, 2))
    c[300:, 2:4] = rng.uniform(0, 640, (100, 2))
    K = np.array([[700.0, 0, 320], [0, 720, 240], [0, 0, 1]])
    F = np.array([[1e-6, -2e-5, 3e-3], [2.2e-5, 1e-7, -4e-3], [-3e-3, 4.1e-3, 1.0]])
    est = affcorr.ShapeEstimator(threads=1)
    img = np.random.default_rng(4).random((160, 200))
    x1 = rng.uniform(20, 140, (60, 2))
    tasks = {
        "H": lambda s: affcorr.estimate_homography(c, threshold=2.0, seed=s),
        "F": lambda s: affcorr.estimate_fundamental(c, threshold=2.0, seed=s),
        "pose": lambda s: affcorr.estimate_relative_pose(c, K, K, threshold=2.0, seed=s),
        "sampson": lambda s: affcorr.sampson_affine(F, c * (1 + s * 1e-3)),
        "shape": lambda s: est.estimate(img, img, x1 + s, x1 + 2 * s),
    }
    seeds = range(3)
    reference = {(k, s): flatten(f(s)) for k, f in tasks.items() for s in seeds}
    return tasks, seeds, reference


def flatten(result) -> bytes:
    """The bytes of every array and number in a result, for exact comparison."""
    if isinstance(result, np.ndarray):
        return result.tobytes()
    if isinstance(result, tuple | list):
        return b"".join(flatten(r) for r in result)
    if hasattr(result, "__dict__"):  # RelativePose, RansacInfo
        return b"".join(flatten(v) for v in vars(result).values())
    return np.asarray(result).tobytes()


def test_four_threads_at_once_give_the_single_threaded_results(workload):
    tasks, seeds, reference = workload
    jobs = [(k, s) for _ in range(2) for k in tasks for s in seeds]
    np.random.default_rng(0).shuffle(jobs)
    barrier = threading.Barrier(4)

    def run(i):
        if i < 4:
            barrier.wait()  # the first four calls start together
        k, s = jobs[i]
        return jobs[i], flatten(tasks[k](s))

    with ThreadPoolExecutor(max_workers=4) as pool:
        results = list(pool.map(run, range(len(jobs))))
    assert len(results) == len(jobs)
    for (k, s), got in results:
        assert got == reference[(k, s)], f"{k} (seed {s}) differs when run concurrently"


def progress_during(call) -> int:
    """How many iterations a pure-Python loop in this thread makes while `call` runs in another
    thread and is inside Rust.

    Timing-free: the switch interval is raised so that the calling thread, once it holds the
    GIL, cannot be preempted between setting its flag and entering Rust (nor between leaving
    Rust and clearing it). This thread can then count only if the Rust call lets go of the GIL;
    its time.sleep(0) hands the GIL back so the call can finish."""
    state = {"in_rust": False, "count": 0}

    def worker():
        state["in_rust"] = True
        call()
        state["in_rust"] = False

    old = sys.getswitchinterval()
    sys.setswitchinterval(30.0)
    try:
        t = threading.Thread(target=worker)
        t.start()
        while t.is_alive():
            if state["in_rust"]:
                state["count"] += 1
            time.sleep(0)
        t.join()
    finally:
        sys.setswitchinterval(old)
    return state["count"]


@pytest.mark.parametrize("api", ["estimate_homography", "estimate_relative_pose", "shape"])
def test_the_gil_is_released_during_long_calls(api):
    rng = np.random.default_rng(8)
    H = np.array([[0.9, 0.1, 20.0], [-0.05, 1.05, -10.0], [1e-4, 2e-4, 1.0]])
    c = affcorr.correspondences_from_homography(H, rng.uniform(0, 640, (500, 2)))
    c[200:, 2:4] = rng.uniform(0, 640, (300, 2))
    K = np.array([[700.0, 0, 320], [0, 720, 240], [0, 0, 1]])
    long = dict(threshold=2.0, min_iterations=20000, max_iterations=20000)
    if api == "estimate_homography":
        call = lambda: affcorr.estimate_homography(c[:, :4], **long)  # noqa: E731
    elif api == "estimate_relative_pose":
        call = lambda: affcorr.estimate_relative_pose(c, K, K, **long)  # noqa: E731
    else:
        est = affcorr.ShapeEstimator(threads=1)
        img = rng.random((300, 300))
        x = rng.uniform(20, 280, (3000, 2))
        call = lambda: est.estimate(img, img, x, x)  # noqa: E731
    # On a loaded machine this thread may get no CPU slice during one call; a call that held
    # the GIL would give 0 every time, so a few attempts do not weaken the test.
    assert any(progress_during(call) > 0 for _ in range(3))
