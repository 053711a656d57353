//! End-to-end robust estimation on exact plane-induced scenes with noise and outliers.
//!
//! Several planes seen by the same two cameras (K1 ≠ K2, fx ≠ fy) give ACs with exact ground
//! truth; we add pixel noise to x2, relative noise to A, and replace a fraction of the
//! correspondences by random ones.

use affcorr_geom::synthetic::PlaneScene;
use affcorr_ransac::{
    Correspondences, EstimatorOptions, LoKind, RansacError, RansacOptions, SampleKind, SamplerKind,
    estimate_fundamental, estimate_homography, estimate_relative_pose,
};
use rand::SeedableRng;
use rand_pcg::Pcg64;

mod common;
use common::{angle_deg, make_data, transfer_error};

fn recall(truth: &[bool], found: &[bool]) -> f64 {
    let tp = truth.iter().zip(found).filter(|(t, f)| **t && **f).count();
    tp as f64 / truth.iter().filter(|t| **t).count() as f64
}

fn options(threshold: f64, kind: SampleKind, seed: u64) -> EstimatorOptions {
    EstimatorOptions {
        sample: Some(kind),
        ..default_options(threshold, seed)
    }
}

/// The estimators' defaults at `threshold` and `seed`.
fn default_options(threshold: f64, seed: u64) -> EstimatorOptions {
    EstimatorOptions {
        ransac: RansacOptions {
            threshold,
            seed,
            ..Default::default()
        },
        ..Default::default()
    }
}

#[test]
fn homography_at_50_percent_outliers_points_and_acs() {
    let mut rng = Pcg64::seed_from_u64(10);
    for trial in 0..5 {
        let scene = PlaneScene::random(&mut rng);
        let d = make_data(&mut rng, &scene, 1, 1000, 0.5, 0.5, 0.02);
        for kind in [SampleKind::Points, SampleKind::Affine, SampleKind::Hybrid] {
            let est = estimate_homography(&d.data, &options(2.0, kind, trial)).unwrap();
            let err = transfer_error(&est.model, &scene.homography(), 80);
            assert!(err < 1.0, "{kind:?}: transfer error {err}");
            let r = recall(&d.is_inlier, &est.inliers);
            assert!(r >= 0.99, "{kind:?}: recall {r}");
        }
    }
}

#[test]
fn ac_sampling_needs_far_fewer_iterations() {
    // 2-AC samples instead of 5 points: at 50% outliers the adaptive bound drops from ~290 to
    // ~32 iterations; noisy affine maps make some all-inlier samples miss, so ask for 3×.
    let mut rng = Pcg64::seed_from_u64(11);
    let (mut it_pts, mut it_acs) = (0, 0);
    for seed in 0..5 {
        let scene = PlaneScene::random(&mut rng);
        let d = make_data(&mut rng, &scene, 3, 2000, 0.5, 0.5, 0.02);
        let (k1, k2) = (scene.k1, scene.k2);
        it_pts +=
            estimate_relative_pose(&d.data, &k1, &k2, &options(1.5, SampleKind::Points, seed))
                .unwrap()
                .iterations;
        it_acs +=
            estimate_relative_pose(&d.data, &k1, &k2, &options(1.5, SampleKind::Affine, seed))
                .unwrap()
                .iterations;
    }
    assert!(it_acs * 3 < it_pts, "AC {it_acs} vs points {it_pts}");
}

#[test]
fn hybrid_sampling_needs_fewer_iterations_than_points() {
    // One AC and two points (3 data) instead of 5 points: at 50% outliers the bound drops from
    // ~290 to ~70 iterations; ask for half.
    let mut rng = Pcg64::seed_from_u64(15);
    let (mut it_pts, mut it_hybrid) = (0, 0);
    for seed in 0..5 {
        let scene = PlaneScene::random(&mut rng);
        let d = make_data(&mut rng, &scene, 3, 2000, 0.5, 0.5, 0.02);
        let (k1, k2) = (scene.k1, scene.k2);
        let run = |kind| {
            estimate_relative_pose(&d.data, &k1, &k2, &options(1.5, kind, seed))
                .unwrap()
                .iterations
        };
        it_pts += run(SampleKind::Points);
        it_hybrid += run(SampleKind::Hybrid);
    }
    assert!(
        it_hybrid * 2 < it_pts,
        "hybrid {it_hybrid} vs points {it_pts}"
    );
}

