//! Scenes and error measures shared by the estimation tests. Each test binary uses a part of
//! them.
#![allow(dead_code)]

use affcorr_geom::synthetic::{NoiseModel, PlaneScene, noisy_correspondences};
use affcorr_geom::{Mat3, Vec3};
use affcorr_ransac::Correspondences;
use rand_pcg::Pcg64;

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

/// Correspondences and which of them are inliers.
pub struct Noisy {
    pub data: Correspondences,
    pub is_inlier: Vec<bool>,
}

/// ACs from `planes` planes of `scene`'s cameras, with noise and outliers.
pub fn make_data(
    rng: &mut Pcg64,
    scene: &PlaneScene,
    planes: usize,
    n: usize,
    outlier_ratio: f64,
    pixel_noise: f64,
    affine_noise: f64,
) -> Noisy {
    let noise = NoiseModel {
        planes,
        outlier_ratio,
        pixel_noise,
        affine_noise,
    };
    let (acs, is_inlier) = noisy_correspondences(rng, scene, n, &noise);
    Noisy {
        data: Correspondences::from_acs(&acs).unwrap(),
        is_inlier,
    }
}
