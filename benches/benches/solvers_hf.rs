//! ns/call of the homography and fundamental-matrix solvers on exact samples.
//!
//! Each benchmark cycles through 64 precomputed exact samples of different random scenes
//! (anisotropic K1 ≠ K2; for F every correspondence lies on its own plane), so branch predictors
//! and caches see varied data, as inside RANSAC. Benchmark ids are `<solver>` or
//! `<solver>/<N>` for the non-minimal ones. The table with the command is in
//! `benches/results/solvers_hf.md`.

use std::hint::black_box;
use std::time::Duration;

use affcorr::geom::synthetic::{PlaneScene, random_unit, rotation_about};
use affcorr::geom::{AffineCorrespondence, Mat3, Vec2, Vec3};
use affcorr::solvers::fundamental as f;
use affcorr::solvers::homography as h;
use criterion::{BenchmarkGroup, Criterion, measurement::WallTime};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

const SAMPLES: usize = 64;

struct Sample {
    acs: Vec<AffineCorrespondence>,
    x1: Vec<Vec2>,
    x2: Vec<Vec2>,
    f: Mat3,
}

fn sample(acs: Vec<AffineCorrespondence>, f: Mat3) -> Sample {
    Sample {
        x1: acs.iter().map(|a| a.x1).collect(),
        x2: acs.iter().map(|a| a.x2).collect(),
        acs,
        f,
    }
}

/// `SAMPLES` samples of `n` ACs on one plane each.
fn plane_samples(seed: u64, n: usize) -> Vec<Sample> {
    let mut rng = Pcg64::seed_from_u64(seed);
    (0..SAMPLES)
        .map(|_| {
            let scene = PlaneScene::random(&mut rng);
            sample(scene.sample(&mut rng, n), scene.fundamental())
        })
        .collect()
}

/// `SAMPLES` samples of `n` ACs, each on its own plane.
fn general_samples(seed: u64, n: usize) -> Vec<Sample> {
    let mut rng = Pcg64::seed_from_u64(seed);
    (0..SAMPLES)
        .map(|_| {
            let scene = PlaneScene::random(&mut rng);
            let acs = (0..n)
                .map(|_| {
                    let mut s = scene;
                    s.normal = rotation_about(&random_unit(&mut rng), rng.random_range(-0.7..0.7))
                        * Vec3::z();
                    s.distance = rng.random_range(3.0..6.0);
                    s.sample(&mut rng, 1)[0]
                })
                .collect();
            sample(acs, scene.fundamental())
        })
        .collect()
}

fn run(
    group: &mut BenchmarkGroup<'_, WallTime>,
    id: &str,
    samples: &[Sample],
    solve: impl Fn(&Sample, &mut [Mat3]) -> usize,
) {
    // Every sample must give a model, or the benchmark would time an early exit.
    let mut out = [Mat3::zeros(); 4];
    assert!(samples.iter().all(|s| solve(s, &mut out) > 0), "{id}");
    group.bench_function(id, |b| {
        let mut i = 0;
        b.iter(|| {
            i = (i + 1) % SAMPLES;
            black_box(solve(black_box(&samples[i]), &mut out))
        })
    });
}

fn solvers(c: &mut Criterion) {
    let mut g = c.benchmark_group("solvers_hf");
    g.sample_size(30);
    g.warm_up_time(Duration::from_millis(500));
    g.measurement_time(Duration::from_secs(2));

    run(&mut g, "homography_4pt", &plane_samples(1, 4), |s, o| {
        h::homography_4pt(&s.x1, &s.x2, o)
    });
    run(&mut g, "homography_2ac", &plane_samples(2, 2), |s, o| {
        h::homography_2ac(&s.acs, o)
    });
    run(
        &mut g,
        "homography_1ac_given_f",
        &plane_samples(3, 1),
        |s, o| h::homography_1ac_given_f(&s.acs, &s.f, o),
    );
    for n in [4, 100] {
        run(
            &mut g,
            &format!("homography_lsq/{n}"),
            &plane_samples(4, n),
            |s, o| h::homography_lsq(&s.x1, &s.x2, o),
        );
    }
    run(
        &mut g,
        "homography_ac_lsq/100",
        &plane_samples(5, 100),
        |s, o| h::homography_ac_lsq(&s.acs, o),
    );
    run(&mut g, "fundamental_7pt", &general_samples(6, 7), |s, o| {
        f::fundamental_7pt(&s.x1, &s.x2, o)
    });
    for n in [8, 100] {
        run(
            &mut g,
            &format!("fundamental_8pt/{n}"),
            &general_samples(7, n),
            |s, o| f::fundamental_8pt(&s.x1, &s.x2, o),
        );
    }
    run(&mut g, "fundamental_3ac", &general_samples(8, 3), |s, o| {
        f::fundamental_3ac(&s.acs, o)
    });
    run(
        &mut g,
        "fundamental_ac_lsq/100",
        &general_samples(9, 100),
        |s, o| f::fundamental_ac_lsq(&s.acs, o),
    );
    g.finish();
}

fn main() {
    let mut c = Criterion::default().configure_from_args();
    solvers(&mut c);
    c.final_summary();
}
