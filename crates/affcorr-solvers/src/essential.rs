//! Essential-matrix solvers for calibrated cameras (docs/design.md §4), one file per solver.
//!
//! | solver | sample | max models | reference |
//! |---|---|---|---|
//! | [`essential_5pt`] | 5 points | [`ESSENTIAL_5PT_MAX_SOLUTIONS`] = 10 | Nistér 2004; Stewénius et al. 2006 |
//! | [`essential_2ac`] | 2 ACs | [`ESSENTIAL_2AC_MAX_SOLUTIONS`] = 10 | Barath & Hajder 2018 (5 best rows + 5-point machinery, ranked by the 6th) |
//! | [`essential_1ac2pt`] | 1 AC + 2 points | [`ESSENTIAL_1AC2PT_MAX_SOLUTIONS`] = 10 | 5 linear rows + 5-point machinery |
//! | [`essential_8pt`] | N ≥ 8 points | 1 | Longuet-Higgins 1981; Hartley 1997 |
//! | [`essential_lsq`] | points + ACs, ≥ 8 rows | 1 | least squares, projected to the essential manifold |
//!
//! Conventions (docs/design.md §2): inputs are in normalised coordinates, x̂ = K⁻¹p and
//! Â = K2\[:2,:2\]⁻¹ A K1\[:2,:2\] ([`affcorr_geom::camera::normalize_ac`]); the models satisfy
//! x̂2ᵀ E x̂1 = 0 with E = \[t\]× R for X2 = R X1 + t, and have unit Frobenius norm (the sign is
//! arbitrary). Each solver writes into a caller-owned buffer of at least its `*_MAX_SOLUTIONS`
//! matrices and returns how many it wrote; a degenerate sample gives 0, never a panic.
//! The minimal solvers allocate nothing.
//!
//! - `constraints`: the linear rows (point and affine), null spaces, and the ten cubic
//!   essential constraints over a linear family, shared by the 5-point, 2AC and 1AC + 2-point
//!   solvers.
//!
//! Poses (R, t) from these matrices: [`crate::relpose`].

mod constraints;
mod essential_1ac2pt;
mod essential_2ac;
mod essential_5pt;
mod essential_8pt;

pub use essential_1ac2pt::{ESSENTIAL_1AC2PT_MAX_SOLUTIONS, essential_1ac2pt};
pub use essential_2ac::{ESSENTIAL_2AC_MAX_SOLUTIONS, essential_2ac};
pub use essential_5pt::{ESSENTIAL_5PT_MAX_SOLUTIONS, essential_5pt};
pub use essential_8pt::{
    ESSENTIAL_8PT_MAX_SOLUTIONS, essential_8pt, essential_lsq, project_to_essential,
};
