"""affcorr batch on local processes (issue 25): the results equal the serial pipeline's, hloc's
HDF5 layout, a bad pair is recorded and never stops the batch, a resumed run skips exactly the
pairs written, a killed worker's pairs are retried, and the CLI.

The images are synthetic views of graffiti (mild homographies, 320x256), the matcher is XFeat
MNN at 256 keypoints: a pair takes ~0.1 s, the file ~30 s on 2 loaded cores.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import affcorr
import numpy as np
import pytest
from affcorr.data import data_dir

h5py = pytest.importorskip("h5py", reason="affcorr batch writes HDF5 through h5py")

from affcorr import batch  # noqa: E402

#: The pipeline options of every batch test (fast, deterministic).
OPTIONS: dict[str, Any] = dict(matcher="xfeat", max_keypoints=256, views="off")
N_IMAGES = 5


def make_images(folder: Path, n: int = N_IMAGES, size=(320, 256), seed: int = 0) -> list[str]:
    """``n`` views of graffiti 1 through mild random homographies (corners moved by up to
    8 %), resized to ``size``; PNG files ``view<i>.png``."""
    PIL = pytest.importorskip("PIL.Image", reason="the synthetic views are drawn with Pillow")
    folder.mkdir(parents=True, exist_ok=True)
    src = PIL.open(data_dir() / "graffiti" / "graf1.png").convert("L")
    rng = np.random.default_rng(seed)
    w, h = src.size
    names = []
    for i in range(n):
        quad = np.array([[0, 0], [0, h], [w, h], [w, 0]], float)
        quad += rng.uniform(-0.08, 0.08, size=(4, 2)) * [w, h]
        im = src.transform(src.size, PIL.Transform.QUAD, quad.ravel().tolist(), PIL.BILINEAR)
        im.resize(size, PIL.BILINEAR).save(folder / f"view{i}.png")
        names.append(f"view{i}.png")
    return names


def good_pairs(names: list[str]) -> list[tuple[str, str]]:
    return list(itertools.combinations(names, 2))


@pytest.fixture(scope="session")
def images(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[str]]:
    folder = tmp_path_factory.mktemp("batch_images")
    names = make_images(folder)
    (folder / "broken.png").write_text("not an image")
    return folder, names


@pytest.fixture(scope="session")
def serial(images: tuple[Path, list[str]]) -> dict[tuple[str, str], affcorr.MatchResult]:
    """The serial reference: Pipeline.match_pair on every good pair."""
    folder, names = images
    p = affcorr.Pipeline(threads=1, **OPTIONS)
    return {(a, b): p.match_pair(folder / a, folder / b) for a, b in good_pairs(names)}


def read_matches(output: Path) -> dict[tuple[str, str], dict[str, np.ndarray]]:
    out = {}
    with h5py.File(output / "matches.h5", "r") as fd:
        for a in fd:
            for b in fd[a]:
                g = fd[a][b]
                out[(a, b)] = {k: g[k][()] for k in g} | {"_attrs": dict(g.attrs)}
    return out


def assert_equals_serial(output: Path, serial: dict, pairs=None) -> None:
    got = read_matches(output)
    for key in pairs or serial:
        want = serial[key]
        g = got[key]
        np.testing.assert_array_equal(g["acs"], want.corrs, err_msg=str(key))
        np.testing.assert_array_equal(g["certainty"], want.certainty.astype(np.float32))
        assert tuple(g["num_keypoints"]) == want.num_keypoints
        if len(getattr(want, "reliable", ())) == len(want):
            np.testing.assert_array_equal(g["reliable"], want.reliable)


def test_local_batch_equals_serial_with_hloc_layout(images, serial, tmp_path) -> None:
    folder, names = images
    pairs = good_pairs(names)
    s = batch.run(
        pairs + [(b, a) for a, b in pairs[:3]],  # reversed repeats are matched once
        folder,
        tmp_path,
        workers=2,
        chunk_size=3,
        geometry=["homography", "fundamental", "relative_pose"],
        progress=False,
        **OPTIONS,
    )
    assert (s.pairs, s.matched, s.failed, s.skipped) == (len(pairs), len(pairs), 0, 0), s
    assert s.workers == 2 and s.pairs_per_second > 0
    assert_equals_serial(tmp_path, serial)

    # hloc's layout: features.h5 groups per image; matches.h5 names_to_pair groups with
    # matches0 int16 (-1: unmatched) and matching_scores0 float16 over image 0's keypoints.
    p = affcorr.Pipeline(threads=1, **OPTIONS)
    with h5py.File(tmp_path / "features.h5", "r") as fd:
        assert sorted(fd) == sorted(names)
        for n in names:
            g = fd[n]
            f = p.extract(folder / n)
            np.testing.assert_array_equal(g["keypoints"][()], f.keypoints.astype(np.float32))
            assert g["keypoints"].dtype == np.float32 and g["scores"].shape == (len(f),)
            assert g["descriptors"].shape == (64, len(f)) and g["descriptors"].dtype == np.float16
            assert tuple(g["image_size"][()]) == (320, 256)
    matches = read_matches(tmp_path)
    assert set(matches) == set(pairs)
    with h5py.File(tmp_path / "features.h5", "r") as fd:
        for (a, b), g in matches.items():
            assert batch.names_to_pair(a, b) == f"{a}/{b}"
            m0, sc = g["matches0"], g["matching_scores0"]
            assert m0.dtype == np.int16 and sc.dtype == np.float16
            k0, k1 = fd[a]["keypoints"][()], fd[b]["keypoints"][()]
            assert m0.shape == (len(k0),) and m0.max() < len(k1)
            valid = m0 >= 0
            assert valid.sum() > 0.5 * len(g["acs"]), (a, b)
            assert len(set(m0[valid])) == valid.sum()  # one-to-one
            # Each match is an AC: x1 the keypoint of A, x2 within 2 px of the keypoint of B.
            ack = g["ac_keypoints"]
            for i in np.flatnonzero(valid)[:20]:
                row = np.flatnonzero(ack[:, 0] == i)[0]
                np.testing.assert_array_equal(g["acs"][row, :2], k0[i].astype(np.float64))
                assert np.linalg.norm(g["acs"][row, 2:4] - k1[m0[i]]) <= 2.0
            for model, mask in (("H", "H_inliers"), ("F", "F_inliers"), ("E", "pose_inliers")):
                assert g[model].shape == (3, 3) and g[mask].shape == (len(g["acs"]),)
            assert g["F_inliers"].sum() > 20
            assert len(g["_attrs"]["checksum"]) == 64


def test_without_the_feature_cache_the_results_are_the_same(images, serial, tmp_path) -> None:
    folder, names = images
    pairs = good_pairs(names)[:3]
    s = batch.run(pairs, folder, tmp_path, workers=1, cache=False, progress=False, **OPTIONS)
    assert (s.matched, s.failed) == (3, 0), s
    assert not (tmp_path / "cache").exists()
    assert_equals_serial(tmp_path, serial, pairs)


def test_bad_pairs_are_recorded_and_the_batch_goes_on(images, serial, tmp_path) -> None:
    folder, names = images
    pairs = [*good_pairs(names)[:3], (names[0], "broken.png"), ("missing.png", names[1])]
    s = batch.run(pairs, folder, tmp_path, workers=1, progress=False, **OPTIONS)
    assert (s.matched, s.failed) == (3, 2), s
    errors = {(a, b): e for a, b, e in s.failures}
    assert "broken.png" in errors[(names[0], "broken.png")]
    assert "missing.png" in errors[("missing.png", names[1])]
    lines = [json.loads(x) for x in (tmp_path / "failures.jsonl").read_text().splitlines()]
    assert {(x["name0"], x["name1"]) for x in lines} == set(errors)
    assert_equals_serial(tmp_path, serial, pairs[:3])
    assert json.loads((tmp_path / "summary.json").read_text())["failed"] == 2


def test_resume_after_an_interrupted_run(images, serial, tmp_path) -> None:
    folder, names = images
    pairs = good_pairs(names)
    seen: list[Any] = []

    def interrupt(r: dict) -> None:
        seen.append(r)
        if len(seen) == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        batch.run(
            pairs, folder, tmp_path, workers=1, chunk_size=1, on_result=interrupt,
            progress=False, **OPTIONS,
        )  # fmt: skip
    written = set(read_matches(tmp_path))
    assert 3 <= len(written) < len(pairs)
    # Without resume (or overwrite) an existing output is refused.
    with pytest.raises(ValueError, match="resume"):
        batch.run(pairs, folder, tmp_path, progress=False, **OPTIONS)
    s = batch.run(pairs, folder, tmp_path, workers=1, resume=True, progress=False, **OPTIONS)
    assert (s.skipped, s.matched, s.failed) == (len(written), len(pairs) - len(written), 0)
    assert_equals_serial(tmp_path, serial)
    # Everything written: a second resume does nothing; other options redo every pair.
    s = batch.run(pairs, folder, tmp_path, workers=1, resume=True, progress=False, **OPTIONS)
    assert (s.skipped, s.matched) == (len(pairs), 0)
    changed = dict(OPTIONS, max_keypoints=128)
    s = batch.run(pairs[:2], folder, tmp_path, workers=1, resume=True, progress=False, **changed)
    assert (s.skipped, s.matched) == (0, 2)
    # The view cascade's budget is an option like any other: the batch's default spelled out
    # is the default, another budget redoes the pairs.
    default_budget = dict(OPTIONS, view_relative_budget=batch.BATCH_VIEW_RELATIVE_BUDGET)
    s = batch.run(
        pairs[2:], folder, tmp_path, workers=1, resume=True, progress=False, **default_budget
    )
    assert (s.skipped, s.matched) == (len(pairs) - 2, 0)
    other_budget = dict(OPTIONS, view_relative_budget=5.0)
    s = batch.run(
        pairs[2:4], folder, tmp_path, workers=1, resume=True, progress=False, **other_budget
    )
    assert (s.skipped, s.matched) == (0, 2)


def test_resume_after_the_driver_is_killed(images, serial, tmp_path) -> None:
    """SIGKILL of the whole run (driver and workers) once results are being written: the HDF5
    files still open (no libver="latest" consistency flags), and a resume completes the run
    with the serial results."""
    folder, names = images
    pairs_file = tmp_path / "pairs.txt"
    pairs_file.write_text("".join(f"{a} {b}\n" for a, b in good_pairs(names)))
    out = tmp_path / "out"
    cmd = [
        sys.executable, "-m", "affcorr.cli", "batch", str(pairs_file), str(folder), "-o",
        str(out), "--matcher", "xfeat", "--max-keypoints", "256", "--views", "off",
        "--workers", "1", "--chunk-size", "1", "--no-progress",
    ]  # fmt: skip
    p = subprocess.Popen(cmd, start_new_session=True, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while not (out / "matches.h5").exists() and p.poll() is None:
            assert time.monotonic() < deadline, "no pair was written in 120 s"
            time.sleep(0.05)
        time.sleep(0.3)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(p.pid, signal.SIGKILL)
        p.wait()
    before = len(read_matches(out))
    s = batch.run(good_pairs(names), folder, out, workers=1, resume=True, progress=False,
                  **OPTIONS)  # fmt: skip
    assert s.skipped == before and s.matched + s.skipped == len(serial) and s.failed == 0
    assert_equals_serial(out, serial)


@pytest.mark.parametrize("settle", [0.0, 2.0], ids=["at-once", "pool-noticed"])
def test_a_killed_local_worker_is_replaced_and_its_pairs_retried(images, serial, tmp_path, settle):
    """``settle``: how long the callback waits after the kill. With 2 s the executor has
    marked the pool broken before the driver submits its next chunk, so the break surfaces
    in ``submit`` rather than in a result (the race CI once lost)."""
    folder, names = images
    pairs = good_pairs(names)
    killed: list[int] = []

    def kill_first_worker(r: dict) -> None:
        if not killed:
            pid = int(r["worker"].rsplit(":", 1)[1])
            killed.append(pid)
            os.kill(pid, signal.SIGKILL)
            time.sleep(settle)

    s = batch.run(
        pairs, folder, tmp_path, workers=2, chunk_size=1, on_result=kill_first_worker,
        progress=False, **OPTIONS,
    )  # fmt: skip
    assert killed and s.retried >= 1, s
    assert (s.matched, s.failed) == (len(pairs), 0), s
    assert_equals_serial(tmp_path, serial)
    workers = {g["_attrs"]["worker"] for g in read_matches(tmp_path).values()}
    assert len(workers) >= 2  # the replacement pool's processes wrote some pairs


def test_cli_batch_writes_and_resumes(images, tmp_path) -> None:
    folder, names = images
    pairs_file = tmp_path / "pairs.txt"
    pairs_file.write_text(
        "# hloc pairs\n" + "".join(f"{a} {b}\n" for a, b in good_pairs(names)[:3])
        + f"{names[0]} broken.png\n"
    )  # fmt: skip
    out = tmp_path / "out"
    cmd = [
        sys.executable, "-m", "affcorr.cli", "batch", str(pairs_file), str(folder), "-o",
        str(out), "--matcher", "xfeat", "--max-keypoints", "256", "--views", "off",
        "--workers", "1", "--geometry", "homography",
    ]  # fmt: skip
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert r.returncode == 3, r.stderr  # one pair failed
    assert "3 pairs matched" in r.stderr and "failed: view0.png broken.png" in r.stderr
    r = subprocess.run([*cmd, "--resume"], capture_output=True, text=True, timeout=300)
    assert "0 pairs matched, 3 already done, 1 failed" in r.stderr, r.stderr
    r = subprocess.run([*cmd[:-2], "--geometry", "sift"], capture_output=True, text=True)
    assert r.returncode != 0 and "geometry" in r.stderr


def test_bad_arguments_name_themselves(images, tmp_path) -> None:
    folder, names = images
    with pytest.raises(ValueError, match="chunk_size"):
        batch.run([(names[0], names[1])], folder, tmp_path, chunk_size=0)
    with pytest.raises(ValueError, match=r"pairs\[0\]"):
        batch.run(["view0.png"], folder, tmp_path)
    with pytest.raises(FileNotFoundError, match="image_dir"):
        batch.run([(names[0], names[1])], tmp_path / "nope", tmp_path)
    with pytest.raises(ValueError, match="view_relative_budget"):
        batch.run([(names[0], names[1])], folder, tmp_path, view_relative_budget=0.0)
    with pytest.raises(ValueError, match="ship_images: .*ray_address"):
        batch.run([(names[0], names[1])], folder, tmp_path, ship_images=True)
    cams = tmp_path / "cams.txt"
    cams.write_text("view0.png PINHOLE 320 256 300 300\n")
    with pytest.raises(ValueError, match="PINHOLE takes 4 parameters"):
        batch.read_cameras(cams)
    cams.write_text("view0.png SIMPLE_RADIAL 320 256 300 160 128 0.01\n")
    k = batch.read_cameras(cams)["view0.png"].K()
    np.testing.assert_array_equal(k, [[300, 0, 160], [0, 300, 128], [0, 0, 1]])


def test_shipped_models_share_one_folder_per_content(tmp_path) -> None:
    """Ray workers write the shipped models to a folder named by their digest: the same models
    reuse the folder (no folder left behind per worker), other models get their own, and a
    damaged file is rewritten."""
    from affcorr.batch._worker import shipped_models_dir

    files = {"shape.onnx": b"shape bytes", "xfeat_backbone.onnx": b"backbone bytes"}
    first = shipped_models_dir(files, root=tmp_path)
    assert shipped_models_dir(dict(files), root=tmp_path) == first
    assert {p.name: p.read_bytes() for p in first.iterdir()} == files
    other = shipped_models_dir({**files, "shape.onnx": b"another shape"}, root=tmp_path)
    assert other != first and (other / "shape.onnx").read_bytes() == b"another shape"
    (first / "shape.onnx").write_bytes(b"truncat")
    assert shipped_models_dir(files, root=tmp_path) == first
    assert (first / "shape.onnx").read_bytes() == b"shape bytes"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([first.name, other.name])


def test_a_portrait_photo_is_matched_upright_and_written_in_its_stored_pixels(
    images, tmp_path
) -> None:
    """A view stored turned by 90 degrees counter-clockwise with the EXIF tag of a camera held
    in portrait (6): the batch matches it upright (views off: the plain pass alone, which a
    quarter turn would defeat) and writes its keypoints, size and H in the stored pixels, as
    COLMAP reads the file (docs/design.md section 2)."""
    PIL = pytest.importorskip("PIL.Image")
    folder, names = images
    portrait = tmp_path / "images"
    portrait.mkdir()
    (portrait / names[0]).write_bytes((folder / names[0]).read_bytes())
    exif = PIL.Exif()
    exif[0x0112] = 6
    PIL.open(folder / names[1]).rotate(90, expand=True).save(portrait / "p.png", exif=exif)
    s = batch.run(
        [(names[0], "p.png")], portrait, tmp_path / "out", geometry=["homography"],
        progress=False, **OPTIONS,
    )  # fmt: skip
    assert s.matched == 1, s
    with h5py.File(tmp_path / "out" / "features.h5", "r") as fd:
        assert tuple(fd["p.png"]["image_size"][()]) == (256, 320)  # stored: 256 wide, 320 high
        k = fd["p.png"]["keypoints"][()]
        assert k[:, 0].max() <= 255.5 and k[:, 1].max() <= 319.5
    H = read_matches(tmp_path / "out")[(names[0], "p.png")]["H"]
    # The same pair upright, mapped into the stored pixels: shown (x, y) = (319 - y, x).
    H_up, _ = affcorr.Pipeline(threads=1, **OPTIONS).homography(
        folder / names[0], folder / names[1]
    )
    shown_from_stored = np.array([[0, -1, 319], [1, 0, 0], [0, 0, 1.0]])
    grid = np.c_[
        np.stack(np.meshgrid(np.arange(0, 320, 40), np.arange(0, 256, 40)), -1).reshape(-1, 2),
        np.ones(56),
    ]

    def project(m):
        p = grid @ m.T
        return p[:, :2] / p[:, 2:]

    err = np.linalg.norm(project(H) - project(np.linalg.inv(shown_from_stored) @ H_up), axis=1)
    assert np.median(err) < 1.0, np.median(err)
