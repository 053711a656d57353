//! The robust estimators (`estimate_homography`, `estimate_fundamental`,
//! `estimate_relative_pose` and their `_batch` forms) on arbitrary correspondences,
//! intrinsics, thresholds and options: no panic, no hang; on success the inlier flags match
//! the count and the model is finite; bad options are errors.
//!
//! The data are either rows read straight from the input, or a seeded synthetic plane scene
//! (noise, outliers) with some entries overwritten by hostile values, so that the fuzzer
//! also reaches the deep paths (local optimisation, refinement, SPRT) of plausible data.
//! Rows go through `Correspondences::from_ac_rows` (which rejects non-finite rows) or, on a
//! flag, straight into the struct's public fields.
#![no_main]

use affcorr_fuzz::{Reader, assert_finite};
use affcorr_geom::camera::Intrinsics;
use affcorr_geom::synthetic::{NoiseModel, PlaneScene, noisy_correspondences};
use affcorr_geom::types::AcRow;
use affcorr_geom::{Mat2, Vec2};
use affcorr_ransac::{
    BatchOptions, Correspondences, Estimate, EstimatorOptions, LoSchedule, RansacOptions, Result,
    SampleKind, SamplerKind, ScoringKind, estimate_fundamental, estimate_fundamental_batch,
    estimate_homography, estimate_homography_batch, estimate_relative_pose,
    estimate_relative_pose_batch,
};
use libfuzzer_sys::fuzz_target;
use rand::SeedableRng;
use rand_pcg::Pcg64;

/// At most this many correspondences, and iterations bounded below, so one run stays fast
/// (a hang is then a real loop without end, not a large problem).
const MAX_N: usize = 160;
const MAX_ITERATIONS: usize = 400;

fn rows(r: &mut Reader, scene: &PlaneScene) -> Vec<AcRow> {
    let mut rows: Vec<AcRow> = if r.bool() {
        let n = usize::from(r.u8()) % 48;
        (0..n).map(|_| std::array::from_fn(|_| r.f64())).collect()
    } else {
        let mut rng = Pcg64::seed_from_u64(r.u64());
        let noise = NoiseModel {
            planes: 1 + usize::from(r.u8() % 3),
            outlier_ratio: f64::from(r.u8() % 10) / 10.0,
            pixel_noise: f64::from(r.u8() % 8) / 4.0,
            affine_noise: f64::from(r.u8() % 8) / 40.0,
        };
        let n = usize::from(r.u8()) % MAX_N;
        let (acs, _) = noisy_correspondences(&mut rng, scene, n, &noise);
        acs.iter().map(|a| a.to_row()).collect()
    };
    // Hostile edits: an entry overwritten, a row duplicated.
    for _ in 0..r.u8() % 8 {
        if rows.is_empty() {
            break;
        }
        let i = usize::from(r.u8()) % rows.len();
        if r.bool() {
            let j = usize::from(r.u8() % 8);
            rows[i][j] = r.f64();
        } else {
            let copy = rows[i];
            rows.push(copy);
        }
    }
    rows
}

fn correspondences(r: &mut Reader, rows: &[AcRow]) -> Option<Correspondences> {
    let points_only = r.u8().is_multiple_of(4);
    if r.bool() {
        // Straight into the public fields: nothing checked.
        return Some(Correspondences {
            x1: rows.iter().map(|v| Vec2::new(v[0], v[1])).collect(),
            x2: rows.iter().map(|v| Vec2::new(v[2], v[3])).collect(),
            a: if points_only {
                Vec::new()
            } else {
                rows.iter()
                    .map(|v| Mat2::new(v[4], v[5], v[6], v[7]))
                    .collect()
            },
        });
    }
    let checked = if points_only {
        let p: Vec<[f64; 4]> = rows.iter().map(|v| [v[0], v[1], v[2], v[3]]).collect();
        Correspondences::from_point_rows(&p)
    } else {
        Correspondences::from_ac_rows(rows)
    };
    let finite = rows.iter().all(|v| {
        let w = if points_only { 4 } else { 8 };
        v[..w].iter().all(|x| x.is_finite())
    });
    assert_eq!(
        checked.is_ok(),
        finite,
        "from_*_rows accepts exactly finite rows"
    );
    checked.ok()
}