#[test]
fn noisy_affine_parts_make_ac_sampling_search_longer_and_still_find_the_pose() {
    // Learned ACs have affine errors of ~30%: few all-inlier 2-AC samples then give a model
    // near the truth, and the textbook bound (inliers only) stopped after a few dozen samples
    // at wrong models. The bound counts the data whose affine part is accurate too.
    let mut rng = Pcg64::seed_from_u64(13);
    let (mut it_exact, mut it_noisy) = (0, 0);
    for trial in 0..5 {
        let scene = PlaneScene::random(&mut rng);
        let exact = make_data(&mut rng, &scene, 3, 1000, 0.3, 0.5, 0.02);
        let noisy = make_data(&mut rng, &scene, 3, 1000, 0.3, 0.5, 0.3);
        // Points-only scoring: the default would give way to point samples on the noisy ACs
        // (DEFAULT_AFFINE_FALLBACK), and this test is about the 2-AC search.
        let opts = EstimatorOptions {
            affine_weight: Some(0.0),
            ..options(1.5, SampleKind::Affine, trial)
        };
        it_exact += estimate_relative_pose(&exact.data, &scene.k1, &scene.k2, &opts)
            .unwrap()
            .iterations;
        let est = estimate_relative_pose(&noisy.data, &scene.k1, &scene.k2, &opts).unwrap();
        it_noisy += est.iterations;
        let r_err = angle_deg(&(est.model.pose.r.transpose() * scene.pose.r));
        let t_err = est.model.pose.t.angle(&scene.pose.t).to_degrees();
        assert!(
            r_err < 0.5 && t_err < 3.0,
            "trial {trial}: {r_err}°, {t_err}°"
        );
        let r = recall(&noisy.is_inlier, &est.inliers);
        assert!(r >= 0.99, "trial {trial}: recall {r}");
    }
    assert!(
        it_noisy > 5 * it_exact,
        "noisy {it_noisy} vs exact {it_exact}"
    );
}

#[test]
fn relative_pose_at_50_percent_outliers_points_and_acs() {
    let mut rng = Pcg64::seed_from_u64(12);
    for trial in 0..5 {
        let scene = PlaneScene::random(&mut rng);
        let d = make_data(&mut rng, &scene, 3, 1000, 0.5, 0.5, 0.02);
        for kind in [SampleKind::Points, SampleKind::Affine, SampleKind::Hybrid] {
            let est =
                estimate_relative_pose(&d.data, &scene.k1, &scene.k2, &options(1.5, kind, trial))
                    .unwrap();
            let r_err = angle_deg(&(est.model.pose.r.transpose() * scene.pose.r));
            let t_err = est.model.pose.t.angle(&scene.pose.t).to_degrees();
            assert!(
                r_err < 0.5,
                "{kind:?} trial {trial}: rotation error {r_err}°"
            );
            assert!(
                t_err < 3.0,
                "{kind:?} trial {trial}: translation error {t_err}°"
            );
            let r = recall(&d.is_inlier, &est.inliers);
            assert!(r >= 0.99, "{kind:?} trial {trial}: recall {r}");
        }
    }
}

#[test]
fn fundamental_at_50_percent_outliers_points_and_acs() {
    let mut rng = Pcg64::seed_from_u64(13);
    for trial in 0..5 {
        let scene = PlaneScene::random(&mut rng);
        let d = make_data(&mut rng, &scene, 5, 1000, 0.5, 0.5, 0.02);
        let truth = scene.fundamental();
        for kind in [SampleKind::Points, SampleKind::Affine, SampleKind::Hybrid] {
            let est = estimate_fundamental(&d.data, &options(1.5, kind, trial)).unwrap();
            // The true inliers' Sampson error under the estimate is at the noise level.
            let rows: Vec<usize> = (0..d.data.len()).filter(|&i| d.is_inlier[i]).collect();
            let mean: f64 = rows
                .iter()
                .map(|&i| {
                    affcorr_geom::sampson::sampson_point(&est.model, &d.data.ac(i).points()).sqrt()
                })
                .sum::<f64>()
                / rows.len() as f64;
            let truth_mean: f64 = rows
                .iter()
                .map(|&i| {
                    affcorr_geom::sampson::sampson_point(&truth, &d.data.ac(i).points()).sqrt()
                })
                .sum::<f64>()
                / rows.len() as f64;
            assert!(
                mean < 1.2 * truth_mean + 0.05,
                "{kind:?} trial {trial}: {mean} vs truth {truth_mean}"
            );
            let r = recall(&d.is_inlier, &est.inliers);
            assert!(r >= 0.99, "{kind:?} trial {trial}: recall {r}");
        }
    }
}

