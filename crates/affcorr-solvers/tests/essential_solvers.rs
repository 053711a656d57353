//! The essential solvers on exact synthetic data with K1 ≠ K2 and fx ≠ fy (normalised), on
//! noisy data, and on degenerate samples.

mod common;
use affcorr_geom::camera::normalize_ac;
use affcorr_geom::epipolar::Pose;
use affcorr_geom::synthetic::{PlaneScene, general_points, random_pose, random_unit};
use affcorr_geom::{AffineCorrespondence, Mat2, Mat3, Vec2, Vec3};
use affcorr_solvers::essential::*;
use affcorr_solvers::relpose::*;
use common::best_error;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

const TRIALS: usize = 1000;

/// `n` exact normalised ACs of a random plane scene.
fn plane_acs(rng: &mut Pcg64, n: usize) -> (PlaneScene, Vec<AffineCorrespondence>) {
    let scene = PlaneScene::random(rng);
    let acs = scene
        .sample(rng, n)
        .iter()
        .map(|ac| normalize_ac(ac, &scene.k1, &scene.k2))
        .collect();
    (scene, acs)
}

/// Asserts that at least 99% of the errors are below 1e-8 and reports the rate.
fn assert_rate(name: &str, errors: &[f64]) {
    assert_rate_at_least(name, errors, 0.99);
}

/// Asserts that at least `min_rate` of the errors are below 1e-8 and reports the rate.
fn assert_rate_at_least(name: &str, errors: &[f64], min_rate: f64) {
    let ok = errors.iter().filter(|&&e| e < 1e-8).count();
    let rate = ok as f64 / errors.len() as f64;
    let mut sorted = errors.to_vec();
    sorted.sort_by(f64::total_cmp);
    eprintln!(
        "{name}: {ok}/{} below 1e-8 ({:.1}%), median {:.1e}",
        errors.len(),
        100.0 * rate,
        sorted[sorted.len() / 2]
    );
    assert!(rate >= min_rate, "{name}: success rate {rate}");
}

#[test]
fn five_point_recovers_e_on_one_plane() {
    let mut rng = Pcg64::seed_from_u64(10);
    let mut out = [Mat3::zeros(); ESSENTIAL_5PT_MAX_SOLUTIONS];
    let errors: Vec<f64> = (0..TRIALS)
        .map(|_| {
            let (scene, acs) = plane_acs(&mut rng, 5);
            let x1: Vec<Vec2> = acs.iter().map(|a| a.x1).collect();
            let x2: Vec<Vec2> = acs.iter().map(|a| a.x2).collect();
            let n = essential_5pt(&x1, &x2, &mut out);
            assert!(n <= ESSENTIAL_5PT_MAX_SOLUTIONS);
            best_error(&out[..n], &scene.essential())
        })
        .collect();
    assert_rate("5pt plane", &errors);
}

#[test]
fn five_point_recovers_e_on_general_points() {
    let mut rng = Pcg64::seed_from_u64(11);
    let mut out = [Mat3::zeros(); ESSENTIAL_5PT_MAX_SOLUTIONS];
    let errors: Vec<f64> = (0..TRIALS)
        .map(|_| {
            let pose = random_pose(&mut rng);
            let (x1, x2) = general_points(&mut rng, &pose, 5);
            let n = essential_5pt(&x1, &x2, &mut out);
            // Every returned model satisfies the five epipolar constraints.
            for e in &out[..n] {
                for (p, q) in x1.iter().zip(&x2) {
                    let r = Vec3::new(q.x, q.y, 1.0).dot(&(e * Vec3::new(p.x, p.y, 1.0)));
                    assert!(r.abs() < 1e-6, "{r}");
                }
            }
            best_error(&out[..n], &pose.essential())
        })
        .collect();
    assert_rate("5pt general", &errors);
}

