"""The shape network: E_os (orientation and scale per patch) and E_aff (residual shape per pair).

Paper §3.2.2, docs/design.md §2 and §6. One module, one ONNX graph:

    patch_a, patch_b (N, 1, 32, 32) grayscale in [0, 1]
      -> angle_logits_a/b (N, K_theta), scale_logits_a/b (N, K_s), residual_shape (N, 3)

- **E_os** (S3Esti style) classifies each patch's orientation over ``K_theta`` bins on
  [-pi, pi) and its scale over ``K_s`` log-spaced bins. The decoded values are the softmax
  circular mean of the angle bins and the softmax geometric mean of the scale bins
  (:func:`decode_orientation`, :func:`decode_scale`); the runner does the same from the bin
  centres stored in the ONNX metadata. Patch B of a pair whose content is patch A's rotated by
  phi and magnified by s gets O_B - O_A = phi and S_B / S_A = s, hence A = S R(O) A' with
  O = O_B - O_A, S = S_B / S_A (paper eqs. 7-11).
- **E_aff** sees patch A and patch B resampled into A's frame by the similarity (O, S) that E_os
  predicted, and regresses the residual shape A'' = (x0, x1, x2). ``1 + x0`` and ``1 + x2`` are
  exponentials, so A'' is always in the domain of docs/design.md §2's det-normalisation.

Each patch is normalised to zero mean and unit standard deviation inside the graph, so the runner
feeds raw grayscale; illumination changes that are affine in intensity do not reach the weights.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

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


@dataclass(frozen=True)
class Architecture:
    """The layer plan of both sub-networks; checkpoints record its ``name``.

    ``os_layers`` / ``aff_layers``: (output channels, stride) per 3x3 convolution; both trunks
    end at 4x4. ``aff_size``: E_aff sees both patches at this resolution (32, or 16 by 2x2
    averaging over the same support). ``renormalise_b``: patch B is normalised again after its
    resampling into A's frame (the zeros outside B shift its statistics).
    """

    name: str
    os_layers: tuple[tuple[int, int], ...]
    aff_layers: tuple[tuple[int, int], ...]
    aff_size: int
    renormalise_b: bool
    hidden: int = 128


ARCHITECTURES = {
    # The first shipped model: six layers (width 8-16-32, every other one strided), full
    # resolution throughout; 3.61 M multiply-adds per pair.
    "v1": Architecture(
        "v1",
        os_layers=((8, 1), (8, 2), (16, 1), (16, 2), (32, 1), (32, 2)),
        aff_layers=((8, 1), (8, 2), (16, 1), (16, 2), (32, 1), (32, 2)),
        aff_size=32,
        renormalise_b=True,
    ),
    # Chosen for speed in ONNX Runtime (benches/results/shape.md): a stride-2 stem, since
    # full-resolution layers cost the most, few wide layers rather than more narrow ones, and
    # E_aff at 16x16 (A'' is a low-frequency property of the pair); 1.59 M multiply-adds.
    "fast": Architecture(
        "fast",
        os_layers=((8, 2), (16, 2), (32, 1), (32, 2)),
        aff_layers=((16, 1), (16, 2), (32, 2)),
        aff_size=16,
        renormalise_b=False,
    ),
}
DEFAULT_ARCHITECTURE = "v1"


def architecture(name: str) -> Architecture:
    """The preset called ``name``; a ValueError lists the known ones."""
    try:
        return ARCHITECTURES[name]
    except KeyError:
        raise ValueError(
            f"architecture: unknown {name!r}; known: {', '.join(ARCHITECTURES)}"
        ) from None


class Trunk(nn.Module):
    """Patches -> a feature vector: 3x3 convolutions (``layers``) down to 4x4, then a linear
    layer."""

    def __init__(self, c_in: int, layers: tuple[tuple[int, int], ...], out: int) -> None:
        super().__init__()
        convs, c = [], c_in
        for c_out, stride in layers:
            convs.append(_conv(c, c_out, stride))
            c = c_out
        self.features = nn.Sequential(*convs)
        self.head = nn.Sequential(
            nn.Flatten(), nn.Linear(c * 16, out), nn.BatchNorm1d(out), nn.ReLU(inplace=True)
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.features(x))


class OrientationScaleNet(nn.Module):
    """E_os: one patch -> (angle logits, scale logits). Shared by both views."""

    def __init__(self, arch: Architecture | str = DEFAULT_ARCHITECTURE) -> None:
        super().__init__()
        self.arch = architecture(arch) if isinstance(arch, str) else arch
        self.trunk = Trunk(1, self.arch.os_layers, self.arch.hidden)
        self.angle = nn.Linear(self.arch.hidden, ANGLE_BINS)
        self.scale = nn.Linear(self.arch.hidden, SCALE_BINS)

    def logits(self, normalised: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Logits of patches already passed through :func:`normalise_patches`."""
        h = self.trunk(normalised)
        return self.angle(h), self.scale(h)

    def forward(self, patch: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.logits(normalise_patches(patch))


class ResidualShapeNet(nn.Module):
    """E_aff: (patch A, patch B in A's frame by E_os's similarity) -> A'' = (x0, x1, x2)."""

    def __init__(self, arch: Architecture | str = DEFAULT_ARCHITECTURE) -> None:
        super().__init__()
        self.arch = architecture(arch) if isinstance(arch, str) else arch
        self.trunk = Trunk(2, self.arch.aff_layers, self.arch.hidden)
        self.out = nn.Linear(self.arch.hidden, 3)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)

    def forward(
        self,
        norm_a: torch.Tensor,
        norm_b: torch.Tensor,
        cos_o: torch.Tensor,
        sin_o: torch.Tensor,
        scale: torch.Tensor,
    ) -> torch.Tensor:
        """``norm_a``, ``norm_b``: normalised 32x32 patches; (cos O, sin O, S): the similarity
        x2 = S R(O) x1 from E_os."""
        factor = PATCH_SIZE // self.arch.aff_size
        if factor > 1:
            norm_a, norm_b = F.avg_pool2d(norm_a, factor), F.avg_pool2d(norm_b, factor)
        b_in_a = similarity_to_frame_a(norm_b, cos_o, sin_o, scale)
        if self.arch.renormalise_b:
            b_in_a = normalise_patches(b_in_a)
        u = self.out(self.trunk(torch.cat([norm_a, b_in_a], dim=1)))
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
    square and of the same size, so the normalised grid coordinates transform by the same 2x2
    matrix. Outside patch B reads zero (the patch mean, for a normalised patch).
    """
    size = patch_b.shape[-1]
    c, s = (cos_o * scale).view(-1, 1, 1), (sin_o * scale).view(-1, 1, 1)
    # Normalised coordinates of the pixel centres (align_corners=False); affine_grid itself
    # does not export to ONNX.
    u = (torch.arange(size, dtype=patch_b.dtype) + 0.5) * (2.0 / size) - 1.0
    bx, by = u.view(1, 1, -1), u.view(1, -1, 1)
    grid = torch.stack([c * bx - s * by, s * bx + c * by], dim=-1)
    return F.grid_sample(patch_b, grid, mode="bilinear", padding_mode="zeros", align_corners=False)


class ShapeNet(nn.Module):
    """E_os + E_aff in the ONNX contract of docs/design.md §6."""

    def __init__(self, arch: Architecture | str = DEFAULT_ARCHITECTURE) -> None:
        super().__init__()
        self.arch = architecture(arch) if isinstance(arch, str) else arch
        self.os = OrientationScaleNet(self.arch)
        self.aff = ResidualShapeNet(self.arch)

    def forward(self, patch_a: torch.Tensor, patch_b: torch.Tensor):
        norm_a, norm_b = normalise_patches(patch_a), normalise_patches(patch_b)
        # Two calls rather than one on the concatenated batch: the same convolutions without
        # the copy.
        angle_a, scale_a = self.os.logits(norm_a)
        angle_b, scale_b = self.os.logits(norm_b)
        ca, sa = orientation_vector(angle_a)
        cb, sb = orientation_vector(angle_b)
        # cos and sin of O_B - O_A
        c, s = cb * ca + sb * sa, sb * ca - cb * sa
        scale = decode_scale(scale_b) / decode_scale(scale_a)
        residual = self.aff(norm_a, norm_b, c, s, scale)
        return angle_a, angle_b, scale_a, scale_b, residual


def synthesize_torch(
    orientation: torch.Tensor, scale: torch.Tensor, residual: torch.Tensor
) -> torch.Tensor:
    """A = S R(O) A'(A'') as (N, 2, 2), differentiable (docs/design.md §2; geom's
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