#[test]
fn prosac_and_batch_and_errors() {
    let mut rng = Pcg64::seed_from_u64(14);
    let scene = PlaneScene::random(&mut rng);
    let d = make_data(&mut rng, &scene, 1, 500, 0.6, 0.5, 0.02);
    // Quality: the true inliers rank first (a perfect matcher certainty).
    let quality: Vec<f64> = d
        .is_inlier
        .iter()
        .map(|&b| if b { 1.0 } else { 0.0 })
        .collect();
    let mut opts = options(2.0, SampleKind::Points, 0);
    opts.sampler = SamplerKind::Prosac;
    opts.quality = Some(quality);
    let est = estimate_homography(&d.data, &opts).unwrap();
    assert!(transfer_error(&est.model, &scene.homography(), 80) < 1.0);
    let uniform = estimate_homography(&d.data, &options(2.0, SampleKind::Points, 0)).unwrap();
    assert!(est.iterations <= uniform.iterations);

    let batch = affcorr_ransac::estimate_homography_batch(
        &[d.data.clone(), d.data.clone()],
        &options(2.0, SampleKind::Affine, 3),
    );
    let single = estimate_homography(&d.data, &options(2.0, SampleKind::Affine, 3)).unwrap();
    for b in batch {
        assert_eq!(b.unwrap().model, single.model);
    }

    opts.quality = Some(vec![1.0; 3]);
    assert!(estimate_homography(&d.data, &opts).is_err());
    let points = Correspondences::from_point_rows(&[[0.0; 4]; 10]).unwrap();
    assert!(estimate_homography(&points, &options(1.0, SampleKind::Affine, 0)).is_err());
    for kind in [SampleKind::Affine, SampleKind::Hybrid] {
        let err = estimate_fundamental(&points, &options(1.0, kind, 0)).unwrap_err();
        assert!(
            matches!(err, RansacError::InvalidOption { name: "sample", .. }),
            "{err}"
        );
    }
    assert!(Correspondences::from_ac_rows(&[[f64::NAN; 8]]).is_err());
}

#[test]
fn acs_and_their_rows_make_the_same_data_and_the_same_errors() {
    let mut rng = Pcg64::seed_from_u64(31);
    let scene = PlaneScene::random(&mut rng);
    let d = make_data(&mut rng, &scene, 2, 40, 0.3, 0.5, 0.02);
    let acs: Vec<_> = (0..d.data.len()).map(|i| d.data.ac(i)).collect();
    let rows: Vec<_> = acs.iter().map(|ac| ac.to_row()).collect();
    let (from_acs, from_rows) = (
        Correspondences::from_acs(&acs).unwrap(),
        Correspondences::from_ac_rows(&rows).unwrap(),
    );
    assert_eq!(
        (&from_acs.x1, &from_acs.x2, &from_acs.a),
        (&from_rows.x1, &from_rows.x2, &from_rows.a)
    );
    let points = from_acs.points_only();
    assert!(!points.has_affine() && points.x1 == from_acs.x1 && points.x2 == from_acs.x2);
    let mut bad = acs;
    bad[7].a[(1, 0)] = f64::INFINITY;
    match Correspondences::from_acs(&bad) {
        Err(RansacError::NonFinite { what, index }) => assert_eq!((what, index), ("corrs", 7)),
        other => panic!("{other:?}"),
    }
}