#[test]
fn two_ac_recovers_e_on_one_plane() {
    let mut rng = Pcg64::seed_from_u64(12);
    let mut out = [Mat3::zeros(); ESSENTIAL_2AC_MAX_SOLUTIONS];
    let mut counts = [0usize; ESSENTIAL_2AC_MAX_SOLUTIONS + 1];
    let errors: Vec<f64> = (0..TRIALS)
        .map(|_| {
            let (scene, acs) = plane_acs(&mut rng, 2);
            let n = essential_2ac(&acs, &mut out);
            counts[n] += 1;
            best_error(&out[..n], &scene.essential())
        })
        .collect();
    eprintln!("2ac plane: models per call histogram {counts:?}");
    // Two ACs of one plane are the ambiguous case (up to 10 consistent solutions, B(z) often
    // nearly rank 1): measured 99.0% at seed 12; the bound leaves room for other seeds.
    assert_rate_at_least("2ac plane", &errors, 0.985);
}

#[test]
fn two_ac_recovers_e_from_two_planes() {
    let mut rng = Pcg64::seed_from_u64(13);
    let mut out = [Mat3::zeros(); ESSENTIAL_2AC_MAX_SOLUTIONS];
    let mut first = 0;
    let errors: Vec<f64> = (0..TRIALS)
        .map(|_| {
            let a = PlaneScene::random(&mut rng);
            // A second plane seen by the same cameras.
            let tilt = affcorr_geom::synthetic::rotation_about(
                &random_unit(&mut rng),
                rng.random_range(-0.7..0.7),
            );
            let b = PlaneScene {
                normal: tilt * Vec3::z(),
                distance: rng.random_range(3.0..6.0),
                ..a
            };
            let acs = [
                normalize_ac(&a.sample(&mut rng, 1)[0], &a.k1, &a.k2),
                normalize_ac(&b.sample(&mut rng, 1)[0], &b.k1, &b.k2),
            ];
            let n = essential_2ac(&acs, &mut out);
            if n > 0 && best_error(&out[..1], &a.essential()) < 1e-8 {
                first += 1;
            }
            best_error(&out[..n], &a.essential())
        })
        .collect();
    eprintln!("2ac two planes: best-first candidate correct in {first}/{TRIALS}");
    assert_rate("2ac two planes", &errors);
}

#[test]
fn one_ac_and_two_points_recover_e_on_one_plane() {
    let mut rng = Pcg64::seed_from_u64(41);
    let mut out = [Mat3::zeros(); ESSENTIAL_1AC2PT_MAX_SOLUTIONS];
    let errors: Vec<f64> = (0..TRIALS)
        .map(|_| {
            let (scene, acs) = plane_acs(&mut rng, 3);
            let (x1, x2) = ([acs[1].x1, acs[2].x1], [acs[1].x2, acs[2].x2]);
            let n = essential_1ac2pt(&acs[0], &x1, &x2, &mut out);
            best_error(&out[..n], &scene.essential())
        })
        .collect();
    assert_rate("1ac2pt plane", &errors);
}

/// The AC on the plane, the two points anywhere in the scene: every returned E satisfies the
/// five linear rows (the AC's three and the points'), and the truth is among them.
#[test]
fn one_ac_and_two_points_recover_e_on_general_points() {
    let mut rng = Pcg64::seed_from_u64(42);
    let mut out = [Mat3::zeros(); ESSENTIAL_1AC2PT_MAX_SOLUTIONS];
    let errors: Vec<f64> = (0..TRIALS)
        .map(|_| {
            let (scene, acs) = plane_acs(&mut rng, 1);
            let (x1, x2) = general_points(&mut rng, &scene.pose, 2);
            let n = essential_1ac2pt(&acs[0], &x1, &x2, &mut out);
            for e in &out[..n] {
                let ac = &acs[0];
                let (p1, p2) = (ac.x1.push(1.0), ac.x2.push(1.0));
                let (ep1, etp2) = (e * p1, e.transpose() * p2);
                for k in 0..2 {
                    let affine = ac.a[(0, k)] * ep1.x + ac.a[(1, k)] * ep1.y + etp2[k];
                    assert!(affine.abs() < 1e-6, "{affine}");
                }
                for (p, q) in x1.iter().chain([&ac.x1]).zip(x2.iter().chain([&ac.x2])) {
                    let r = q.push(1.0).dot(&(e * p.push(1.0)));
                    assert!(r.abs() < 1e-6, "{r}");
                }
            }
            best_error(&out[..n], &scene.essential())
        })
        .collect();
    assert_rate("1ac2pt general", &errors);
}

