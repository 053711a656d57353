//! Robust estimation at N = 2000, 50% outliers (0.5 px, 2% affine noise), single thread:
//! `cargo bench -p affcorr-benches --bench ransac`.

use affcorr::geom::synthetic::{NoiseModel, PlaneScene, noisy_correspondences};
use affcorr::ransac::{
    Correspondences, EstimatorOptions, LoKind, RansacOptions, SampleKind, ScoringKind,
    estimate_fundamental, estimate_homography, estimate_relative_pose,
};
use criterion::{Criterion, criterion_group, criterion_main};
use rand::SeedableRng;

/// A bench variant: its name, the sample kind and how it changes the default options.
type Variant = (&'static str, SampleKind, fn(&mut EstimatorOptions));

fn data(planes: usize, seed: u64) -> (PlaneScene, Correspondences) {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let scene = PlaneScene::random(&mut rng);
    let noise = NoiseModel {
        planes,
        outlier_ratio: 0.5,
        pixel_noise: 0.5,
        affine_noise: 0.02,
    };
    let (acs, _) = noisy_correspondences(&mut rng, &scene, 2000, &noise);
    (scene, Correspondences::from_acs(&acs).expect("finite"))
}

fn options(threshold: f64, sample: SampleKind) -> EstimatorOptions {
    EstimatorOptions {
        ransac: RansacOptions {
            threshold,
            ..Default::default()
        },
        sample: Some(sample),
        ..Default::default()
    }
}

fn bench(c: &mut Criterion) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("pool");
    let mut g = c.benchmark_group("ransac_n2000_50pct");
    g.sample_size(20);
    let (_, h_data) = data(1, 1);
    let (scene, e_data) = data(8, 2);
    // Default options (scoring "auto", SPRT on, IRLS LO), then MAGSAC++ scoring, SPRT off and
    // graph-cut LO with AC samples.
    let variants: [Variant; 5] = [
        ("ac", SampleKind::Affine, |_| {}),
        ("points", SampleKind::Points, |_| {}),
        ("ac_magsac", SampleKind::Affine, |o| {
            o.scoring = ScoringKind::Magsac
        }),
        ("ac_nosprt", SampleKind::Affine, |o| o.ransac.sprt = false),
        ("ac_graph_cut", SampleKind::Affine, |o| {
            o.ransac.lo = LoKind::GraphCut
        }),
    ];
    for (name, kind, tweak) in variants {
        let opts = |threshold| {
            let mut o = options(threshold, kind);
            tweak(&mut o);
            o
        };
        let (h_opts, e_opts) = (opts(2.0), opts(1.5));
        g.bench_function(format!("homography_{name}"), |b| {
            b.iter(|| pool.install(|| estimate_homography(&h_data, &h_opts)))
        });
        g.bench_function(format!("relative_pose_{name}"), |b| {
            b.iter(|| {
                pool.install(|| estimate_relative_pose(&e_data, &scene.k1, &scene.k2, &e_opts))
            })
        });
        g.bench_function(format!("fundamental_{name}"), |b| {
            b.iter(|| pool.install(|| estimate_fundamental(&e_data, &e_opts)))
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
