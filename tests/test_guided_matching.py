"""Guided re-matching from Python (the Rust test crates/affcorr-pipeline/tests/guided.rs checks
the grown ACs against graffiti's ground truth): the plain matches come first and unchanged, the
grown ones follow, flagged reliable, and the option reaches the CLI."""

from __future__ import annotations

import affcorr
import numpy as np
from affcorr.data import data_dir, graffiti
from affcorr.metrics import transfer

GRAF = data_dir() / "graffiti"


def _pipe(guided: bool) -> affcorr.Pipeline:
    return affcorr.Pipeline(max_keypoints=1024, threads=2, views="off", guided_matching=guided)


def test_guided_matching_adds_matches_that_agree_with_the_plane():
    a, b = GRAF / "graf1.png", GRAF / "graf3.png"
    plain = _pipe(False).match_pair(a, b)
    guided = _pipe(True).match_pair(a, b)
    n = len(plain)
    np.testing.assert_array_equal(guided.corrs[:n], plain.corrs)
    assert len(guided) >= 1.2 * n
    assert guided.reliable[n:].all() and guided.timings["guided"] > 0
    assert plain.timings["guided"] == 0
    H = graffiti()[2]  # noqa: N806
    d = np.linalg.norm(transfer(H, guided.corrs[n:, :2]) - guided.corrs[n:, 2:4], axis=1)
    assert np.mean(d < 3.0) >= 0.85


def test_the_default_and_the_cli_flag():
    from affcorr import cli

    assert affcorr.PIPELINE_DEFAULTS["guided_matching"] is False
    parse = cli.build_parser().parse_args
    assert parse(["match", "a.png", "b.png", "-o", "x.npz"]).guided_matching is False
    args = parse(["match", "a.png", "b.png", "-o", "x.npz", "--guided-matching"])
    assert args.guided_matching is True