#[test]
fn eight_point_recovers_e_on_general_points() {
    let mut rng = Pcg64::seed_from_u64(14);
    let mut out = [Mat3::zeros(); 1];
    let errors: Vec<f64> = (0..TRIALS)
        .map(|_| {
            let pose = random_pose(&mut rng);
            let n_pts = rng.random_range(8..40);
            let (x1, x2) = general_points(&mut rng, &pose, n_pts);
            let n = essential_8pt(&x1, &x2, &mut out);
            best_error(&out[..n], &pose.essential())
        })
        .collect();
    assert_rate("8pt general", &errors);
}

#[test]
fn least_squares_with_acs_from_several_planes() {
    let mut rng = Pcg64::seed_from_u64(15);
    let mut out = [Mat3::zeros(); 1];
    let errors: Vec<f64> = (0..TRIALS)
        .map(|_| {
            let a = PlaneScene::random(&mut rng);
            let mut acs = Vec::new();
            for _ in 0..3 {
                let tilt = affcorr_geom::synthetic::rotation_about(
                    &random_unit(&mut rng),
                    rng.random_range(-0.7..0.7),
                );
                let s = PlaneScene {
                    normal: tilt * Vec3::z(),
                    distance: rng.random_range(3.0..6.0),
                    ..a
                };
                for ac in s.sample(&mut rng, 1) {
                    acs.push(normalize_ac(&ac, &s.k1, &s.k2));
                }
            }
            // Three ACs (9 rows) and no points, then two more points from the first plane.
            let n = essential_lsq(&[], &[], &acs, &mut out);
            let mut err = best_error(&out[..n], &a.essential());
            let extra: Vec<AffineCorrespondence> = a
                .sample(&mut rng, 2)
                .iter()
                .map(|ac| normalize_ac(ac, &a.k1, &a.k2))
                .collect();
            let x1: Vec<Vec2> = extra.iter().map(|ac| ac.x1).collect();
            let x2: Vec<Vec2> = extra.iter().map(|ac| ac.x2).collect();
            let n = essential_lsq(&x1, &x2, &acs, &mut out);
            err = err.max(best_error(&out[..n], &a.essential()));
            err
        })
        .collect();
    assert_rate("lsq ACs", &errors);
}

#[test]
fn eight_point_with_noise_stays_close_and_is_essential() {
    let mut rng = Pcg64::seed_from_u64(16);
    let mut out = [Mat3::zeros(); 1];
    let mut errors = Vec::new();
    for _ in 0..200 {
        let pose = random_pose(&mut rng);
        let (mut x1, mut x2) = general_points(&mut rng, &pose, 100);
        // ~0.5 px at f ≈ 800.
        for p in x1.iter_mut().chain(x2.iter_mut()) {
            *p += Vec2::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)) * 6e-4;
        }
        assert_eq!(essential_8pt(&x1, &x2, &mut out), 1);
        let e = out[0];
        let s = e.svd(false, false).singular_values;
        let mut s: Vec<f64> = s.iter().copied().collect();
        s.sort_by(f64::total_cmp);
        assert!(s[0] < 1e-12 && (s[1] - s[2]).abs() < 1e-12 && (e.norm() - 1.0).abs() < 1e-12);
        errors.push(best_error(&out[..1], &pose.essential()));
    }
    errors.sort_by(f64::total_cmp);
    let median = errors[errors.len() / 2];
    eprintln!("8pt noisy: median E error {median:.2e}");
    assert!(median < 0.02, "median {median}");
}

#[test]
fn two_ac_with_noise_stays_close() {
    let mut rng = Pcg64::seed_from_u64(17);
    let mut out = [Mat3::zeros(); ESSENTIAL_2AC_MAX_SOLUTIONS];
    let mut errors = Vec::new();
    for _ in 0..300 {
        let (scene, mut acs) = plane_acs(&mut rng, 2);
        for ac in acs.iter_mut() {
            ac.x1 += Vec2::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)) * 3e-4;
            ac.x2 += Vec2::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)) * 3e-4;
            ac.a += Mat2::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            ) * 1e-3;
        }
        let n = essential_2ac(&acs, &mut out);
        errors.push(best_error(&out[..n], &scene.essential()));
    }
    errors.sort_by(f64::total_cmp);
    let median = errors[errors.len() / 2];
    eprintln!("2ac noisy: median E error {median:.2e}");
    assert!(median < 0.05, "median {median}");
}

