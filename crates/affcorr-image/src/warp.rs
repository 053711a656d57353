//! Synthetic views: an image seen under an affine map (rotation, zoom, tilt), and the map of
//! ACs found between views back to the original images.
//!
//! A view of an image is I′(x′) = I(M⁻¹ (x′ − c)) for the affine map x′ = M x + c, sampled
//! bilinearly (0 outside the image's pixel squares). ASIFT's parametrisation (Morel & Yu 2009)
//! writes M = s · R(ψ) · T(t, φ) with the tilt T(t, φ) = R(φ)ᵀ · diag(1, 1/t) · R(φ): the
//! image is compressed by t along the direction φ, then rotated by ψ and zoomed by s. Where M
//! shrinks the image (a singular value σ < 1), the image is first blurred along that singular
//! direction with a Gaussian of σ_b = 0.8 √(1/σ² − 1) px, as ASIFT does before subsampling, so
//! the view does not alias. Only along it: a tilt compresses one direction, and an isotropic
//! blur of a t = 4 tilt (σ_b ≈ 3 px) would also wash out the direction the view keeps at full
//! resolution, where the matcher finds its keypoints.
//!
//! ACs (x1, x2, A) found between views x1′ = M_a x1 + c_a of image A and x2′ = M_b x2 + c_b of
//! image B map back by x1 = M_a⁻¹ (x1′ − c_a), x2 = M_b⁻¹ (x2′ − c_b) and, since
//! A′ = ∂x2′/∂x1′ = M_b A M_a⁻¹, A = M_b⁻¹ A′ M_a (A = ∂x2/∂x1, docs/design.md §2).

use rayon::prelude::*;

use crate::affine_refine::gaussian_blur;
use crate::error::{ImageError, Result};
use crate::gray::GrayImage;

/// An affine map of the plane, x′ = M x + c, with M row-major.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AffineWarp {
    /// The linear part, row-major `[m11, m12, m21, m22]`.
    pub m: [f64; 4],
    /// The translation.
    pub c: [f64; 2],
}

impl AffineWarp {
    /// The identity.
    pub const IDENTITY: Self = Self {
        m: [1.0, 0.0, 0.0, 1.0],
        c: [0.0, 0.0],
    };

    /// The linear part s · R(ψ) · R(φ)ᵀ · diag(1, 1/t) · R(φ) (angles in radians, `scale`
    /// > 0, `tilt` ≥ 1), with no translation.
    pub fn linear(rotation: f64, scale: f64, tilt: f64, tilt_angle: f64) -> Self {
        let rot = |a: f64| [a.cos(), -a.sin(), a.sin(), a.cos()];
        let t = mul(
            &mul(&transpose(&rot(tilt_angle)), &[1.0, 0.0, 0.0, 1.0 / tilt]),
            &rot(tilt_angle),
        );
        let m = mul(&rot(rotation), &t).map(|v| scale * v);
        Self { m, c: [0.0, 0.0] }
    }

