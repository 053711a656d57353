//! Fundamental-matrix solvers on exact plane-induced data (K1 ≠ K2, fx ≠ fy), with noise, and on
//! degenerate samples (which must give no model, not a wrong one).
//!
//! F cannot be recovered from a single plane (any F = [e₂]×H fits), so every correspondence here
//! is induced by its own random plane, seen by the same two cameras: each is an exact AC of that
//! plane, and all share the scene's F.

use affcorr_geom::sampson::sampson_point;
mod common;
use affcorr_geom::synthetic::{PlaneScene, random_unit, rotation_about};
use affcorr_geom::{AffineCorrespondence, Mat2, Mat3, Vec3};
use affcorr_solvers::fundamental::*;
use common::{best_error, perturb, points};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

const TRIALS: usize = 1000;
const TOL: f64 = 1e-8;

/// `n` exact ACs, each on its own random plane (facing camera 1, tilted up to ~40°, at
/// distance 3–6), all seen by the cameras of `scene`.
fn multi_plane_sample<R: Rng>(
    scene: &PlaneScene,
    rng: &mut R,
    n: usize,
) -> Vec<AffineCorrespondence> {
    (0..n)
        .map(|_| {
            let mut s = *scene;
            s.normal = rotation_about(&random_unit(rng), rng.random_range(-0.7..0.7)) * Vec3::z();
            s.distance = rng.random_range(3.0..6.0);
            s.sample(rng, 1)[0]
        })
        .collect()
}

/// Success rate (best candidate within `TOL`) over `TRIALS` scenes; asserts ≥ 99 %. Also
/// returns the mean number of models.
fn success_rate(
    seed: u64,
    n: usize,
    solve: impl Fn(&[AffineCorrespondence], &mut [Mat3]) -> usize,
) -> (f64, f64) {
    let mut rng = Pcg64::seed_from_u64(seed);
    let (mut ok, mut models) = (0, 0);
    let mut out = [Mat3::zeros(); 3];
    for _ in 0..TRIALS {
        let scene = PlaneScene::random(&mut rng);
        let acs = multi_plane_sample(&scene, &mut rng, n);
        let k = solve(&acs, &mut out);
        models += k;
        if k > 0 && best_error(&out[..k], &scene.fundamental()) < TOL {
            ok += 1;
        }
    }
    let rate = ok as f64 / TRIALS as f64;
    assert!(rate >= 0.99, "success rate {rate}");
    (rate, models as f64 / TRIALS as f64)
}

#[test]
fn seven_point_recovers_ground_truth() {
    let (rate, models) = success_rate(11, 7, |acs, out| {
        let (x1, x2) = points(acs);
        let n = fundamental_7pt(&x1, &x2, out);
        for f in &out[..n] {
            assert!(f.determinant().abs() < 1e-10, "rank 2");
        }
        n
    });
    println!("fundamental_7pt: {rate}, {models} models on average");
}

#[test]
fn one_ac_and_four_points_recover_ground_truth() {
    let (rate, models) = success_rate(31, 5, |acs, out| {
        let (x1, x2) = points(&acs[1..]);
        let n = fundamental_1ac4pt(&acs[0], &x1, &x2, out);
        for f in &out[..n] {
            assert!(f.determinant().abs() < 1e-10, "rank 2");
        }
        n
    });
    println!("fundamental_1ac4pt: {rate}, {models} models on average");
}

/// Unlike 3 ACs, the hybrid sample solves when the AC and the points share one plane with
/// any two of them: here the AC and two points lie on one plane, the other two points elsewhere.
#[test]
fn one_ac_and_four_points_with_three_on_one_plane_recover_ground_truth() {
    let mut rng = Pcg64::seed_from_u64(32);
    let mut out = [Mat3::zeros(); FUNDAMENTAL_1AC4PT_MAX_SOLUTIONS];
    let mut ok = 0;
    for _ in 0..TRIALS {
        let scene = PlaneScene::random(&mut rng);
        let on_plane = scene.sample(&mut rng, 3);
        let elsewhere = multi_plane_sample(&scene, &mut rng, 2);
        let pts: Vec<_> = on_plane[1..].iter().chain(&elsewhere).copied().collect();
        let (x1, x2) = points(&pts);
        let n = fundamental_1ac4pt(&on_plane[0], &x1, &x2, &mut out);
        if n > 0 && best_error(&out[..n], &scene.fundamental()) < TOL {
            ok += 1;
        }
    }
    assert!(ok as f64 >= 0.99 * TRIALS as f64, "{ok}/{TRIALS}");
}

