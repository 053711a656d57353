//! Relative pose (calibrated): X2 = R X1 + t from correspondences and intrinsics K1, K2.
//!
//! - Minimal samples in normalised coordinates (DESIGN.md §2): 5 points
//!   ([`relative_pose_5pt`], ≤ 10 poses) or 2 ACs ([`relative_pose_2ac`]); each essential matrix
//!   is decomposed and only factorisations with the sample in front of both cameras are kept.
//! - Non-minimal fit: the 8-point essential matrix on the inliers (plus their AC equations when
//!   there are fewer than 8), decomposed with cheirality on those inliers.
//! - Residual (px²): the Sampson distance of F = K2⁻ᵀ E K1⁻¹ on the pixel coordinates, exact
//!   for any fx ≠ fy (no mean-focal approximation), plus the weighted affine Sampson distances.

use super::fundamental::epipolar_residuals;
use super::{Correspondences, SampleKind, epipolar_lm};
use crate::problem::Problem;
use crate::refine::{LeastSquares, LmOptions, Loss, Mat9, Vec9, levenberg_marquardt};
use affcorr_geom::camera::{Intrinsics, normalize_ac};
use affcorr_geom::epipolar::{Pose, fundamental_from_essential, pose_from_essential, skew};
use affcorr_geom::{AffineCorrespondence, Mat3, Vec2, Vec3};
use affcorr_solvers::essential::essential_lsq;
use affcorr_solvers::relpose::{
    RELPOSE_2AC_MAX_SOLUTIONS, RELPOSE_5PT_MAX_SOLUTIONS, relative_pose_2ac, relative_pose_5pt,
};

const MAX_POSES: usize = if RELPOSE_5PT_MAX_SOLUTIONS > RELPOSE_2AC_MAX_SOLUTIONS {
    RELPOSE_5PT_MAX_SOLUTIONS
} else {
    RELPOSE_2AC_MAX_SOLUTIONS
};

/// A pose with the pixel fundamental matrix it induces (cached for scoring).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseModel {
    /// X2 = R X1 + t, |t| = 1.
    pub pose: Pose,
    /// E = [t]× R.
    pub essential: Mat3,
    /// F = K2⁻ᵀ E K1⁻¹ (pixels).
    pub fundamental: Mat3,
}

/// A relative-pose problem: pixel data for scoring, normalised data for the solvers.
pub struct RelativePoseProblem<'a> {
    pixels: &'a Correspondences,
    normalized: Correspondences,
    k1: Intrinsics,
    k2: Intrinsics,
    kind: SampleKind,
    affine_weight: f64,
}

impl<'a> RelativePoseProblem<'a> {
    /// `pixels` with intrinsics `k1`, `k2`, sampled as `kind`, scored with `affine_weight`.
    pub fn new(
        pixels: &'a Correspondences,
        k1: Intrinsics,
        k2: Intrinsics,
        kind: SampleKind,
        affine_weight: f64,
    ) -> Self {
        let normalized = if pixels.has_affine() {
            let acs: Vec<AffineCorrespondence> = (0..pixels.len())
                .map(|i| normalize_ac(&pixels.ac(i), &k1, &k2))
                .collect();
            Correspondences {
                x1: acs.iter().map(|a| a.x1).collect(),
                x2: acs.iter().map(|a| a.x2).collect(),
                a: acs.iter().map(|a| a.a).collect(),
            }
        } else {
            Correspondences {
                x1: pixels.x1.iter().map(|p| k1.normalize_point(p)).collect(),
                x2: pixels.x2.iter().map(|p| k2.normalize_point(p)).collect(),
                a: Vec::new(),
            }
        };
        Self {
            pixels,
            normalized,
            k1,
            k2,
            kind,
            affine_weight,
        }
    }

    /// The model of a pose.
    pub fn model(&self, pose: Pose) -> PoseModel {
        let essential = pose.essential();
        PoseModel {
            pose,
            essential,
            fundamental: fundamental_from_essential(&essential, &self.k1, &self.k2),
        }
    }

    /// Normalised coordinates of the data.
    pub fn normalized(&self) -> &Correspondences {
        &self.normalized
    }
}

