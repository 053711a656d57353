//! Exact plane-induced scenes: the ground truth the tests of every crate stand on.
//!
//! A plane nᵀX1 = d (n unit, d > 0, in camera-1 coordinates) seen by two cameras related by
//! X2 = R X1 + t induces X2 = (R + t nᵀ/d) X1, hence the homography
//! H = K2 (R + t nᵀ / d) K1⁻¹, and the fundamental matrix F = K2⁻ᵀ \[t\]× R K1⁻¹. Every point on
//! the plane has an exact AC from H ([`crate::homography::ac_from_homography`]), which satisfies
//! the affine epipolar constraint of F exactly.

use crate::camera::Intrinsics;
use crate::epipolar::{Pose, fundamental_from_essential};
use crate::error::Result;
use crate::homography::ac_from_homography;
use crate::types::{AffineCorrespondence, Mat3, Vec2, Vec3};
use rand::Rng;

/// Two cameras looking at a plane.
#[derive(Debug, Clone, Copy)]
pub struct PlaneScene {
    /// Camera 1 intrinsics.
    pub k1: Intrinsics,
    /// Camera 2 intrinsics.
    pub k2: Intrinsics,
    /// X2 = R X1 + t.
    pub pose: Pose,
    /// Unit normal of the plane in camera-1 coordinates.
    pub normal: Vec3,
    /// Distance of the plane from camera 1's centre (nᵀX1 = d).
    pub distance: f64,
}

impl PlaneScene {
    /// The homography in pixels, p2 ~ H p1.
    pub fn homography(&self) -> Mat3 {
        let euclidean = self.pose.r + self.pose.t * self.normal.transpose() / self.distance;
        self.k2.matrix() * euclidean * self.k1.inverse()
    }

    /// The homography in normalised coordinates, x̂2 ~ Ĥ x̂1.
    pub fn normalized_homography(&self) -> Mat3 {
        self.pose.r + self.pose.t * self.normal.transpose() / self.distance
    }

    /// The essential matrix E = \[t\]× R.
    pub fn essential(&self) -> Mat3 {
        self.pose.essential()
    }

    /// The fundamental matrix F = K2⁻ᵀ E K1⁻¹.
    pub fn fundamental(&self) -> Mat3 {
        fundamental_from_essential(&self.essential(), &self.k1, &self.k2)
    }

    /// The exact AC at pixel `x1` (in pixels).
    pub fn correspondence(&self, x1: &Vec2) -> Result<AffineCorrespondence> {
        ac_from_homography(&self.homography(), x1, 0)
    }

    /// Depth of the plane point seen at pixel `x1` in camera 1 (negative: behind the camera).
    pub fn depth1(&self, x1: &Vec2) -> f64 {
        let ray = self.k1.inverse() * Vec3::new(x1.x, x1.y, 1.0);
        self.distance / self.normal.dot(&ray)
    }

    /// A random scene whose plane faces both cameras: anisotropic K1 ≠ K2 (fx ≠ fy), rotation up to
    /// ~25°, baseline ~0.3–1 units, plane at distance 3–6 tilted up to ~40°, 640×480 images.
    pub fn random<R: Rng + ?Sized>(rng: &mut R) -> Self {
        let k = |rng: &mut R| {
            let f = rng.random_range(500.0..1000.0);
            Intrinsics::from_focal(
                f,
                f * rng.random_range(0.8..1.2),
                rng.random_range(300.0..340.0),
                rng.random_range(220.0..260.0),
            )
            .expect("positive focal lengths")
        };
        let (k1, k2) = (k(rng), k(rng));
        let r = rotation_about(&random_unit(rng), rng.random_range(-0.45..0.45));
        let t = random_unit(rng) * rng.random_range(0.3..1.0);
        let tilt = rotation_about(&random_unit(rng), rng.random_range(-0.7..0.7));
        let normal = tilt * Vec3::z();
        Self {
            k1,
            k2,
            pose: Pose { r, t },
            normal,
            distance: rng.random_range(3.0..6.0),
        }
    }

    /// `n` exact ACs at random pixels of a 640×480 image 1 whose plane point lies in front of
    /// both cameras.
    pub fn sample<R: Rng + ?Sized>(&self, rng: &mut R, n: usize) -> Vec<AffineCorrespondence> {
        let mut out = Vec::with_capacity(n);
        let h = self.homography();
        while out.len() < n {
            let x1 = Vec2::new(rng.random_range(0.0..640.0), rng.random_range(0.0..480.0));
            let d1 = self.depth1(&x1);
            if d1 <= 0.0 {
                continue;
            }
            let ray = self.k1.inverse() * Vec3::new(x1.x, x1.y, 1.0);
            let x_cam2 = self.pose.r * (ray * d1) + self.pose.t;
            if x_cam2.z <= 0.0 {
                continue;
            }
            if let Ok(ac) = ac_from_homography(&h, &x1, out.len()) {
                out.push(ac);
            }
        }
        out
    }
}

/// Settings of [`noisy_correspondences`].
#[derive(Debug, Clone, Copy)]
pub struct NoiseModel {
    /// Number of planes (the first is the scene's own; the others get random tilts up to ~57°
    /// and distances 2–10): 1 gives a homography scene, several a general one.
    pub planes: usize,
    /// Fraction of correspondences replaced by random ones (random x2 and a random similarity A).
    pub outlier_ratio: f64,
    /// Standard deviation of the Gaussian noise added to x2, pixels.
    pub pixel_noise: f64,
    /// Relative noise on A: A ← A (I + N) with N's entries Gaussian of this deviation.
    pub affine_noise: f64,
}

