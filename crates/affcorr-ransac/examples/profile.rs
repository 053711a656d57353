//! Runs one estimator on `scenes` scenes like the criterion bench's (N = 2000, 50% outliers,
//! 0.5 px and 2% affine noise; H: 1 plane, threshold 2 px; F and pose: 8 planes, 1.5 px) and
//! prints the mean time and the median accuracy, for `perf record` / callgrind and for checking
//! that a speed-up costs no accuracy:
//! `cargo run --release -p affcorr-ransac --example profile -- homography affine 20`.
//!
//! The fourth argument changes the defaults: any of `nosprt`, `msac`, `magsac`, `graph_cut`,
//! and one of the local-optimisation schedules `widening`, `threshold`, `both`
//! (comma-separated).

use affcorr_geom::sampson::sampson_point;
use affcorr_geom::synthetic::{NoiseModel, PlaneScene, noisy_correspondences};
use affcorr_geom::{Mat3, PointCorrespondence, Vec3};
use affcorr_ransac::{
    Correspondences, EstimatorOptions, LoKind, LoSchedule, RansacOptions, SampleKind, ScoringKind,
    estimate_fundamental, estimate_homography, estimate_relative_pose,
};
use rand::SeedableRng;

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Mean transfer error (px) of `h` against `truth` over a 20-px grid of a 640×480 image.
fn transfer_error(h: &Mat3, truth: &Mat3) -> f64 {
    let mut sum = 0.0;
    let mut n = 0;
    for x in (0..640).step_by(20) {
        for y in (0..480).step_by(20) {
            let p = Vec3::new(x as f64, y as f64, 1.0);
            let (a, b) = (h * p, truth * p);
            sum += (a.xy() / a.z - b.xy() / b.z).norm();
            n += 1;
        }
    }
    sum / n as f64
}

fn angle_deg(cos: f64) -> f64 {
    cos.clamp(-1.0, 1.0).acos().to_degrees()
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let problem = args.get(1).map_or("fundamental", String::as_str);
    let sample = match args.get(2).map_or("affine", String::as_str) {
        "points" => SampleKind::Points,
        "hybrid" => SampleKind::Hybrid,
        _ => SampleKind::Affine,
    };
    let scenes: u64 = args.get(3).and_then(|r| r.parse().ok()).unwrap_or(20);
    let extra = args.get(4).map_or("", String::as_str);
    let planes = if problem == "homography" { 1 } else { 8 };
    let threshold = if planes == 1 { 2.0 } else { 1.5 };
    let opts = EstimatorOptions {
        ransac: RansacOptions {
            threshold,
            sprt: !extra.contains("nosprt"),
            lo: if extra.contains("graph_cut") {
                LoKind::GraphCut
            } else {
                LoKind::Irls
            },
            lo_schedule: if extra.contains("widening") {
                LoSchedule::Widening
            } else if extra.contains("threshold") {
                LoSchedule::Threshold
            } else if extra.contains("both") {
                LoSchedule::Both
            } else {
                LoSchedule::Auto
            },
            ..Default::default()
        },
        sample: Some(sample),
        scoring: if extra.contains("magsac") {
            ScoringKind::Magsac
        } else if extra.contains("msac") {
            ScoringKind::Msac
        } else {
            ScoringKind::Auto
        },
        ..Default::default()
    };
    let (mut seconds, mut iterations, mut lo, mut refinements) = (0.0, 0, 0, 0);
    let (mut err, mut err2, mut precision, mut recall) = (vec![], vec![], vec![], vec![]);
    for seed in 0..scenes {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(1000 + seed);
        let scene = PlaneScene::random(&mut rng);
        let noise = NoiseModel {
            planes,
            outlier_ratio: 0.5,
            pixel_noise: 0.5,
            affine_noise: 0.02,
        };
        let (acs, truth) = noisy_correspondences(&mut rng, &scene, 2000, &noise);
        let data = Correspondences::from_acs(&acs).expect("finite");
        let start = std::time::Instant::now();
        let (mask, it, l, r) = match problem {
            "homography" => {
                let e = estimate_homography(&data, &opts).expect("model");
                err.push(transfer_error(&e.model, &scene.homography()));
                (e.inliers, e.iterations, e.lo_runs, e.refinements)
            }
            "pose" => {
                let e = estimate_relative_pose(&data, &scene.k1, &scene.k2, &opts).expect("model");
                let (r, t) = (e.model.pose.r, e.model.pose.t);
                err.push(angle_deg(
                    ((r * scene.pose.r.transpose()).trace() - 1.0) / 2.0,
                ));
                err2.push(angle_deg(t.dot(&scene.pose.t.normalize())));
                (e.inliers, e.iterations, e.lo_runs, e.refinements)
            }
            _ => {
                let e = estimate_fundamental(&data, &opts).expect("model");
                let mut sd: Vec<f64> = acs
                    .iter()
                    .zip(&truth)
                    .filter(|(_, t)| **t)
                    .map(|(a, _)| {
                        sampson_point(&e.model, &PointCorrespondence { x1: a.x1, x2: a.x2 }).sqrt()
                    })
                    .collect();
                err.push(median(&mut sd));
                (e.inliers, e.iterations, e.lo_runs, e.refinements)
            }
        };
        seconds += start.elapsed().as_secs_f64();
        let tp = mask.iter().zip(&truth).filter(|(m, t)| **m && **t).count() as f64;
        precision.push(tp / mask.iter().filter(|m| **m).count().max(1) as f64);
        recall.push(tp / truth.iter().filter(|t| **t).count() as f64);
        iterations += it;
        lo += l;
        refinements += r;
    }
    let s = scenes as usize;
    if std::env::var_os("PROFILE_ERRORS").is_some() {
        println!("errors {err:?}");
    }
    let e2 = if err2.is_empty() {
        String::new()
    } else {
        format!(", t err {:.4}°", median(&mut err2))
    };
    println!(
        "{problem} {sample:?} {extra}: {:.2} ms/run, {} iterations, {:.1} LO runs, {:.1} refinements; \
         median error {:.4} (mean {:.4}){e2}, precision {:.4}, recall {:.4}",
        seconds * 1e3 / s as f64,
        iterations / s,
        lo as f64 / s as f64,
        refinements as f64 / s as f64,
        median(&mut err),
        err.iter().sum::<f64>() / err.len() as f64,
        median(&mut precision),
        median(&mut recall),
    );
}