impl Problem for RelativePoseProblem<'_> {
    type Model = PoseModel;

    fn len(&self) -> usize {
        self.pixels.len()
    }

    fn sample_size(&self) -> usize {
        match self.kind {
            SampleKind::Points => 5,
            SampleKind::Affine => 2,
        }
    }

    fn fit_minimal(&self, sample: &[usize], out: &mut Vec<PoseModel>) {
        let mut poses = [Pose {
            r: Mat3::identity(),
            t: Default::default(),
        }; MAX_POSES];
        let n = match self.kind {
            SampleKind::Points => {
                let x1: [Vec2; 5] = std::array::from_fn(|k| self.normalized.x1[sample[k]]);
                let x2: [Vec2; 5] = std::array::from_fn(|k| self.normalized.x2[sample[k]]);
                relative_pose_5pt(&x1, &x2, &mut poses)
            }
            SampleKind::Affine => {
                let acs: [AffineCorrespondence; 2] =
                    std::array::from_fn(|k| self.normalized.ac(sample[k]));
                relative_pose_2ac(&acs, &mut poses)
            }
        };
        out.extend(poses[..n].iter().map(|p| self.model(*p)));
    }

    fn fit_nonminimal(&self, indices: &[usize], _weights: Option<&[f64]>) -> Option<PoseModel> {
        let x1: Vec<Vec2> = indices.iter().map(|&i| self.normalized.x1[i]).collect();
        let x2: Vec<Vec2> = indices.iter().map(|&i| self.normalized.x2[i]).collect();
        let mut e = [Mat3::zeros(); 1];
        let acs: Vec<AffineCorrespondence> = if indices.len() < 8 && self.normalized.has_affine() {
            indices.iter().map(|&i| self.normalized.ac(i)).collect()
        } else {
            Vec::new()
        };
        if essential_lsq(&x1, &x2, &acs, &mut e) != 1 {
            return None;
        }
        let (pose, in_front) = pose_from_essential(&e[0], &x1, &x2).ok()?;
        (in_front > 0).then(|| self.model(pose))
    }

    fn residuals(&self, m: &PoseModel, start: usize, out: &mut [f64]) {
        epipolar_residuals(self.pixels, &m.fundamental, self.affine_weight, start, out);
    }

    /// Levenberg–Marquardt on the manifold (R, t ∈ S²) of the pixel Sampson error.
    fn refine(
        &self,
        model: &PoseModel,
        inliers: &[usize],
        loss: &Loss,
        max_iterations: usize,
    ) -> Option<PoseModel> {
        Some(
            levenberg_marquardt(
                self,
                model,
                inliers,
                loss,
                &LmOptions {
                    max_iterations,
                    ..Default::default()
                },
            )
            .0,
        )
    }
}

/// Two unit vectors completing `t` (unit) to an orthonormal basis.
fn tangent_basis(t: &Vec3) -> (Vec3, Vec3) {
    let helper = if t.x.abs() < 0.9 {
        Vec3::x()
    } else {
        Vec3::y()
    };
    let b1 = t.cross(&helper).normalize();
    (b1, t.cross(&b1))
}

/// Pose refinement: R ← R·exp([ω]×), t ← (t + α₁b₁ + α₂b₂)/‖·‖, θ = (ω, α), 5 degrees of
/// freedom. ∂E/∂ω_k = [t]× R [e_k]×, ∂E/∂α_i = [b_i]× R, and ∂F = K2⁻ᵀ ∂E K1⁻¹.
impl LeastSquares for RelativePoseProblem<'_> {
    type Model = PoseModel;

    fn dof(&self) -> usize {
        5
    }

    fn cost(&self, m: &PoseModel, indices: &[usize], loss: &Loss) -> f64 {
        epipolar_lm::cost(self.pixels, &m.fundamental, indices, loss)
    }

    fn normal_equations(
        &self,
        m: &PoseModel,
        indices: &[usize],
        loss: &Loss,
        jtj: &mut Mat9,
        jtr: &mut Vec9,
    ) -> f64 {
        let (r, t) = (&m.pose.r, &m.pose.t);
        let (b1, b2) = tangent_basis(t);
        let (k1i, k2it) = (self.k1.inverse(), self.k2.inverse().transpose());
        let tx = skew(t);
        let de = [
            tx * r * skew(&Vec3::x()),
            tx * r * skew(&Vec3::y()),
            tx * r * skew(&Vec3::z()),
            skew(&b1) * r,
            skew(&b2) * r,
        ];
        let basis = de.map(|d| k2it * d * k1i);
        epipolar_lm::normal_equations(self.pixels, &m.fundamental, &basis, indices, loss, jtj, jtr)
    }

    fn retract(&self, m: &PoseModel, d: &Vec9) -> PoseModel {
        let w = Vec3::new(d[0], d[1], d[2]);
        let angle = w.norm();
        let rot = if angle > 0.0 {
            affcorr_geom::synthetic::rotation_about(&(w / angle), angle)
        } else {
            Mat3::identity()
        };
        let (b1, b2) = tangent_basis(&m.pose.t);
        let t = (m.pose.t + b1 * d[3] + b2 * d[4]).normalize();
        self.model(Pose {
            r: m.pose.r * rot,
            t,
        })
    }
}
