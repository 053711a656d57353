"""The CLI as a newcomer uses it (issue 24, issue 23's CLI items): --version, -v/-q, models
printed at full precision and saved by -o, -o meaning exactly the path given and checked before
any work, --pairs that goes on past bad lines and failing pairs, show --inliers, and the
commands that need an optional extra saying so in one line."""

from __future__ import annotations

import ast
import json
import subprocess
import sys

import affcorr
import numpy as np
import pytest
from affcorr import cli
from affcorr.data import data_dir
from affcorr.metrics import corner_error

G = data_dir() / "graffiti"
A, B, GT = str(G / "graf1.png"), str(G / "graf3.png"), str(G / "H1to3p.xml")
FAST = ["--matcher", "xfeat", "--max-keypoints", "256", "--threads", "2"]

# Runs a command with some modules made unimportable, as in an environment without them.
BLOCK = """
import sys
class _Block:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in {blocked!r}:
            raise ModuleNotFoundError(f"No module named {{name!r}}")
sys.meta_path.insert(0, _Block())
from affcorr.cli import main
raise SystemExit(main(sys.argv[1:]))
"""


def run_without(blocked: set[str], args: list[str], cwd) -> subprocess.CompletedProcess:
    code = BLOCK.format(blocked=sorted(blocked))
    return subprocess.run(
        [sys.executable, "-c", code, *args], cwd=cwd, capture_output=True, text=True, timeout=300
    )


def printed(text: str, name: str) -> np.ndarray:
    """The matrix that `name = [[...], ...]` (possibly over several lines) prints."""
    start = text.index(f"{name} = ") + len(name) + 3
    depth = 0
    for end, ch in enumerate(text[start:], start):
        depth += {"[": 1, "]": -1}.get(ch, 0)
        if depth == 0:
            return np.array(ast.literal_eval(text[start : end + 1]))
    raise AssertionError(f"{name} is not printed whole")


