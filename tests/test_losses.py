"""Torch losses over the Rust Sampson kernels (docs/design.md §3): agreement with the pure-torch
reference, gradcheck, dtype/shape handling, and that the losses drive A toward the exact one."""

from __future__ import annotations

import subprocess
import sys

import affcorr
import numpy as np
import pytest
from conftest import random_scene

torch = pytest.importorskip("torch", reason="torch (affcorr[train], Debian python3-torch) missing")

from affcorr.losses import (  # noqa: E402 (after the importorskip)
    AffineSampsonFunction,
    AffineSampsonLoss,
    PointSampsonFunction,
    PointSampsonLoss,
    affine_sampson,
    point_sampson,
    reference_affine_sampson,
    reference_point_sampson,
)


def perturbed(rng, n, scene=None):
    """A scene's unit F and n exact ACs with ~1 px noise on x2 and ~5% on A, as float64 tensors;
    also the exact ACs."""
    scene = scene or random_scene(rng)
    exact = affcorr.correspondences_from_homography(scene.H, scene.sample_pixels(rng, n))
    noisy = exact.copy()
    noisy[:, 2:4] += rng.uniform(-1, 1, (n, 2))
    noisy[:, 4:8] += rng.uniform(-0.05, 0.05, (n, 4))
    return torch.from_numpy(scene.F.copy()), torch.from_numpy(noisy), torch.from_numpy(exact)


def test_torch_is_not_imported_by_the_package():
    code = "import sys, affcorr; assert 'torch' not in sys.modules, 'affcorr imported torch'"
    subprocess.run([sys.executable, "-c", code], check=True)


def test_kernels_agree_with_the_torch_reference(rng):
    F, corrs, _ = perturbed(rng, 200)
    tol = {"rtol": 1e-10, "atol": 1e-12}
    torch.testing.assert_close(point_sampson(F, corrs), reference_point_sampson(F, corrs), **tol)
    torch.testing.assert_close(
        point_sampson(F, corrs[:, :4]), reference_point_sampson(F, corrs), **tol
    )
    sd = affine_sampson(F, corrs)
    assert sd.shape == (200, 2) and sd.dtype == torch.float64
    torch.testing.assert_close(sd, reference_affine_sampson(F, corrs), **tol)
    # The autograd Functions behind the functional forms.
    torch.testing.assert_close(AffineSampsonFunction.apply(F, corrs), sd, rtol=0, atol=0)
    torch.testing.assert_close(
        PointSampsonFunction.apply(F, corrs), point_sampson(F, corrs), rtol=0, atol=0
    )
    # ... and with the numpy-facing bindings.
    np.testing.assert_array_equal(sd.numpy(), affcorr.sampson_affine(F.numpy(), corrs.numpy()))


def test_gradients_agree_with_autograd_through_the_reference(rng):
    F1, c1, _ = perturbed(rng, 30)
    F2, c2, _ = perturbed(rng, 20)
    corrs = torch.cat([c1, c2])
    for F in (F1, torch.stack([F1] * 30 + [F2] * 20)):
        w = torch.from_numpy(rng.uniform(0.5, 2.0, (50, 2)))
        grads = []
        for fun in (affine_sampson, reference_affine_sampson):
            Fg, cg = F.clone().requires_grad_(), corrs.clone().requires_grad_()
            (fun(Fg, cg) * w).sum().backward()
            grads.append((Fg.grad, cg.grad))
        assert grads[0][0].shape == F.shape
        for a, b in zip(grads[0], grads[1]):
            torch.testing.assert_close(a, b, rtol=1e-9, atol=1e-12 * b.abs().max().item())
        grads = []
        for fun in (point_sampson, reference_point_sampson):
            Fg, cg = F.clone().requires_grad_(), corrs.clone().requires_grad_()
            (fun(Fg, cg) * w[:, 0]).sum().backward()
            grads.append((Fg.grad, cg.grad))
        assert not grads[0][1][:, 4:].any()
        for a, b in zip(grads[0], grads[1]):
            torch.testing.assert_close(a, b, rtol=1e-9, atol=1e-12 * b.abs().max().item())


def _normalised(rng, n):
    """gradcheck perturbs every input by 1e-6: in pixels that step would be far too large for
    F's tiny entries, so check on normalised coordinates (K = I), where all entries are O(1)."""
    scene = random_scene(rng)
    scene.K1 = scene.K2 = np.eye(3)
    x1 = rng.uniform(-0.3, 0.3, (n, 2))
    exact = affcorr.correspondences_from_homography(scene.H, x1)
    noisy = exact + rng.uniform(-0.05, 0.05, exact.shape)
    return torch.from_numpy(scene.F.copy()), torch.from_numpy(noisy)


@pytest.mark.parametrize("per_row_f", [False, True])
def test_gradcheck(rng, per_row_f):
    F, corrs = _normalised(rng, 5)
    if per_row_f:
        F = torch.stack([F + 0.01 * torch.from_numpy(rng.normal(size=(3, 3))) for _ in range(5)])
    F.requires_grad_()
    corrs.requires_grad_()
    assert torch.autograd.gradcheck(affine_sampson, (F, corrs), eps=1e-6, atol=1e-7, rtol=1e-5)
    assert torch.autograd.gradcheck(point_sampson, (F, corrs), eps=1e-6, atol=1e-7, rtol=1e-5)
    c4 = corrs.detach()[:, :4].clone().requires_grad_()
    assert torch.autograd.gradcheck(point_sampson, (F, c4), eps=1e-6, atol=1e-7, rtol=1e-5)
    # Only one input requiring grad.
    assert torch.autograd.gradcheck(
        affine_sampson, (F.detach(), corrs), eps=1e-6, atol=1e-7, rtol=1e-5
    )