    /// This map followed by the translation that puts the image `width` × `height` (its pixel
    /// centres' bounding box) at the origin, and the size of the view that holds it.
    pub fn fitted(self, width: usize, height: usize) -> (Self, usize, usize) {
        let (w, h) = ((width - 1) as f64, (height - 1) as f64);
        let corners = [[0.0, 0.0], [w, 0.0], [0.0, h], [w, h]].map(|p| self.linear_apply(p));
        let min = |k: usize| corners.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min);
        let max = |k: usize| {
            corners
                .iter()
                .map(|p| p[k])
                .fold(f64::NEG_INFINITY, f64::max)
        };
        let c = [-min(0), -min(1)];
        let size = |k: usize| ((max(k) - min(k)).round() as usize + 1).max(1);
        (Self { m: self.m, c }, size(0), size(1))
    }

    /// The crop `window` = `[x0, y0, x1, y1]` (fractions of the view's width and height) of
    /// the view `self` of `width` × `height` pixels: the same map shifted so that the
    /// window's corner is the origin, and the window's size. Matching a magnified window of an
    /// image spends the matcher's keypoint budget on that part only.
    pub fn windowed(self, width: usize, height: usize, window: [f64; 4]) -> (Self, usize, usize) {
        let [x0, y0, x1, y1] = window.map(|v| v.clamp(0.0, 1.0));
        let (w, h) = (width as f64, height as f64);
        let c = [self.c[0] - (x0 * w).floor(), self.c[1] - (y0 * h).floor()];
        let size = |lo: f64, hi: f64, n: f64| (((hi - lo) * n).round() as usize).max(1);
        (Self { m: self.m, c }, size(x0, x1, w), size(y0, y1, h))
    }

    fn linear_apply(&self, p: [f64; 2]) -> [f64; 2] {
        let m = &self.m;
        [m[0] * p[0] + m[1] * p[1], m[2] * p[0] + m[3] * p[1]]
    }

    /// x′ = M x + c.
    pub fn apply(&self, p: [f64; 2]) -> [f64; 2] {
        let q = self.linear_apply(p);
        [q[0] + self.c[0], q[1] + self.c[1]]
    }

    /// The inverse map, or `None` when M is singular.
    pub fn inverse(&self) -> Option<Self> {
        let m = &self.m;
        let det = m[0] * m[3] - m[1] * m[2];
        if !(det.abs() > 1e-300) || !det.is_finite() {
            return None;
        }
        let inv = [m[3] / det, -m[1] / det, -m[2] / det, m[0] / det];
        let c = [
            -(inv[0] * self.c[0] + inv[1] * self.c[1]),
            -(inv[2] * self.c[0] + inv[3] * self.c[1]),
        ];
        Some(Self { m: inv, c })
    }

    /// The smaller singular value of M.
    pub fn min_singular_value(&self) -> f64 {
        self.singular_directions().1
    }

    /// The singular values of M, larger first, and the unit vector (in the source's pixels)
    /// that M shrinks most: the right singular vector of the smaller one.
    pub fn singular_directions(&self) -> (f64, f64, [f64; 2]) {
        let [a, b, c, d] = self.m;
        // MᵀM = [[p, q], [q, r]].
        let (p, q, r) = (a * a + c * c, a * b + c * d, b * b + d * d);
        let (mean, half) = ((p + r) / 2.0, (((p - r) / 2.0).powi(2) + q * q).sqrt());
        let (hi, lo) = ((mean + half).max(0.0), (mean - half).max(0.0));
        // The eigenvector of lo: (q, lo − p) or (lo − r, q), whichever is better conditioned.
        let (u, w) = if (lo - p).abs() + q.abs() >= (lo - r).abs() + q.abs() {
            (q, lo - p)
        } else {
            (lo - r, q)
        };
        let n = u.hypot(w);
        let v = if n > 1e-300 {
            [u / n, w / n]
        } else {
            [1.0, 0.0]
        };
        (hi.sqrt(), lo.sqrt(), v)
    }
}

