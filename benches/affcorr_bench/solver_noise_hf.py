"""Error-vs-noise curves of the homography and fundamental-matrix solvers.

Writes benches/results/solver_noise_hf.csv and .png (median error per solver and noise level).

Scenes are built here in numpy: two cameras with K1 != K2 and fx != fy (640x480), a rotation of
up to ~25 deg, a baseline of 0.3-1, planes at distance 3-6 tilted up to ~40 deg. Homography
samples lie on one plane; fundamental samples put every correspondence on its own plane (F is not
determined by a single plane).

Noise: pixel noise is Gaussian with std sigma_px on both x1 and x2; affine noise multiplies
A by (I + sigma_a G), G with i.i.d. N(0, 1) entries (sigma_a = 10% is a 10% relative
perturbation). Three sweeps: pixel noise 0..2 px alone, affine noise 0..10% alone, and both
together (sigma_px = 2t px, sigma_a = 10t %, t in 0..1).

Errors, in pixels, measured on 100 noise-free test correspondences of the same scene:
- H: mean transfer error |H(x1) - x2| on points of the plane;
- F: RMS point Sampson distance on correspondences off the plane.
A solver that returns several models is scored by its best one; a sample with no model counts
as a failure (reported, not in the median). 1AC+F is given the exact F.

Usage: .venv/bin/python -m affcorr_bench.solver_noise_hf [--trials 200] [--seed 0]
"""

from __future__ import annotations

import argparse

import affcorr
import numpy as np

from . import common
from .common import intrinsics, skew

RESULTS = common.RESULTS
LEVELS = np.linspace(0.0, 1.0, 6)
SWEEPS = {
    "pixel": lambda t: (2.0 * t, 0.0),
    "affine": lambda t: (0.0, 0.10 * t),
    "both": lambda t: (2.0 * t, 0.10 * t),
}