fn options(r: &mut Reader, n: usize) -> EstimatorOptions {
    let wild = |r: &mut Reader, tame: f64| {
        if r.u8().is_multiple_of(8) {
            r.f64()
        } else {
            tame
        }
    };
    let threshold = 0.25 + f64::from(r.u8()) / 16.0;
    let ransac = RansacOptions {
        threshold: wild(r, threshold),
        confidence: wild(r, 0.99),
        min_iterations: usize::from(r.u8() % 64),
        max_iterations: usize::from(r.u8()) * MAX_ITERATIONS / 255,
        seed: r.u64(),
        local_optimization: r.bool(),
        lo_iterations: usize::from(r.u8() % 12),
        lo_schedule: [
            LoSchedule::Auto,
            LoSchedule::Widening,
            LoSchedule::Threshold,
            LoSchedule::Both,
        ][usize::from(r.u8() % 4)],
        final_refinement: r.bool(),
        sprt: r.bool(),
        ..Default::default()
    };
    let sample = match r.u8() % 3 {
        0 => None,
        1 => Some(SampleKind::Points),
        _ => Some(SampleKind::Affine),
    };
    let (sampler, quality) = match r.u8() % 4 {
        0 => {
            let len = match r.u8() % 8 {
                0 => n + 1,
                1 => n.saturating_sub(1),
                _ => n,
            };
            let q: Vec<f64> = (0..len).map(|_| r.f64()).collect();
            (
                SamplerKind::Prosac,
                (!r.u8().is_multiple_of(8)).then_some(q),
            )
        }
        _ => (SamplerKind::Uniform, None),
    };
    let scoring = match r.u8() % 3 {
        0 => ScoringKind::Auto,
        1 => ScoringKind::Msac,
        _ => ScoringKind::Magsac,
    };
    let affine_weight = match r.u8() % 4 {
        0 => Some(r.f64()),
        1 => Some(f64::from(r.u8()) / 32.0),
        2 => Some(0.0),
        _ => None,
    };
    EstimatorOptions {
        ransac,
        sample,
        sampler,
        quality,
        scoring,
        affine_weight,
        affine_confidence: r
            .u8()
            .is_multiple_of(4)
            .then(|| (0..n).map(|_| r.f64()).collect()),
    }
}

fn intrinsics(r: &mut Reader, fallback: &Intrinsics) -> Intrinsics {
    if !r.u8().is_multiple_of(4) {
        return *fallback;
    }
    // Whatever Intrinsics::new accepts must be usable; what it rejects is an error, not a panic.
    Intrinsics::new(r.mat3(), "K").unwrap_or(*fallback)
}

fn check<M>(result: &Result<Estimate<M>>, n: usize, finite: impl Fn(&M)) {
    if let Ok(e) = result {
        assert_eq!(e.inliers.len(), n, "one inlier flag per correspondence");
        let count = e.inliers.iter().filter(|&&b| b).count();
        assert_eq!(count, e.num_inliers, "num_inliers counts the flags");
        finite(&e.model);
    }
}

fuzz_target!(|input: &[u8]| {
    let mut r = Reader::new(input);
    let problem = r.u8() % 3;
    let batch = r.u8().is_multiple_of(16);
    let scene = PlaneScene::random(&mut Pcg64::seed_from_u64(u64::from(r.u8())));
    let rows = rows(&mut r, &scene);
    let Some(data) = correspondences(&mut r, &rows) else {
        return;
    };
    let n = data.len();
    let opts = options(&mut r, n);
    let h = |m: &affcorr_geom::Mat3| assert_finite(m, "H / F");
    match problem {
        0 if batch => {
            let pairs = [data.clone(), data];
            for res in estimate_homography_batch(&pairs, &opts) {
                check(&res, n, h);
            }
        }
        0 => check(&estimate_homography(&data, &opts), n, h),
        1 if batch => {
            // A per-pair list of the wrong length is an error for every pair.
            let list = vec![opts.clone(); 1 + usize::from(r.bool())];
            let pairs = [data.clone(), data];
            let res = estimate_fundamental_batch(&pairs, BatchOptions::PerPair(&list));
            for res in &res {
                check(res, n, h);
            }
        }
        1 => check(&estimate_fundamental(&data, &opts), n, h),
        _ => {
            let (k1, k2) = (intrinsics(&mut r, &scene.k1), intrinsics(&mut r, &scene.k2));
            let pose = |m: &affcorr_ransac::problems::relpose::PoseModel| {
                assert_finite(&m.pose.r, "R");
                assert_finite(&m.essential, "E");
                assert_finite(&m.fundamental, "F of the pose");
                assert!(m.pose.t.iter().all(|v| v.is_finite()), "t = {}", m.pose.t);
            };
            if batch {
                let pairs = [(data.clone(), k1, k2), (data, k1, k2)];
                for res in estimate_relative_pose_batch(&pairs, &opts) {
                    check(&res, n, pose);
                }
            } else {
                check(&estimate_relative_pose(&data, &k1, &k2, &opts), n, pose);
            }
        }
    }
});