#[test]
fn eight_point_recovers_ground_truth() {
    for (seed, n) in [(12, 8), (13, 50)] {
        let (rate, _) = success_rate(seed, n, |acs, out| {
            let (x1, x2) = points(acs);
            let k = fundamental_8pt(&x1, &x2, out);
            assert!(k == 0 || out[0].determinant().abs() < 1e-12, "rank 2");
            k
        });
        println!("fundamental_8pt ({n} points): {rate}");
    }
}

#[test]
fn normal_equation_eight_point_recovers_ground_truth() {
    for (seed, n) in [(22, 8), (23, 50)] {
        let (rate, _) = success_rate(seed, n, |acs, out| {
            let (x1, x2) = points(acs);
            let idx: Vec<usize> = (0..n).collect();
            let k = fundamental_8pt_normal_equations(&x1, &x2, &idx, None, out);
            assert!(k == 0 || out[0].determinant().abs() < 1e-12, "rank 2");
            k
        });
        println!("fundamental_8pt_normal_equations ({n} points): {rate}");
    }
}

#[test]
fn normal_equation_eight_point_matches_the_qr_fit_and_weights_remove_data() {
    let mut rng = Pcg64::seed_from_u64(24);
    let (mut qr, mut ne) = ([Mat3::zeros(); 1], [Mat3::zeros(); 1]);
    for _ in 0..50 {
        let scene = PlaneScene::random(&mut rng);
        let exact = multi_plane_sample(&scene, &mut rng, 200);
        let (x1, x2) = points(&perturb(&mut rng, &exact, 0.5, 0.02));
        let idx: Vec<usize> = (0..200).step_by(3).collect();
        let sub = |x: &[affcorr_geom::Vec2]| idx.iter().map(|&i| x[i]).collect::<Vec<_>>();
        assert_eq!(fundamental_8pt(&sub(&x1), &sub(&x2), &mut qr), 1);
        assert_eq!(
            fundamental_8pt_normal_equations(&x1, &x2, &idx, None, &mut ne),
            1
        );
        assert!(
            best_error(&ne, &qr[0]) < 1e-8,
            "{}",
            best_error(&ne, &qr[0])
        );
        // A constant weight changes nothing; zero weights remove gross outliers.
        assert_eq!(
            fundamental_8pt_normal_equations(&x1, &x2, &idx, Some(&vec![2.5; idx.len()]), &mut qr),
            1
        );
        assert!(best_error(&ne, &qr[0]) < 1e-8, "constant weight");
        let mut bad = x2.clone();
        let mut w = vec![1.0; idx.len()];
        for k in (0..idx.len()).step_by(4) {
            bad[idx[k]] =
                affcorr_geom::Vec2::new(rng.random_range(0.0..640.0), rng.random_range(0.0..480.0));
            w[k] = 0.0;
        }
        assert_eq!(
            fundamental_8pt_normal_equations(&x1, &bad, &idx, None, &mut qr),
            1
        );
        assert_eq!(
            fundamental_8pt_normal_equations(&x1, &bad, &idx, Some(&w), &mut ne),
            1
        );
        let (e, e_unweighted) = (sampson_rms(&ne[0], &exact), sampson_rms(&qr[0], &exact));
        assert!(
            e < 0.6 && e_unweighted > 2.0 * e,
            "{e} px vs {e_unweighted} px unweighted"
        );
    }
}

#[test]
fn normal_equation_eight_point_rejects_bad_input() {
    let mut rng = Pcg64::seed_from_u64(25);
    let scene = PlaneScene::random(&mut rng);
    let (x1, x2) = points(&multi_plane_sample(&scene, &mut rng, 12));
    let all: Vec<usize> = (0..12).collect();
    let mut out = [Mat3::zeros(); 1];
    let f = fundamental_8pt_normal_equations;
    assert_eq!(f(&x1, &x2, &all, None, &mut out), 1);
    assert_eq!(f(&x1, &x2, &all[..7], None, &mut out), 0, "fewer than 8");
    assert_eq!(f(&x1, &x2[..11], &all[..8], None, &mut out), 0, "lengths");
    assert_eq!(
        f(&x1, &x2, &[0, 1, 2, 3, 4, 5, 6, 12], None, &mut out),
        0,
        "index"
    );
    assert_eq!(
        f(&x1, &x2, &all, Some(&[1.0; 11]), &mut out),
        0,
        "weights' length"
    );
    let mut w = [1.0; 12];
    w[3] = -1.0;
    assert_eq!(f(&x1, &x2, &all, Some(&w), &mut out), 0, "negative weight");
    let mut nan = x2.clone();
    nan[4].y = f64::NAN;
    assert_eq!(f(&x1, &nan, &all, None, &mut out), 0, "NaN point");
    // One plane: any F = [e₂]×H fits, the null space is not one-dimensional.
    let (p1, p2) = points(&scene.sample(&mut rng, 12));
    assert_eq!(f(&p1, &p2, &all, None, &mut out), 0, "one plane");
}