#[test]
fn relative_poses_recover_r_and_t() {
    let mut rng = Pcg64::seed_from_u64(18);
    let blank = Pose {
        r: Mat3::identity(),
        t: Vec3::zeros(),
    };
    let pose_error = |poses: &[Pose], truth: &Pose| {
        let t = truth.t.normalize();
        poses
            .iter()
            .map(|p| (p.r - truth.r).norm().max((p.t - t).norm()))
            .fold(f64::INFINITY, f64::min)
    };
    let (mut e5, mut e2, mut e8) = (Vec::new(), Vec::new(), Vec::new());
    let mut e3 = Vec::new();
    for _ in 0..TRIALS {
        let (scene, acs) = plane_acs(&mut rng, 5);
        let x1: Vec<Vec2> = acs.iter().map(|a| a.x1).collect();
        let x2: Vec<Vec2> = acs.iter().map(|a| a.x2).collect();
        let mut out = [blank; RELPOSE_5PT_MAX_SOLUTIONS];
        let n = relative_pose_5pt(&x1, &x2, &mut out);
        e5.push(pose_error(&out[..n], &scene.pose));
        let n = relative_pose_2ac(&acs[..2], &mut out);
        e2.push(pose_error(&out[..n], &scene.pose));
        let n = relative_pose_1ac2pt(&acs[2], &x1[3..], &x2[3..], &mut out);
        e3.push(pose_error(&out[..n], &scene.pose));
        let pose = random_pose(&mut rng);
        let (x1, x2) = general_points(&mut rng, &pose, 12);
        let n = relative_pose_8pt(&x1, &x2, &mut out);
        assert!(n <= 1);
        e8.push(pose_error(&out[..n], &pose));
    }
    assert_rate("relpose 5pt", &e5);
    // One-plane 2AC pairs, as in two_ac_recovers_e_on_one_plane (measured 98.7%).
    assert_rate_at_least("relpose 2ac", &e2, 0.985);
    assert_rate("relpose 8pt", &e8);
    assert_rate("relpose 1ac2pt", &e3);
}