def test_version(capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(["--version"])
    assert e.value.code == 0
    assert capsys.readouterr().out.strip() == f"affcorr {affcorr.__version__}"


def test_format_matrix_round_trips_every_digit():
    m = np.array([[0.1 + 1e-17, 1 / 3, -2e-9], [np.pi, 1e12, 7.0], [3.5e-4, -1.4e-5, 1.0]])
    text = cli.format_matrix("H", m)
    assert text.startswith("H = [[")
    np.testing.assert_array_equal(printed(text, "H"), m)


@pytest.fixture(scope="module")
def homography_run(tmp_path_factory):
    """`affcorr homography -o h.json` and `-o h.npz` on graffiti, with what they printed."""
    d = tmp_path_factory.mktemp("h")
    out = {}
    for name in ("h.json", "h.npz"):
        p = subprocess.run(
            [sys.executable, "-m", "affcorr.cli", "homography", A, B, "--gt", GT, "-o",
             str(d / name), *FAST],
            capture_output=True, text=True, timeout=300, check=True,
        )  # fmt: skip
        out[name] = p
    return d, out


def test_homography_prints_the_model_it_saves(homography_run):
    d, out = homography_run
    text = out["h.json"].stdout
    H = printed(text, "H")
    saved = json.loads((d / "h.json").read_text())
    np.testing.assert_array_equal(H, np.array(saved["H"]))
    # copied as printed, H is the model: the same corner error as the saved one
    h, w = affcorr.read_gray_image(A).shape
    H_gt = cli.read_matrix(GT, "--gt")
    assert corner_error(H, H_gt, w, h) == corner_error(np.array(saved["H"]), H_gt, w, h)
    assert corner_error(H, H_gt, w, h) < 3.0
    for key in ("num_inliers", "num_iterations", "score", "lo_runs", "refinements", "inliers"):
        assert key in saved
    assert saved["num_inliers"] == len(saved["inliers"])
    npz = np.load(d / "h.npz")
    assert npz["inliers"].dtype == bool and npz["corrs"].shape == (int(npz["num_acs"]), 8)
    assert int(npz["inliers"].sum()) == int(npz["num_inliers"])


def test_pose_prints_r_and_t_at_full_precision(tmp_path, capsys):
    K = "800,800,400,320"
    out = tmp_path / "pose.json"
    assert cli.main(["pose", A, B, "--K1", K, "--K2", K, "-o", str(out), *FAST]) == 0
    text = capsys.readouterr().out
    saved = json.loads(out.read_text())
    for name in ("R", "t"):
        np.testing.assert_array_equal(printed(text, name), saved[name])
    assert {"E", "F", "inliers", "num_inliers"} <= set(saved)


def test_quiet_hides_timings_and_verbose_is_accepted_after_the_command(tmp_path, capsys):
    out = tmp_path / "acs.npz"
    assert cli.main(["match", A, B, "-o", str(out), *FAST]) == 0
    assert "timings" in capsys.readouterr().err
    assert cli.main(["-q", "match", A, B, "-o", str(out), *FAST]) == 0
    captured = capsys.readouterr()
    assert "timings" not in captured.err and "ACs ->" in captured.out
    assert cli.main(["match", A, B, "-o", str(out), "-v", *FAST]) == 0


def test_output_means_exactly_that_path(tmp_path, capsys):
    name = tmp_path / "acs"  # no .npz: written as given, not as acs.npz
    assert cli.main(["match", A, B, "-o", str(name), *FAST]) == 0
    assert name.is_file() and not (tmp_path / "acs.npz").exists()
    assert f"-> {name}" in capsys.readouterr().out
    assert np.load(name)["corrs"].shape[1] == 8
    png = tmp_path / "picture"  # no suffix: a PNG at exactly that path
    assert cli.main(["show", str(name), "-o", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and not (tmp_path / "picture.png").exists()


@pytest.mark.parametrize("command", ["match", "homography"])
def test_an_existing_directory_as_output_fails_before_any_work(tmp_path, capsys, command):
    d = tmp_path / "dir"
    d.mkdir()
    # a missing image would fail later: the output is checked first
    args = [command, A, str(tmp_path / "missing.png"), "-o", str(d)]
    assert cli.main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith(f"affcorr {command}: -o:") and "is a directory" in err[-1]


def test_pairs_go_on_past_bad_lines_and_failing_pairs(tmp_path, capsys):
    (tmp_path / "with space").mkdir()
    spaced = tmp_path / "with space" / "g3.png"
    spaced.write_bytes(open(B, "rb").read())
    pairs = tmp_path / "pairs.txt"
    pairs.write_text(
        "# graffiti, three ways\n"
        f"{A} {B}\n"
        "\n"
        f"{A}\n"  # line 4: one path
        f"{A} {tmp_path / 'nope.png'}   # line 5: no such image\n"
        f'{A} "{spaced}"\n'  # line 6: quoted path with a space
    )
    out = tmp_path / "out"
    assert cli.main(["match", "--pairs", str(pairs), "-o", str(out), *FAST]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("affcorr match: --pairs: 2 of 4 lines failed (lines [4, 5])")
    assert any("line 5" in e and "nope.png" in e for e in err)
    files = sorted(p.name for p in out.iterdir())
    assert files == ["graf1__g3.npz", "graf1__graf3.npz", "summary.json"]
    summary = json.loads((out / "summary.json").read_text())
    status = {e["line"]: e["status"] for e in summary["pairs"]}
    assert status == {2: "ok", 4: "bad line", 5: "failed", 6: "ok"}
    assert summary["ok"] == 2 and summary["failed"] == 2
    ok = next(e for e in summary["pairs"] if e["line"] == 2)
    data = np.load(out / ok["file"])
    assert str(data["image_a"]) == A and str(data["image_b"]) == B
    assert ok["num_acs"] == len(data["corrs"])


def test_pairs_with_only_good_lines_exit_0_and_same_names_get_line_numbers(tmp_path):
    pairs = tmp_path / "pairs.txt"
    pairs.write_text(f"{A} {B}\n{A} {B}\n")
    out = tmp_path / "out"
    assert cli.main(["match", "--pairs", str(pairs), "-o", str(out), *FAST]) == 0
    assert (out / "graf1__graf3.npz").is_file() and (out / "graf1__graf3__line2.npz").is_file()


def test_pairs_output_must_not_be_a_file(tmp_path, capsys):
    pairs = tmp_path / "pairs.txt"
    pairs.write_text(f"{A} {B}\n")
    (tmp_path / "f").write_text("")
    assert cli.main(["match", "--pairs", str(pairs), "-o", str(tmp_path / "f")]) == 2
    assert "not a directory" in capsys.readouterr().err


def test_show_inliers_of_the_saved_and_of_an_estimated_model(homography_run, tmp_path, capsys):
    d, _ = homography_run
    saved = np.load(d / "h.npz")
    png = tmp_path / "inliers.png"
    assert cli.main(["show", str(d / "h.npz"), "--inliers", "-o", str(png), "--gt", GT]) == 0
    text = capsys.readouterr().out
    assert f"inliers of the saved H (transfer error): {int(saved['num_inliers'])} / " in text
    assert png.stat().st_size > 10_000
    acs = tmp_path / "acs.npz"
    assert cli.main(["match", A, B, "-o", str(acs), *FAST]) == 0
    assert cli.main(["show", str(acs), "--inliers", "-o", str(png)]) == 0
    assert "inliers of H estimated at" in capsys.readouterr().out


def test_model_residuals_match_the_saved_inliers(homography_run):
    d, _ = homography_run
    data = np.load(d / "h.npz")
    what, r, inliers = cli.model_residuals(data, 3.0)
    np.testing.assert_array_equal(inliers, data["inliers"])
    assert np.median(r[inliers]) < float(data["threshold"])


def test_show_without_matplotlib_says_which_extra(tmp_path):
    p = run_without({"matplotlib"}, ["show", "whatever.npz"], cwd=tmp_path)
    assert p.returncode == 2, p.stderr
    assert p.stderr.strip().splitlines() == [
        "affcorr show: this command needs matplotlib: pip install 'affcorr[plot]'"
    ]


def test_demo_runs_outside_the_repository_without_pillow_or_matplotlib(tmp_path):
    p = run_without({"matplotlib", "PIL"}, ["demo", "--max-keypoints", "512"], cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert "homography mean corner error vs ground truth" in p.stdout
    assert "picture skipped: it needs matplotlib: pip install 'affcorr[plot]'" in p.stdout
    p = run_without({"matplotlib", "PIL"}, ["demo", "--geometry"], cwd=tmp_path)
    assert p.returncode == 0 and "picture skipped" in p.stdout, p.stderr
