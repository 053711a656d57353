//! Throughput of the batched geometry kernels and the machine's attainable memory bandwidth,
//! measured in the same run so that the two can be compared.
//!
//! Benchmark ids are `<kernel>/t<threads>/<N>`; every kernel runs inside a local rayon pool of
//! 1 thread and of all cores. Below `batch::PARALLEL_MIN_LEN` rows the kernels stay on the
//! calling thread by design, so `t1` and `tN` coincide there.
//!
//! `stream/<op>/t<threads>/<MB>` are STREAM-like `scale` (b = s·a) and `triad` (a = b + s·c)
//! loops: once on arrays far larger than the last-level cache (DRAM bandwidth), once on a
//! footprint like that of a kernel at N = 10⁶ (which may be served partly by L3).
//!
//! `python -m affcorr_bench.geom_table` turns criterion's output into `benches/results/geom.md`;
//! the bytes per row that it charges each kernel are listed there next to the table.

use std::hint::black_box;
use std::time::Duration;

use affcorr::geom::affine::{self, AffineShape};
use affcorr::geom::camera::{self, Intrinsics};
use affcorr::geom::homography;
use affcorr::geom::sampson::{self, AffineSampsonGrad, PointSampsonGrad};
use affcorr::geom::synthetic::PlaneScene;
use affcorr::geom::types::{AcRow, PointRow};
use affcorr::geom::{Mat3, batch};
use criterion::measurement::Measurement;
use criterion::{BenchmarkGroup, BenchmarkId, Criterion, Throughput};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use rayon::prelude::*;

const SIZES: [usize; 4] = [1_000, 10_000, 100_000, 1_000_000];

/// 1 thread and every core (deduplicated on a 1-core machine).
fn thread_counts() -> Vec<usize> {
    let all = std::thread::available_parallelism().map_or(1, |n| n.get());
    if all > 1 { vec![1, all] } else { vec![1] }
}

fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("rayon pool")
}

/// A criterion measurement usable inside a rayon pool (wall-clock time here; the benches are
/// generic so that another measurement can be plugged in).
trait Clock: Measurement<Value: Send> + Sync + 'static {}
impl<M: Measurement<Value: Send> + Sync + 'static> Clock for M {}

fn configure<M: Measurement>(group: &mut BenchmarkGroup<'_, M>) {
    // Keep the run short on a shared machine; the command line can override both times.
    group.sample_size(20);
    group.warm_up_time(Duration::from_secs(1));
    group.measurement_time(Duration::from_secs(2));
}

/// Runs `body` for every thread count and N, each inside its own pool. `setup(n)` builds the
/// inputs once per N, outside the timing and only if a benchmark of that N passes the filter.
fn bench_kernel<M, T, S, B>(c: &mut Criterion<M>, name: &str, setup: S, body: B)
where
    M: Clock,
    T: Send,
    S: Fn(usize) -> T,
    B: Fn(&mut T) + Sync,
{
    let mut group = c.benchmark_group(name);
    configure(&mut group);
    for &n in &SIZES {
        let mut data = None;
        group.throughput(Throughput::Elements(n as u64));
        for threads in thread_counts() {
            let pool = pool(threads);
            group.bench_function(BenchmarkId::new(format!("t{threads}"), n), |b| {
                let data = data.get_or_insert_with(|| setup(n));
                pool.install(|| b.iter(|| body(data)));
            });
        }
    }
    group.finish();
}

fn rng() -> Pcg64 {
    Pcg64::seed_from_u64(0x5eed_a11e)
}

struct SynthData {
    orientation: Vec<f64>,
    scale: Vec<f64>,
    residual: Vec<[f64; 3]>,
    out: Vec<[f64; 4]>,
}

fn random_shapes(n: usize) -> SynthData {
    let mut r = rng();
    SynthData {
        orientation: (0..n).map(|_| r.random_range(-3.1..3.1)).collect(),
        scale: (0..n).map(|_| r.random_range(-2.0f64..2.0).exp()).collect(),
        residual: (0..n)
            .map(|_| {
                [
                    r.random_range(-0.5..1.0),
                    r.random_range(-1.0..1.0),
                    r.random_range(-0.5..1.0),
                ]
            })
            .collect(),
        out: vec![[0.0; 4]; n],
    }
}

struct DecompData {
    a: Vec<[f64; 4]>,
    out: Vec<AffineShape>,
}

struct NormData {
    corrs: Vec<AcRow>,
    k1: Intrinsics,
    k2: Intrinsics,
    out: Vec<AcRow>,
}

struct HomData {
    h: Mat3,
    x1: Vec<[f64; 2]>,
    out: Vec<AcRow>,
}

/// The graffiti 1→3 homography (Oxford affine dataset), as in the geometry tests.
fn graffiti_h() -> Mat3 {
    Mat3::new(
        7.6285898e-01,
        -2.9922929e-01,
        2.2567123e+02,
        3.3443473e-01,
        1.0143901e+00,
        -7.6999973e+01,
        3.4663091e-04,
        -1.4364524e-05,
        1.0000000e+00,
    )
}

