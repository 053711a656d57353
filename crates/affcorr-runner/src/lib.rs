//! ONNX runner for the matcher and shape networks (DESIGN.md §6). Empty for now: lands with issues #5 and #6.
