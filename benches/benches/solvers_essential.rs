//! ns/call of the essential-matrix solvers and relative-pose wrappers on exact
//! samples.
//!
//! Each benchmark cycles through 64 precomputed exact samples of different random plane scenes
//! (anisotropic K1 ≠ K2, normalised): 5-point samples from one plane (as PoseLib's benchmark
//! and as inside RANSAC on a dominant plane), 2AC samples from one plane and from two planes,
//! and 8-point / LSQ samples from several planes. Ids: `<solver>` or `<solver>/<N>`. The table
//! with the command is in `benches/results/solvers_essential.md`.

use std::hint::black_box;
use std::time::Duration;

use affcorr::geom::camera::normalize_ac;
use affcorr::geom::epipolar::Pose;
use affcorr::geom::synthetic::{PlaneScene, random_unit, rotation_about};
use affcorr::geom::{AffineCorrespondence, Mat3, Vec2, Vec3};
use affcorr::solvers::essential as e;
use affcorr::solvers::relpose as rp;
use criterion::{BenchmarkGroup, Criterion, measurement::WallTime};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

const SAMPLES: usize = 64;

fn configure(group: &mut BenchmarkGroup<'_, WallTime>) {
    group.sample_size(30);
    group.warm_up_time(Duration::from_secs(1));
    group.measurement_time(Duration::from_secs(2));
}

/// Normalised ACs of `planes` random planes (same cameras), `per_plane` on each.
fn acs(rng: &mut Pcg64, planes: usize, per_plane: usize) -> Vec<AffineCorrespondence> {
    let base = PlaneScene::random(rng);
    let mut out = Vec::new();
    for p in 0..planes {
        let s = if p == 0 {
            base
        } else {
            PlaneScene {
                normal: rotation_about(&random_unit(rng), rng.random_range(-0.7..0.7)) * Vec3::z(),
                distance: rng.random_range(3.0..6.0),
                ..base
            }
        };
        for ac in s.sample(rng, per_plane) {
            out.push(normalize_ac(&ac, &s.k1, &s.k2));
        }
    }
    out
}

fn split(a: &[AffineCorrespondence]) -> (Vec<Vec2>, Vec<Vec2>) {
    (
        a.iter().map(|c| c.x1).collect(),
        a.iter().map(|c| c.x2).collect(),
    )
}

fn bench(c: &mut Criterion) {
    let mut rng = Pcg64::seed_from_u64(7);
    let five: Vec<_> = (0..SAMPLES).map(|_| split(&acs(&mut rng, 1, 5))).collect();
    let two_one: Vec<_> = (0..SAMPLES).map(|_| acs(&mut rng, 1, 2)).collect();
    let two_two: Vec<_> = (0..SAMPLES).map(|_| acs(&mut rng, 2, 1)).collect();
    let many: Vec<_> = (0..SAMPLES).map(|_| acs(&mut rng, 4, 25)).collect();
    let many_pts: Vec<_> = many.iter().map(|a| split(a)).collect();

    let mut g = c.benchmark_group("essential");
    configure(&mut g);
    let mut out = [Mat3::zeros(); 10];
    let blank = Pose {
        r: Mat3::identity(),
        t: Vec3::zeros(),
    };
    let mut poses = [blank; 10];
    let mut i = 0;
    g.bench_function("essential_5pt", |b| {
        b.iter(|| {
            i = (i + 1) % SAMPLES;
            let (x1, x2) = &five[i];
            black_box(e::essential_5pt(black_box(x1), black_box(x2), &mut out))
        })
    });
    g.bench_function("relative_pose_5pt", |b| {
        b.iter(|| {
            i = (i + 1) % SAMPLES;
            let (x1, x2) = &five[i];
            black_box(rp::relative_pose_5pt(
                black_box(x1),
                black_box(x2),
                &mut poses,
            ))
        })
    });
    g.bench_function("essential_2ac/one_plane", |b| {
        b.iter(|| {
            i = (i + 1) % SAMPLES;
            black_box(e::essential_2ac(black_box(&two_one[i]), &mut out))
        })
    });
    g.bench_function("essential_2ac/two_planes", |b| {
        b.iter(|| {
            i = (i + 1) % SAMPLES;
            black_box(e::essential_2ac(black_box(&two_two[i]), &mut out))
        })
    });
    g.bench_function("relative_pose_2ac/two_planes", |b| {
        b.iter(|| {
            i = (i + 1) % SAMPLES;
            black_box(rp::relative_pose_2ac(black_box(&two_two[i]), &mut poses))
        })
    });
    for n in [8usize, 100] {
        g.bench_function(format!("essential_8pt/{n}"), |b| {
            b.iter(|| {
                i = (i + 1) % SAMPLES;
                let (x1, x2) = &many_pts[i];
                black_box(e::essential_8pt(
                    black_box(&x1[..n]),
                    black_box(&x2[..n]),
                    &mut out,
                ))
            })
        });
    }
    g.bench_function("essential_lsq/100acs", |b| {
        b.iter(|| {
            i = (i + 1) % SAMPLES;
            black_box(e::essential_lsq(&[], &[], black_box(&many[i]), &mut out))
        })
    });
    g.finish();
}

fn main() {
    let mut c = Criterion::default().configure_from_args();
    bench(&mut c);
    c.final_summary();
}