fn random_points(n: usize) -> Vec<[f64; 2]> {
    let mut r = rng();
    (0..n)
        .map(|_| [r.random_range(0.0..800.0), r.random_range(0.0..640.0)])
        .collect()
}

fn geometry_kernels<M: Clock>(c: &mut Criterion<M>) {
    bench_kernel(
        c,
        "synthesize_affine",
        random_shapes,
        |d: &mut SynthData| {
            affine::synthesize_affine(
                black_box(&d.orientation),
                black_box(&d.scale),
                black_box(&d.residual),
                &mut d.out,
            )
            .unwrap();
            black_box(&d.out);
        },
    );

    bench_kernel(
        c,
        "decompose_affine",
        |n| {
            let mut s = random_shapes(n);
            affine::synthesize_affine(&s.orientation, &s.scale, &s.residual, &mut s.out).unwrap();
            DecompData {
                a: s.out,
                out: vec![
                    AffineShape {
                        orientation: 0.0,
                        scale: 1.0,
                        residual_shape: [0.0; 3],
                    };
                    n
                ],
            }
        },
        |d: &mut DecompData| {
            affine::decompose_affine(black_box(&d.a), &mut d.out).unwrap();
            black_box(&d.out);
        },
    );

    bench_kernel(
        c,
        "normalize_correspondences",
        |n| {
            let h = graffiti_h();
            let x1 = random_points(n);
            let mut corrs = vec![[0.0; 8]; n];
            homography::correspondences_from_homography(&h, &x1, &mut corrs).unwrap();
            NormData {
                corrs,
                k1: Intrinsics::from_focal(900.0, 880.0, 400.0, 320.0).unwrap(),
                k2: Intrinsics::from_focal(700.0, 760.0, 410.0, 300.0).unwrap(),
                out: vec![[0.0; 8]; n],
            }
        },
        |d: &mut NormData| {
            camera::normalize_correspondences(black_box(&d.corrs), &d.k1, &d.k2, &mut d.out)
                .unwrap();
            black_box(&d.out);
        },
    );

    bench_kernel(
        c,
        "correspondences_from_homography",
        |n| HomData {
            h: graffiti_h(),
            x1: random_points(n),
            out: vec![[0.0; 8]; n],
        },
        |d: &mut HomData| {
            homography::correspondences_from_homography(&d.h, black_box(&d.x1), &mut d.out)
                .unwrap();
            black_box(&d.out);
        },
    );
}

/// STREAM `scale`: b = s·a (16 B per element moved).
fn stream_scale(b: &mut [f64], a: &[f64], s: f64) {
    if b.len() < batch::PARALLEL_MIN_LEN {
        b.iter_mut().zip(a).for_each(|(b, a)| *b = s * a);
        return;
    }
    const CHUNK: usize = 1 << 16;
    b.par_chunks_mut(CHUNK)
        .zip(a.par_chunks(CHUNK))
        .for_each(|(b, a)| b.iter_mut().zip(a).for_each(|(b, a)| *b = s * a));
}

/// STREAM `triad`: a = b + s·c (24 B per element moved).
fn stream_triad(a: &mut [f64], b: &[f64], c: &[f64], s: f64) {
    const CHUNK: usize = 1 << 16;
    a.par_chunks_mut(CHUNK)
        .zip(b.par_chunks(CHUNK).zip(c.par_chunks(CHUNK)))
        .for_each(|(a, (b, c))| {
            a.iter_mut()
                .zip(b.iter().zip(c))
                .for_each(|(a, (b, c))| *a = b + s * c)
        });
}

fn memory_bandwidth<M: Clock>(c: &mut Criterion<M>) {
    // Elements per array: 3 × 2²⁵ f64 = 768 MiB for the triad, far beyond any cache here; and
    // 3 × 3·10⁶ f64 = 72 MB, the footprint of synthesis/decomposition at N = 10⁶.
    const DRAM: usize = 1 << 25;
    const KERNEL_SIZED: usize = 3_000_000;
    let mut group = c.benchmark_group("stream");
    group.sample_size(10);
    group.warm_up_time(Duration::from_secs(1));
    group.measurement_time(Duration::from_secs(3));
    for len in [DRAM, KERNEL_SIZED] {
        let mut arrays = None;
        let init = || (vec![1.0f64; len], vec![2.0f64; len], vec![3.0f64; len]);
        for threads in thread_counts() {
            let pool = pool(threads);
            // Throughput is in bytes moved (the STREAM convention: write-allocate not counted).
            group.throughput(Throughput::Bytes((16 * len) as u64));
            group.bench_function(
                BenchmarkId::new(format!("scale/t{threads}"), 16 * len / 1_000_000),
                |bch| {
                    let (a, b, _) = arrays.get_or_insert_with(init);
                    pool.install(|| bch.iter(|| stream_scale(b, black_box(a), 1.0001)))
                },
            );
            group.throughput(Throughput::Bytes((24 * len) as u64));
            group.bench_function(
                BenchmarkId::new(format!("triad/t{threads}"), 24 * len / 1_000_000),
                |bch| {
                    let (a, b, c) = arrays.get_or_insert_with(init);
                    pool.install(|| bch.iter(|| stream_triad(a, black_box(b), black_box(c), 0.5)))
                },
            );
        }
        black_box(&arrays);
    }
    group.finish();
}

