"""Minimal and non-minimal solvers (docs/design.md §4), the kernels inside every RANSAC iteration.

Each takes a sample and returns a list of candidate models, each a (3, 3) float64 array with unit
Frobenius norm (sign arbitrary); a degenerate sample (collinear or repeated points, det A <= 0,
NaN) returns ``[]``. H and F solvers take pixels and normalise internally; essential solvers take
normalised coordinates (see :func:`affcorr.normalize_correspondences`).

============================================  ===============  ====  =============================
solver                                        sample           max   method
============================================  ===============  ====  =============================
``homography_4pt(x1, x2)``                    4 points         1     normalised DLT
``homography_2ac(corrs)``                     2 ACs            1     6 equations per AC, LSQ
``homography_1ac2pt(corr, x1, x2)``            1 AC + 2 points  1     10 equations of rank 8, LSQ
``homography_1ac_given_f(corrs, F)``          1 AC + F         1     H = -[e2]x F + e2 v^T
``homography_lsq`` / ``homography_ac_lsq``    N>=4 / N>=2      1     least squares
``fundamental_7pt(x1, x2)``                   7 points         3     det F = 0 cubic
``fundamental_8pt(x1, x2)``                   N >= 8 points    1     normalised 8-point, rank 2
``fundamental_3ac(corrs)``                    3 ACs            3     9 equations + rank 2
``fundamental_1ac4pt(corr, x1, x2)``           1 AC + 4 points  3     7 equations, as 7 points
``fundamental_ac_lsq(corrs)``                 N >= 3 ACs       1     least squares + rank 2
``essential_5pt(x1, x2)``                     5 points         10    Nister / Stewenius, Sturm
``essential_2ac(corrs)``                      2 ACs            10    Barath & Hajder 2018
``essential_1ac2pt(corr, x1, x2)``             1 AC + 2 points  10    5 equations, 5-point machinery
``essential_8pt`` / ``essential_lsq``         N >= 8 rows      1     LSQ, essential projection
============================================  ===============  ====  =============================

Example:

>>> import numpy as np, affcorr.solvers as s
>>> x1 = np.array([[0, 0], [100, 0], [100, 80], [10, 90]], float)
>>> H = np.array([[1.1, 0.1, 5], [-0.05, 0.9, 3], [1e-4, 2e-4, 1]])
>>> p = np.c_[x1, np.ones(4)] @ H.T
>>> [Hhat] = s.homography_4pt(x1, p[:, :2] / p[:, 2:])
>>> bool(np.allclose(Hhat / Hhat[2, 2], H / H[2, 2]))
True
"""

from ._docs import document as _document
from ._native import (
    essential_1ac2pt,
    essential_2ac,
    essential_5pt,
    essential_8pt,
    essential_lsq,
    fundamental_1ac4pt,
    fundamental_3ac,
    fundamental_7pt,
    fundamental_8pt,
    fundamental_ac_lsq,
    homography_1ac2pt,
    homography_1ac_given_f,
    homography_2ac,
    homography_4pt,
    homography_ac_lsq,
    homography_lsq,
)

__all__ = [
    "essential_1ac2pt",
    "essential_2ac",
    "essential_5pt",
    "essential_8pt",
    "essential_lsq",
    "fundamental_1ac4pt",
    "fundamental_3ac",
    "fundamental_7pt",
    "fundamental_8pt",
    "fundamental_ac_lsq",
    "homography_1ac2pt",
    "homography_1ac_given_f",
    "homography_2ac",
    "homography_4pt",
    "homography_ac_lsq",
    "homography_lsq",
]

_document(globals(), __all__)
