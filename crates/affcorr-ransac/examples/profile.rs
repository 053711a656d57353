//! Runs one estimator many times on the criterion bench's scene (N = 2000, 50% outliers), for
//! `perf record` / callgrind:
//! `cargo run --release -p affcorr-ransac --example profile -- fundamental affine 50`.

use affcorr_geom::synthetic::{NoiseModel, PlaneScene, noisy_correspondences};
use affcorr_ransac::{
    Correspondences, EstimatorOptions, RansacOptions, SampleKind, ScoringKind,
    estimate_fundamental, estimate_homography, estimate_relative_pose,
};
use rand::SeedableRng;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let problem = args.get(1).map_or("fundamental", String::as_str);
    let sample = match args.get(2).map_or("affine", String::as_str) {
        "points" => SampleKind::Points,
        _ => SampleKind::Affine,
    };
    let reps: usize = args.get(3).and_then(|r| r.parse().ok()).unwrap_or(50);
    let extra = args.get(4).map_or("", String::as_str);
    let planes = if problem == "homography" { 1 } else { 8 };
    let mut rng = rand_pcg::Pcg64::seed_from_u64(if planes == 1 { 1 } else { 2 });
    let scene = PlaneScene::random(&mut rng);
    let noise = NoiseModel {
        planes,
        outlier_ratio: 0.5,
        pixel_noise: 0.5,
        affine_noise: 0.02,
    };
    let (acs, _) = noisy_correspondences(&mut rng, &scene, 2000, &noise);
    let rows: Vec<[f64; 8]> = acs.iter().map(|a| a.to_row()).collect();
    let data = Correspondences::from_ac_rows(&rows).expect("finite");
    let threshold = if planes == 1 { 2.0 } else { 1.5 };
    let opts = EstimatorOptions {
        ransac: RansacOptions {
            threshold,
            sprt: extra.contains("sprt"),
            ..Default::default()
        },
        sample: Some(sample),
        scoring: if extra.contains("magsac") {
            ScoringKind::Magsac
        } else {
            ScoringKind::Msac
        },
        ..Default::default()
    };
    let start = std::time::Instant::now();
    let (mut iterations, mut lo, mut residuals) = (0, 0, 0);
    for _ in 0..reps {
        let (it, l, r) = match problem {
            "homography" => {
                let e = estimate_homography(&data, &opts).expect("model");
                (e.iterations, e.lo_runs, e.residual_evaluations)
            }
            "pose" => {
                let e = estimate_relative_pose(&data, &scene.k1, &scene.k2, &opts).expect("model");
                (e.iterations, e.lo_runs, e.residual_evaluations)
            }
            _ => {
                let e = estimate_fundamental(&data, &opts).expect("model");
                (e.iterations, e.lo_runs, e.residual_evaluations)
            }
        };
        iterations += it;
        lo += l;
        residuals += r;
    }
    let ms = start.elapsed().as_secs_f64() * 1e3 / reps as f64;
    println!(
        "{problem} {sample:?} {extra}: {ms:.2} ms/run, {} iterations, {} LO runs, {} residuals per run",
        iterations / reps,
        lo / reps,
        residuals / reps as u64
    );
}
