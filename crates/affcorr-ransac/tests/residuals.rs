//! The scoring residuals of the epipolar problems, computed in vectorised blocks (`residuals`)
//! and datum by datum in the SPRT's order (`residuals_at`), against their definition from the
//! geometry crate's Sampson distances: SD_P + min(λ c (SD_A,0 + SD_A,1), cap), bit for bit.

use affcorr_geom::AffineCorrespondence;
use affcorr_geom::sampson::{sampson_affine, sampson_point};
use affcorr_geom::synthetic::{NoiseModel, PlaneScene, noisy_correspondences};
use affcorr_ransac::Problem;
use affcorr_ransac::problems::fundamental::FundamentalProblem;
use affcorr_ransac::{Correspondences, SampleKind};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// 203 ACs (not a multiple of any vector width) of a three-plane scene with outliers, one of
/// them with A = 0, and the scene's F.
fn data(seed: u64) -> (Vec<AffineCorrespondence>, affcorr_geom::Mat3) {
    let mut rng = Pcg64::seed_from_u64(seed);
    let scene = PlaneScene::random(&mut rng);
    let noise = NoiseModel {
        planes: 3,
        outlier_ratio: 0.4,
        pixel_noise: 0.5,
        affine_noise: 0.05,
    };
    let (mut acs, _) = noisy_correspondences(&mut rng, &scene, 203, &noise);
    acs[7].a = affcorr_geom::Mat2::zeros();
    (acs, scene.fundamental())
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
        let (acs, f) = data(seed);
        let data = Correspondences::from_acs(&acs).unwrap();
        let mut rng = Pcg64::seed_from_u64(100 + seed);
        let confidence: Vec<f64> = (0..acs.len()).map(|_| rng.random_range(0.0..1.0)).collect();
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
            let expected: Vec<f64> = acs
                .iter()
                .enumerate()
                .map(|(i, ac)| definition(&f, ac, weight * conf.map_or(1.0, |c| c[i]), cap))
                .collect();
            // Blocks that start anywhere, as the engine's scoring windows do.
            for (start, len) in [(0, acs.len()), (5, 37), (64, 139), (200, 3)] {
                let mut out = vec![f64::NAN; len];
                problem.residuals(&f, start, &mut out);
                for (k, o) in out.iter().enumerate() {
                    assert_eq!(
                        o.to_bits(),
                        expected[start + k].to_bits(),
                        "datum {}",
                        start + k
                    );
                }
            }
            let order: Vec<usize> = (0..acs.len()).rev().step_by(3).collect();
            let mut out = vec![f64::NAN; order.len()];
            problem.residuals_at(&f, &order, &mut out);
            for (o, &i) in out.iter().zip(&order) {
                assert_eq!(o.to_bits(), expected[i].to_bits(), "datum {i} in order");
            }
        }
    }
}
