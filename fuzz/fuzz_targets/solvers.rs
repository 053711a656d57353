//! The minimal and non-minimal solvers on arbitrary f64 input (NaN, infinities, huge, tiny,
//! duplicates, wrong lengths): no panic, no hang, at most the documented number of models,
//! and every model returned finite.
#![no_main]

use affcorr_fuzz::{Reader, assert_finite};
use affcorr_geom::epipolar::Pose;
use affcorr_geom::{Mat3, Vec3};
use affcorr_solvers::essential::{
    ESSENTIAL_2AC_MAX_SOLUTIONS, ESSENTIAL_5PT_MAX_SOLUTIONS, essential_2ac, essential_5pt,
    essential_lsq,
};
use affcorr_solvers::fundamental::{
    FUNDAMENTAL_3AC_MAX_SOLUTIONS, FUNDAMENTAL_7PT_MAX_SOLUTIONS, fundamental_3ac, fundamental_7pt,
    fundamental_8pt, fundamental_ac_lsq,
};
use affcorr_solvers::homography::{
    homography_1ac_given_f, homography_2ac, homography_4pt, homography_ac_lsq, homography_lsq,
};
use affcorr_solvers::poly::{MAX_DEGREE, real_roots};
use affcorr_solvers::relpose::{
    RELPOSE_2AC_MAX_SOLUTIONS, RELPOSE_5PT_MAX_SOLUTIONS, relative_pose_2ac, relative_pose_5pt,
    relative_pose_8pt,
};
use libfuzzer_sys::fuzz_target;

/// Room for every solver's models.
const OUT: usize = 16;

fn check_models(out: &[Mat3], n: usize, max: usize, what: &str) {
    assert!(
        n <= max,
        "{what} returned {n} models, at most {max} documented"
    );
    for m in &out[..n] {
        assert_finite(m, what);
    }
}

fn check_poses(out: &[Pose], n: usize, max: usize, what: &str) {
    assert!(
        n <= max,
        "{what} returned {n} poses, at most {max} documented"
    );
    for p in &out[..n] {
        assert_finite(&p.r, what);
        assert!(p.t.iter().all(|v| v.is_finite()), "{what}: t = {}", p.t);
    }
}

/// The sample size: mostly the solver's own, sometimes off (wrong lengths must give 0 models).
fn size(r: &mut Reader, minimal: usize) -> usize {
    match r.u8() {
        0..=223 => minimal,
        b => usize::from(b % 16),
    }
}

fuzz_target!(|data: &[u8]| {
    let mut r = Reader::new(data);
    let which = r.u8() % 15;
    let mut out = [Mat3::zeros(); OUT];
    let mut poses = [Pose {
        r: Mat3::identity(),
        t: Vec3::zeros(),
    }; OUT];
    match which {
        0 => {
            let n = size(&mut r, 4);
            let (x1, x2) = (r.points(n), r.points(n));
            let k = homography_4pt(&x1, &x2, &mut out);
            check_models(&out, k, 1, "homography_4pt");
        }
        1 => {
            let n = size(&mut r, 2);
            let acs = r.acs(n);
            let k = homography_2ac(&acs, &mut out);
            check_models(&out, k, 1, "homography_2ac");
        }
        2 => {
            let n = size(&mut r, 7);
            let (x1, x2) = (r.points(n), r.points(n));
            let k = fundamental_7pt(&x1, &x2, &mut out);
            check_models(&out, k, FUNDAMENTAL_7PT_MAX_SOLUTIONS, "fundamental_7pt");
        }
        3 => {
            let n = size(&mut r, 3);
            let acs = r.acs(n);
            let k = fundamental_3ac(&acs, &mut out);
            check_models(&out, k, FUNDAMENTAL_3AC_MAX_SOLUTIONS, "fundamental_3ac");
        }
        4 => {
            let n = size(&mut r, 5);
            let (x1, x2) = (r.points(n), r.points(n));
            let k = essential_5pt(&x1, &x2, &mut out);
            check_models(&out, k, ESSENTIAL_5PT_MAX_SOLUTIONS, "essential_5pt");
        }
        5 => {
            let n = size(&mut r, 2);
            let acs = r.acs(n);
            let k = essential_2ac(&acs, &mut out);
            check_models(&out, k, ESSENTIAL_2AC_MAX_SOLUTIONS, "essential_2ac");
        }
        6 => {
            let n = size(&mut r, 5);
            let (x1, x2) = (r.points(n), r.points(n));
            let k = relative_pose_5pt(&x1, &x2, &mut poses);
            check_poses(&poses, k, RELPOSE_5PT_MAX_SOLUTIONS, "relative_pose_5pt");
        }
        7 => {
            let n = size(&mut r, 2);
            let acs = r.acs(n);
            let k = relative_pose_2ac(&acs, &mut poses);
            check_poses(&poses, k, RELPOSE_2AC_MAX_SOLUTIONS, "relative_pose_2ac");
        }
        8 => {
            let n = size(&mut r, 8) + usize::from(r.u8() % 8);
            let (x1, x2) = (r.points(n), r.points(n));
            let k = relative_pose_8pt(&x1, &x2, &mut poses);
            check_poses(&poses, k, 1, "relative_pose_8pt");
        }
        9 => {
            let n = size(&mut r, 8) + usize::from(r.u8() % 8);
            let (x1, x2) = (r.points(n), r.points(n));
            let k = fundamental_8pt(&x1, &x2, &mut out);
            check_models(&out, k, 1, "fundamental_8pt");
        }
        10 => {
            let n = size(&mut r, 4) + usize::from(r.u8() % 8);
            let (x1, x2) = (r.points(n), r.points(n));
            let k = homography_lsq(&x1, &x2, &mut out);
            check_models(&out, k, 1, "homography_lsq");
        }
        11 => {
            let n = size(&mut r, 3) + usize::from(r.u8() % 8);
            let acs = r.acs(n);
            let k = if r.bool() {
                homography_ac_lsq(&acs, &mut out)
            } else {
                fundamental_ac_lsq(&acs, &mut out)
            };
            check_models(&out, k, 1, "homography_ac_lsq / fundamental_ac_lsq");
        }
        12 => {
            let n = size(&mut r, 1);
            let acs = r.acs(n);
            let f = r.mat3();
            let k = homography_1ac_given_f(&acs, &f, &mut out);
            check_models(&out, k, 1, "homography_1ac_given_f");
        }
        13 => {
            let n = usize::from(r.u8() % 10);
            let (x1, x2) = (r.points(n), r.points(n));
            let m = usize::from(r.u8() % 4);
            let acs = r.acs(m);
            let k = essential_lsq(&x1, &x2, &acs, &mut out);
            check_models(&out, k, 1, "essential_lsq");
        }
        _ => {
            let len = usize::from(r.u8()) % (MAX_DEGREE + 2);
            let c: Vec<f64> = (0..len).map(|_| r.f64()).collect();
            let mut roots = [0.0; MAX_DEGREE + 1];
            let k = real_roots(&c, &mut roots);
            assert!(
                k <= len.saturating_sub(1),
                "{k} roots of a degree-{len} polynomial"
            );
            let found = &roots[..k];
            assert!(found.iter().all(|v| v.is_finite()), "roots {found:?}");
            assert!(
                found.windows(2).all(|w| w[0] < w[1]),
                "not ascending: {found:?}"
            );
        }
    }
});
