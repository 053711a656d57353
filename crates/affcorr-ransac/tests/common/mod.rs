//! Error measures shared by the estimation tests.

use affcorr_geom::{Mat3, Vec3};

/// Mean transfer error (px) of `h` against `truth` over a `step`-px grid of a 640×480 image 1.
pub fn transfer_error(h: &Mat3, truth: &Mat3, step: usize) -> f64 {
    let mut sum = 0.0;
    let mut n = 0;
    for x in (0..640).step_by(step) {
        for y in (0..480).step_by(step) {
            let p = Vec3::new(x as f64, y as f64, 1.0);
            let (a, b) = (h * p, truth * p);
            sum += (a.xy() / a.z - b.xy() / b.z).norm();
            n += 1;
        }
    }
    sum / n as f64
}

/// The rotation angle of `r` in degrees.
pub fn angle_deg(r: &Mat3) -> f64 {
    ((r.trace() - 1.0) / 2.0)
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees()
}
