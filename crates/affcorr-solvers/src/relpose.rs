//! Relative pose (R, t) with X2 = R X1 + t from the essential solvers ([`crate::essential`]).
//!
//! The decomposition and the cheirality test live in [`affcorr_geom::epipolar`] (re-exported
//! here): E = U diag(1, 1, 0) Vᵀ has four factorisations R ∈ {U W Vᵀ, U Wᵀ Vᵀ}, t = ±u₃
//! (Hartley & Zisserman, Result 9.19), and the one that puts the sample in front of both cameras
//! is kept. These wrappers run a solver, then keep, for each of its essential matrices, the
//! factorisation with every sample correspondence in front of both cameras (minimal solvers) or
//! the most of them (non-minimal solvers). t has unit norm.
//!
//! | wrapper | solver | max poses |
//! |---|---|---|
//! | [`relative_pose_5pt`] | [`essential_5pt`] | [`RELPOSE_5PT_MAX_SOLUTIONS`] |
//! | [`relative_pose_2ac`] | [`essential_2ac`] | [`RELPOSE_2AC_MAX_SOLUTIONS`] |
//! | [`relative_pose_1ac2pt`] | [`essential_1ac2pt`] | [`RELPOSE_1AC2PT_MAX_SOLUTIONS`] |
//! | [`relative_pose_8pt`] | [`essential_8pt`] | 1 |

use crate::essential::{
    ESSENTIAL_1AC2PT_MAX_SOLUTIONS, ESSENTIAL_2AC_MAX_SOLUTIONS, ESSENTIAL_5PT_MAX_SOLUTIONS,
    essential_1ac2pt, essential_2ac, essential_5pt, essential_8pt,
};
use affcorr_geom::{AffineCorrespondence, Mat3, Vec2};

pub use affcorr_geom::epipolar::{
    Pose, count_in_front, decompose_essential, pose_from_essential, pose_with_all_in_front,
    triangulate_depths,
};

/// Largest number of poses [`relative_pose_5pt`] writes.
pub const RELPOSE_5PT_MAX_SOLUTIONS: usize = ESSENTIAL_5PT_MAX_SOLUTIONS;
/// Largest number of poses [`relative_pose_2ac`] writes.
pub const RELPOSE_2AC_MAX_SOLUTIONS: usize = ESSENTIAL_2AC_MAX_SOLUTIONS;
/// Largest number of poses [`relative_pose_1ac2pt`] writes.
pub const RELPOSE_1AC2PT_MAX_SOLUTIONS: usize = ESSENTIAL_1AC2PT_MAX_SOLUTIONS;

/// Keeps the poses of `es` whose best factorisation has at least `need` of the sample in front
/// of both cameras. The minimal solvers need the whole sample in front; their E are essential up
/// to rounding, so the closed-form factorisation serves them (the SVD's projection only for the
/// over-determined fit).
fn poses_in_front(es: &[Mat3], x1: &[Vec2], x2: &[Vec2], need: usize, out: &mut [Pose]) -> usize {
    let mut n = 0;
    for e in es {
        let pose = if need == x1.len() {
            pose_with_all_in_front(e, x1, x2)
        } else {
            pose_from_essential(e, x1, x2)
                .ok()
                .and_then(|(pose, count)| (count >= need).then_some(pose))
        };
        if let Some(pose) = pose
            && n < out.len()
        {
            out[n] = pose;
            n += 1;
        }
    }
    n
}

/// Relative poses from five normalised point correspondences: [`essential_5pt`], then the
/// factorisation of each E with all five points in front of both cameras (E without one is
/// dropped). `out` must hold [`RELPOSE_5PT_MAX_SOLUTIONS`]; returns the number written.
pub fn relative_pose_5pt(x1: &[Vec2], x2: &[Vec2], out: &mut [Pose]) -> usize {
    if out.len() < RELPOSE_5PT_MAX_SOLUTIONS {
        return 0;
    }
    let mut es = [Mat3::zeros(); ESSENTIAL_5PT_MAX_SOLUTIONS];
    let n = essential_5pt(x1, x2, &mut es);
    poses_in_front(&es[..n], x1, x2, x1.len(), out)
}

/// Relative poses from two normalised ACs: [`essential_2ac`], then the factorisation of each E
/// with both AC centres in front of both cameras. `out` must hold
/// [`RELPOSE_2AC_MAX_SOLUTIONS`]; returns the number written (best first).
pub fn relative_pose_2ac(acs: &[AffineCorrespondence], out: &mut [Pose]) -> usize {
    if out.len() < RELPOSE_2AC_MAX_SOLUTIONS || acs.len() != 2 {
        return 0;
    }
    let mut es = [Mat3::zeros(); ESSENTIAL_2AC_MAX_SOLUTIONS];
    let n = essential_2ac(acs, &mut es);
    let x1 = [acs[0].x1, acs[1].x1];
    let x2 = [acs[0].x2, acs[1].x2];
    poses_in_front(&es[..n], &x1, &x2, 2, out)
}

/// Relative poses from one normalised AC and two normalised point correspondences:
/// [`essential_1ac2pt`], then the factorisation of each E with the AC's centre and both points
/// in front of both cameras. `out` must hold [`RELPOSE_1AC2PT_MAX_SOLUTIONS`]; returns the
/// number written.
pub fn relative_pose_1ac2pt(
    ac: &AffineCorrespondence,
    x1: &[Vec2],
    x2: &[Vec2],
    out: &mut [Pose],
) -> usize {
    if out.len() < RELPOSE_1AC2PT_MAX_SOLUTIONS || x1.len() != 2 || x2.len() != 2 {
        return 0;
    }
    let mut es = [Mat3::zeros(); ESSENTIAL_1AC2PT_MAX_SOLUTIONS];
    let n = essential_1ac2pt(ac, x1, x2, &mut es);
    let p1 = [ac.x1, x1[0], x1[1]];
    let p2 = [ac.x2, x2[0], x2[1]];
    poses_in_front(&es[..n], &p1, &p2, 3, out)
}

/// The relative pose from N ≥ 8 normalised point correspondences: [`essential_8pt`], then the
/// factorisation with the most points in front of both cameras (at least one). Writes at most
/// one pose; returns the number written.
pub fn relative_pose_8pt(x1: &[Vec2], x2: &[Vec2], out: &mut [Pose]) -> usize {
    if out.is_empty() {
        return 0;
    }
    let mut es = [Mat3::zeros(); 1];
    let n = essential_8pt(x1, x2, &mut es);
    poses_in_front(&es[..n], x1, x2, 1, out)
}
