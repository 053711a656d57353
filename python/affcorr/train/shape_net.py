"""The shape network: E_os (orientation and scale per patch) and E_aff (residual shape per pair).

Paper §3.2.2, DESIGN.md §2 and §6. One module, one ONNX graph:

    patch_a, patch_b (N, 1, 32, 32) grayscale in [0, 1]
      -> angle_logits_a/b (N, K_theta), scale_logits_a/b (N, K_s), residual_shape (N, 3)

- **E_os** (S3Esti style) classifies each patch's orientation over ``K_theta`` bins on
  [-pi, pi) and its scale over ``K_s`` log-spaced bins. The decoded values are the softmax
  circular mean of the angle bins and the softmax geometric mean of the scale bins
  (:func:`decode_orientation`, :func:`decode_scale`); the runner does the same from the bin
  centres stored in the ONNX metadata. Patch B of a pair whose content is patch A's rotated by
  phi and magnified by s gets O_B - O_A = phi and S_B / S_A = s, hence A = S R(O) A' with
  O = O_B - O_A, S = S_B / S_A (paper eqs. 4-7).
- **E_aff** sees patch A and patch B resampled into A's frame by the similarity (O, S) that E_os
  predicted, and regresses the residual shape A'' = (x0, x1, x2). ``1 + x0`` and ``1 + x2`` are
  exponentials, so A'' is always in the domain of DESIGN.md §2's det-normalisation.

Each patch is normalised to zero mean and unit standard deviation inside the graph, so the runner
feeds raw grayscale; illumination changes that are affine in intensity do not reach the weights.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F  # noqa: N812
from torch import nn

PATCH_SIZE = 32
ANGLE_BINS = 72
SCALE_BINS = 25
# log2 of the scale bin centres: [-3, 3] in quarter octaves. Relative scales up to 4x between
# views need two octaves on either side of a patch's own scale.
LOG2_SCALE_RANGE = 3.0


def angle_bin_centres() -> torch.Tensor:
    """Centres of the angle bins (radians), ``K_theta`` values on [-pi, pi)."""
    k = torch.arange(ANGLE_BINS, dtype=torch.float64)
    return -math.pi + (k + 0.5) * (2.0 * math.pi / ANGLE_BINS)


def scale_bin_centres() -> torch.Tensor:
    """Centres of the scale bins (linear scale factors), log-spaced on 2^[-3, 3]."""
    return torch.pow(
        2.0, torch.linspace(-LOG2_SCALE_RANGE, LOG2_SCALE_RANGE, SCALE_BINS, dtype=torch.float64)
    )


def normalise_patches(x: torch.Tensor, eps: float = 1e-3) -> torch.Tensor:
    """Zero mean, unit standard deviation per patch (flat patches stay near zero)."""
    mean = x.mean(dim=(2, 3), keepdim=True)
    std = ((x - mean) ** 2).mean(dim=(2, 3), keepdim=True).add(eps * eps).sqrt()
    return (x - mean) / std


def _conv(c_in: int, c_out: int, stride: int) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(c_in, c_out, 3, stride=stride, padding=1, bias=False),
        nn.BatchNorm2d(c_out),
        nn.ReLU(inplace=True),
    )


class Trunk(nn.Module):
    """32x32 patches -> a feature vector: strided 3x3 convolutions down to 4x4, then a linear
    layer. Small on purpose (about 0.5 MFLOP per patch): the runner's goal is >= 20k pairs/s on
    two CPU cores."""

    def __init__(self, c_in: int, width: int, out: int) -> None:
        super().__init__()
        w = width
        self.features = nn.Sequential(
            _conv(c_in, w, 1),  # 32
            _conv(w, w, 2),  # 16
            _conv(w, 2 * w, 1),
            _conv(2 * w, 2 * w, 2),  # 8
            _conv(2 * w, 4 * w, 1),
            _conv(4 * w, 4 * w, 2),  # 4
        )
        self.head = nn.Sequential(
            nn.Flatten(), nn.Linear(4 * w * 16, out), nn.BatchNorm1d(out), nn.ReLU(inplace=True)
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.features(x))


class OrientationScaleNet(nn.Module):
    """E_os: one patch -> (angle logits, scale logits). Shared by both views."""

    def __init__(self, width: int = 8, hidden: int = 128) -> None:
        super().__init__()
        self.trunk = Trunk(1, width, hidden)
        self.angle = nn.Linear(hidden, ANGLE_BINS)
        self.scale = nn.Linear(hidden, SCALE_BINS)

    def forward(self, patch: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        h = self.trunk(normalise_patches(patch))
        return self.angle(h), self.scale(h)


class ResidualShapeNet(nn.Module):
    """E_aff: (patch A, patch B in A's frame) -> A'' = (x0, x1, x2)."""

    def __init__(self, width: int = 8, hidden: int = 128) -> None:
        super().__init__()
        self.trunk = Trunk(2, width, hidden)
        self.out = nn.Linear(hidden, 3)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)

    def forward(self, patch_a: torch.Tensor, patch_b_in_a: torch.Tensor) -> torch.Tensor:
        x = torch.cat([normalise_patches(patch_a), normalise_patches(patch_b_in_a)], dim=1)
        u = self.out(self.trunk(x))
        # 1 + x0 = exp(u0), 1 + x2 = exp(u2): always inside the det-normalisation's domain.
        return torch.stack([torch.exp(u[:, 0]) - 1.0, u[:, 1], torch.exp(u[:, 2]) - 1.0], dim=1)