#[test]
fn three_ac_recovers_ground_truth_with_one_model() {
    let (rate, models) = success_rate(14, 3, |acs, out| {
        let n = fundamental_3ac(acs, out);
        // Generically the null space is 1-dim: one model.
        assert!(n <= 1, "{n} models");
        n
    });
    println!("fundamental_3ac: {rate}, {models} models on average");
    let (rate, _) = success_rate(15, 12, fundamental_ac_lsq);
    println!("fundamental_ac_lsq (12 ACs): {rate}");
}

#[test]
fn three_ac_with_two_on_one_plane_recovers_ground_truth() {
    // Two ACs of one plane fix only [e₂]×H; the third, on another plane, fixes e₂.
    let mut rng = Pcg64::seed_from_u64(16);
    let mut out = [Mat3::zeros(); 3];
    let mut ok = 0;
    for _ in 0..TRIALS {
        let scene = PlaneScene::random(&mut rng);
        let mut acs = scene.sample(&mut rng, 2);
        acs.extend(multi_plane_sample(&scene, &mut rng, 1));
        let n = fundamental_3ac(&acs, &mut out);
        if n > 0 && best_error(&out[..n], &scene.fundamental()) < TOL {
            ok += 1;
        }
    }
    assert!(ok as f64 >= 0.99 * TRIALS as f64, "{ok}");
}

/// RMS point Sampson distance (pixels) of `f` on exact correspondences.
fn sampson_rms(f: &Mat3, acs: &[AffineCorrespondence]) -> f64 {
    let s: f64 = acs.iter().map(|ac| sampson_point(f, &ac.points())).sum();
    (s / acs.len() as f64).sqrt()
}

#[test]
fn non_minimal_with_noise_is_close() {
    let mut rng = Pcg64::seed_from_u64(17);
    let mut out = [Mat3::zeros(); 1];
    for _ in 0..50 {
        let scene = PlaneScene::random(&mut rng);
        let exact = multi_plane_sample(&scene, &mut rng, 200);
        let noisy = perturb(&mut rng, &exact, 0.5, 0.02);
        let (x1, x2) = points(&noisy);
        assert_eq!(fundamental_8pt(&x1, &x2, &mut out), 1);
        let e = sampson_rms(&out[0], &exact);
        assert!(e < 0.5, "points: {e} px");
        assert_eq!(fundamental_ac_lsq(&noisy, &mut out), 1);
        let e = sampson_rms(&out[0], &exact);
        assert!(e < 0.5, "ACs: {e} px");
    }
}

#[test]
fn single_plane_samples_give_no_model() {
    let mut rng = Pcg64::seed_from_u64(18);
    let mut out = [Mat3::zeros(); 3];
    for _ in 0..100 {
        let scene = PlaneScene::random(&mut rng);
        let acs = scene.sample(&mut rng, 8);
        let (x1, x2) = points(&acs);
        assert_eq!(fundamental_7pt(&x1[..7], &x2[..7], &mut out), 0);
        assert_eq!(fundamental_8pt(&x1, &x2, &mut out), 0);
        assert_eq!(fundamental_3ac(&acs[..3], &mut out), 0);
        assert_eq!(fundamental_ac_lsq(&acs, &mut out), 0);
    }
}