#[test]
fn batch_options_per_pair_and_no_model_iterations() {
    let mut rng = Pcg64::seed_from_u64(15);
    let scene = PlaneScene::random(&mut rng);
    let d = make_data(&mut rng, &scene, 1, 300, 0.5, 0.5, 0.02);
    let per_pair = [
        options(2.0, SampleKind::Affine, 1),
        options(2.0, SampleKind::Points, 2),
    ];
    let data = [d.data.clone(), d.data.clone()];
    let batch = affcorr_ransac::estimate_homography_batch(&data, &per_pair);
    for (b, o) in batch.into_iter().zip(&per_pair) {
        let single = estimate_homography(&d.data, o).unwrap();
        let b = b.unwrap();
        assert_eq!(b.model, single.model);
        assert_eq!(b.iterations, single.iterations);
    }
    // Per-pair seeds differ, so the two pairs ran differently.
    let [a, b] = &per_pair;
    assert_ne!(
        estimate_homography(&d.data, a).unwrap().iterations,
        estimate_homography(&d.data, b).unwrap().iterations
    );
    // A wrong number of option sets is an error for every pair.
    let wrong = affcorr_ransac::estimate_fundamental_batch(&data, &per_pair[..1]);
    assert!(wrong.iter().all(|r| matches!(
        r,
        Err(affcorr_ransac::RansacError::InvalidOption {
            name: "options",
            ..
        })
    )));

    // NoModel reports the iterations it ran: identical points make every sample degenerate.
    let same = Correspondences::from_point_rows(&[[10.0, 20.0, 30.0, 40.0]; 20]).unwrap();
    let mut o = options(1.0, SampleKind::Points, 0);
    o.ransac.max_iterations = 37;
    match estimate_homography(&same, &o) {
        Err(affcorr_ransac::RansacError::NoModel { iterations }) => assert_eq!(iterations, 37),
        other => panic!("expected NoModel, got {:?}", other.map(|e| e.num_inliers)),
    }
}

/// Precision of `found` against `truth`.
fn precision(truth: &[bool], found: &[bool]) -> f64 {
    let tp = truth.iter().zip(found).filter(|(t, f)| **t && **f).count();
    tp as f64 / found.iter().filter(|f| **f).count().max(1) as f64
}

#[test]
fn graph_cut_lo_recovers_the_inliers_at_least_as_well_as_irls() {
    // A tight threshold (2σ of the pixel noise) at 60% outliers: thresholding alone misses the
    // true inliers beyond 2σ, which neighbours can pull in.
    let mut rng = Pcg64::seed_from_u64(21);
    let (mut sums_irls, mut sums_gc) = ([0.0; 3], [0.0; 3]);
    let trials = 6;
    for trial in 0..trials {
        let scene = PlaneScene::random(&mut rng);
        let h = make_data(&mut rng, &scene, 1, 1500, 0.6, 0.5, 0.02);
        let e = make_data(&mut rng, &scene, 6, 1500, 0.6, 0.5, 0.02);
        for (lo, sums) in [
            (LoKind::Irls, &mut sums_irls),
            (LoKind::GraphCut, &mut sums_gc),
        ] {
            let mut o = options(1.0, SampleKind::Affine, trial);
            o.ransac.lo = lo;
            let est = estimate_homography(&h.data, &o).unwrap();
            sums[0] += recall(&h.is_inlier, &est.inliers);
            sums[1] += transfer_error(&est.model, &scene.homography(), 40);
            let est = estimate_relative_pose(&e.data, &scene.k1, &scene.k2, &o).unwrap();
            sums[0] += recall(&e.is_inlier, &est.inliers);
            assert!(precision(&e.is_inlier, &est.inliers) > 0.98, "{lo:?}");
            sums[2] += angle_deg(&(est.model.pose.r * scene.pose.r.transpose()));
        }
    }
    let mean = |s: [f64; 3]| s.map(|v| v / trials as f64);
    let (irls, gc) = (mean(sums_irls), mean(sums_gc));
    // recall summed over H and pose (2 per trial), H transfer error (px), rotation error (°).
    assert!(
        gc[0] >= irls[0] - 0.005,
        "recall: graph cut {gc:?} vs IRLS {irls:?}"
    );
    assert!(gc[0] > 2.0 * 0.8, "{gc:?}");
    assert!(gc[1] <= 1.2 * irls[1] + 0.01, "H error: {gc:?} vs {irls:?}");
    assert!(
        gc[2] <= 1.2 * irls[2] + 0.005,
        "rotation error: {gc:?} vs {irls:?}"
    );
    eprintln!("graph cut {gc:?}, IRLS {irls:?}");
}

#[test]
fn graph_cut_lo_is_deterministic() {
    let mut rng = Pcg64::seed_from_u64(22);
    let scene = PlaneScene::random(&mut rng);
    let d = make_data(&mut rng, &scene, 3, 800, 0.5, 0.5, 0.02);
    let mut o = options(1.5, SampleKind::Affine, 4);
    o.ransac.lo = LoKind::GraphCut;
    let a = estimate_fundamental(&d.data, &o).unwrap();
    let b = estimate_fundamental(&d.data, &o).unwrap();
    assert_eq!(a.model, b.model);
    assert_eq!(a.inliers, b.inliers);
    assert!(a.lo_runs >= 1);
}

