//! MAGSAC++ scoring and the SPRT against the MSAC / no-SPRT baseline, on seeded synthetic
//! scenes with known ground truth (planes seen by two cameras, 0.5 px noise, outliers).

use affcorr_geom::sampson::sampson_point;
use affcorr_geom::synthetic::{
    NoiseModel, PlaneScene, noisy_correspondences, random_unit, rotation_about,
};
use affcorr_geom::{PointCorrespondence, Vec3};
use affcorr_ransac::{
    Correspondences, EstimatorOptions, RansacOptions, SampleKind, ScoringKind,
    estimate_fundamental, estimate_homography, estimate_relative_pose,
};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

mod common;
use common::{angle_deg, transfer_error};

#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    H,
    F,
    Pose,
}

struct Scene {
    scene: PlaneScene,
    data: Correspondences,
    is_inlier: Vec<bool>,
    /// Exact correspondences on 4 more planes of the same cameras (to measure F).
    check: Vec<PointCorrespondence>,
}

fn scene(kind: Kind, seed: u64, n: usize, outlier_ratio: f64) -> Scene {
    let mut rng = Pcg64::seed_from_u64(1000 + seed);
    let scene = PlaneScene::random(&mut rng);
    let noise = NoiseModel {
        planes: if kind == Kind::H { 1 } else { 5 },
        outlier_ratio,
        pixel_noise: 0.5,
        affine_noise: 0.02,
    };
    let (acs, is_inlier) = noisy_correspondences(&mut rng, &scene, n, &noise);
    let mut check = Vec::new();
    for _ in 0..4 {
        let mut s = scene;
        s.normal = rotation_about(&random_unit(&mut rng), rng.random_range(-0.8..0.8)) * Vec3::z();
        s.distance = rng.random_range(2.0..10.0);
        check.extend(s.sample(&mut rng, 100).iter().map(|a| a.points()));
    }
    Scene {
        scene,
        data: Correspondences::from_acs(&acs).unwrap(),
        is_inlier,
        check,
    }
}

/// One run: (error, recall, precision, iterations, residual evaluations). The error is the
/// mean transfer error to the true H (px), the mean Sampson distance of exact correspondences
/// under F (px), or the rotation error (degrees).
struct Outcome {
    error: f64,
    recall: f64,
    iterations: usize,
    residuals: u64,
    model: Vec<f64>,
}

fn run(s: &Scene, kind: Kind, opts: &EstimatorOptions) -> Outcome {
    let (error, inliers, iterations, residuals, model) = match kind {
        Kind::H => {
            let e = estimate_homography(&s.data, opts).unwrap();
            let err = transfer_error(&e.model, &s.scene.homography(), 40);
            (
                err,
                e.inliers,
                e.iterations,
                e.residual_evaluations,
                e.model.as_slice().to_vec(),
            )
        }
        Kind::F => {
            let e = estimate_fundamental(&s.data, opts).unwrap();
            let err = s
                .check
                .iter()
                .map(|c| sampson_point(&e.model, c).sqrt())
                .sum::<f64>()
                / s.check.len() as f64;
            (
                err,
                e.inliers,
                e.iterations,
                e.residual_evaluations,
                e.model.as_slice().to_vec(),
            )
        }
        Kind::Pose => {
            let e = estimate_relative_pose(&s.data, &s.scene.k1, &s.scene.k2, opts).unwrap();
            let err = angle_deg(&(e.model.pose.r.transpose() * s.scene.pose.r));
            let m = e.model.pose.r.as_slice().to_vec();
            (err, e.inliers, e.iterations, e.residual_evaluations, m)
        }
    };
    let tp = s
        .is_inlier
        .iter()
        .zip(&inliers)
        .filter(|(t, f)| **t && **f)
        .count();
    Outcome {
        error,
        recall: tp as f64 / s.is_inlier.iter().filter(|t| **t).count() as f64,
        iterations,
        residuals,
        model,
    }
}

