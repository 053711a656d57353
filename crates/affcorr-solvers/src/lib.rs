//! Minimal and non-minimal solvers (DESIGN.md §4). In progress.