def test_losses_are_positive_means(rng):
    F, corrs, exact = perturbed(rng, 40)
    sd_p = reference_point_sampson(F, corrs)
    sd_a = reference_affine_sampson(F, corrs).sum(1)
    l_pc, l_aff = PointSampsonLoss()(F, corrs), AffineSampsonLoss()(F, corrs)
    assert l_pc.dim() == 0 and l_pc > 0 and l_aff > 0
    torch.testing.assert_close(l_pc, sd_p.mean(), rtol=1e-10, atol=0)
    torch.testing.assert_close(l_aff, sd_a.mean(), rtol=1e-10, atol=0)
    torch.testing.assert_close(AffineSampsonLoss("sum")(F, corrs), sd_a.sum(), rtol=1e-10, atol=0)
    torch.testing.assert_close(AffineSampsonLoss("none")(F, corrs), sd_a, rtol=1e-10, atol=1e-12)
    assert AffineSampsonLoss()(F, exact) < 1e-12
    assert PointSampsonLoss()(F, exact) < 1e-12
    with pytest.raises(ValueError, match="reduction"):
        PointSampsonLoss("max")


def test_gradient_steps_on_a_drive_it_to_the_affine_constraint(rng):
    F, _, exact = perturbed(rng, 50)
    noisy = exact.clone()
    noisy[:, 4:8] += torch.from_numpy(rng.uniform(-0.1, 0.1, (50, 4)))
    loss = AffineSampsonLoss()
    # The segment toward the exact A goes down hill: the residual is linear in A.
    A = noisy[:, 4:8].clone().requires_grad_()
    l0 = loss(F, torch.cat([noisy[:, :4], A], 1))
    l0.backward()
    direction = exact[:, 4:8] - noisy[:, 4:8]
    assert (A.grad * direction).sum() < 0
    half = torch.cat([noisy[:, :4], noisy[:, 4:8] + 0.5 * direction], 1)
    assert loss(F, half) < l0
    # Plain gradient descent on A alone: monotone, and the constraint ends up satisfied.
    A = noisy[:, 4:8].clone().requires_grad_()
    # mean over N rows: each row sees lr / N, and SD_A,k ≤ r_k² / ‖l1[:2]‖² makes a step of
    # N / 5 contract every row.
    opt = torch.optim.SGD([A], lr=50 / 5)
    history = []
    for _ in range(200):
        opt.zero_grad()
        value = loss(F, torch.cat([noisy[:, :4], A], 1))
        value.backward()
        opt.step()
        history.append(value.item())
    assert all(b <= a for a, b in zip(history, history[1:]))
    assert history[-1] < 1e-3 * history[0]


def test_gradient_step_on_x2_lowers_the_point_loss(rng):
    F, corrs, _ = perturbed(rng, 50)
    x2 = corrs[:, 2:4].clone().requires_grad_()
    loss = PointSampsonLoss()
    l0 = loss(F, torch.cat([corrs[:, :2], x2], 1))
    l0.backward()
    with torch.no_grad():
        l1 = loss(F, torch.cat([corrs[:, :2], x2 - 0.1 * x2.grad], 1))
    assert l1 < l0


def test_float32_inputs_and_grads_keep_their_dtype(rng):
    F, corrs, _ = perturbed(rng, 10)
    F32 = F.float().requires_grad_()
    c32 = corrs.float().requires_grad_()
    out = affine_sampson(F32, c32)
    assert out.dtype == torch.float32
    # Computed in float64 from the float32 values, rounded once at the end.
    torch.testing.assert_close(
        out, affine_sampson(F32.double(), c32.double()).float(), rtol=0, atol=0
    )
    out.sum().backward()
    assert F32.grad.dtype == torch.float32 and c32.grad.dtype == torch.float32
    assert F32.grad.shape == (3, 3) and c32.grad.shape == (10, 8)
    # Mixed: the output takes the promoted dtype, each gradient its own input's.
    Fd = F.clone().requires_grad_()
    c32.grad = None
    out = point_sampson(Fd, c32)
    assert out.dtype == torch.float64
    out.sum().backward()
    assert Fd.grad.dtype == torch.float64 and c32.grad.dtype == torch.float32


def test_no_grad_and_numpy_inputs(rng):
    F, corrs, _ = perturbed(rng, 10)
    with torch.no_grad():
        a = affine_sampson(F, corrs)
    b = affine_sampson(F.numpy(), corrs.numpy())
    assert not a.requires_grad and not b.requires_grad
    torch.testing.assert_close(a, b, rtol=0, atol=0)


def test_bad_inputs_raise_value_errors_naming_the_argument(rng):
    F, corrs, _ = perturbed(rng, 4)
    with pytest.raises(ValueError, match=r"corrs must have shape \(N, 8\), got \(4, 4\)"):
        affine_sampson(F, corrs[:, :4])
    with pytest.raises(ValueError, match=r"F must have shape"):
        point_sampson(F[:2], corrs)
    with pytest.raises(ValueError, match="F: expected 4 rows, got 2"):
        affine_sampson(torch.stack([F, F]), corrs)
    bad = corrs.clone()
    bad[2, 0] = float("nan")
    with pytest.raises(ValueError, match=r"corrs\[2\] contains NaN"):
        AffineSampsonLoss()(F, bad.requires_grad_())