def orientation_vector(angle_logits: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(cos O, sin O) of the softmax circular mean over the angle bin centres. (ONNX has no
    atan2, so the graph works with the unit vector.)"""
    p = torch.softmax(angle_logits, dim=-1)
    c = angle_bin_centres().to(p)
    x, y = p @ torch.cos(c), p @ torch.sin(c)
    r = torch.sqrt(x * x + y * y).clamp_min(1e-12)
    return x / r, y / r


def decode_orientation(angle_logits: torch.Tensor) -> torch.Tensor:
    """Softmax circular mean over the angle bin centres (radians)."""
    c, s = orientation_vector(angle_logits)
    return torch.atan2(s, c)


def decode_scale(scale_logits: torch.Tensor) -> torch.Tensor:
    """Softmax geometric mean over the scale bin centres."""
    p = torch.softmax(scale_logits, dim=-1)
    return torch.exp(p @ torch.log(scale_bin_centres().to(p)))


def similarity_to_frame_a(
    patch_b: torch.Tensor, cos_o: torch.Tensor, sin_o: torch.Tensor, scale: torch.Tensor
) -> torch.Tensor:
    """Resample patch B into patch A's frame under the similarity x2 = S R(O) x1.

    Pixel u of the output (offset from the centre) reads patch B at S R(O) u; both patches are
    square, so the normalised grid coordinates transform by the same 2x2 matrix. Outside
    patch B reads zero, i.e. the patch mean after normalisation.
    """
    c, s = (cos_o * scale).view(-1, 1, 1), (sin_o * scale).view(-1, 1, 1)
    # Normalised coordinates of the pixel centres (align_corners=False); affine_grid itself
    # does not export to ONNX.
    u = (torch.arange(PATCH_SIZE, dtype=patch_b.dtype) + 0.5) * (2.0 / PATCH_SIZE) - 1.0
    bx, by = u.view(1, 1, -1), u.view(1, -1, 1)
    grid = torch.stack([c * bx - s * by, s * bx + c * by], dim=-1)
    b = normalise_patches(patch_b)
    return F.grid_sample(b, grid, mode="bilinear", padding_mode="zeros", align_corners=False)


class ShapeNet(nn.Module):
    """E_os + E_aff in the ONNX contract of DESIGN.md §6."""

    def __init__(self, width: int = 8, hidden: int = 128) -> None:
        super().__init__()
        self.os = OrientationScaleNet(width, hidden)
        self.aff = ResidualShapeNet(width, hidden)

    def forward(self, patch_a: torch.Tensor, patch_b: torch.Tensor):
        n = patch_a.shape[0]
        angle, scale = self.os(torch.cat([patch_a, patch_b], dim=0))
        angle_a, angle_b = angle[:n], angle[n:]
        scale_a, scale_b = scale[:n], scale[n:]
        ca, sa = orientation_vector(angle_a)
        cb, sb = orientation_vector(angle_b)
        # cos and sin of O_B - O_A
        c, s = cb * ca + sb * sa, sb * ca - cb * sa
        scale = decode_scale(scale_b) / decode_scale(scale_a)
        residual = self.aff(patch_a, similarity_to_frame_a(patch_b, c, s, scale))
        return angle_a, angle_b, scale_a, scale_b, residual


def synthesize_torch(
    orientation: torch.Tensor, scale: torch.Tensor, residual: torch.Tensor
) -> torch.Tensor:
    """A = S R(O) A'(A'') as (N, 2, 2), differentiable (DESIGN.md §2; geom's
    ``synthesize_affine`` in torch)."""
    b11, b21, b22 = 1.0 + residual[:, 0], residual[:, 1], 1.0 + residual[:, 2]
    r = torch.rsqrt(b11 * b22)
    c, s = torch.cos(orientation) * scale, torch.sin(orientation) * scale
    # S R(O) @ [[b11, 0], [b21, b22]] / sqrt(b11 b22)
    a11 = (c * b11 - s * b21) * r
    a12 = (-s * b22) * r
    a21 = (s * b11 + c * b21) * r
    a22 = (c * b22) * r
    return torch.stack([torch.stack([a11, a12], -1), torch.stack([a21, a22], -1)], 1)
