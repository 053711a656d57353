"""The `affcorr` command line."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="affcorr", description="Affine correspondences.")
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="geometry demo on graffiti 1→3 with its ground-truth H")
    demo.add_argument(
        "-o", "--out", type=Path, default=Path("affcorr_demo.png"), help="picture to write"
    )
    demo.add_argument("--step", type=int, default=40, help="grid step in pixels")
    args = parser.parse_args(argv)

    if args.command == "demo":
        from affcorr import demo as demo_module

        try:
            demo_module.run(out=args.out, step=args.step)
        except FileNotFoundError as e:
            print(f"affcorr demo: {e}", file=sys.stderr)
            return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
