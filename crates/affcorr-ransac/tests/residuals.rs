//! The scoring residuals of the epipolar problems, computed in vectorised blocks (`residuals`)
//! and in gathered blocks in the SPRT's order (`residuals_at`), against their definition from
//! the geometry crate: SD_P + min(λ c (SD_A,0 + SD_A,1), cap), bit for bit, and for relative
//! poses +∞ where a datum below the cheirality threshold triangulates behind a camera; for
//! homographies scored on points the squared transfer error.

use affcorr_geom::AffineCorrespondence;
use affcorr_geom::epipolar::{Pose, triangulate_depths};
use affcorr_geom::sampson::{sampson_affine, sampson_point};
use affcorr_geom::synthetic::PlaneScene;
use affcorr_ransac::Problem;
use affcorr_ransac::problems::fundamental::FundamentalProblem;
use affcorr_ransac::problems::homography::HomographyProblem;
use affcorr_ransac::problems::relpose::RelativePoseProblem;
use affcorr_ransac::{Correspondences, SampleKind};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

mod common;
use common::make_data;

/// 203 ACs (not a multiple of any vector width) of a three-plane scene with outliers, one of
/// them with A = 0, and the scene.
fn scene_data(seed: u64) -> (Correspondences, PlaneScene) {
    let mut rng = Pcg64::seed_from_u64(seed);
    let scene = PlaneScene::random(&mut rng);
    let mut data = make_data(&mut rng, &scene, 3, 203, 0.4, 0.5, 0.05).data;
    data.a[7] = affcorr_geom::Mat2::zeros();
    (data, scene)
}

/// `problem`'s residuals under `model`, in blocks that start anywhere (as the engine's scoring
/// windows do) and in a random-like order, each equal to `expected` bit for bit.
fn assert_residuals<P: Problem>(problem: &P, model: &P::Model, expected: &[f64]) {
    let n = expected.len();
    for (start, len) in [(0, n), (5, 37), (64, 139), (n - 3, 3)] {
        let mut out = vec![f64::NAN; len];
        problem.residuals(model, start, &mut out);
        for (k, o) in out.iter().enumerate() {
            assert_eq!(
                o.to_bits(),
                expected[start + k].to_bits(),
                "datum {}",
                start + k
            );
        }
    }
    let order: Vec<usize> = (0..n).rev().step_by(3).collect();
    let mut out = vec![f64::NAN; order.len()];
    problem.residuals_at(model, &order, &mut out);
    for (o, &i) in out.iter().zip(&order) {
        assert_eq!(o.to_bits(), expected[i].to_bits(), "datum {i} in order");
    }
}

fn definition(f: &affcorr_geom::Mat3, ac: &AffineCorrespondence, w: f64, cap: f64) -> f64 {
    let [a0, a1] = sampson_affine(f, ac);
    let p = sampson_point(f, &ac.points());
    if w == 0.0 {
        p
    } else {
        p + (w * (a0 + a1)).min(cap)
    }
}

#[test]
fn epipolar_scoring_residuals_equal_their_definition_bit_for_bit() {
    for seed in 0..3 {
        let (data, scene) = scene_data(seed);
        let f = scene.fundamental();
        let mut rng = Pcg64::seed_from_u64(100 + seed);
        let confidence: Vec<f64> = (0..data.len())
            .map(|_| rng.random_range(0.0..1.0))
            .collect();
        for (weight, cap, conf) in [
            (0.0, f64::INFINITY, None),
            (50.0, f64::INFINITY, None),
            (50.0, f64::INFINITY, Some(&confidence[..])),
            (7.5, 0.5, Some(&confidence[..])),
            (7.5, 0.5, None),
        ] {
            let problem = FundamentalProblem::new(&data, SampleKind::Affine, weight, 1.0)
                .with_affine_confidence(conf)
                .with_affine_cap(cap);
            let expected: Vec<f64> = (0..data.len())
                .map(|i| definition(&f, &data.ac(i), weight * conf.map_or(1.0, |c| c[i]), cap))
                .collect();
            assert_residuals(&problem, &f, &expected);
        }
    }
}

#[test]
fn relative_pose_residuals_put_points_behind_a_camera_out_bit_for_bit() {
    let cheirality_threshold = 8.0;
    for seed in 0..3 {
        let (data, scene) = scene_data(seed);
        for weight in [0.0, 50.0] {
            let problem = RelativePoseProblem::new(
                &data,
                scene.k1,
                scene.k2,
                SampleKind::Affine,
                weight,
                cheirality_threshold,
            );
            // The true pose, and its twin with -t, which puts the scene behind the cameras.
            let twin = Pose {
                r: scene.pose.r,
                t: -scene.pose.t,
            };
            let mut behind = 0;
            for pose in [scene.pose, twin] {
                let model = problem.model(pose);
                let normalized = problem.normalized();
                let expected: Vec<f64> = (0..data.len())
                    .map(|i| {
                        let r2 = definition(&model.fundamental, &data.ac(i), weight, f64::INFINITY);
                        let (x1, x2) = (&normalized.x1[i], &normalized.x2[i]);
                        match triangulate_depths(&pose, x1, x2) {
                            Some((l1, l2))
                                if r2 < cheirality_threshold.powi(2) && !(l1 > 0.0 && l2 > 0.0) =>
                            {
                                behind += 1;
                                f64::INFINITY
                            }
                            _ => r2,
                        }
                    })
                    .collect();
                assert_residuals(&problem, &model, &expected);
            }
            assert!(
                behind > 100,
                "the twin pose puts the inliers behind ({behind})"
            );
        }
    }
}

#[test]
fn homography_residuals_are_the_squared_transfer_error_bit_for_bit() {
    for seed in 0..3 {
        let (data, scene) = scene_data(seed);
        let h = scene.homography();
        let problem = HomographyProblem::new(&data, SampleKind::Affine, 0.0);
        let expected: Vec<f64> = (0..data.len())
            .map(|i| {
                let ac = data.ac(i);
                let p = h * affcorr_geom::Vec3::new(ac.x1.x, ac.x1.y, 1.0);
                let inv_w = 1.0 / p.z;
                let (du, dv) = (p.x * inv_w - ac.x2.x, p.y * inv_w - ac.x2.y);
                du * du + dv * dv
            })
            .collect();
        assert_residuals(&problem, &h, &expected);
    }
}
