//! Relative pose from one affine correspondence and two point correspondences: the hybrid
//! minimal sample (issue 22's "1 AC + points").
//!
//! Each constraint is linear in E (docs/design.md §2): the AC gives its point row p̂2ᵀ E p̂1 = 0
//! and the two rows of Âᵀ (E p̂1)₁:₂ + (Eᵀ p̂2)₁:₂ = 0, each point one more point row. Five
//! rows for E's five degrees of freedom: the system is exactly minimal, its null space is
//! 4-dimensional, E = x·X + y·Y + z·Z + W, and the five-point machinery
//! ([`super::essential_5pt`], Nistér 2004 eqs. 6–15) returns the up to ten essential matrices of
//! that family. No row is dropped and none is left over to rank the candidates, so RANSAC's
//! scoring picks among them, as for five points.
//!
//! Why a hybrid sample: two ACs ([`super::essential_2ac`]) need the fewest correspondences but
//! take four of their five rows from the affine maps, whose errors are relatively larger than
//! the points' (a few percent of A against a fraction of a pixel); five points need no A but
//! 5 correspondences. One AC and two points use two affine rows and three correspondences: an
//! all-inlier sample at inlier ratio w comes w³ of the time (w² for 2 ACs, w⁵ for 5 points).
//! Barath, Polic, Förstner, Sattler, Pajdla, Kukelova, "Making affine correspondences work in
//! camera geometry computation", ECCV 2020, discuss when fewer affine rows pay.

use super::constraints::{affine_rows, null_space, point_row};
use super::essential_5pt::solve_from_basis;
use affcorr_geom::{AffineCorrespondence, Mat3, Vec2};

/// Largest number of essential matrices [`essential_1ac2pt`] writes.
pub const ESSENTIAL_1AC2PT_MAX_SOLUTIONS: usize = 10;

/// The essential matrices (unit Frobenius norm, up to sign) consistent with one affine
/// correspondence `ac` and two point correspondences `x1[k] ↔ x2[k]`, all in normalised
/// coordinates (x̂ = K⁻¹p, Â = K2\[:2,:2\]⁻¹ A K1\[:2,:2\]; see
/// [`affcorr_geom::camera::normalize_ac`]).
///
/// Writes up to [`ESSENTIAL_1AC2PT_MAX_SOLUTIONS`] models into `out` (which must be at least
/// that long) and returns how many. Degenerate samples (not two points, det A ≤ 0, a point
/// repeating the AC's or another, a rank-deficient system, NaN or infinity) give 0 models.
///
/// ```
/// use affcorr_geom::camera::normalize_ac;
/// use affcorr_geom::synthetic::PlaneScene;
/// use affcorr_solvers::essential::{essential_1ac2pt, ESSENTIAL_1AC2PT_MAX_SOLUTIONS};
/// use affcorr_geom::Mat3;
/// use rand::SeedableRng;
/// let mut rng = rand_pcg::Pcg64::seed_from_u64(1);
/// let scene = PlaneScene::random(&mut rng);
/// let acs: Vec<_> = scene.sample(&mut rng, 3).iter()
///     .map(|ac| normalize_ac(ac, &scene.k1, &scene.k2)).collect();
/// let (x1, x2) = ([acs[1].x1, acs[2].x1], [acs[1].x2, acs[2].x2]);
/// let mut out = [Mat3::zeros(); ESSENTIAL_1AC2PT_MAX_SOLUTIONS];
/// let n = essential_1ac2pt(&acs[0], &x1, &x2, &mut out);
/// let truth = scene.essential().normalize();
/// assert!(out[..n].iter().any(|e| (e - truth).norm().min((e + truth).norm()) < 1e-8));
/// ```
pub fn essential_1ac2pt(
    ac: &AffineCorrespondence,
    x1: &[Vec2],
    x2: &[Vec2],
    out: &mut [Mat3],
) -> usize {
    if x1.len() != 2 || x2.len() != 2 || out.len() < ESSENTIAL_1AC2PT_MAX_SOLUTIONS {
        return 0;
    }
    // Relative to ‖A‖², as in essential_2ac: a singular pixel A normalised leaves a det of
    // rounding size and either sign.
    if !(ac.a.determinant() > 1e-12 * ac.a.norm_squared()) {
        return 0;
    }
    let [r1, r2] = affine_rows(ac);
    let rows = [
        point_row(&ac.x1, &ac.x2),
        r1,
        r2,
        point_row(&x1[0], &x2[0]),
        point_row(&x1[1], &x2[1]),
    ];
    let mut basis = [[0.0; 9]; 4];
    if !null_space(&rows, &mut basis) {
        return 0;
    }
    solve_from_basis(&basis, out)
}