/// A standard normal sample (Box–Muller), so callers need no extra dependency.
pub fn gaussian<R: Rng + ?Sized>(rng: &mut R) -> f64 {
    let (u, v): (f64, f64) = (rng.random::<f64>().max(1e-300), rng.random());
    (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
}

/// `n` ACs of `scene`'s cameras looking at `noise.planes` planes, with noise and outliers, and
/// which of them are inliers. Rows are grouped by plane.
pub fn noisy_correspondences<R: Rng + ?Sized>(
    rng: &mut R,
    scene: &PlaneScene,
    n: usize,
    noise: &NoiseModel,
) -> (Vec<AffineCorrespondence>, Vec<bool>) {
    let mut acs = Vec::with_capacity(n);
    let per_plane = n.div_ceil(noise.planes.max(1));
    for p in 0..noise.planes.max(1) {
        let mut s = *scene;
        if p > 0 {
            s.normal = rotation_about(&random_unit(rng), rng.random_range(-1.0..1.0)) * Vec3::z();
            s.distance = rng.random_range(2.0..10.0);
        }
        let take = per_plane.min(n - acs.len());
        acs.extend(s.sample(rng, take));
    }
    let mut is_inlier = Vec::with_capacity(n);
    for ac in acs.iter_mut() {
        let outlier = rng.random::<f64>() < noise.outlier_ratio;
        if outlier {
            let t: f64 = rng.random_range(-3.0..3.0);
            ac.x2 = Vec2::new(rng.random_range(0.0..640.0), rng.random_range(0.0..480.0));
            ac.a = crate::affine::rotation(t) * rng.random_range(0.5..2.0);
        } else {
            ac.x2 += Vec2::new(gaussian(rng), gaussian(rng)) * noise.pixel_noise;
            let n = crate::Mat2::new(gaussian(rng), gaussian(rng), gaussian(rng), gaussian(rng));
            ac.a += ac.a * n * noise.affine_noise;
        }
        is_inlier.push(!outlier);
    }
    (acs, is_inlier)
}

/// A uniformly distributed unit vector.
pub fn random_unit<R: Rng + ?Sized>(rng: &mut R) -> Vec3 {
    loop {
        let v = Vec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        );
        let n = v.norm();
        if n > 1e-3 && n <= 1.0 {
            return v / n;
        }
    }
}

/// Rotation by `angle` radians about the unit `axis` (Rodrigues).
pub fn rotation_about(axis: &Vec3, angle: f64) -> Mat3 {
    let k = crate::epipolar::skew(axis);
    Mat3::identity() + k * angle.sin() + k * k * (1.0 - angle.cos())
}

/// A random rotation: uniform axis, angle uniform in [−π, π).
pub fn random_rotation<R: Rng + ?Sized>(rng: &mut R) -> Mat3 {
    rotation_about(
        &random_unit(rng),
        rng.random_range(-std::f64::consts::PI..std::f64::consts::PI),
    )
}

/// A random pose with a rotation of up to ~30° and a translation of norm 0.2–2.
pub fn random_pose<R: Rng + ?Sized>(rng: &mut R) -> Pose {
    Pose {
        r: rotation_about(&random_unit(rng), rng.random_range(-0.5..0.5)),
        t: random_unit(rng) * rng.random_range(0.2..2.0),
    }
}

/// `n` exact normalised point correspondences of random 3D points in general position under
/// `pose`: depth 2–8 in camera 1 within a ±0.6 × ±0.45 field of view, and in front of camera 2.
pub fn general_points<R: Rng + ?Sized>(
    rng: &mut R,
    pose: &Pose,
    n: usize,
) -> (Vec<Vec2>, Vec<Vec2>) {
    let (mut x1, mut x2) = (Vec::new(), Vec::new());
    while x1.len() < n {
        let z = rng.random_range(2.0..8.0);
        let p = Vec3::new(
            rng.random_range(-0.6..0.6) * z,
            rng.random_range(-0.45..0.45) * z,
            z,
        );
        let q = pose.r * p + pose.t;
        if q.z > 0.1 {
            x1.push(Vec2::new(p.x / p.z, p.y / p.z));
            x2.push(Vec2::new(q.x / q.z, q.y / q.z));
        }
    }
    (x1, x2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn plane_scene_satisfies_point_and_affine_epipolar_constraints() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
        for _ in 0..50 {
            let scene = PlaneScene::random(&mut rng);
            let f = scene.fundamental();
            let f = f / f.norm();
            for ac in scene.sample(&mut rng, 20) {
                let p1 = Vec3::new(ac.x1.x, ac.x1.y, 1.0);
                let p2 = Vec3::new(ac.x2.x, ac.x2.y, 1.0);
                let (l1, l2) = (f * p1, f.transpose() * p2);
                let scale = l1.norm() * p2.norm();
                assert!(p2.dot(&l1).abs() < 1e-12 * scale);
                // docs/design.md §2: Aᵀ (F p1)₁:₂ + (Fᵀ p2)₁:₂ = 0.
                let r = ac.a.transpose() * l1.xy() + l2.xy();
                assert!(r.norm() < 1e-11 * l1.xy().norm().max(l2.xy().norm()), "{r}");
            }
        }
    }

    #[test]
    fn rotations_are_proper() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(4);
        for _ in 0..100 {
            let r = random_rotation(&mut rng);
            assert!((r.transpose() * r - Mat3::identity()).norm() < 1e-14);
            assert!((r.determinant() - 1.0).abs() < 1e-14);
        }
    }
}