#[test]
fn degenerate_samples_give_no_model() {
    let mut rng = Pcg64::seed_from_u64(19);
    let scene = PlaneScene::random(&mut rng);
    let acs = multi_plane_sample(&scene, &mut rng, 8);
    let (x1, x2) = points(&acs);
    let mut out = [Mat3::zeros(); 3];
    assert!(fundamental_7pt(&x1[..7], &x2[..7], &mut out) > 0);
    assert_eq!(fundamental_8pt(&x1, &x2, &mut out), 1);
    assert_eq!(fundamental_3ac(&acs[..3], &mut out), 1);
    let hybrid = |ac: &AffineCorrespondence, pts: &[AffineCorrespondence], out: &mut [Mat3]| {
        let (p1, p2) = points(pts);
        fundamental_1ac4pt(ac, &p1, &p2, out)
    };
    assert!(hybrid(&acs[0], &acs[1..5], &mut out) > 0);
    // A point repeating the AC's centre: rank 6 < 7.
    assert_eq!(
        hybrid(&acs[0], &[acs[1], acs[2], acs[3], acs[0]], &mut out),
        0
    );
    // A repeated point: rank 6 < 7.
    let (mut r1, mut r2) = (x1.clone(), x2.clone());
    r1[6] = r1[0];
    r2[6] = r2[0];
    assert_eq!(fundamental_7pt(&r1[..7], &r2[..7], &mut out), 0);
    // A repeated AC: 6 equations only.
    assert_eq!(fundamental_3ac(&[acs[0], acs[1], acs[1]], &mut out), 0);
    assert_eq!(
        fundamental_ac_lsq(&[acs[0], acs[1], acs[0], acs[1]], &mut out),
        0
    );
    // det A ≤ 0.
    let mut bad = acs.clone();
    bad[1].a = Mat2::new(1.0, 0.0, 0.0, -1.0);
    assert_eq!(fundamental_3ac(&bad[..3], &mut out), 0);
    assert_eq!(fundamental_ac_lsq(&bad, &mut out), 0);
    assert_eq!(hybrid(&bad[1], &acs[2..6], &mut out), 0);
    bad[1].a = Mat2::zeros();
    assert_eq!(fundamental_3ac(&bad[..3], &mut out), 0);
    assert_eq!(hybrid(&bad[1], &acs[2..6], &mut out), 0);
    // NaN / infinity anywhere.
    for k in 0..8 {
        let mut row = acs[2].to_row();
        row[k] = if k % 2 == 0 { f64::NAN } else { f64::INFINITY };
        let mut bad = acs.clone();
        bad[2] = AffineCorrespondence::from_row(&row);
        assert_eq!(fundamental_3ac(&bad[..3], &mut out), 0);
        assert_eq!(fundamental_ac_lsq(&bad, &mut out), 0);
        assert_eq!(hybrid(&bad[2], &acs[3..7], &mut out), 0);
        if k < 4 {
            assert_eq!(hybrid(&acs[0], &bad[1..5], &mut out), 0);
        }
        let (b1, b2) = points(&bad);
        if k < 4 {
            assert_eq!(fundamental_7pt(&b1[..7], &b2[..7], &mut out), 0);
            assert_eq!(fundamental_8pt(&b1, &b2, &mut out), 0);
        }
    }
    // Wrong lengths.
    assert_eq!(fundamental_7pt(&x1[..6], &x2[..6], &mut out), 0);
    assert_eq!(fundamental_7pt(&x1[..7], &x2[..6], &mut out), 0);
    assert_eq!(fundamental_8pt(&x1[..7], &x2[..7], &mut out), 0);
    assert_eq!(fundamental_8pt(&x1, &x2[..7], &mut out), 0);
    assert_eq!(fundamental_3ac(&acs[..2], &mut out), 0);
    assert_eq!(fundamental_3ac(&acs[..4], &mut out), 0);
    assert_eq!(fundamental_ac_lsq(&acs[..2], &mut out), 0);
    assert_eq!(hybrid(&acs[0], &acs[1..4], &mut out), 0);
    assert_eq!(hybrid(&acs[0], &acs[1..6], &mut out), 0);
}

/// Found by fuzzing (fuzz/, target `solvers`): a degenerate sample (repeated points) whose cubic
/// has a negligible c₃ gave three roots and F₂ as well: 4 models, more than documented.
#[test]
fn seven_point_never_returns_more_than_its_maximum() {
    let v = affcorr_geom::Vec2::new;
    let x1 = [
        v(1.0, 1.0),
        v(1.0, -1.0),
        v(-1.0, -1.0),
        v(-1.0, -1.0),
        v(-1.0, 34.0),
        v(97.0, 3116.125),
        v(-0.0, 3116.125),
    ];
    let x2 = [
        v(3116.125, 3116.125),
        v(3116.125, 3116.125),
        v(3116.125, 3116.125),
        v(-0.125, -1.0),
        v(0.0, 0.0),
        v(0.0, 0.0),
        v(0.0, 0.0),
    ];
    let mut out = [Mat3::zeros(); 8];
    let n = fundamental_7pt(&x1, &x2, &mut out);
    assert!(n <= FUNDAMENTAL_7PT_MAX_SOLUTIONS, "{n} models");
    assert!(out[..n].iter().all(|f| f.iter().all(|x| x.is_finite())));
}
