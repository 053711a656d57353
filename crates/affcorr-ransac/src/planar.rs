//! The planar ambiguity of a relative pose. When (nearly) all of a pose's inliers lie on one
//! plane, the plane's homography decomposes into two physically valid motions that induce the
//! same homography, hence the same points and the same A = ∂x2/∂x1 of every AC: no estimator
//! can choose between them from the two views alone (docs/estimation.md, "One plane").
//! [`planar_twin`] says whether a pose is in that case and gives the other motion.

use crate::error::{RansacError, Result};
use crate::estimators::{EstimatorOptions, estimate_homography};
use crate::options::RansacOptions;
use crate::problems::Correspondences;
use affcorr_geom::camera::Intrinsics;
use affcorr_geom::epipolar::Pose;
use affcorr_geom::homography::decompose_homography;
use affcorr_geom::{Mat3, Vec2, Vec3};

/// A pose is planar when one homography explains at least this share of its inliers (COLMAP's
/// `max_H_inlier_ratio` for a planar two-view geometry).
pub const PLANAR_SHARE: f64 = 0.8;

/// The share of the homography's inliers that a decomposition must put in front of camera 1
/// (a few inliers of a robust fit can be wrong).
const IN_FRONT: f64 = 0.9;

/// The other motion of a planar pose ([`planar_twin`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanarTwin {
    /// The twin: X2 = R X1 + t, |t| = 1.
    pub pose: Pose,
    /// The twin's plane: its unit normal in camera 1 (nᵀ X1 = d > 0 on the plane).
    pub normal: Vec3,
    /// The share of the pose's inliers that one homography explains (≥ [`PLANAR_SHARE`]).
    pub planar_share: f64,
    /// That homography (pixels, x2 ~ H x1, ‖H‖_F = 1): the pose and its twin both induce it.
    pub homography: Mat3,
}

/// The twin of the relative pose `pose` estimated on `data` (pixels) with the inlier flags
/// `inliers`, or `None` when the pose is not planar or its plane has one physically valid
/// decomposition only.
///
/// A homography is fitted robustly (affcorr's RANSAC on points, transfer error below
/// `threshold` pixels, seed 0) to the pose's inliers. If it explains at least
/// [`PLANAR_SHARE`] of them, its calibrated form K2⁻¹ H K1 is decomposed
/// ([`decompose_homography`]); of the decompositions that keep 90% of its inliers in front of
/// both cameras, the one farther from `pose` (the larger of the rotation angle and the angle
/// between the translations) is the twin.
pub fn planar_twin(
    data: &Correspondences,
    k1: &Intrinsics,
    k2: &Intrinsics,
    pose: &Pose,
    inliers: &[bool],
    threshold: f64,
) -> Result<Option<PlanarTwin>> {
    if inliers.len() != data.len() {
        return Err(RansacError::InvalidOption {
            name: "inliers",
            value: format!("{} flags", inliers.len()),
            reason: "must have one flag per correspondence",
        });
    }
    if !(threshold > 0.0 && threshold.is_finite()) {
        return Err(RansacError::InvalidOption {
            name: "threshold",
            value: threshold.to_string(),
            reason: "must be a positive number of pixels",
        });
    }
    let idx: Vec<usize> = (0..data.len()).filter(|&i| inliers[i]).collect();
    if idx.len() < 8 {
        return Ok(None);
    }
    let rows: Vec<[f64; 4]> = idx
        .iter()
        .map(|&i| [data.x1[i].x, data.x1[i].y, data.x2[i].x, data.x2[i].y])
        .collect();
    let points = Correspondences::from_point_rows(&rows)?;
    let opts = EstimatorOptions {
        ransac: RansacOptions {
            threshold,
            ..RansacOptions::default()
        },
        ..EstimatorOptions::default()
    };
    let h = estimate_homography(&points, &opts)?;
    let planar_share = h.num_inliers as f64 / idx.len() as f64;
    if planar_share < PLANAR_SHARE {
        return Ok(None);
    }
    let (x1, x2): (Vec<Vec2>, Vec<Vec2>) = (0..points.len())
        .filter(|&i| h.inliers[i])
        .map(|i| {
            (
                k1.normalize_point(&points.x1[i]),
                k2.normalize_point(&points.x2[i]),
            )
        })
        .unzip();
    let calibrated = k2.inverse() * h.model * k1.matrix();
    let motions = decompose_homography(&calibrated, &x1, &x2, IN_FRONT)?;
    if motions.len() < 2 {
        return Ok(None);
    }
    let twin = motions
        .iter()
        .max_by(|a, b| distance(&a.pose, pose).total_cmp(&distance(&b.pose, pose)))
        .expect("two motions");
    Ok(Some(PlanarTwin {
        pose: Pose {
            r: twin.pose.r,
            t: twin.pose.t.normalize(),
        },
        normal: twin.normal,
        planar_share,
        homography: h.model,
    }))
}