/// Rows of `a` then `b`, as one data set.
fn concat(a: &Correspondences, b: &Correspondences) -> Correspondences {
    Correspondences {
        x1: [&a.x1[..], &b.x1[..]].concat(),
        x2: [&a.x2[..], &b.x2[..]].concat(),
        a: [&a.a[..], &b.a[..]].concat(),
    }
}

#[test]
fn poor_acs_of_the_true_model_never_lose_to_a_consistent_decoy() {
    // Repetitive texture gives both: the true motion's ACs with wrong A, and a smaller set of
    // matches consistent with another motion, A included. The affine score prefers the decoy
    // (its own inliers are all it explains); the default must see that the points of the true
    // model explain twice as many and return the points-scored estimate.
    let mut rng = Pcg64::seed_from_u64(22);
    let mut decoys = 0;
    for trial in 0..4 {
        let truth = PlaneScene::random(&mut rng);
        let mut decoy_scene = PlaneScene::random(&mut rng);
        (decoy_scene.k1, decoy_scene.k2) = (truth.k1, truth.k2);
        let poor = make_data(&mut rng, &truth, 3, 600, 0.0, 0.5, 1.0);
        let decoy = make_data(&mut rng, &decoy_scene, 3, 300, 0.0, 0.5, 0.0);
        let data = concat(&poor.data, &decoy.data);
        let opts = EstimatorOptions {
            ransac: RansacOptions {
                threshold: 1.5,
                seed: trial,
                ..Default::default()
            },
            ..Default::default()
        };
        let scored = EstimatorOptions {
            affine_weight: Some(affcorr_ransac::DEFAULT_AFFINE_WEIGHT),
            ..opts.clone()
        };
        let pose_error = |r: &affcorr_geom::Mat3| angle_deg(&(r.transpose() * truth.pose.r));
        // The premise (counted below): affine scoring alone picks the decoy.
        let e = estimate_relative_pose(&data, &truth.k1, &truth.k2, &scored).unwrap();
        decoys += usize::from(pose_error(&e.model.pose.r) > 5.0);
        let e = estimate_relative_pose(&data, &truth.k1, &truth.k2, &opts).unwrap();
        let r_err = pose_error(&e.model.pose.r);
        assert!(r_err < 0.5, "trial {trial}: pose {r_err}°");
        assert!(
            e.num_inliers >= 550,
            "trial {trial}: {} inliers",
            e.num_inliers
        );
        // F: the same rule.
        let f = estimate_fundamental(&data, &opts).unwrap();
        let found = f.inliers[..600].iter().filter(|&&v| v).count();
        assert!(
            found >= 550,
            "trial {trial}: F kept {found} of the true model's 600"
        );
    }
    assert!(
        decoys >= 2,
        "affine scoring chose the decoy in only {decoys} of 4 trials"
    );
}

