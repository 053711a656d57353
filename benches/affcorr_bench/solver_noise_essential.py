"""Error-vs-noise curves of the essential solvers through the Python bindings.

Scenes: random relative pose (rotation up to ~29°, baseline 0.3-1), anisotropic K1 != K2
(fx != fy), 640x480 images, ACs induced exactly by random planes in front of both cameras
(pixels), then noise in pixels:
  - pixel noise: Gaussian sigma in {0, 0.25, ..., 2} px on x1 and x2;
  - affine noise: A <- A (I + s N), N 2x2 standard normal, s in {0, 1, ..., 10} %.
The noisy pixel ACs are normalised with affcorr.normalize_correspondences and fed to
  - essential_5pt: 5 points, from 3 planes;
  - essential_2ac: 2 ACs, one from each of 2 planes;
  - essential_8pt: 50 points from 3 planes.
Error of a call = the best candidate (oracle selection, usual for solver studies): rotation
and translation-direction angles (degrees) of pose_from_essential(E) against the truth, and
||E - E_true|| up to sign. Reported: medians over TRIALS calls per level.

    .venv/bin/python -m affcorr_bench.solver_noise_essential

writes benches/results/solver_noise_essential.csv and .png.
"""

import argparse

import affcorr
import numpy as np

from . import common
from .common import intrinsics, random_rotation

TRIALS = 300
OUT = common.RESULTS


def scene(rng):
    R = random_rotation(rng, 0.5)
    t = rng.normal(size=3)
    t *= rng.uniform(0.3, 1.0) / np.linalg.norm(t)
    return R, t, intrinsics(rng), intrinsics(rng)


def plane_acs(rng, R, t, K1, K2, n):
    """n exact pixel ACs of a random plane, with both depths positive."""
    normal = random_rotation(rng, 0.7) @ np.array([0, 0, 1.0])
    d = rng.uniform(3, 6)
    H = K2 @ (R + np.outer(t, normal) / d) @ np.linalg.inv(K1)
    x1 = np.stack([rng.uniform(0, 640, 4 * n + 8), rng.uniform(0, 480, 4 * n + 8)], axis=1)
    rays = np.c_[x1, np.ones(len(x1))] @ np.linalg.inv(K1).T
    depth = d / (rays @ normal)
    z2 = ((rays * depth[:, None]) @ R.T + t)[:, 2]
    keep = x1[(depth > 0) & (z2 > 0)][:n]
    if len(keep) < n:
        return plane_acs(rng, R, t, K1, K2, n)
    return affcorr.correspondences_from_homography(H, keep)


def perturb(rng, corrs, px, aff):
    c = corrs.copy()
    c[:, :4] += rng.normal(scale=px, size=(len(c), 4)) if px > 0 else 0
    if aff > 0:
        for row in c:
            A = row[4:].reshape(2, 2)
            row[4:] = (A @ (np.eye(2) + aff * rng.normal(size=(2, 2)))).ravel()
    return c


def angle_deg(R):
    return np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1)))


def errors(models, R, t, x1, x2):
    E_true = np.cross(np.eye(3), t) @ R  # row i is e_i x t, i.e. [t]x; E = [t]x R
    E_true /= np.linalg.norm(E_true)
    best = (np.inf, np.inf, np.inf)
    for M in models:
        Rm, tm, _ = affcorr.pose_from_essential(M, x1, x2)
        tu = t / np.linalg.norm(t)
        cand = (
            angle_deg(Rm @ R.T),
            np.degrees(np.arccos(np.clip(abs(tm.dot(tu)), -1, 1))),
            min(np.linalg.norm(M - E_true), np.linalg.norm(M + E_true)),
        )
        if cand[0] + cand[1] < best[0] + best[1]:
            best = cand
    return best


def run_level(rng, px, aff):
    out = {name: [] for name in ("5pt", "2ac", "8pt")}
    for _ in range(TRIALS):
        R, t, K1, K2 = scene(rng)

        def norm(c, K1=K1, K2=K2):
            return affcorr.normalize_correspondences(c, K1, K2)

        # 5pt: 5 points from 3 planes.
        c = norm(
            perturb(rng, np.vstack([plane_acs(rng, R, t, K1, K2, k) for k in (2, 2, 1)]), px, aff)
        )
        out["5pt"].append(
            errors(affcorr.essential_5pt(c[:, :2], c[:, 2:4]), R, t, c[:, :2], c[:, 2:4])
        )
        # 2ac: one AC from each of two planes.
        c = norm(
            perturb(rng, np.vstack([plane_acs(rng, R, t, K1, K2, 1) for _ in range(2)]), px, aff)
        )
        out["2ac"].append(errors(affcorr.essential_2ac(c), R, t, c[:, :2], c[:, 2:4]))
        # 8pt: 50 points from 3 planes.
        c = norm(
            perturb(
                rng, np.vstack([plane_acs(rng, R, t, K1, K2, k) for k in (17, 17, 16)]), px, aff
            )
        )
        out["8pt"].append(
            errors(affcorr.essential_8pt(c[:, :2], c[:, 2:4]), R, t, c[:, :2], c[:, 2:4])
        )
    return {k: np.median(np.array(v), axis=0) for k, v in out.items()}


def main(argv=None):
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args(argv)
    rng = np.random.default_rng(2026)
    rows = []
    for px in np.linspace(0, 2, 9):
        for name, med in run_level(rng, px, 0.0).items():
            rows.append(("pixel", name, px, 0.0, *med))
    for aff in np.linspace(0, 0.10, 11):
        for name, med in run_level(rng, 0.0, aff).items():
            rows.append(("affine", name, 0.0, aff, *med))
    path = OUT / "solver_noise_essential.csv"
    fields = ["sweep", "solver", "pixel_sigma_px", "affine_sigma"]
    fields += ["median_rot_deg", "median_trans_deg", "median_E_err"]
    formats = ["", "", ".3f", ".3f", ".6g", ".6g", ".6g"]
    common.write_csv(
        [{k: format(v, f) for k, v, f in zip(fields, r, formats)} for r in rows], path, fields
    )

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for ax, sweep, col, label in (
        (axes[0], "pixel", 2, "pixel noise sigma [px]"),
        (axes[1], "affine", 3, "affine noise sigma [%]"),
    ):
        for name, style in (("5pt", "o-"), ("2ac", "s-"), ("8pt", "^-")):
            sel = [r for r in rows if r[0] == sweep and r[1] == name]
            xs = [r[col] * (100 if sweep == "affine" else 1) for r in sel]
            ax.plot(xs, [r[4] for r in sel], style, label=f"{name} rotation")
            ax.plot(
                xs, [r[5] for r in sel], style[0] + "--", alpha=0.5, label=f"{name} translation"
            )
        ax.set_xlabel(label)
        ax.set_ylabel("median error [deg]")
        ax.set_title(f"{sweep} noise ({TRIALS} trials/level, best candidate)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    common.save_figure(fig, OUT / "solver_noise_essential.png")
    print(f"wrote {path} and the .png")


if __name__ == "__main__":
    main()
