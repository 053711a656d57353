//! Point and affine Sampson distances with analytic gradients (DESIGN.md §3). In progress.
