"""Progress bars for long work: tqdm when installed and stderr is a terminal, else plain."""

from __future__ import annotations

import sys
from collections.abc import Iterable, Iterator
from typing import TypeVar

T = TypeVar("T")


def progress(items: Iterable[T], desc: str, unit: str = "it") -> Iterator[T]:
    """Iterate over ``items`` with a progress bar (tqdm) or, without tqdm, a line per 10%."""
    try:
        from tqdm import tqdm

        yield from tqdm(items, desc=desc, unit=unit, disable=None)
        return
    except ImportError:
        pass
    items = list(items)
    n = len(items)
    step = max(n // 10, 1)
    for i, x in enumerate(items):
        if i % step == 0:
            print(f"{desc}: {i}/{n} {unit}", file=sys.stderr, flush=True)
        yield x
    print(f"{desc}: {n}/{n} {unit}", file=sys.stderr, flush=True)
