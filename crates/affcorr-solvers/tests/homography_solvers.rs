//! Homography solvers on exact plane-induced data (K1 ≠ K2, fx ≠ fy), with noise, and on
//! degenerate samples (which must give no model, not a wrong one).

mod common;
use affcorr_geom::synthetic::PlaneScene;
use affcorr_geom::{AffineCorrespondence, Mat2, Mat3, Vec2, Vec3};
use affcorr_solvers::homography::*;
use common::{best_error, perturb, points};
use rand::SeedableRng;
use rand_pcg::Pcg64;

const TRIALS: usize = 1000;
const TOL: f64 = 1e-8;

/// Runs `solve` on `TRIALS` random scenes with samples of `n` ACs; asserts a success rate
/// ≥ 99 % and returns it.
fn success_rate(
    seed: u64,
    n: usize,
    solve: impl Fn(&PlaneScene, &[AffineCorrespondence], &mut [Mat3]) -> usize,
) -> f64 {
    let mut rng = Pcg64::seed_from_u64(seed);
    let mut ok = 0;
    let mut out = [Mat3::zeros(); 4];
    for _ in 0..TRIALS {
        let scene = PlaneScene::random(&mut rng);
        let acs = scene.sample(&mut rng, n);
        let k = solve(&scene, &acs, &mut out);
        if k > 0 && best_error(&out[..k], &scene.homography()) < TOL {
            ok += 1;
        }
    }
    let rate = ok as f64 / TRIALS as f64;
    assert!(rate >= 0.99, "success rate {rate}");
    rate
}

#[test]
fn four_point_recovers_ground_truth() {
    let rate = success_rate(1, 4, |_, acs, out| {
        let (x1, x2) = points(acs);
        homography_4pt(&x1, &x2, out)
    });
    println!("homography_4pt: {rate}");
}

#[test]
fn two_ac_recovers_ground_truth() {
    let rate = success_rate(2, 2, |_, acs, out| homography_2ac(acs, out));
    println!("homography_2ac: {rate}");
}

#[test]
fn one_ac_and_two_points_recover_ground_truth() {
    let rate = success_rate(21, 3, |_, acs, out| {
        let (x1, x2) = points(&acs[1..]);
        homography_1ac2pt(&acs[0], &x1, &x2, out)
    });
    println!("homography_1ac2pt: {rate}");
}