/// `src` (`w` × `h`) blurred along the unit vector `v` by a Gaussian of `sigma` px: taps one
/// pixel apart along v, sampled bilinearly (clamped at the edges).
fn directional_blur(src: &[f32], w: usize, h: usize, sigma: f64, v: [f64; 2]) -> Vec<f32> {
    let r = (3.0 * sigma).ceil() as i64;
    let taps: Vec<(f64, f64, f32)> = (-r..=r)
        .map(|k| {
            let k = k as f64;
            let weight = (-(k * k) / (2.0 * sigma * sigma)).exp() as f32;
            (k * v[0], k * v[1], weight)
        })
        .collect();
    let total: f32 = taps.iter().map(|t| t.2).sum();
    let (wf, hf) = ((w - 1) as f64, (h - 1) as f64);
    // Away from the edges no tap is clamped, and a tap's offset (dx, dy) from an integer pixel
    // has the same integer part and bilinear fractions at every pixel: computed once, the
    // inner loop is four loads and the fixed weights (the blur of every tilt view, which
    // dominated their warps). The margins keep x0 + 1 and y0 + 1 inside the image.
    let interior: Vec<(isize, f32, f32, f32)> = taps
        .iter()
        .map(|&(dx, dy, weight)| {
            let (ix, iy) = (dx.floor(), dy.floor());
            let offset = iy as isize * w as isize + ix as isize;
            (offset, (dx - ix) as f32, (dy - iy) as f32, weight)
        })
        .collect();
    let margin = |d: f64| d.ceil() as usize + 1;
    let (mx, my) = (
        margin((r as f64) * v[0].abs()),
        margin((r as f64) * v[1].abs()),
    );
    let mut out = vec![0f32; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let rows_inside = y >= my && y + my < h;
        for (x, o) in row.iter_mut().enumerate() {
            let mut acc = 0f32;
            if rows_inside && x >= mx && x + mx < w {
                let at = (y * w + x) as isize;
                for &(offset, fx, fy, weight) in &interior {
                    let i = (at + offset) as usize;
                    let top = src[i] * (1.0 - fx) + src[i + 1] * fx;
                    let bottom = src[i + w] * (1.0 - fx) + src[i + w + 1] * fx;
                    acc += weight * (top * (1.0 - fy) + bottom * fy);
                }
            } else {
                for &(dx, dy, weight) in &taps {
                    let (u, v) = (
                        (x as f64 + dx).clamp(0.0, wf),
                        (y as f64 + dy).clamp(0.0, hf),
                    );
                    acc += weight * bilinear(src, w, h, u, v);
                }
            }
            *o = acc / total;
        }
    });
    out
}

/// The bilinear sample of `src` (`w` × `h`) at (u, v), both inside [0, w − 1] × [0, h − 1].
fn bilinear(src: &[f32], w: usize, h: usize, u: f64, v: f64) -> f32 {
    let (x0, y0) = (u.floor() as usize, v.floor() as usize);
    let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
    let (fx, fy) = ((u - x0 as f64) as f32, (v - y0 as f64) as f32);
    let top = src[y0 * w + x0] * (1.0 - fx) + src[y0 * w + x1] * fx;
    let bottom = src[y1 * w + x0] * (1.0 - fx) + src[y1 * w + x1] * fx;
    top * (1.0 - fy) + bottom * fy
}

fn mul(a: &[f64; 4], b: &[f64; 4]) -> [f64; 4] {
    [
        a[0] * b[0] + a[1] * b[2],
        a[0] * b[1] + a[1] * b[3],
        a[2] * b[0] + a[3] * b[2],
        a[2] * b[1] + a[3] * b[3],
    ]
}

fn transpose(a: &[f64; 4]) -> [f64; 4] {
    [a[0], a[2], a[1], a[3]]
}

