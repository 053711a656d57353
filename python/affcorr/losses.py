"""Torch losses over the Rust Sampson kernels (docs/design.md §3). Needs the ``affcorr[train]``
extra.

torch comes from Debian's ``python3-torch`` (docs/design.md §7); it is never imported by
``import affcorr``, only by ``import affcorr.losses``.

- :func:`point_sampson` ``(F, corrs) -> (N,)``: SD_P per row, differentiable w.r.t. ``F`` and
  ``corrs`` (the autograd Function is :class:`PointSampsonFunction`).
- :func:`affine_sampson` ``(F, corrs) -> (N, 2)``: SD_A,k per row k of the affine epipolar
  constraint ``A^T (F p1)[:2] + (F^T p2)[:2] = 0``; SD_A is the sum of the two columns
  (:class:`AffineSampsonFunction`).
- :class:`PointSampsonLoss` and :class:`AffineSampsonLoss`: the positive means
  L_pc = mean SD_P and L_aff = mean SD_A (docs/design.md §3; the paper's minus sign is a typo).
- :func:`reference_point_sampson`, :func:`reference_affine_sampson`: the same distances in plain
  torch ops, a check on the kernels (they agree to 1e-10 in float64).

``F`` is ``(3, 3)`` (shared by every row) or ``(N, 3, 3)`` (one per row, e.g. a batch that mixes
image pairs). ``corrs`` is ``(N, 8)`` = ``[x1, y1, x2, y2, a11, a12, a21, a22]`` with
``A = dx2/dx1``, or ``(N, 4)`` for the point distance. The kernels run in float64 on the CPU:
inputs of other dtypes or devices are converted, the outputs come back in the promoted input
dtype on the input's device, and each gradient in its input's dtype. The analytic gradients come
from Rust; the Functions are once-differentiable (no double backward).

Degenerate denominators (only for special F) give a distance of 0 when the residual is 0 too and
``+inf`` otherwise, with zero gradient; the pure-torch references do not special-case them.
"""

from __future__ import annotations

import numpy as np
import torch
from torch.autograd.function import once_differentiable

from . import _native

__all__ = [
    "AffineSampsonFunction",
    "AffineSampsonLoss",
    "PointSampsonFunction",
    "PointSampsonLoss",
    "affine_sampson",
    "point_sampson",
    "reference_affine_sampson",
    "reference_point_sampson",
]


def _as_tensor(x) -> torch.Tensor:
    return x if isinstance(x, torch.Tensor) else torch.as_tensor(np.asarray(x))


def _to_numpy(t: torch.Tensor) -> np.ndarray:
    return t.detach().to(device="cpu", dtype=torch.float64).contiguous().numpy()


def _out_dtype(F: torch.Tensor, corrs: torch.Tensor) -> torch.dtype:
    dtype = torch.promote_types(F.dtype, corrs.dtype)
    return dtype if dtype.is_floating_point else torch.float64


def _save(ctx, F: torch.Tensor, corrs: torch.Tensor, d_corrs, d_f) -> None:
    """Keeps the per-row gradients and what backward needs to shape and cast its results."""
    ctx.d_corrs, ctx.d_f = torch.from_numpy(d_corrs), torch.from_numpy(d_f)
    ctx.f_meta = (F.dim() == 3, F.dtype, F.device)
    ctx.corrs_meta = (corrs.dtype, corrs.device)


def _grad_F(ctx, per_row: torch.Tensor) -> torch.Tensor:
    """Per-row gradients (N, 3, 3) to the gradient of F: summed over rows when F is shared."""
    per_row_f, dtype, device = ctx.f_meta
    g = per_row if per_row_f else per_row.sum(dim=0)
    return g.to(device=device, dtype=dtype)


def _grad_corrs(ctx, g: torch.Tensor) -> torch.Tensor:
    dtype, device = ctx.corrs_meta
    return g.to(device=device, dtype=dtype)


def _forward(ctx, F, corrs, value, value_and_grad):  # noqa: N803
    """Runs the Rust kernel, with its gradients only when autograd needs them."""
    f, c = _to_numpy(F), _to_numpy(corrs)
    out = {"device": corrs.device, "dtype": _out_dtype(F, corrs)}
    if not any(ctx.needs_input_grad):
        return torch.from_numpy(value(f, c)).to(**out)
    dist, d_corrs, d_f = value_and_grad(f, c)
    _save(ctx, F, corrs, d_corrs, d_f)
    return torch.from_numpy(dist).to(**out)


class PointSampsonFunction(torch.autograd.Function):
    """``apply(F, corrs) -> (N,)``: SD_P with the Rust kernel's analytic gradients."""

    @staticmethod
    def forward(ctx, F, corrs):  # noqa: N803 (F is the fundamental matrix)
        return _forward(ctx, F, corrs, _native.sampson_point, _native.sampson_point_grad)

    @staticmethod
    @once_differentiable
    def backward(ctx, grad):
        w = grad.detach().to(device="cpu", dtype=torch.float64)
        g_F = g_corrs = None
        if ctx.needs_input_grad[0]:
            g_F = _grad_F(ctx, ctx.d_f * w[:, None, None])
        if ctx.needs_input_grad[1]:
            g_corrs = _grad_corrs(ctx, ctx.d_corrs * w[:, None])
        return g_F, g_corrs