fn options(kind: Kind, sample: SampleKind, seed: u64) -> EstimatorOptions {
    EstimatorOptions {
        ransac: RansacOptions {
            threshold: if kind == Kind::H { 2.0 } else { 1.5 },
            seed,
            ..Default::default()
        },
        sample: Some(sample),
        ..Default::default()
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Median errors of MSAC and MAGSAC++ over 10 seeded scenes at `scale` × the nominal threshold;
/// checks recall and bit-reproducibility of MAGSAC++ on the way.
fn compare_scorings(kind: Kind, scale: f64, min_recall: f64) -> (f64, f64) {
    let (mut e_msac, mut e_magsac) = (vec![], vec![]);
    for seed in 0..10 {
        let s = scene(kind, seed, 800, 0.5);
        let mut o = options(kind, SampleKind::Affine, seed);
        o.ransac.threshold *= scale;
        // The scorings alone, on the point residuals: the default affine terms (λ = 50 px² in
        // scoring, the affine final refinement) take most of MSAC's loss at a loose threshold
        // away (pose at 3×: 0.0146° instead of 0.0438°, MAGSAC++ 0.0137°).
        o.affine_weight = Some(0.0);
        o.ransac.affine_refinement = affcorr_ransac::AffineRefinement::Off;
        o.scoring = ScoringKind::Msac;
        let msac = run(&s, kind, &o);
        o.scoring = ScoringKind::Magsac;
        let magsac = run(&s, kind, &o);
        assert!(
            magsac.recall >= min_recall,
            "{kind:?} seed {seed}: recall {}",
            magsac.recall
        );
        // Reproducible: the same seed gives the same model, bit for bit.
        if seed < 2 {
            let again = run(&s, kind, &o);
            assert_eq!(again.model, magsac.model);
            assert_eq!(again.iterations, magsac.iterations);
        }
        e_msac.push(msac.error);
        e_magsac.push(magsac.error);
    }
    let (m0, m1) = (median(e_msac), median(e_magsac));
    eprintln!("{kind:?} at {scale}x threshold: median error MSAC {m0:.4}, MAGSAC++ {m1:.4}");
    (m0, m1)
}

/// At the nominal threshold (3σ of the residual) MSAC followed by unit-weight least squares on
/// the inliers is already the Gaussian maximum-likelihood estimate, so MAGSAC++ (which
/// down-weights residuals near the threshold) can only match it: within 30% on these scenes
/// (measured: pose 0.0172° vs 0.0167° since pose residuals reject points behind a camera,
/// which used to pull MSAC's rotation; H 0.065 vs 0.061 px, F 0.056 vs 0.050 px).
#[test]
fn magsac_at_the_nominal_threshold_matches_msac() {
    for kind in [Kind::Pose, Kind::H, Kind::F] {
        let (m0, m1) = compare_scorings(kind, 1.0, 0.99);
        assert!(m1 <= 1.3 * m0, "{kind:?}: MAGSAC++ {m1} vs MSAC {m0}");
    }
}

/// With a loose threshold (3× nominal), MSAC lets near-threshold outliers pull the model with
/// full weight; MAGSAC++ marginalises the noise scale and keeps its accuracy (measured: pose
/// 0.0275° vs 0.0438°, F 0.063 vs 0.150 px, H 0.0615 vs 0.0610 px).
#[test]
fn magsac_at_a_loose_threshold_beats_msac() {
    for (kind, factor) in [(Kind::Pose, 0.7), (Kind::F, 0.7), (Kind::H, 1.05)] {
        let (m0, m1) = compare_scorings(kind, 3.0, 0.0);
        assert!(m1 <= factor * m0, "{kind:?}: MAGSAC++ {m1} vs MSAC {m0}");
    }
}

/// Success (error below `bound`), median error and total residual evaluations over 20 seeded
/// scenes, with and without the SPRT.
fn compare_sprt(kind: Kind, sample: SampleKind, outliers: f64, bound: f64, max_ratio: f64) {
    let mut rows = [(0usize, vec![], 0u64, 0usize, 0usize), (0, vec![], 0, 0, 0)];
    for seed in 0..20 {
        let s = scene(kind, 100 + seed, 600, outliers);
        for (k, sprt) in [false, true].into_iter().enumerate() {
            let mut o = options(kind, sample, seed);
            o.ransac.sprt = sprt;
            let r = run(&s, kind, &o);
            rows[k].0 += usize::from(r.error < bound && r.recall >= 0.99);
            rows[k].1.push(r.error);
            rows[k].2 += r.residuals;
            rows[k].3 += r.iterations;
            if sprt && seed == 0 {
                // Reproducible with the SPRT too.
                assert_eq!(run(&s, kind, &o).model, r.model);
            }
        }
    }
    let [off, on] = rows;
    let (m_off, m_on) = (median(off.1), median(on.1));
    eprintln!(
        "{kind:?} {sample:?} {outliers}: success {}/{} , median error {m_off:.4}/{m_on:.4}, \
         residuals {}/{} ({:.2}), iterations {}/{}",
        off.0,
        on.0,
        off.2,
        on.2,
        on.2 as f64 / off.2 as f64,
        off.3,
        on.3
    );
    assert_eq!(
        on.0, off.0,
        "{kind:?} {sample:?}: successes with / without SPRT"
    );
    assert!(
        m_on <= 1.1 * m_off,
        "{kind:?} {sample:?}: median error {m_on} vs {m_off}"
    );
    assert!(
        (on.2 as f64) < max_ratio * off.2 as f64,
        "{kind:?} {sample:?}: residuals {} vs {}",
        on.2,
        off.2
    );
}

#[test]
fn sprt_costs_no_accuracy_and_cuts_verification() {
    // Measured residual ratios (SPRT on / off): 0.17, 0.23, 0.48, 0.74, 0.58; the more
    // iterations a run needs, the more the SPRT saves (LO and refinement are not verified).
    compare_sprt(Kind::H, SampleKind::Points, 0.5, 0.3, 0.3);
    compare_sprt(Kind::H, SampleKind::Affine, 0.7, 0.3, 0.4);
    compare_sprt(Kind::F, SampleKind::Points, 0.3, 0.3, 0.7);
    compare_sprt(Kind::Pose, SampleKind::Points, 0.3, 0.2, 0.9);
    compare_sprt(Kind::Pose, SampleKind::Affine, 0.6, 0.2, 0.8);
}