/// The view of `image` under `warp` (x′ = M x + c), `width` × `height` pixels: bilinear
/// samples of the image, blurred first where M shrinks it (see the module docs); 0 outside
/// the image's pixel squares.
pub fn warp_image(
    image: &GrayImage,
    warp: &AffineWarp,
    width: usize,
    height: usize,
) -> Result<GrayImage> {
    let inv = warp
        .inverse()
        .ok_or_else(|| ImageError::invalid("warp", format!("{:?} is singular", warp.m)))?;
    if width == 0 || height == 0 || width.saturating_mul(height) > 1 << 28 {
        return Err(ImageError::invalid(
            "warp",
            format!("a view of {width}×{height} pixels"),
        ));
    }
    let (w, h) = (image.width(), image.height());
    // Σ = σ_iso² I + σ_dir² v vᵀ: the blur both directions need (the larger singular value's),
    // then the rest along v, the direction M shrinks most.
    let (s_max, s_min, v) = warp.singular_directions();
    let sigma = |s: f64| {
        if s < 1.0 {
            0.8 * (1.0 / (s * s) - 1.0).sqrt()
        } else {
            0.0
        }
    };
    let iso = sigma(s_max);
    let dir = (sigma(s_min).powi(2) - iso * iso).max(0.0).sqrt();
    let blurred;
    let src: &[f32] = if iso > 0.0 {
        blurred = gaussian_blur(image, iso);
        &blurred
    } else {
        image.data()
    };
    let directed;
    let src: &[f32] = if dir > 0.25 {
        directed = directional_blur(src, w, h, dir, v);
        &directed
    } else {
        src
    };
    let mut out = vec![0f32; width * height];
    out.par_chunks_mut(width).enumerate().for_each(|(y, row)| {
        for (x, o) in row.iter_mut().enumerate() {
            let [u, v] = inv.apply([x as f64, y as f64]);
            // The image covers its pixels' squares: up to half a pixel beyond the outer
            // centres reads the edge.
            if u < -0.5 || v < -0.5 || u > w as f64 - 0.5 || v > h as f64 - 0.5 {
                continue;
            }
            let (u, v) = (u.clamp(0.0, (w - 1) as f64), v.clamp(0.0, (h - 1) as f64));
            *o = bilinear(src, w, h, u, v);
        }
    });
    GrayImage::new(width, height, out)
}

