"""Runtime docstrings for the functions of the Rust extension.

The text of each ``affcorr._native`` function lives once, in ``_native.pyi`` (the typed stub that
editors and type checkers read; ``scripts/lint.sh`` checks its signatures against the runtime
with mypy's stubtest). A builtin function's ``__doc__`` cannot be assigned, so each public
native function is exposed through a thin wrapper that carries the stub's docstring and the
native signature (``help()``, ``inspect.signature``, pdoc and IDEs show both), and calls the
native function unchanged: same arguments, results and errors.
"""

from __future__ import annotations

import ast
import functools
import inspect
from pathlib import Path
from typing import Any, Callable

from . import _native

_STUB = Path(__file__).with_name("_native.pyi")


@functools.lru_cache(maxsize=1)
def stub_docstrings() -> dict[str, str]:
    """``{name: docstring}`` of the top-level functions of ``_native.pyi``."""
    try:
        tree = ast.parse(_STUB.read_text(encoding="utf-8"))
    except OSError:  # a build without the stub: wrappers keep no text rather than fail
        return {}
    docs = {}
    for node in tree.body:
        if isinstance(node, ast.FunctionDef):
            doc = ast.get_docstring(node)
            if doc:
                docs[node.name] = doc
    return docs


_wrappers: dict[str, Callable[..., Any]] = {}


def documented(name: str) -> Callable[..., Any]:
    """The public wrapper of ``_native.<name>`` (one object per name, shared by every module)."""
    if name in _wrappers:
        return _wrappers[name]
    native = getattr(_native, name)

    @functools.wraps(native)
    def wrapper(*args, **kwargs):
        return native(*args, **kwargs)

    wrapper.__doc__ = stub_docstrings().get(name, native.__doc__)
    wrapper.__module__ = "affcorr"
    wrapper.__signature__ = inspect.signature(native)  # type: ignore[attr-defined]
    # No __wrapped__: documentation tools that unwrap (pdoc) would read the native's empty text.
    del wrapper.__wrapped__
    _wrappers[name] = wrapper
    return wrapper


def document(namespace: dict[str, Any], names: list[str]) -> None:
    """Replaces each native builtin of ``names`` in ``namespace`` by its documented wrapper."""
    for name in names:
        obj = namespace.get(name)
        if inspect.isbuiltin(obj) and getattr(_native, name, None) is obj:
            namespace[name] = documented(name)
