"""One pipeline, three entry points: with every default, the Rust API (the
``pipeline_homography`` example of affcorr-pipeline), the Python API (``affcorr.Pipeline``) and
the CLI (``affcorr homography -o``) give the same ACs and the same homography on the bundled
graffiti pair, and the Python and CLI defaults are the Rust crate's."""

from __future__ import annotations

import inspect
import json
import os
import subprocess
from pathlib import Path

import affcorr
import numpy as np
import pytest
from affcorr import cli
from affcorr.data import data_dir
from affcorr.pipeline import MATCHERS, PIPELINE_DEFAULTS, bundled_models_dir
from affcorr.shape import find_ort_library

ROOT = Path(__file__).resolve().parents[1]
GRAF = data_dir() / "graffiti"
A, B = GRAF / "graf1.png", GRAF / "graf3.png"


def _rust_example() -> Path:
    """The example's binary, built (or found up to date) by cargo: a stale binary would compare
    old defaults with new ones."""
    subprocess.run(
        ["cargo", "build", "--offline", "-q", "-p", "affcorr-pipeline", "--example",
         "pipeline_homography"],
        cwd=ROOT,
        check=True,
    )  # fmt: skip
    return ROOT / "target" / "debug" / "examples" / "pipeline_homography"


@pytest.fixture(scope="module")
def python_result():
    H, info, res = affcorr.Pipeline().homography(A, B, return_matches=True)
    return H, info, res


def test_rust_python_and_cli_agree_with_every_default(python_result, tmp_path):
    H, info, res = python_result
    assert len(res.corrs) > 200 and info.num_inliers > 150

    env = dict(os.environ)
    if not env.get("ORT_DYLIB_PATH"):  # else find_ort_library defers to it (None)
        env["ORT_DYLIB_PATH"] = str(find_ort_library())
    out = subprocess.run(
        [str(_rust_example()), str(bundled_models_dir()), str(A), str(B)],
        env=env,
        capture_output=True,
        text=True,
    )
    assert out.returncode == 0, out.stderr
    rust = json.loads(out.stdout)
    assert rust["matcher"] == PIPELINE_DEFAULTS["matcher"]
    np.testing.assert_array_equal(np.array(rust["corrs"]), res.corrs)
    np.testing.assert_array_equal(np.array(rust["H"]).reshape(3, 3), H)
    assert rust["num_inliers"] == info.num_inliers

    path = tmp_path / "h.json"
    assert cli.main(["homography", str(A), str(B), "-o", str(path)]) == 0
    saved = json.loads(path.read_text())
    np.testing.assert_array_equal(np.array(saved["H"]), H)
    assert saved["num_inliers"] == info.num_inliers
    assert saved["num_acs"] == len(res.corrs)
    assert saved["inliers"] == np.flatnonzero(info.inliers).tolist()
    assert saved["threshold"] == PIPELINE_DEFAULTS["homography_threshold"]


def test_estimation_runs_in_rust_on_the_matches_it_returns(python_result):
    """Pipeline.homography is match_pair + estimate_homography on the same ACs, with the
    pipeline's threshold; its timings include the estimation."""
    H, info, res = python_result
    H2, info2 = affcorr.estimate_homography(
        res.corrs, threshold=PIPELINE_DEFAULTS["homography_threshold"]
    )
    np.testing.assert_array_equal(H2, H)
    np.testing.assert_array_equal(info2.inliers, info.inliers)
    assert res.timings["ransac"] > 0 and res.timings["total"] >= res.timings["ransac"]


def test_python_and_cli_defaults_are_the_rust_crates():
    d = PIPELINE_DEFAULTS
    assert set(d) == {
        "matcher",
        "max_keypoints",
        "aliked_detection_threshold",
        "dense_matches",
        "refine_affine",
        "exif_orientation",
        "views",
        "view_relative_budget",
        "guided_matching",
        "seed",
        "homography_threshold",
        "fundamental_threshold",
        "pose_threshold",
    }
    assert MATCHERS[0] == d["matcher"] and set(MATCHERS) == set(affcorr._native.PIPELINE_MATCHERS)
    init = inspect.signature(affcorr.Pipeline.__init__).parameters
    assert init["max_keypoints"].default == d["max_keypoints"]
    assert init["refine_affine"].default == d["refine_affine"]
    assert init["exif_orientation"].default == d["exif_orientation"]
    assert init["seed"].default == d["seed"]
    assert init["views"].default == d["views"]
    assert init["view_relative_budget"].default == d["view_relative_budget"]
    assert init["guided_matching"].default == d["guided_matching"]
    # None: the matcher's default, ALIKED's from the crate
    assert init["detection_threshold"].default is None
    for method, key in [
        (affcorr.Pipeline.homography, "homography_threshold"),
        (affcorr.Pipeline.fundamental, "fundamental_threshold"),
        (affcorr.Pipeline.relative_pose, "pose_threshold"),
    ]:
        assert inspect.signature(method).parameters["threshold"].default == d[key]
    p = cli.build_parser()
    args = p.parse_args(["homography", "a.png", "b.png"])
    assert args.threshold == d["homography_threshold"]
    assert args.max_keypoints == d["max_keypoints"] and args.refine_affine == d["refine_affine"]
    assert args.exif_orientation == d["exif_orientation"]
    args = p.parse_args(["pose", "a.png", "b.png", "--K1", "1,1,0,0", "--K2", "1,1,0,0"])
    assert args.threshold == d["pose_threshold"]
    pipe = affcorr.Pipeline(threads=1)
    assert pipe.matcher == d["matcher"] and pipe.max_keypoints == d["max_keypoints"]


def test_fundamental_through_the_pipeline(python_result):
    """F of the planar graffiti pair is not unique, but every inlier satisfies it: the
    fundamental entry point runs and returns (F, info) on the pipeline's ACs."""
    F, info, res = affcorr.Pipeline().fundamental(A, B, return_matches=True)
    assert F.shape == (3, 3) and abs(np.linalg.norm(F) - 1) < 1e-9
    c = res.corrs[info.inliers]
    p1, p2 = np.c_[c[:, :2], np.ones(len(c))], np.c_[c[:, 2:4], np.ones(len(c))]
    lines = p1 @ F.T
    dist = np.abs(np.sum(p2 * lines, axis=1)) / np.linalg.norm(lines[:, :2], axis=1)
    assert info.num_inliers > 150 and np.median(dist) < 1.0


def test_cli_output_must_be_json_or_npz(tmp_path, capsys):
    assert cli.main(["homography", str(A), str(B), "-o", str(tmp_path / "h.txt")]) == 2
    assert ".json or .npz" in capsys.readouterr().err
