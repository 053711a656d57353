//! The affine terms of the refinements (`RansacOptions::affine_refinement`) and the per-AC
//! confidence (`EstimatorOptions::affine_confidence`): accuracy against ground truth, poor ACs
//! never worse than points, and typed errors for bad confidences.

mod common;

use affcorr_geom::synthetic::{NoiseModel, PlaneScene, noisy_correspondences};
use affcorr_ransac::{
    AffineRefinement, Correspondences, EstimatorOptions, RansacError, ScoringKind,
    estimate_fundamental, estimate_homography, estimate_relative_pose,
};
use common::angle_deg;
use rand::SeedableRng;
use rand_pcg::Pcg64;

/// Median over `seeds` scenes of the rotation and translation errors (degrees) of the relative
/// pose under `opts`, the scenes made with `noise` (300 ACs).
fn pose_errors(noise: &NoiseModel, seeds: u64, opts: &EstimatorOptions) -> (f64, f64) {
    let (mut rot, mut tra) = (Vec::new(), Vec::new());
    for seed in 0..seeds {
        let mut rng = Pcg64::seed_from_u64(100 + seed);
        let scene = PlaneScene::random(&mut rng);
        let (acs, _) = noisy_correspondences(&mut rng, &scene, 300, noise);
        let data = Correspondences::from_acs(&acs).unwrap();
        let est = estimate_relative_pose(&data, &scene.k1, &scene.k2, opts).unwrap();
        let p = est.model.pose;
        rot.push(angle_deg(&(p.r.transpose() * scene.pose.r)));
        let t = scene.pose.t.normalize();
        tra.push(p.t.dot(&t).clamp(-1.0, 1.0).acos().to_degrees());
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    (median(&mut rot), median(&mut tra))
}

fn options(affine: AffineRefinement, scoring: ScoringKind) -> EstimatorOptions {
    // Points-only scoring: these tests are about the refinements.
    let mut o = EstimatorOptions {
        affine_weight: Some(0.0),
        ..Default::default()
    };
    o.ransac.threshold = 3.0;
    o.ransac.affine_refinement = affine;
    o.scoring = scoring;
    o
}

#[test]
fn accurate_acs_make_the_pose_more_accurate_than_points() {
    // 1 px of point noise, A exact to 0.1%: the affine terms carry most of the information.
    let noise = NoiseModel {
        planes: 3,
        outlier_ratio: 0.3,
        pixel_noise: 1.0,
        affine_noise: 0.001,
    };
    for scoring in [ScoringKind::Msac, ScoringKind::Magsac] {
        let points = pose_errors(&noise, 9, &options(AffineRefinement::Off, scoring));
        let affine = pose_errors(&noise, 9, &options(AffineRefinement::All, scoring));
        eprintln!("{scoring:?}: points {points:?}, affine {affine:?}");
        assert!(
            affine.0 < 0.7 * points.0,
            "{scoring:?} rotation: {affine:?} vs {points:?}"
        );
        assert!(
            affine.1 < 0.7 * points.1,
            "{scoring:?} translation: {affine:?} vs {points:?}"
        );
    }
}

#[test]
fn poor_acs_do_not_make_the_pose_worse_than_points() {
    // A off by 30%: the estimated scale of A makes its terms weigh (almost) nothing.
    let noise = NoiseModel {
        planes: 3,
        outlier_ratio: 0.3,
        pixel_noise: 0.5,
        affine_noise: 0.3,
    };
    let o = |a| options(a, ScoringKind::Msac);
    let points = pose_errors(&noise, 9, &o(AffineRefinement::Off));
    let affine = pose_errors(&noise, 9, &o(AffineRefinement::All));
    eprintln!("points {points:?}, affine {affine:?}");
    assert!(
        affine.0 < 1.1 * points.0,
        "rotation: {affine:?} vs {points:?}"
    );
    assert!(
        affine.1 < 1.1 * points.1,
        "translation: {affine:?} vs {points:?}"
    );
}

#[test]
fn accurate_acs_make_the_fundamental_matrix_more_accurate() {
    let noise = NoiseModel {
        planes: 3,
        outlier_ratio: 0.3,
        pixel_noise: 1.0,
        affine_noise: 0.001,
    };
    // The error of F: the median Sampson distance of exact correspondences of the scene.
    let mut errors = [Vec::new(), Vec::new()];
    for seed in 0..9 {
        let mut rng = Pcg64::seed_from_u64(200 + seed);
        let scene = PlaneScene::random(&mut rng);
        let (acs, _) = noisy_correspondences(&mut rng, &scene, 300, &noise);
        let exact = noisy_correspondences(
            &mut rng,
            &scene,
            300,
            &NoiseModel {
                planes: 3,
                outlier_ratio: 0.0,
                pixel_noise: 0.0,
                affine_noise: 0.0,
            },
        )
        .0;
        let data = Correspondences::from_acs(&acs).unwrap();
        for (k, a) in [AffineRefinement::Off, AffineRefinement::All]
            .into_iter()
            .enumerate()
        {
            let est = estimate_fundamental(&data, &options(a, ScoringKind::Msac)).unwrap();
            let f = est.model;
            let mut d: Vec<f64> = exact
                .iter()
                .map(|ac| affcorr_geom::sampson::sampson_point(&f, &ac.points()).sqrt())
                .collect();
            d.sort_by(f64::total_cmp);
            errors[k].push(d[d.len() / 2]);
        }
    }
    for e in &mut errors {
        e.sort_by(f64::total_cmp);
    }
    let (points, affine) = (errors[0][4], errors[1][4]);
    eprintln!("F error: points {points}, affine {affine}");
    assert!(affine < 0.8 * points, "{affine} vs {points}");
}

#[test]
fn accurate_acs_make_the_homography_more_accurate_than_points() {
    // One plane, 0.5 px on the points, A exact to 0.1%, 30% outliers: through the whole
    // estimator (default options), the final refinement's affine terms must land in the
    // result. They once did not: the engine rejected any affine-refined H that scored below
    // the unrefined one on the points, and then kept the unrefined model.
    let noise = NoiseModel {
        planes: 1,
        outlier_ratio: 0.3,
        pixel_noise: 0.5,
        affine_noise: 0.001,
    };
    let (mut points, mut affine, mut better) = (Vec::new(), Vec::new(), 0);
    for seed in 0..9 {
        let mut rng = Pcg64::seed_from_u64(300 + seed);
        let scene = PlaneScene::random(&mut rng);
        let (acs, _) = noisy_correspondences(&mut rng, &scene, 300, &noise);
        let data = Correspondences::from_acs(&acs).unwrap();
        let mut opts = EstimatorOptions::default();
        opts.ransac.threshold = 2.0;
        let mut errors = [0.0; 2];
        for (k, a) in [AffineRefinement::Off, AffineRefinement::Final]
            .into_iter()
            .enumerate()
        {
            opts.ransac.affine_refinement = a;
            let h = estimate_homography(&data, &opts).unwrap().model;
            errors[k] = common::transfer_error(&h, &scene.homography(), 40);
        }
        better += usize::from(errors[1] < errors[0]);
        points.push(errors[0]);
        affine.push(errors[1]);
    }
    points.sort_by(f64::total_cmp);
    affine.sort_by(f64::total_cmp);
    eprintln!("H transfer error: points {points:?}, affine {affine:?}");
    assert!(
        better >= 8,
        "the affine terms helped in {better} of 9 scenes"
    );
    assert!(
        affine[4] < 0.85 * points[4],
        "median {} vs {}",
        affine[4],
        points[4]
    );
}

#[test]
fn zero_confidence_everywhere_is_the_points_only_fit() {
    let mut rng = Pcg64::seed_from_u64(7);
    let scene = PlaneScene::random(&mut rng);
    let noise = NoiseModel {
        planes: 3,
        outlier_ratio: 0.3,
        pixel_noise: 0.5,
        affine_noise: 0.01,
    };
    let (acs, _) = noisy_correspondences(&mut rng, &scene, 300, &noise);
    let data = Correspondences::from_acs(&acs).unwrap();
    let off = options(AffineRefinement::Off, ScoringKind::Msac);
    let mut zero = options(AffineRefinement::All, ScoringKind::Msac);
    zero.affine_confidence = Some(vec![0.0; acs.len()]);
    let a = estimate_relative_pose(&data, &scene.k1, &scene.k2, &off).unwrap();
    let b = estimate_relative_pose(&data, &scene.k1, &scene.k2, &zero).unwrap();
    assert_eq!(a.model, b.model);
    assert_eq!(a.inliers, b.inliers);
    // Full confidence is the default, and a half confidence changes the fit.
    let mut one = options(AffineRefinement::All, ScoringKind::Msac);
    let all = estimate_relative_pose(&data, &scene.k1, &scene.k2, &one).unwrap();
    one.affine_confidence = Some(vec![1.0; acs.len()]);
    let ones = estimate_relative_pose(&data, &scene.k1, &scene.k2, &one).unwrap();
    assert_eq!(all.model, ones.model);
    assert_ne!(all.model, a.model);
}

#[test]
fn bad_confidences_are_typed_errors_naming_the_option() {
    let mut rng = Pcg64::seed_from_u64(8);
    let scene = PlaneScene::random(&mut rng);
    let noise = NoiseModel {
        planes: 2,
        outlier_ratio: 0.0,
        pixel_noise: 0.5,
        affine_noise: 0.01,
    };
    let (acs, _) = noisy_correspondences(&mut rng, &scene, 50, &noise);
    let data = Correspondences::from_acs(&acs).unwrap();
    let point_data = data.points_only();
    let cases: [(Vec<f64>, &Correspondences, &str); 5] = [
        (vec![1.0; 49], &data, "one value per correspondence"),
        (vec![1.5; 50], &data, "[0, 1]"),
        (vec![-0.1; 50], &data, "[0, 1]"),
        (vec![f64::NAN; 50], &data, "[0, 1]"),
        (vec![1.0; 50], &point_data, "(N, 8)"),
    ];
    for (c, d, why) in cases {
        let o = EstimatorOptions {
            affine_confidence: Some(c),
            ..Default::default()
        };
        for e in [
            estimate_homography(d, &o).err(),
            estimate_fundamental(d, &o).err(),
            estimate_relative_pose(d, &scene.k1, &scene.k2, &o).err(),
        ] {
            match e {
                Some(RansacError::InvalidOption { name, reason, .. }) => {
                    assert_eq!(name, "affine_confidence");
                    assert!(reason.contains(why), "{reason}");
                }
                other => panic!("{other:?}"),
            }
        }
    }
}

#[test]
fn the_defaults_use_the_affine_terms_on_acs_only() {
    let d = EstimatorOptions::default();
    assert_eq!(d.affine_weight, None);
    assert_eq!(d.scoring, ScoringKind::Auto);
    assert_eq!(d.ransac.affine_refinement, AffineRefinement::Final);
    // On ACs the defaults are MSAC with a capped λ = 50 px² in scoring and the affine terms in
    // the final refinement; on points plain MSAC.
    let mut rng = Pcg64::seed_from_u64(9);
    let scene = PlaneScene::random(&mut rng);
    let noise = NoiseModel {
        planes: 3,
        outlier_ratio: 0.4,
        pixel_noise: 0.5,
        affine_noise: 0.02,
    };
    let (acs, _) = noisy_correspondences(&mut rng, &scene, 300, &noise);
    let data = Correspondences::from_acs(&acs).unwrap();
    let point_data = data.points_only();
    let (k1, k2) = (&scene.k1, &scene.k2);
    let mut off = EstimatorOptions {
        affine_weight: Some(0.0),
        scoring: ScoringKind::Msac,
        ..Default::default()
    };
    off.ransac.affine_refinement = AffineRefinement::Off;
    assert_ne!(
        estimate_relative_pose(&data, k1, k2, &d).unwrap().model,
        estimate_relative_pose(&data, k1, k2, &off).unwrap().model
    );
    let plain = EstimatorOptions {
        affine_weight: Some(0.0),
        scoring: ScoringKind::Msac,
        ..Default::default()
    };
    assert_eq!(
        estimate_relative_pose(&point_data, k1, k2, &d)
            .unwrap()
            .model,
        estimate_relative_pose(&point_data, k1, k2, &plain)
            .unwrap()
            .model
    );
    // H: points only in scoring (the affine weight is an epipolar default), whatever the data.
    let h_plain = EstimatorOptions {
        affine_weight: Some(0.0),
        ..Default::default()
    };
    assert_eq!(
        estimate_homography(&data, &d).unwrap().model,
        estimate_homography(&data, &h_plain).unwrap().model
    );
}

#[test]
fn the_default_resolves_the_planar_ambiguity_that_points_leave() {
    // One plane: E from points is two-fold ambiguous; the affine term of scoring picks the
    // right one (benches/results/scene_families.md, family "1 plane").
    let noise = NoiseModel {
        planes: 1,
        outlier_ratio: 0.3,
        pixel_noise: 0.5,
        affine_noise: 0.02,
    };
    let mut points = EstimatorOptions {
        affine_weight: Some(0.0),
        ..Default::default()
    };
    points.ransac.threshold = 1.5;
    points.ransac.affine_refinement = AffineRefinement::Off;
    let mut default = EstimatorOptions::default();
    default.ransac.threshold = 1.5;
    let p = pose_errors(&noise, 11, &points);
    let d = pose_errors(&noise, 11, &default);
    eprintln!("one plane: points-only scoring {p:?}, default {d:?}");
    assert!(d.0 < 0.8 * p.0 && d.1 < 0.8 * p.1, "{d:?} vs {p:?}");
}