#[test]
fn the_default_affine_weight_follows_the_noise_of_a() {
    // Exact A keeps the default weight. A noisier than it assumes (20%) is scored at the
    // weight its measured noise allows, which keeps more of the true inliers than the fixed
    // weight does, unless the run at the default weight already showed A too poor to score
    // with: then points, as for A off by 50%. An explicit weight is used as given, and points
    // and H score by points.
    let mut rng = Pcg64::seed_from_u64(26);
    let default = affcorr_ransac::DEFAULT_AFFINE_WEIGHT;
    let opts = |seed| EstimatorOptions {
        ransac: RansacOptions {
            threshold: 1.5,
            seed,
            ..Default::default()
        },
        ..Default::default()
    };
    let fixed = |seed| EstimatorOptions {
        affine_weight: Some(default),
        ..opts(seed)
    };
    let mut measured_runs = 0;
    for trial in 0..4 {
        let scene = PlaneScene::random(&mut rng);
        let (k1, k2) = (&scene.k1, &scene.k2);
        let pose = |data: &Correspondences, o: &EstimatorOptions| {
            estimate_relative_pose(data, k1, k2, o).unwrap()
        };
        let exact = make_data(&mut rng, &scene, 4, 500, 0.3, 0.5, 0.0);
        assert_eq!(pose(&exact.data, &opts(trial)).affine_weight, default);
        let f = estimate_fundamental(&exact.data, &opts(trial)).unwrap();
        assert_eq!(f.affine_weight, default, "trial {trial}: exact A, F");

        let noisy = make_data(&mut rng, &scene, 4, 500, 0.3, 0.5, 0.2);
        let truth = &noisy.is_inlier;
        let (e, by_fixed) = (
            pose(&noisy.data, &opts(trial)),
            pose(&noisy.data, &fixed(trial)),
        );
        let r_err = angle_deg(&(e.model.pose.r.transpose() * scene.pose.r));
        assert!(r_err < 0.5, "trial {trial}: pose {r_err}°");
        let f = estimate_fundamental(&noisy.data, &opts(trial)).unwrap();
        let f_fixed = estimate_fundamental(&noisy.data, &fixed(trial)).unwrap();
        for (what, w, found, assumed) in [
            ("pose", e.affine_weight, &e.inliers, &by_fixed.inliers),
            ("F", f.affine_weight, &f.inliers, &f_fixed.inliers),
        ] {
            let (found, assumed) = (recall(truth, found), recall(truth, assumed));
            assert!(
                found > assumed + 0.02,
                "trial {trial}, {what}: recall {found:.3} at weight {w}, {assumed:.3} at {default}"
            );
            // 0: the fallback to points, which the fixed weight's inlier loss triggers.
            assert!(
                (0.0..default).contains(&w),
                "trial {trial}, {what}: weight {w}"
            );
            measured_runs += usize::from(w > 0.0);
        }
        assert_eq!(f_fixed.affine_weight, default);

        let poor = make_data(&mut rng, &scene, 4, 500, 0.3, 0.5, 0.5);
        assert_eq!(pose(&poor.data, &opts(trial)).affine_weight, 0.0);
        let f = estimate_fundamental(&poor.data, &opts(trial)).unwrap();
        assert_eq!(f.affine_weight, 0.0, "trial {trial}: A off by 50%, F");

        let points = noisy.data.points_only();
        assert_eq!(
            estimate_fundamental(&points, &opts(trial))
                .unwrap()
                .affine_weight,
            0.0
        );
        let h = estimate_homography(&noisy.data, &opts(trial)).unwrap();
        assert_eq!(h.affine_weight, 0.0, "H scores by points by default");
    }
    assert!(
        measured_runs >= 2,
        "the measured weight scored only {measured_runs} of 8 estimates"
    );
}

#[test]
fn acs_too_poor_to_score_with_give_the_estimate_of_their_points() {
    // A off by 50%: the default falls back to points (`affine_weight` 0), and then its A no
    // longer enters the final refinement either, so the ACs give exactly what their points
    // give (the same seed, the same samples). With A in that refinement, repetitive texture
    // moved real poses away from the points' (docs/estimation.md, "Poor A stays out").
    let mut rng = Pcg64::seed_from_u64(31);
    for trial in 0..3 {
        let scene = PlaneScene::random(&mut rng);
        let poor = make_data(&mut rng, &scene, 4, 500, 0.3, 0.5, 0.5);
        let points = poor.data.points_only();
        let opts = default_options(1.5, trial);
        let (k1, k2) = (&scene.k1, &scene.k2);
        let e = estimate_relative_pose(&poor.data, k1, k2, &opts).unwrap();
        let p = estimate_relative_pose(&points, k1, k2, &opts).unwrap();
        assert_eq!(e.affine_weight, 0.0, "trial {trial}: the fallback");
        assert_eq!(e.inliers, p.inliers, "trial {trial}: pose inliers");
        let (re, rp) = (&e.model.pose, &p.model.pose);
        assert!(
            (re.r - rp.r).norm() < 1e-12 && (re.t - rp.t).norm() < 1e-12,
            "trial {trial}: pose {re:?} against the points' {rp:?}"
        );
        let f = estimate_fundamental(&poor.data, &opts).unwrap();
        let fp = estimate_fundamental(&points, &opts).unwrap();
        assert_eq!(f.affine_weight, 0.0, "trial {trial}: F's fallback");
        assert_eq!(f.inliers, fp.inliers, "trial {trial}: F inliers");
        let (fe, fq) = (f.model / f.model.norm(), fp.model / fp.model.norm());
        assert!(
            (fe - fq).norm().min((fe + fq).norm()) < 1e-12,
            "trial {trial}: F {fe} against the points' {fq}"
        );
    }
}