#[test]
fn degenerate_samples_give_no_model() {
    let mut rng = Pcg64::seed_from_u64(19);
    let (_, acs) = plane_acs(&mut rng, 5);
    let x1: Vec<Vec2> = acs.iter().map(|a| a.x1).collect();
    let x2: Vec<Vec2> = acs.iter().map(|a| a.x2).collect();
    let mut out = [Mat3::zeros(); ESSENTIAL_5PT_MAX_SOLUTIONS];

    // 5pt: wrong counts, short buffer, repeated point, NaN, infinity, all-equal points.
    assert_eq!(essential_5pt(&x1[..4], &x2[..4], &mut out), 0);
    assert_eq!(essential_5pt(&x1, &x2[..4], &mut out), 0);
    assert_eq!(essential_5pt(&x1, &x2, &mut out[..3]), 0);
    let (mut r1, mut r2) = (x1.clone(), x2.clone());
    r1[4] = r1[0];
    r2[4] = r2[0];
    assert_eq!(essential_5pt(&r1, &r2, &mut out), 0);
    let mut bad = x1.clone();
    bad[2].x = f64::NAN;
    assert_eq!(essential_5pt(&bad, &x2, &mut out), 0);
    bad[2].x = f64::INFINITY;
    assert_eq!(essential_5pt(&bad, &x2, &mut out), 0);
    assert_eq!(essential_5pt(&[x1[0]; 5], &[x2[0]; 5], &mut out), 0);

    // 2AC: det A ≤ 0, repeated AC, NaN, wrong count, short buffer.
    let mut two = [acs[0], acs[1]];
    assert!(essential_2ac(&two, &mut out) > 0);
    two[1].a = Mat2::new(1.0, 0.0, 0.0, -1.0);
    assert_eq!(essential_2ac(&two, &mut out), 0);
    two[1].a = Mat2::zeros();
    assert_eq!(essential_2ac(&two, &mut out), 0);
    assert_eq!(essential_2ac(&[acs[0], acs[0]], &mut out), 0);
    let mut nan = [acs[0], acs[1]];
    nan[0].x2.y = f64::NAN;
    assert_eq!(essential_2ac(&nan, &mut out), 0);
    nan[0].x2.y = 0.0;
    nan[1].a[(0, 1)] = f64::NAN;
    assert_eq!(essential_2ac(&nan, &mut out), 0);
    assert_eq!(essential_2ac(&acs[..1], &mut out), 0);

    // 1AC + 2 points: det A ≤ 0, a point repeating the AC's centre, NaN, wrong count, short
    // buffer.
    let (p1, p2) = (&x1[1..3], &x2[1..3]);
    assert!(essential_1ac2pt(&acs[0], p1, p2, &mut out) > 0);
    let mut flipped = acs[0];
    flipped.a = Mat2::new(1.0, 0.0, 0.0, -1.0);
    assert_eq!(essential_1ac2pt(&flipped, p1, p2, &mut out), 0);
    let (r1, r2) = ([x1[1], acs[0].x1], [x2[1], acs[0].x2]);
    assert_eq!(essential_1ac2pt(&acs[0], &r1, &r2, &mut out), 0);
    let mut nan = acs[0];
    nan.a[(1, 0)] = f64::NAN;
    assert_eq!(essential_1ac2pt(&nan, p1, p2, &mut out), 0);
    let mut nan_pts = [x1[1], x1[2]];
    nan_pts[1].y = f64::NAN;
    assert_eq!(essential_1ac2pt(&acs[0], &nan_pts, p2, &mut out), 0);
    assert_eq!(essential_1ac2pt(&acs[0], &x1[1..4], &x2[1..4], &mut out), 0);
    assert_eq!(essential_1ac2pt(&acs[0], p1, p2, &mut out[..9]), 0);
    assert_eq!(essential_2ac(&acs[..3], &mut out), 0);
    assert_eq!(essential_2ac(&acs[..2], &mut out[..1]), 0);

    // 8pt: too few, one plane (rank-deficient), repeated, NaN, mismatched.
    let (_, plane) = plane_acs(&mut rng, 20);
    let p1: Vec<Vec2> = plane.iter().map(|a| a.x1).collect();
    let p2: Vec<Vec2> = plane.iter().map(|a| a.x2).collect();
    assert_eq!(essential_8pt(&p1[..7], &p2[..7], &mut out), 0);
    assert_eq!(essential_8pt(&p1, &p2, &mut out), 0, "coplanar points");
    assert_eq!(essential_8pt(&[p1[0]; 10], &[p2[0]; 10], &mut out), 0);
    let pose = random_pose(&mut rng);
    let (mut g1, g2) = general_points(&mut rng, &pose, 10);
    assert_eq!(essential_8pt(&g1, &g2, &mut out), 1);
    assert_eq!(essential_8pt(&g1, &g2[..9], &mut out), 0);
    assert_eq!(essential_8pt(&g1, &g2, &mut out[..0]), 0);
    g1[3].y = f64::NAN;
    assert_eq!(essential_8pt(&g1, &g2, &mut out), 0);
    // Fewer than eight rows (two ACs + one point = 7 rows), and a flipped AC.
    assert_eq!(essential_lsq(&p1[..1], &p2[..1], &plane[..2], &mut out), 0);
    let mut flipped = plane[..3].to_vec();
    // A reflection: negate one column, det A < 0.
    flipped[0].a.column_mut(0).neg_mut();
    assert_eq!(essential_lsq(&g1[..0], &g2[..0], &flipped, &mut out), 0);

    // Pose wrappers inherit the degeneracies.
    let blank = Pose {
        r: Mat3::identity(),
        t: Vec3::zeros(),
    };
    let mut poses = [blank; RELPOSE_5PT_MAX_SOLUTIONS];
    assert_eq!(relative_pose_5pt(&r1, &r2, &mut poses), 0);
    assert_eq!(relative_pose_2ac(&[acs[0], acs[0]], &mut poses), 0);
    assert_eq!(relative_pose_8pt(&p1, &p2, &mut poses), 0);
}
