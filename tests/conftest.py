"""Shared fixtures: exact plane-induced scenes built in numpy, independently of the Rust code.

A plane n^T X1 = d seen by two cameras with X2 = R X1 + t induces H = K2 (R + t n^T / d) K1^-1
and F = K2^-T [t]x R K1^-1 (docs/design.md §2). K1 != K2 and fx != fy, so a wrong normalisation
shows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest


def skew(t: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -t[2], t[1]], [t[2], 0.0, -t[0]], [-t[1], t[0], 0.0]])


def rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    k = skew(axis / np.linalg.norm(axis))
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * k @ k


@dataclass
class PlaneScene:
    K1: np.ndarray
    K2: np.ndarray
    R: np.ndarray
    t: np.ndarray
    n: np.ndarray
    d: float

    @property
    def H(self) -> np.ndarray:
        return self.K2 @ (self.R + np.outer(self.t, self.n) / self.d) @ np.linalg.inv(self.K1)

    @property
    def E(self) -> np.ndarray:
        return skew(self.t) @ self.R

    @property
    def F(self) -> np.ndarray:
        f = np.linalg.inv(self.K2).T @ self.E @ np.linalg.inv(self.K1)
        return f / np.linalg.norm(f)

    def project(self, x1: np.ndarray) -> np.ndarray:
        p = np.c_[x1, np.ones(len(x1))] @ self.H.T
        return p[:, :2] / p[:, 2:]

    def jacobians(self, x1: np.ndarray) -> np.ndarray:
        """A = dx2/dx1 (N, 2, 2) by the quotient rule, written independently of the Rust code."""
        H = self.H
        p = np.c_[x1, np.ones(len(x1))] @ H.T
        w = p[:, 2]
        x2 = p[:, :2] / w[:, None]
        return (H[None, :2, :2] - x2[:, :, None] * H[None, 2:3, :2]) / w[:, None, None]

    def correspondences(self, x1: np.ndarray) -> np.ndarray:
        """Exact ACs (N, 8) at the pixels x1."""
        return np.c_[x1, self.project(x1), self.jacobians(x1).reshape(-1, 4)]

    def sample_pixels(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """Pixels of a 640x480 image 1 whose plane point is in front of both cameras."""
        out = []
        K1i = np.linalg.inv(self.K1)
        while len(out) < n:
            x = rng.uniform([0, 0], [640, 480])
            ray = K1i @ np.r_[x, 1.0]
            depth = self.d / (self.n @ ray)
            if depth > 0 and (self.R @ (ray * depth) + self.t)[2] > 0:
                out.append(x)
        return np.array(out)


def random_scene(rng: np.random.Generator) -> PlaneScene:
    def k() -> np.ndarray:
        f = rng.uniform(500, 1000)
        return np.array(
            [
                [f, 0, rng.uniform(300, 340)],
                [0, f * rng.uniform(0.8, 1.2), rng.uniform(220, 260)],
                [0, 0, 1.0],
            ]
        )

    R = rotation(rng.normal(size=3), rng.uniform(-0.45, 0.45))
    t = rng.normal(size=3)
    t *= rng.uniform(0.3, 1.0) / np.linalg.norm(t)
    n = rotation(rng.normal(size=3), rng.uniform(-0.7, 0.7)) @ np.array([0.0, 0.0, 1.0])
    return PlaneScene(k(), k(), R, t, n, rng.uniform(3.0, 6.0))


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


@pytest.fixture
def scene(rng: np.random.Generator) -> PlaneScene:
    return random_scene(rng)