struct SampsonData {
    f: Mat3,
    /// One copy of `f` per row, for the per-row-F (training) layout.
    f_rows: Vec<[f64; 9]>,
    corrs: Vec<AcRow>,
    points: Vec<PointRow>,
}

/// Plane-induced ACs of a random two-camera scene with ~1 px / 1 % noise, and its F.
fn sampson_data(n: usize) -> SampsonData {
    let mut r = rng();
    let scene = PlaneScene::random(&mut r);
    let f = scene.fundamental();
    let corrs: Vec<AcRow> = scene
        .sample(&mut r, n)
        .iter()
        .map(|ac| {
            let mut row = ac.to_row();
            row[..4]
                .iter_mut()
                .for_each(|v| *v += r.random_range(-1.0..1.0));
            row[4..]
                .iter_mut()
                .for_each(|v| *v *= 1.0 + r.random_range(-0.01..0.01));
            row
        })
        .collect();
    let f_row = [
        f[(0, 0)],
        f[(0, 1)],
        f[(0, 2)],
        f[(1, 0)],
        f[(1, 1)],
        f[(1, 2)],
        f[(2, 0)],
        f[(2, 1)],
        f[(2, 2)],
    ];
    SampsonData {
        f,
        f_rows: vec![f_row; n],
        points: corrs.iter().map(|c| [c[0], c[1], c[2], c[3]]).collect(),
        corrs,
    }
}

fn sampson_kernels<M: Clock>(c: &mut Criterion<M>) {
    bench_kernel(
        c,
        "sampson_point",
        |n| (sampson_data(n), vec![0.0; n]),
        |(d, out): &mut (SampsonData, Vec<f64>)| {
            sampson::sampson_point_batch(&d.f, black_box(&d.points), out).unwrap();
            black_box(out);
        },
    );
    bench_kernel(
        c,
        "sampson_affine",
        |n| (sampson_data(n), vec![[0.0; 2]; n]),
        |(d, out): &mut (SampsonData, Vec<[f64; 2]>)| {
            sampson::sampson_affine_batch(&d.f, black_box(&d.corrs), out).unwrap();
            black_box(out);
        },
    );
    bench_kernel(
        c,
        "sampson_affine_per_row_f",
        |n| (sampson_data(n), vec![[0.0; 2]; n]),
        |(d, out): &mut (SampsonData, Vec<[f64; 2]>)| {
            sampson::sampson_affine_batch(&d.f_rows, black_box(&d.corrs), out).unwrap();
            black_box(out);
        },
    );
    bench_kernel(
        c,
        "sampson_point_grad",
        |n| (sampson_data(n), vec![PointSampsonGrad::default(); n]),
        |(d, out): &mut (SampsonData, Vec<PointSampsonGrad>)| {
            sampson::sampson_point_grad_batch(&d.f, black_box(&d.points), out).unwrap();
            black_box(out);
        },
    );
    bench_kernel(
        c,
        "sampson_affine_grad",
        |n| (sampson_data(n), vec![[AffineSampsonGrad::default(); 2]; n]),
        |(d, out): &mut (SampsonData, Vec<[AffineSampsonGrad; 2]>)| {
            sampson::sampson_affine_grad_batch(&d.f, black_box(&d.corrs), out).unwrap();
            black_box(out);
        },
    );
    // The struct-of-arrays gradient layout of the Python bindings (value, d_corrs, d_F).
    type PointCols = (Vec<f64>, Vec<[f64; 4]>, Vec<[f64; 9]>);
    bench_kernel(
        c,
        "sampson_point_grad_columns",
        |n| {
            (
                sampson_data(n),
                (vec![0.0; n], vec![[0.0; 4]; n], vec![[0.0; 9]; n]),
            )
        },
        |(d, (v, dc, df)): &mut (SampsonData, PointCols)| {
            sampson::sampson_point_grad_columns(&d.f, black_box(&d.points), v, dc, df).unwrap();
            black_box((v, dc, df));
        },
    );
    type AffineCols = (Vec<[f64; 2]>, Vec<[[f64; 8]; 2]>, Vec<[[f64; 9]; 2]>);
    bench_kernel(
        c,
        "sampson_affine_grad_columns",
        |n| {
            let cols = (
                vec![[0.0; 2]; n],
                vec![[[0.0; 8]; 2]; n],
                vec![[[0.0; 9]; 2]; n],
            );
            (sampson_data(n), cols)
        },
        |(d, (v, dc, df)): &mut (SampsonData, AffineCols)| {
            sampson::sampson_affine_grad_columns(&d.f, black_box(&d.corrs), v, dc, df).unwrap();
            black_box((v, dc, df));
        },
    );
}

fn run_all<M: Clock>(mut c: Criterion<M>) {
    memory_bandwidth(&mut c);
    geometry_kernels(&mut c);
    sampson_kernels(&mut c);
}

fn main() {
    run_all(Criterion::default().configure_from_args());
    Criterion::default().configure_from_args().final_summary();
}
