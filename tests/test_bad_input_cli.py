"""Bad-input battery of the command line: every subcommand given bad arguments exits
with status 2 and one line ``affcorr <command>: <problem>`` on stderr, never a traceback.

Runs ``cli.main`` in-process (an uncaught exception would fail the test, so "no traceback" is
checked) and, once per kind of failure, the real ``python -m affcorr.cli`` in a subprocess.
argparse's own errors (an unknown option, ``--threads abc``) exit 2 with its usage line.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from affcorr import cli
from affcorr.data import data_dir

G = data_dir() / "graffiti"
A, B = str(G / "graf1.png"), str(G / "graf3.png")
FAST = ["--matcher", "xfeat", "--max-keypoints", "128", "--threads", "1"]


@pytest.fixture
def files(tmp_path):
    (tmp_path / "garbage.npz").write_bytes(b"garbage")
    (tmp_path / "dir.npz").mkdir()
    np.save(tmp_path / "single.npy", np.zeros(3))
    np.savez(tmp_path / "no_image.npz", corrs=np.zeros((3, 8)))
    (tmp_path / "h22.txt").write_text("1 2\n3 4\n")
    (tmp_path / "h.xml").write_text("<opencv_storage>no matrix</opencv_storage>")
    (tmp_path / "words.txt").write_text("a b c\nd e f\ng h i\n")
    (tmp_path / "pairs.txt").write_text(f"{A}\n")
    (tmp_path / "missing_pairs.txt").write_text(f"{A} {tmp_path / 'nope.png'}\n")
    (tmp_path / "graffiti_pairs.txt").write_text("graf1.png graf3.png\n")
    return tmp_path


# (argv with {d} for the files directory, message fragment)
CASES = {
    "show: no such file": (["show", "{d}/missing.npz"], "missing.npz"),
    "show: not an npz": (["show", "{d}/garbage.npz"], "not an .npz file"),
    "show: a directory": (["show", "{d}/dir.npz"], "dir.npz"),
    "show: an npy": (["show", "{d}/single.npy"], "a single .npy array"),
    "show: missing arrays": (["show", "{d}/no_image.npz"], "missing arrays ['image_a', 'image_b']"),
    "show: bad --gt": (["show", "{d}/no_image.npz", "--gt", "{d}/h22.txt"], "--gt: expected a 3x3"),
    "match: missing image": (["match", A, "{d}/nope.png", "-o", "{d}/x.npz", *FAST], "nope.png"),
    "match: one image": (["match", A, "-o", "{d}/x.npz", *FAST], "give two images"),
    "match: not an image": (["match", A, "{d}/h22.txt", "-o", "{d}/x.npz", *FAST], "h22.txt"),
    "match: unwritable -o": (["match", A, B, "-o", "{d}/no/x.npz", *FAST], "-o: the directory"),
    "match: missing --pairs": (["match", "--pairs", "{d}/p.txt", "-o", "{d}/o"], "p.txt"),
    "match: bad --pairs line": (["match", "--pairs", "{d}/pairs.txt", "-o", "{d}/o"], "lines [1]"),
    "match: --pairs image": (
        ["match", "--pairs", "{d}/missing_pairs.txt", "-o", "{d}/o", *FAST],
        "nope.png",
    ),
    "match: --max-keypoints 0": (
        ["match", A, B, "-o", "{d}/x.npz", "--max-keypoints", "0"],
        "max_keypoints must be a positive int",
    ),
    "match: --threads 0": (["match", A, B, "-o", "{d}/x.npz", "--threads", "0"], "threads"),
    "batch: --view-relative-budget 0": (
        [
            "batch",
            "{d}/graffiti_pairs.txt",
            str(G),
            "-o",
            "{d}/out",
            "--matcher",
            "xfeat",
            "--view-relative-budget",
            "0",
        ],
        "view_relative_budget must be a positive number",
    ),
    "match: --max-side 5": (["match", A, B, "-o", "{d}/x.npz", "--max-side", "5"], "max_side"),
    "homography: missing --gt": (
        ["homography", A, B, "--gt", "{d}/nope.txt", *FAST],
        "--gt: neither a file",
    ),
    "homography: 2x2 --gt": (
        ["homography", A, B, "--gt", "{d}/h22.txt", *FAST],
        "--gt: expected a 3x3 matrix, got shape (2, 2)",
    ),
    "homography: bad xml --gt": (
        ["homography", A, B, "--gt", "{d}/h.xml", *FAST],
        "--gt: cannot read a 3x3 matrix",
    ),
    "homography: --threshold -1": (
        ["homography", A, B, "--threshold", "-1", *FAST],
        "threshold = -1 is invalid",
    ),
    "pose: words --K1": (["pose", A, B, "--K1", "a,b,c,d", "--K2", "1,1,1,1"], "--K1: neither"),
    "pose: 3 numbers": (["pose", A, B, "--K1", "1,2,3", "--K2", "1,1,1,1"], "--K1: expected 4"),
    "pose: NaN --K2": (
        ["pose", A, B, "--K1", "500,500,1,1", "--K2", "nan,1,1,1"],
        "--K2: the matrix contains NaN",
    ),
    "pose: file of words": (
        ["pose", A, B, "--K1", "{d}/words.txt", "--K2", "1,1,1,1"],
        "--K1: cannot read a 3x3 matrix",
    ),
    "pose: zero focal": (
        ["pose", A, B, "--K1", "0,0,320,240", "--K2", "500,500,1,1", *FAST],
        "K1 is not a valid intrinsic matrix",
    ),
    "demo: unwritable -o": (["demo", "--geometry", "-o", "{d}/no/demo.png"], "-o: the directory"),
    "show: unwritable -o": (
        ["show", "{d}/no_image.npz", "-o", "{d}/no/m.png"],
        "-o: the directory",
    ),
}


def argv(case: str, d) -> list[str]:
    return [a.replace("{d}", str(d)) for a in CASES[case][0]]


@pytest.mark.parametrize("case", list(CASES))
def test_bad_arguments_exit_2_with_one_line_naming_the_problem(files, capsys, case):
    assert cli.main(argv(case, files)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    command = CASES[case][0][0]
    last = err[-1]
    assert last.startswith(f"affcorr {command}: ") and CASES[case][1] in last, err
    assert not any("Traceback" in line for line in err)


@pytest.mark.parametrize("case", ["show: not an npz", "match: missing image", "pose: words --K1"])
def test_the_installed_command_exits_2_without_a_traceback(files, case):
    out = subprocess.run(
        [sys.executable, "-m", "affcorr.cli", *argv(case, files)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 2, out.stderr
    lines = out.stderr.strip().splitlines()
    assert "Traceback" not in out.stderr and CASES[case][1] in lines[-1], out.stderr


@pytest.mark.parametrize(
    "args", [["match", A, B, "-o", "x.npz", "--threads", "abc"], ["pose", A, B], ["frobnicate"]]
)
def test_argparse_errors_exit_2_with_usage(capsys, args):
    with pytest.raises(SystemExit) as info:
        cli.main(args)
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert "usage: affcorr" in err and "error:" in err and "Traceback" not in err


@pytest.mark.parametrize(
    "command", [["match", A, B, "-o", "x.npz"], ["batch", "p.txt", "i", "-o", "o"]]
)
def test_a_view_budget_that_is_not_a_number_is_named(capsys, command):
    with pytest.raises(SystemExit) as info:
        cli.main([*command, "--view-relative-budget", "abc"])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert "--view-relative-budget: 'abc' is not a number of plain passes or 'none'" in err, err
