"""The `affcorr` command line on the bundled graffiti pair (ground truth H1to3p)."""

from __future__ import annotations

import numpy as np
import pytest
from affcorr import cli
from affcorr.data import data_dir
from affcorr.metrics import corner_error


@pytest.fixture(scope="module")
def graf():
    d = data_dir() / "graffiti"
    return str(d / "graf1.png"), str(d / "graf3.png"), str(d / "H1to3p.xml")


def test_read_matrix_forms(tmp_path):
    K = cli.read_matrix("800,780,320,240", "--K1")
    np.testing.assert_allclose(K, [[800, 0, 320], [0, 780, 240], [0, 0, 1]])
    np.testing.assert_allclose(cli.read_matrix(",".join(["1"] * 9), "--K1"), np.ones((3, 3)))
    np.savetxt(tmp_path / "k.txt", np.eye(3))
    np.testing.assert_allclose(cli.read_matrix(str(tmp_path / "k.txt"), "--K1"), np.eye(3))
    with pytest.raises(ValueError, match="--K1: expected 4"):
        cli.read_matrix("1,2,3", "--K1")
    with pytest.raises(ValueError, match="--K2: neither a file"):
        cli.read_matrix("fx=3", "--K2")


def test_corner_error_is_zero_for_the_same_h():
    H = np.array([[1.1, 0.1, 3], [0.0, 0.9, -2], [1e-4, 0, 1]])
    assert corner_error(H, H, 640, 480) == 0.0
    assert corner_error(np.eye(3), H, 640, 480) > 1.0
    assert corner_error(np.full((3, 3), np.nan), H, 640, 480) == np.inf


def test_match_show_and_homography(graf, tmp_path, capsys):
    a, b, h = graf
    out = tmp_path / "acs.npz"
    assert cli.main(["match", a, b, "-o", str(out), "--matcher", "xfeat"]) == 0
    data = np.load(out)
    assert data["corrs"].shape[1] == 8 and len(data["corrs"]) > 300
    png = tmp_path / "m.png"
    assert cli.main(["show", str(out), "-o", str(png), "--gt", h]) == 0
    assert png.stat().st_size > 10_000
    capsys.readouterr()
    assert cli.main(["homography", a, b, "--matcher", "xfeat", "--gt", h]) == 0
    text = capsys.readouterr().out
    err = float(text.split("mean corner error vs ground truth:")[1].split("px")[0])
    assert err < 3.0  # measured 1.0-1.6 px; documented bound


def test_match_with_refinement(graf, tmp_path):
    """The default (--refine-affine) gives refine_affine's ACs of the --no-refine-affine match."""
    import affcorr

    a, b, _ = graf
    plain, refined = tmp_path / "plain.npz", tmp_path / "refined.npz"
    # Views off: the view cascade verifies with the ACs' A, and grows a weakly verified pass,
    # so its matches depend on the refinement; the plain pass's do not.
    common = ["--matcher", "xfeat", "--max-keypoints", "512", "--threads", "2", "--views", "off"]
    assert cli.main(["match", a, b, "-o", str(plain), *common, "--no-refine-affine"]) == 0
    assert cli.main(["match", a, b, "-o", str(refined), *common]) == 0
    expected = affcorr.refine_affine(a, b, np.load(plain)["corrs"]).corrs
    np.testing.assert_allclose(np.load(refined)["corrs"], expected, rtol=0, atol=1e-9)


def test_bad_inputs_exit_2_with_a_message(graf, tmp_path, capsys):
    a, b, _ = graf
    assert cli.main(["pose", a, b, "--K1", "1,2", "--K2", "1,2,3,4"]) == 2
    assert "--K1" in capsys.readouterr().err
    assert cli.main(["match", a, str(tmp_path / "missing.png"), "-o", "x.npz"]) == 2
    np.savez(tmp_path / "bad.npz", corrs=np.zeros((3, 8)))
    assert cli.main(["show", str(tmp_path / "bad.npz")]) == 2
    assert "missing arrays" in capsys.readouterr().err
    out = str(tmp_path / "x.npz")
    args = ["match", a, b, "-o", out, "--matcher", "xfeat-star", "--detection-threshold", "0.1"]
    assert cli.main(args) == 2
    assert "detection_threshold: the xfeat-star matcher" in capsys.readouterr().err


def test_the_detection_threshold_reaches_the_matcher(graf, tmp_path):
    a, b, _ = graf
    common = ["--matcher", "xfeat", "--max-keypoints", "512", "--threads", "2", "--views", "off"]
    counts = []
    for extra in ([], ["--detection-threshold", "0.5"]):
        out = tmp_path / f"acs{len(extra)}.npz"
        assert cli.main(["match", a, b, "-o", str(out), *common, *extra]) == 0
        counts.append(len(np.load(out)["corrs"]))
    assert 0 < counts[1] < counts[0], counts


def test_match_with_a_dense_model(graf, tmp_path):
    pytest.importorskip("onnx")
    from affcorr.data import graffiti
    from affcorr.export.dense_test_model import dense_homography_model

    a, b, _ = graf
    truth = graffiti()[2]
    model = dense_homography_model(tmp_path / "gt.onnx", truth, (800, 640), (800, 640))
    out = tmp_path / "acs.npz"
    # --no-refine-affine: the test checks the dense matcher's own points.
    args = ["match", a, b, "-o", str(out), "--dense-model", str(model), "--no-refine-affine"]
    assert cli.main(args) == 0
    corrs = np.load(out)["corrs"]
    assert len(corrs) > 100
    # the test model's warp is the ground truth: every match lies on H (measured 1e-4 px)
    x = np.c_[corrs[:, :2], np.ones(len(corrs))] @ truth.T
    assert np.abs(x[:, :2] / x[:, 2:] - corrs[:, 2:4]).max() < 0.5


def test_dense_model_with_another_matcher_exits_2(graf, tmp_path, capsys):
    a, b, _ = graf
    code = cli.main(
        ["match", a, b, "-o", str(tmp_path / "x.npz"), "--matcher", "xfeat", "--dense-model", "m"]
    )
    assert code == 2 and "dense_model" in capsys.readouterr().err