def rotations(axes, angles):
    """Rodrigues, batched: axes (n, 3), angles (n,) -> (n, 3, 3)."""
    axes = axes / np.linalg.norm(axes, axis=1, keepdims=True)
    k = np.zeros((len(axes), 3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -axes[:, 2], axes[:, 1], -axes[:, 0]
    k = k - k.transpose(0, 2, 1)
    s, c = np.sin(angles)[:, None, None], np.cos(angles)[:, None, None]
    return np.eye(3) + s * k + (1 - c) * k @ k


class Scene:
    def __init__(self, rng):
        self.rng = rng
        self.K1, self.K2 = intrinsics(rng), intrinsics(rng)
        self.R = rotations(rng.normal(size=(1, 3)), rng.uniform(-0.45, 0.45, 1))[0]
        t = rng.normal(size=3)
        self.t = t / np.linalg.norm(t) * rng.uniform(0.3, 1.0)
        self.F = np.linalg.inv(self.K2).T @ skew(self.t) @ self.R @ np.linalg.inv(self.K1)
        self.plane = self.planes(1)
        n, d = self.plane[0][0], self.plane[1][0]
        self.H = self.K2 @ (self.R + np.outer(self.t, n) / d) @ np.linalg.inv(self.K1)

    def planes(self, count):
        tilt = rotations(self.rng.normal(size=(count, 3)), self.rng.uniform(-0.7, 0.7, count))
        return tilt[:, :, 2], self.rng.uniform(3, 6, count)

    def acs(self, count, multi_plane):
        """`count` exact ACs (count, 8): on the scene's plane, or each on its own plane."""
        out = []
        while sum(len(o) for o in out) < count:
            m = 2 * count
            x1 = np.column_stack(
                [self.rng.uniform(0, 640, m), self.rng.uniform(0, 480, m), np.ones(m)]
            )
            n, d = (
                self.planes(m)
                if multi_plane
                else (np.repeat(self.plane[0], m, 0), np.repeat(self.plane[1], m))
            )
            rays = x1 @ np.linalg.inv(self.K1).T
            depth = d / np.einsum("ij,ij->i", n, rays)
            cam2 = (rays * depth[:, None]) @ self.R.T + self.t
            ok = (depth > 0) & (cam2[:, 2] > 0)
            h = self.K2 @ (self.R + self.t[None, :, None] * n[:, None, :] / d[:, None, None])
            h = h @ np.linalg.inv(self.K1)
            q = np.einsum("nij,nj->ni", h, x1)
            w = q[:, 2]
            x2 = q[:, :2] / w[:, None]
            a = (h[:, :2, :2] - x2[:, :, None] * h[:, 2, None, :2]) / w[:, None, None]
            rows = np.column_stack([x1[:, :2], x2, a.reshape(-1, 4)])
            out.append(rows[ok])
        return np.vstack(out)[:count]


def perturb(rng, acs, sigma_px, sigma_a):
    noisy = acs.copy()
    noisy[:, :4] += rng.normal(scale=sigma_px, size=(len(acs), 4)) if sigma_px > 0 else 0.0
    if sigma_a > 0:
        a = acs[:, 4:].reshape(-1, 2, 2)
        g = np.eye(2) + sigma_a * rng.normal(size=a.shape)
        noisy[:, 4:] = (a @ g).reshape(-1, 4)
    return noisy


def transfer_error(h, test):
    p = np.column_stack([test[:, :2], np.ones(len(test))]) @ h.T
    return np.mean(np.linalg.norm(p[:, :2] / p[:, 2:] - test[:, 2:4], axis=1))


def sampson_rms(f, test):
    p1 = np.column_stack([test[:, :2], np.ones(len(test))])
    p2 = np.column_stack([test[:, 2:4], np.ones(len(test))])
    l1, l2 = p1 @ f.T, p2 @ f
    num = np.einsum("ij,ij->i", p2, l1) ** 2
    den = l1[:, 0] ** 2 + l1[:, 1] ** 2 + l2[:, 0] ** 2 + l2[:, 1] ** 2
    return float(np.sqrt(np.mean(num / den)))


# (problem, solver label, sample size, uses ACs, call)
SOLVERS = [
    ("H", "homography_4pt", 4, False, lambda c, s: affcorr.homography_4pt(c[:, :2], c[:, 2:4])),
    ("H", "homography_2ac", 2, True, lambda c, s: affcorr.homography_2ac(c)),
    ("H", "homography_1ac_given_f", 1, True, lambda c, s: affcorr.homography_1ac_given_f(c, s.F)),
    (
        "H",
        "homography_lsq (50)",
        50,
        False,
        lambda c, s: affcorr.homography_lsq(c[:, :2], c[:, 2:4]),
    ),
    ("H", "homography_ac_lsq (50)", 50, True, lambda c, s: affcorr.homography_ac_lsq(c)),
    ("F", "fundamental_7pt", 7, False, lambda c, s: affcorr.fundamental_7pt(c[:, :2], c[:, 2:4])),
    (
        "F",
        "fundamental_8pt (8)",
        8,
        False,
        lambda c, s: affcorr.fundamental_8pt(c[:, :2], c[:, 2:4]),
    ),
    ("F", "fundamental_3ac", 3, True, lambda c, s: affcorr.fundamental_3ac(c)),
    (
        "F",
        "fundamental_8pt (50)",
        50,
        False,
        lambda c, s: affcorr.fundamental_8pt(c[:, :2], c[:, 2:4]),
    ),
    ("F", "fundamental_ac_lsq (50)", 50, True, lambda c, s: affcorr.fundamental_ac_lsq(c)),
]


def run(trials, seed):
    rng = np.random.default_rng(seed)
    rows = []
    for sweep, noise in SWEEPS.items():
        for t in LEVELS:
            sigma_px, sigma_a = noise(t)
            errors = {s[1]: [] for s in SOLVERS}
            failures = {s[1]: 0 for s in SOLVERS}
            for _ in range(trials):
                scene = Scene(rng)
                plane_acs = scene.acs(150, multi_plane=False)
                general = scene.acs(150, multi_plane=True)
                for problem, name, n, uses_acs, call in SOLVERS:
                    if sweep == "affine" and not uses_acs:
                        continue
                    data = plane_acs if problem == "H" else general
                    sample = perturb(rng, data[:n], sigma_px, sigma_a)
                    models = call(sample, scene)
                    if not models:
                        failures[name] += 1
                        continue
                    test = data[50:]
                    err = transfer_error if problem == "H" else sampson_rms
                    errors[name].append(min(err(m, test) for m in models))
            for problem, name, _, uses_acs, _ in SOLVERS:
                if sweep == "affine" and not uses_acs:
                    continue
                e = np.array(errors[name])
                rows.append(
                    {
                        "problem": problem,
                        "solver": name,
                        "sweep": sweep,
                        "pixel_noise_px": round(sigma_px, 4),
                        "affine_noise": round(sigma_a, 4),
                        "trials": trials,
                        "failures": failures[name],
                        "median_error_px": float(np.median(e)) if len(e) else float("nan"),
                        "p90_error_px": float(np.percentile(e, 90)) if len(e) else float("nan"),
                    }
                )
    return rows


def plot(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 3, figsize=(15, 8.5), constrained_layout=True)
    for i, problem in enumerate(["H", "F"]):
        for j, sweep in enumerate(SWEEPS):
            ax = axes[i, j]
            sel = [r for r in rows if r["problem"] == problem and r["sweep"] == sweep]
            for name in dict.fromkeys(r["solver"] for r in sel):
                rs = [r for r in sel if r["solver"] == name]
                x = [
                    r["affine_noise"] * 100 if sweep == "affine" else r["pixel_noise_px"]
                    for r in rs
                ]
                y = [max(r["median_error_px"], 1e-13) for r in rs]
                ax.semilogy(x, y, marker="o", label=name)
            xlabel = {
                "pixel": "pixel noise std (px)",
                "affine": "affine noise (%)",
                "both": "pixel noise std (px), affine noise = 5 % per px",
            }[sweep]
            ax.set_xlabel(xlabel)
            metric = "mean transfer error" if problem == "H" else "RMS Sampson distance"
            ax.set_ylabel(f"median {metric} (px)")
            ax.set_title(f"{'homography' if problem == 'H' else 'fundamental'}: {sweep} noise")
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(fontsize=8)
    fig.savefig(path, dpi=110)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    rows = run(args.trials, args.seed)
    common.write_csv(rows, RESULTS / "solver_noise_hf.csv")
    plot(rows, RESULTS / "solver_noise_hf.png")
    print(f"wrote {RESULTS / 'solver_noise_hf.csv'} and .png")


if __name__ == "__main__":
    main()
