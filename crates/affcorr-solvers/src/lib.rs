//! Minimal and non-minimal solvers (DESIGN.md §4).
//!
//! Module map:
//! - [`poly`]: real roots of univariate polynomials (Sturm sequences), shared by the solvers.
//!
//! Solvers are being added (issue #3).

pub mod poly;