/// The hybrid sample leans on one A instead of two: with the same relative noise on A and
/// exact points, its H moves the plane's points no more than the 2-AC sample's (measured
/// 18.2 against 20.1 px at seed 22: the least squares still leans on the one A).
#[test]
fn one_ac_and_two_points_lean_less_on_noisy_affine_maps() {
    let mut rng = Pcg64::seed_from_u64(22);
    let (mut hybrid, mut two_ac) = (Vec::new(), Vec::new());
    let mut out = [Mat3::zeros(); 1];
    for _ in 0..400 {
        let scene = PlaneScene::random(&mut rng);
        let exact = scene.sample(&mut rng, 40);
        let noisy = perturb(&mut rng, &exact[..2], 0.0, 0.05);
        let (x1, x2) = points(&exact[1..3]);
        if homography_1ac2pt(&noisy[0], &x1, &x2, &mut out) == 1 {
            hybrid.push(transfer_error(&out[0], &exact));
        }
        if homography_2ac(&noisy, &mut out) == 1 {
            two_ac.push(transfer_error(&out[0], &exact));
        }
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (h, t) = (median(&mut hybrid), median(&mut two_ac));
    println!("5% noise on A: median transfer error 1AC+2pt {h:.2} px, 2AC {t:.2} px");
    assert!(hybrid.len() > 390 && two_ac.len() > 390);
    assert!(h < t, "1AC+2pt {h} against 2AC {t}");
}

#[test]
fn one_ac_given_f_recovers_ground_truth() {
    let rate = success_rate(3, 1, |scene, acs, out| {
        homography_1ac_given_f(acs, &scene.fundamental(), out)
    });
    println!("homography_1ac_given_f: {rate}");
}

#[test]
fn one_ac_given_f_is_scale_invariant_in_f() {
    let mut rng = Pcg64::seed_from_u64(30);
    let scene = PlaneScene::random(&mut rng);
    let acs = scene.sample(&mut rng, 1);
    let mut out = [Mat3::zeros(); 1];
    for s in [1e-6, -1.0, 1e6] {
        assert_eq!(
            homography_1ac_given_f(&acs, &(scene.fundamental() * s), &mut out),
            1
        );
        assert!(best_error(&out[..1], &scene.homography()) < TOL);
    }
}

#[test]
fn least_squares_recovers_ground_truth_exactly() {
    let rate = success_rate(4, 30, |_, acs, out| {
        let (x1, x2) = points(acs);
        homography_lsq(&x1, &x2, out)
    });
    println!("homography_lsq (30 points): {rate}");
    let rate = success_rate(5, 10, |_, acs, out| homography_ac_lsq(acs, out));
    println!("homography_ac_lsq (10 ACs): {rate}");
    // The minimal sizes are accepted by the non-minimal solvers too.
    success_rate(6, 4, |_, acs, out| {
        let (x1, x2) = points(acs);
        homography_lsq(&x1, &x2, out)
    });
}

#[test]
fn normal_equation_least_squares_recovers_ground_truth_exactly() {
    let rate = success_rate(9, 30, |_, acs, out| {
        let (x1, x2) = points(acs);
        let idx: Vec<usize> = (0..x1.len()).collect();
        homography_lsq_normal_equations(&x1, &x2, &idx, None, out)
    });
    println!("homography_lsq_normal_equations (30 points): {rate}");
}

#[test]
fn normal_equation_least_squares_matches_the_qr_fit_and_honours_indices_and_weights() {
    let mut rng = Pcg64::seed_from_u64(10);
    let (mut qr, mut ne) = ([Mat3::zeros(); 1], [Mat3::zeros(); 1]);
    for _ in 0..50 {
        let scene = PlaneScene::random(&mut rng);
        let exact = scene.sample(&mut rng, 200);
        let noisy = perturb(&mut rng, &exact, 0.5, 0.02);
        let (x1, x2) = points(&noisy);
        // Every third point, given by index, against the QR fit on the same subset.
        let idx: Vec<usize> = (0..200).step_by(3).collect();
        let sub = |x: &[Vec2]| idx.iter().map(|&i| x[i]).collect::<Vec<_>>();
        assert_eq!(homography_lsq(&sub(&x1), &sub(&x2), &mut qr), 1);
        assert_eq!(
            homography_lsq_normal_equations(&x1, &x2, &idx, None, &mut ne),
            1
        );
        assert!(
            best_error(&ne, &qr[0]) < 1e-9,
            "{}",
            best_error(&ne, &qr[0])
        );
        // Integer weights equal repeated rows; zero weights drop a datum.
        let w: Vec<f64> = (0..idx.len()).map(|k| (k % 3) as f64).collect();
        let (mut x1r, mut x2r) = (Vec::new(), Vec::new());
        for (&i, &wi) in idx.iter().zip(&w) {
            for _ in 0..wi as usize {
                x1r.push(x1[i]);
                x2r.push(x2[i]);
            }
        }
        assert_eq!(homography_lsq(&x1r, &x2r, &mut qr), 1);
        assert_eq!(
            homography_lsq_normal_equations(&x1, &x2, &idx, Some(&w), &mut ne),
            1
        );
        // The normalisation differs (it uses the weighted-out data too), so the optima differ
        // slightly (DLT is not invariant to it); their errors agree.
        let (e, e_qr) = (
            transfer_error(&ne[0], &exact),
            transfer_error(&qr[0], &exact),
        );
        assert!(
            (e - e_qr).abs() < 0.05 * e_qr,
            "weighted: {e} px, repeated rows {e_qr} px"
        );
    }
}

#[test]
fn normal_equation_least_squares_rejects_bad_input() {
    let mut rng = Pcg64::seed_from_u64(11);
    let scene = PlaneScene::random(&mut rng);
    let (x1, x2) = points(&scene.sample(&mut rng, 10));
    let all: Vec<usize> = (0..10).collect();
    let mut out = [Mat3::zeros(); 1];
    let f = homography_lsq_normal_equations;
    assert_eq!(f(&x1, &x2, &all, None, &mut out), 1);
    assert_eq!(f(&x1, &x2, &all[..3], None, &mut out), 0, "fewer than 4");
    assert_eq!(f(&x1, &x2[..9], &all[..4], None, &mut out), 0, "lengths");
    assert_eq!(f(&x1, &x2, &[0, 1, 2, 10], None, &mut out), 0, "index");
    assert_eq!(
        f(&x1, &x2, &all, Some(&[1.0; 9]), &mut out),
        0,
        "weights' length"
    );
    let mut w = [1.0; 10];
    w[3] = -1.0;
    assert_eq!(f(&x1, &x2, &all, Some(&w), &mut out), 0, "negative weight");
    w[3] = f64::NAN;
    assert_eq!(f(&x1, &x2, &all, Some(&w), &mut out), 0, "NaN weight");
    let mut nan = x2.clone();
    nan[4].y = f64::NAN;
    assert_eq!(f(&x1, &nan, &all, None, &mut out), 0, "NaN point");
    // Collinear points: the null space is not one-dimensional.
    let line: Vec<Vec2> = (0..10)
        .map(|i| Vec2::new(i as f64, 2.0 * i as f64))
        .collect();
    let line2: Vec<Vec2> = line.iter().map(|p| p * 1.5).collect();
    assert_eq!(f(&line, &line2, &all, None, &mut out), 0, "collinear");
}

/// Mean one-sided transfer error (pixels) of `h` on the exact ACs.
fn transfer_error(h: &Mat3, acs: &[AffineCorrespondence]) -> f64 {
    acs.iter()
        .map(|ac| {
            let p = h * Vec3::new(ac.x1.x, ac.x1.y, 1.0);
            (p.xy() / p.z - ac.x2).norm()
        })
        .sum::<f64>()
        / acs.len() as f64
}

#[test]
fn least_squares_with_noise_is_close() {
    let mut rng = Pcg64::seed_from_u64(7);
    let mut out = [Mat3::zeros(); 1];
    for _ in 0..50 {
        let scene = PlaneScene::random(&mut rng);
        let exact = scene.sample(&mut rng, 200);
        let noisy = perturb(&mut rng, &exact, 0.5, 0.02);
        let (x1, x2) = points(&noisy);
        assert_eq!(homography_lsq(&x1, &x2, &mut out), 1);
        let e = transfer_error(&out[0], &exact);
        assert!(e < 0.5, "points: {e} px");
        assert_eq!(homography_ac_lsq(&noisy, &mut out), 1);
        let e = transfer_error(&out[0], &exact);
        assert!(e < 0.5, "ACs: {e} px");
    }
}

#[test]
fn degenerate_point_samples_give_no_model() {
    let mut out = [Mat3::zeros(); 1];
    let sq = [
        Vec2::new(10.0, 10.0),
        Vec2::new(200.0, 15.0),
        Vec2::new(210.0, 190.0),
        Vec2::new(5.0, 220.0),
    ];
    let h = Mat3::new(1.1, 0.1, 5.0, -0.05, 0.9, 3.0, 1e-4, 2e-4, 1.0);
    let map = |p: &Vec2| {
        let q = h * Vec3::new(p.x, p.y, 1.0);
        q.xy() / q.z
    };
    let image = sq.map(|p| map(&p));
    assert_eq!(homography_4pt(&sq, &image, &mut out), 1);
    // Three collinear points in image 1 (and hence in image 2).
    let mut col = sq;
    col[2] = (col[0] + col[1]) * 0.5;
    assert_eq!(homography_4pt(&col, &col.map(|p| map(&p)), &mut out), 0);
    // Collinear only in image 2.
    let mut col2 = image;
    col2[3] = col2[0] * 0.25 + col2[2] * 0.75;
    assert_eq!(homography_4pt(&sq, &col2, &mut out), 0);
    // A repeated point.
    let mut rep = sq;
    rep[3] = rep[1];
    assert_eq!(homography_4pt(&rep, &rep.map(|p| map(&p)), &mut out), 0);
    // All points equal.
    assert_eq!(homography_4pt(&[sq[0]; 4], &[image[0]; 4], &mut out), 0);
    // NaN and infinity.
    let mut bad = sq;
    bad[1].x = f64::NAN;
    assert_eq!(homography_4pt(&bad, &image, &mut out), 0);
    bad[1].x = f64::INFINITY;
    assert_eq!(homography_4pt(&image, &bad, &mut out), 0);
    // Wrong lengths.
    assert_eq!(homography_4pt(&sq[..3], &image[..3], &mut out), 0);
    assert_eq!(homography_4pt(&sq, &image[..3], &mut out), 0);
    assert_eq!(homography_lsq(&sq[..3], &image[..3], &mut out), 0);
    assert_eq!(homography_lsq(&sq, &image[..3], &mut out), 0);
    // All points on one line: the LSQ null space is not 1-dim.
    let line: Vec<Vec2> = (0..10)
        .map(|i| Vec2::new(i as f64, 2.0 * i as f64))
        .collect();
    let line2: Vec<Vec2> = line.iter().map(map).collect();
    assert_eq!(homography_lsq(&line, &line2, &mut out), 0);
    let mut nan = line2.clone();
    nan[4].y = f64::NAN;
    assert_eq!(homography_lsq(&sq, &image, &mut out), 1);
    assert_eq!(homography_lsq(&line, &nan, &mut out), 0);
}

#[test]
fn degenerate_ac_samples_give_no_model() {
    let mut rng = Pcg64::seed_from_u64(8);
    let scene = PlaneScene::random(&mut rng);
    let acs = scene.sample(&mut rng, 2);
    let f = scene.fundamental();
    let mut out = [Mat3::zeros(); 1];
    assert_eq!(homography_2ac(&acs, &mut out), 1);
    assert_eq!(homography_1ac_given_f(&acs[..1], &f, &mut out), 1);
    let more = scene.sample(&mut rng, 2);
    let (p1, p2) = points(&more);
    let hybrid = |ac: &AffineCorrespondence, x1: &[Vec2], x2: &[Vec2]| {
        homography_1ac2pt(ac, x1, x2, &mut [Mat3::zeros(); 1])
    };
    assert_eq!(hybrid(&acs[0], &p1, &p2), 1);
    // The same AC twice; a point at the AC's centre; a repeated point; wrong counts.
    assert_eq!(homography_2ac(&[acs[0], acs[0]], &mut out), 0);
    assert_eq!(hybrid(&acs[0], &[p1[0], acs[0].x1], &[p2[0], acs[0].x2]), 0);
    assert_eq!(hybrid(&acs[0], &[p1[0], p1[0]], &[p2[0], p2[0]]), 0);
    assert_eq!(hybrid(&acs[0], &p1[..1], &p2[..1]), 0);
    assert_eq!(
        hybrid(&acs[0], &[p1[0], p1[1], p1[0]], &[p2[0], p2[1], p2[0]]),
        0
    );
    assert_eq!(homography_ac_lsq(&[acs[0]; 5], &mut out), 0);
    // det A ≤ 0: a reflection, and a singular A.
    for a in [
        Mat2::new(
            -acs[0].a[(0, 0)],
            acs[0].a[(0, 1)],
            -acs[0].a[(1, 0)],
            acs[0].a[(1, 1)],
        ),
        Mat2::new(1.0, 2.0, 2.0, 4.0),
    ] {
        let mut bad = acs.clone();
        bad[0].a = a;
        assert_eq!(homography_2ac(&bad, &mut out), 0);
        assert_eq!(homography_ac_lsq(&bad, &mut out), 0);
        assert_eq!(homography_1ac_given_f(&bad[..1], &f, &mut out), 0);
        assert_eq!(hybrid(&bad[0], &p1, &p2), 0);
    }
    // NaN anywhere.
    for k in 0..8 {
        let mut row = acs[1].to_row();
        row[k] = f64::NAN;
        let bad = [acs[0], AffineCorrespondence::from_row(&row)];
        assert_eq!(homography_2ac(&bad, &mut out), 0);
        assert_eq!(homography_1ac_given_f(&bad[1..], &f, &mut out), 0);
        assert_eq!(hybrid(&bad[1], &p1, &p2), 0);
        if k < 4 {
            // The same NaN in a plain point.
            let (b1, b2) = ([p1[0], bad[1].x1], [p2[0], bad[1].x2]);
            assert_eq!(hybrid(&acs[0], &b1, &b2), 0);
        }
    }
    let mut nan_f = f;
    nan_f[(1, 2)] = f64::NAN;
    assert_eq!(homography_1ac_given_f(&acs[..1], &nan_f, &mut out), 0);
    // F of rank < 2, and the zero F.
    let rank1 = f.column(0) * f.row(0);
    assert_eq!(homography_1ac_given_f(&acs[..1], &rank1, &mut out), 0);
    assert_eq!(
        homography_1ac_given_f(&acs[..1], &Mat3::zeros(), &mut out),
        0
    );
    // Wrong lengths.
    assert_eq!(homography_2ac(&acs[..1], &mut out), 0);
    assert_eq!(homography_2ac(&[acs[0], acs[1], acs[0]], &mut out), 0);
    assert_eq!(homography_ac_lsq(&acs[..1], &mut out), 0);
    assert_eq!(homography_1ac_given_f(&acs, &f, &mut out), 0);
    assert_eq!(homography_1ac_given_f(&[], &f, &mut out), 0);
}

#[test]
#[should_panic(expected = "out too short")]
fn short_output_buffer_is_a_caller_bug() {
    let x = [Vec2::zeros(); 4];
    homography_4pt(&x, &x, &mut []);
}
