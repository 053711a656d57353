"""RSS growth over many calls of each main API (docs/reliability.md, "Memory and concurrency").

Runs the child of tests/test_memory_concurrency.py (one fresh process; each API warmed up,
then called CALLS times; the growth of the resident set is reported) with the full counts,
ShapeEstimator.estimate included, which the CI test runs fewer times to stay fast.

    .venv/bin/python -m affcorr_bench.reliability.leak_check [--calls 10000] [--warmup 1000]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import subprocess
import sys

from .. import common


def leak_child() -> str:
    """The child process's code, from the test that runs it with small counts."""
    path = common.ROOT / "tests" / "test_memory_concurrency.py"
    spec = importlib.util.spec_from_file_location("test_memory_concurrency", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.LEAK_CHILD


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--calls", type=int, default=10_000)
    ap.add_argument("--warmup", type=int, default=1_000)
    args = ap.parse_args(argv)
    n = str(args.calls)
    proc = subprocess.run(
        [sys.executable, "-c", leak_child(), n, n, str(args.warmup)],
        capture_output=True,
        text=True,
        check=True,
    )
    growth = json.loads(proc.stdout)
    print("| API | calls | RSS growth after warm-up (MiB) | bytes per call |")
    print("| --- | ---: | ---: | ---: |")
    for name, mib in growth.items():
        print(f"| {name} | {args.calls} | {mib:.2f} | {mib * 2**20 / args.calls:.0f} |")


if __name__ == "__main__":
    main()