/// An AC row `[x1, y1, x2, y2, a11, a12, a21, a22]` found between the view `wa` of image A and
/// the view `wb` of image B, in the original images (see the module docs). `None` when a warp
/// is singular.
pub fn ac_from_views(row: &[f64; 8], wa: &AffineWarp, wb: &AffineWarp) -> Option<[f64; 8]> {
    let (ia, ib) = (wa.inverse()?, wb.inverse()?);
    let x1 = ia.apply([row[0], row[1]]);
    let x2 = ib.apply([row[2], row[3]]);
    let a = mul(&mul(&ib.m, &[row[4], row[5], row[6], row[7]]), &wa.m);
    Some([x1[0], x1[1], x2[0], x2[1], a[0], a[1], a[2], a[3]])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The directional blur by its definition: every tap of every pixel sampled bilinearly at
    /// its clamped position (what `directional_blur` does near the edges, and computes from
    /// per-tap constants elsewhere).
    fn directional_blur_by_definition(
        src: &[f32],
        w: usize,
        h: usize,
        sigma: f64,
        v: [f64; 2],
    ) -> Vec<f32> {
        let r = (3.0 * sigma).ceil() as i64;
        let weight = |k: f64| (-(k * k) / (2.0 * sigma * sigma)).exp() as f32;
        let total: f32 = (-r..=r).map(|k| weight(k as f64)).sum();
        let (wf, hf) = ((w - 1) as f64, (h - 1) as f64);
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f64, (i / w) as f64);
                let acc: f32 = (-r..=r)
                    .map(|k| {
                        let k = k as f64;
                        let u = (x + k * v[0]).clamp(0.0, wf);
                        let t = (y + k * v[1]).clamp(0.0, hf);
                        weight(k) * bilinear(src, w, h, u, t)
                    })
                    .sum();
                acc / total
            })
            .collect()
    }

    #[test]
    fn the_directional_blur_is_its_definition_inside_and_at_the_edges() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
        let half_pi = std::f64::consts::FRAC_PI_2;
        // Axis-aligned (cos 90° is 6e-17, not 0), oblique, and an image smaller than the
        // kernel (every pixel at an edge).
        for (w, h, sigma, angle) in [
            (97, 61, 3.1, 0.0),
            (97, 61, 3.1, half_pi),
            (97, 61, 6.3, 0.7),
            (80, 120, 1.2, -2.3),
            (9, 7, 4.0, 0.4),
        ] {
            let src: Vec<f32> = (0..w * h).map(|_| rng.random::<f32>()).collect();
            let v = [f64::cos(angle), f64::sin(angle)];
            let fast = directional_blur(&src, w, h, sigma, v);
            let slow = directional_blur_by_definition(&src, w, h, sigma, v);
            let worst = fast
                .iter()
                .zip(&slow)
                .map(|(a, b)| (a - b).abs())
                .fold(0f32, f32::max);
            assert!(worst < 1e-6, "{w}x{h} sigma {sigma} angle {angle}: {worst}");
        }
    }

    fn close(a: &[f64], b: &[f64], tol: f64) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() < tol)
    }

    #[test]
    fn the_tilt_compresses_along_its_direction() {
        // Tilt 2 along φ = 0 compresses y (the direction orthogonal to φ's axis stays).
        let w = AffineWarp::linear(0.0, 1.0, 2.0, 0.0);
        assert!(close(&w.m, &[1.0, 0.0, 0.0, 0.5], 1e-15));
        // Along φ = 90°: compresses x.
        let w = AffineWarp::linear(0.0, 1.0, 2.0, std::f64::consts::FRAC_PI_2);
        assert!(close(&w.m, &[0.5, 0.0, 0.0, 1.0], 1e-15));
        let w = AffineWarp::linear(0.7, 1.5, 3.0, 0.4);
        assert!((w.min_singular_value() - 0.5).abs() < 1e-12);
        let det = w.m[0] * w.m[3] - w.m[1] * w.m[2];
        assert!((det - 1.5 * 1.5 / 3.0).abs() < 1e-12);
    }

    #[test]
    fn the_shrinking_direction_is_the_tilts() {
        // T(4, φ) compresses x ∝ R(φ)ᵀ e_y = (sin φ, cos φ); the rotation after it does not
        // change the direction in the source.
        let phi = 0.7;
        let (hi, lo, v) = AffineWarp::linear(0.3, 1.0, 4.0, phi).singular_directions();
        assert!((hi - 1.0).abs() < 1e-12 && (lo - 0.25).abs() < 1e-12);
        assert!(((v[0] * phi.sin() + v[1] * phi.cos()).abs() - 1.0).abs() < 1e-12);
        let (hi, lo, _) = AffineWarp::linear(1.0, 0.5, 1.0, 0.0).singular_directions();
        assert!((hi - 0.5).abs() < 1e-12 && (lo - 0.5).abs() < 1e-12);
    }

    #[test]
    fn a_tilt_blurs_only_the_direction_it_compresses() {
        // Stripes across x (constant along y) under a tilt that compresses y: the view is the
        // image subsampled along y, with its stripes intact (an isotropic blur of the tilt's
        // σ ≈ 3 px would flatten stripes 6 px apart to a tenth of their contrast).
        let (w, h) = (60, 80);
        let stripe = |x: usize| 100.0 * (2.0 * std::f32::consts::PI * x as f32 / 6.0).sin();
        let img = GrayImage::new(w, h, (0..w * h).map(|i| stripe(i % w)).collect()).unwrap();
        let (warp, vw, vh) = AffineWarp::linear(0.0, 1.0, 4.0, 0.0).fitted(w, h);
        assert_eq!((vw, vh), (60, 21));
        let view = warp_image(&img, &warp, vw, vh).unwrap();
        // The last row samples y = 80, past the image (0 there).
        for y in 0..vh - 1 {
            for x in 0..vw {
                assert!((view.get(x, y) - stripe(x)).abs() < 1e-3, "({x}, {y})");
            }
        }
        // Stripes across y are blurred by it.
        let img = GrayImage::new(w, h, (0..w * h).map(|i| stripe(i / w)).collect()).unwrap();
        let view = warp_image(&img, &warp, vw, vh).unwrap();
        // Away from the clamped top and bottom edges (3σ).
        let peak = view.data()[3 * vw..17 * vw]
            .iter()
            .fold(0f32, |m, v| m.max(v.abs()));
        assert!(peak < 10.0, "{peak}");
    }

    #[test]
    fn a_window_crops_the_view() {
        // A 2× zoom of a 100 × 50 image is 199 × 99 px; its lower-right quarter starts at
        // (49, 24) in view pixels (floored), i.e. at (24.5, 12) in the image.
        let (w, vw, vh) = AffineWarp::linear(0.0, 2.0, 1.0, 0.0).fitted(100, 50);
        let (t, tw, th) = w.windowed(vw, vh, [0.25, 0.25, 0.75, 0.75]);
        assert_eq!((tw, th), (100, 50));
        assert!(close(&t.apply([24.5, 12.0]), &[0.0, 0.0], 1e-12));
        assert_eq!(t.m, w.m);
        // The view of the window is the window of the view.
        let img = GrayImage::new(100, 50, (0..5000).map(|v| (v % 97) as f32).collect()).unwrap();
        let (full, tile) = (
            warp_image(&img, &w, vw, vh).unwrap(),
            warp_image(&img, &t, tw, th).unwrap(),
        );
        for (y, x) in [(0, 0), (10, 33), (49, 99)] {
            let v = full.data()[(y + 24) * vw + x + 49];
            assert_eq!(tile.data()[y * tw + x], v);
        }
    }

    #[test]
    fn fitted_views_hold_the_whole_image() {
        let (w, vw, vh) =
            AffineWarp::linear(std::f64::consts::FRAC_PI_2, 1.0, 1.0, 0.0).fitted(100, 50);
        assert_eq!((vw, vh), (50, 100));
        for p in [[0.0, 0.0], [99.0, 0.0], [0.0, 49.0], [99.0, 49.0]] {
            let q = w.apply(p);
            assert!(q[0] > -1e-9 && q[1] > -1e-9 && q[0] < 49.0 + 1e-9 && q[1] < 99.0 + 1e-9);
        }
        let inv = w.inverse().unwrap();
        assert!(close(&inv.apply(w.apply([3.0, 7.0])), &[3.0, 7.0], 1e-12));
    }

    #[test]
    fn a_rotated_view_is_the_rotated_image() {
        let img = GrayImage::new(4, 3, (0..12).map(|v| v as f32 / 11.0).collect()).unwrap();
        let (w, vw, vh) = AffineWarp::linear(std::f64::consts::PI, 1.0, 1.0, 0.0).fitted(4, 3);
        let view = warp_image(&img, &w, vw, vh).unwrap();
        for y in 0..3 {
            for x in 0..4 {
                assert!((view.get(3 - x, 2 - y) - img.get(x, y)).abs() < 1e-5);
            }
        }
        assert!(
            warp_image(
                &img,
                &AffineWarp {
                    m: [0.0; 4],
                    c: [0.0; 2]
                },
                4,
                3
            )
            .is_err()
        );
    }

    /// The ACs of x2 = H(x1) (an affine H here) seen between a tilted view of A and a rotated,
    /// zoomed view of B map back to the ACs of H itself.
    #[test]
    fn acs_from_views_map_back_to_the_original_images() {
        let (m, c) = ([1.1, 0.2, -0.1, 0.9], [5.0, -3.0]);
        let h = AffineWarp { m, c };
        let wa = AffineWarp::linear(0.0, 0.8, 2.0, 0.3).fitted(640, 480).0;
        let wb = AffineWarp::linear(1.9, 1.3, 1.0, 0.0).fitted(640, 480).0;
        let x1 = [100.0, 200.0];
        let x2 = h.apply(x1);
        let (x1v, x2v) = (wa.apply(x1), wb.apply(x2));
        // In the views, x2′ = W_b H W_a⁻¹ x1′: its Jacobian is M_b M M_a⁻¹.
        let ma_inv = wa.inverse().unwrap().m;
        let av = mul(&mul(&wb.m, &m), &ma_inv);
        let row = [x1v[0], x1v[1], x2v[0], x2v[1], av[0], av[1], av[2], av[3]];
        let back = ac_from_views(&row, &wa, &wb).unwrap();
        let want = [x1[0], x1[1], x2[0], x2[1], m[0], m[1], m[2], m[3]];
        assert!(close(&back, &want, 1e-9), "{back:?} vs {want:?}");
    }
}