/// The larger of the rotation angle between two motions and the angle between their
/// translation directions, radians.
fn distance(a: &Pose, b: &Pose) -> f64 {
    let rotation = ((a.r.transpose() * b.r).trace() - 1.0) / 2.0;
    let direction = a.t.normalize().dot(&b.t.normalize());
    rotation
        .clamp(-1.0, 1.0)
        .acos()
        .max(direction.clamp(-1.0, 1.0).acos())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimators::estimate_relative_pose;
    use affcorr_geom::PointCorrespondence;
    use affcorr_geom::epipolar::essential_from_pose;
    use affcorr_geom::sampson::sampson_point;
    use affcorr_geom::synthetic::{NoiseModel, PlaneScene, noisy_correspondences};
    use rand::SeedableRng;

    fn scene(seed: u64, planes: usize) -> (PlaneScene, Correspondences) {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let scene = PlaneScene::random(&mut rng);
        let noise = NoiseModel {
            planes,
            outlier_ratio: 0.2,
            pixel_noise: 0.3,
            affine_noise: 0.01,
        };
        let (acs, _) = noisy_correspondences(&mut rng, &scene, 300, &noise);
        (scene, Correspondences::from_acs(&acs).unwrap())
    }

    fn angle(a: &Pose, b: &Pose) -> f64 {
        distance(a, b).to_degrees()
    }

    #[test]
    fn a_pose_on_one_plane_has_a_twin_that_fits_its_inliers_as_well() {
        let mut twins = 0;
        for seed in 0..24 {
            let (scene, data) = scene(seed, 1);
            let est =
                estimate_relative_pose(&data, &scene.k1, &scene.k2, &Default::default()).unwrap();
            let pose = est.model.pose;
            let Some(twin) =
                planar_twin(&data, &scene.k1, &scene.k2, &pose, &est.inliers, 2.0).unwrap()
            else {
                continue;
            };
            twins += 1;
            assert!(twin.planar_share >= PLANAR_SHARE, "seed {seed}");
            assert!((twin.pose.t.norm() - 1.0).abs() < 1e-12);
            assert!((twin.normal.norm() - 1.0).abs() < 1e-9);
            // The plane's homography: the true one, up to scale (mean transfer over the image).
            let h = twin.homography;
            assert!((h.norm() - 1.0).abs() < 1e-9);
            let truth_h = scene.homography();
            let mut transfer = 0.0;
            for (x, y) in (0..640)
                .step_by(40)
                .flat_map(|x| (0..480).step_by(40).map(move |y| (x, y)))
            {
                let p = Vec3::new(x as f64, y as f64, 1.0);
                let (a, b) = (h * p, truth_h * p);
                transfer += (a.xy() / a.z - b.xy() / b.z).norm() / 192.0;
            }
            assert!(transfer < 1.0, "seed {seed}: transfer {transfer} px");
            // A different motion ...
            assert!(angle(&twin.pose, &pose) > 1.0, "seed {seed}");
            // One of the two is the true motion.
            let truth = angle(&pose, &scene.pose).min(angle(&twin.pose, &scene.pose));
            assert!(truth < 2.0, "seed {seed}: {truth}°");
            // ... whose F fits the pose's inliers as well as the pose's own F.
            let f = |p: &Pose| {
                let e = essential_from_pose(&p.r, &p.t);
                scene.k2.inverse().transpose() * e * scene.k1.inverse()
            };
            let (fa, fb): (Mat3, Mat3) = (f(&pose), f(&twin.pose));
            let mean = |f: &Mat3| {
                let (mut s, mut n) = (0.0, 0.0);
                for i in (0..data.len()).filter(|&i| est.inliers[i]) {
                    let p = PointCorrespondence {
                        x1: data.x1[i],
                        x2: data.x2[i],
                    };
                    s += sampson_point(&(f / f.norm()), &p);
                    n += 1.0;
                }
                s / n
            };
            assert!(mean(&fb) < 4.0 * mean(&fa).max(0.05), "seed {seed}");
        }
        assert!(twins >= 5, "{twins} of 24 planar scenes have a twin");
    }

    #[test]
    fn a_pose_on_several_planes_is_not_planar() {
        for seed in 0..6 {
            let (scene, data) = scene(100 + seed, 3);
            let est =
                estimate_relative_pose(&data, &scene.k1, &scene.k2, &Default::default()).unwrap();
            let twin = planar_twin(
                &data,
                &scene.k1,
                &scene.k2,
                &est.model.pose,
                &est.inliers,
                2.0,
            );
            assert_eq!(twin.unwrap(), None, "seed {seed}");
        }
    }

    #[test]
    fn bad_inliers_or_thresholds_are_errors_naming_them() {
        let (scene, data) = scene(7, 1);
        let pose = scene.pose;
        let short = vec![true; data.len() - 1];
        let e = planar_twin(&data, &scene.k1, &scene.k2, &pose, &short, 2.0).unwrap_err();
        assert!(e.to_string().contains("inliers"), "{e}");
        let all = vec![true; data.len()];
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let e = planar_twin(&data, &scene.k1, &scene.k2, &pose, &all, bad).unwrap_err();
            assert!(e.to_string().contains("threshold"), "{e}");
        }
        // Too few inliers to tell: no twin, no error.
        let few: Vec<bool> = (0..data.len()).map(|i| i < 5).collect();
        assert_eq!(
            planar_twin(&data, &scene.k1, &scene.k2, &pose, &few, 2.0).unwrap(),
            None
        );
    }
}