class AffineSampsonFunction(torch.autograd.Function):
    """``apply(F, corrs) -> (N, 2)``: SD_A,k with the Rust kernel's analytic gradients."""

    @staticmethod
    def forward(ctx, F, corrs):  # noqa: N803
        return _forward(ctx, F, corrs, _native.sampson_affine, _native.sampson_affine_grad)

    @staticmethod
    @once_differentiable
    def backward(ctx, grad):
        w = grad.detach().to(device="cpu", dtype=torch.float64)
        g_F = g_corrs = None
        if ctx.needs_input_grad[0]:
            g_F = _grad_F(ctx, torch.einsum("nk,nkab->nab", w, ctx.d_f))
        if ctx.needs_input_grad[1]:
            g_corrs = _grad_corrs(ctx, torch.einsum("nk,nkc->nc", w, ctx.d_corrs))
        return g_F, g_corrs


def point_sampson(F, corrs) -> torch.Tensor:  # noqa: N803
    """SD_P per row (N,) of ``corrs`` (N, 4) or (N, 8) under ``F`` (3, 3) or (N, 3, 3).

    Differentiable w.r.t. both arguments; for (N, 8) input the A columns get zero gradient.
    """
    return PointSampsonFunction.apply(_as_tensor(F), _as_tensor(corrs))


def affine_sampson(F, corrs) -> torch.Tensor:  # noqa: N803
    """SD_A,k per row (N, 2) of ``corrs`` (N, 8) under ``F`` (3, 3) or (N, 3, 3).

    Differentiable w.r.t. both arguments. SD_A is ``affine_sampson(F, corrs).sum(-1)``.
    """
    return AffineSampsonFunction.apply(_as_tensor(F), _as_tensor(corrs))


def _reduce(x: torch.Tensor, reduction: str) -> torch.Tensor:
    if reduction == "mean":
        return x.mean()
    if reduction == "sum":
        return x.sum()
    return x


def _check_reduction(reduction: str) -> str:
    if reduction not in ("mean", "sum", "none"):
        raise ValueError(f"reduction must be 'mean', 'sum' or 'none', got {reduction!r}")
    return reduction


class PointSampsonLoss(torch.nn.Module):
    """L_pc = mean over rows of SD_P (docs/design.md §3); ``reduction`` as in torch ('mean'
    default).

    ``forward(F, corrs)`` with F (3, 3) or (N, 3, 3) and corrs (N, 4) or (N, 8).
    """

    def __init__(self, reduction: str = "mean") -> None:
        super().__init__()
        self.reduction = _check_reduction(reduction)

    def forward(self, F, corrs) -> torch.Tensor:  # noqa: N803
        return _reduce(point_sampson(F, corrs), self.reduction)


class AffineSampsonLoss(torch.nn.Module):
    """L_aff = mean over rows of SD_A = SD_A,0 + SD_A,1 (docs/design.md §3); ``reduction`` as in
    torch ('mean' default; 'none' gives SD_A per row, (N,)).

    ``forward(F, corrs)`` with F (3, 3) or (N, 3, 3) and corrs (N, 8).
    """

    def __init__(self, reduction: str = "mean") -> None:
        super().__init__()
        self.reduction = _check_reduction(reduction)

    def forward(self, F, corrs) -> torch.Tensor:  # noqa: N803
        return _reduce(affine_sampson(F, corrs).sum(dim=-1), self.reduction)


def _split(F: torch.Tensor, corrs: torch.Tensor):
    F = F if F.dim() == 3 else F.expand(corrs.shape[0], 3, 3)
    one = torch.ones_like(corrs[:, 0])
    p1 = torch.stack([corrs[:, 0], corrs[:, 1], one], dim=-1)
    p2 = torch.stack([corrs[:, 2], corrs[:, 3], one], dim=-1)
    l1 = (F @ p1.unsqueeze(-1)).squeeze(-1)  # F p1
    l2 = (F.transpose(1, 2) @ p2.unsqueeze(-1)).squeeze(-1)  # F^T p2
    return F, p1, p2, l1, l2


def reference_point_sampson(F, corrs) -> torch.Tensor:  # noqa: N803
    """SD_P (N,) in plain torch ops (autograd through them); a reference for the kernels."""
    _, _, p2, l1, l2 = _split(_as_tensor(F), _as_tensor(corrs))
    e = (p2 * l1).sum(-1)
    return e**2 / (l1[:, 0] ** 2 + l1[:, 1] ** 2 + l2[:, 0] ** 2 + l2[:, 1] ** 2)


def reference_affine_sampson(F, corrs) -> torch.Tensor:  # noqa: N803
    """SD_A,k (N, 2) in plain torch ops (autograd through them); a reference for the kernels.

    r = A^T l1[:2] + l2[:2]; its Jacobian w.r.t. (x1, y1) is A^T F[:2, :2], w.r.t. (x2, y2)
    is F[:2, :2]^T, and w.r.t. column k of A is l1[:2].
    """
    corrs = _as_tensor(corrs)
    F, _, _, l1, l2 = _split(_as_tensor(F), corrs)
    A = corrs[:, 4:8].reshape(-1, 2, 2)
    At = A.transpose(1, 2)
    r = (At @ l1[:, :2].unsqueeze(-1)).squeeze(-1) + l2[:, :2]
    F22 = F[:, :2, :2]
    j1 = At @ F22
    j2 = F22.transpose(1, 2)
    g = (j1**2).sum(-1) + (j2**2).sum(-1) + (l1[:, :2] ** 2).sum(-1, keepdim=True)
    return r**2 / g
