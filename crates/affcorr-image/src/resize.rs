//! Downscaling to a working resolution, and the map of coordinates and affine maps back.
//!
//! A matcher sees an image downscaled by s = max_side / max(W, H) when its longer side exceeds
//! `max_side`. Pixel centres lie at integers and image edges stay aligned (as the resize
//! samples: output pixel i reads the input around (i + 0.5)·W/W′ − 0.5), so a point at x′ in
//! the working image is at x = (x′ + 0.5)/s − 0.5 in the original, per axis; an AC's
//! A = ∂x2/∂x1 becomes diag(1/s_B) · A′ · diag(s_A) (docs/design.md §2).

use std::borrow::Cow;

use crate::gray::GrayImage;

/// The image at most `max_side` pixels on its longer side (antialiased triangle filter: its
/// support widens by the downscale factor), and the factors (s_x, s_y) = (W′/W, H′/H) of the
/// downscale. An image that fits, or `max_side = None`, is borrowed with factors (1, 1).
pub fn limit_side(img: &GrayImage, max_side: Option<usize>) -> (Cow<'_, GrayImage>, [f64; 2]) {
    let side = img.width().max(img.height());
    match max_side {
        Some(m) if side > m => {
            let s = m as f64 / side as f64;
            let w = ((img.width() as f64 * s).round() as usize).clamp(1, m);
            let h = ((img.height() as f64 * s).round() as usize).clamp(1, m);
            let buf = image::ImageBuffer::<image::Luma<f32>, Vec<f32>>::from_raw(
                img.width() as u32,
                img.height() as u32,
                img.data().to_vec(),
            )
            .expect("sizes match");
            let small = image::imageops::resize(
                &buf,
                w as u32,
                h as u32,
                image::imageops::FilterType::Triangle,
            );
            let small = GrayImage::new(w, h, small.into_raw())
                .expect("the resize of a finite image is finite");
            let factors = [
                w as f64 / img.width() as f64,
                h as f64 / img.height() as f64,
            ];
            (Cow::Owned(small), factors)
        }
        _ => (Cow::Borrowed(img), [1.0, 1.0]),
    }
}

/// An AC row `[x1, y1, x2, y2, a11, a12, a21, a22]` of working images downscaled by `sa`
/// (image A) and `sb` (image B), in the original pixels (see the module docs).
pub fn ac_to_original(row: &[f64; 8], sa: [f64; 2], sb: [f64; 2]) -> [f64; 8] {
    let &[p0, p1, q0, q1, m0, m1, m2, m3] = row;
    let ([ax, ay], [bx, by]) = (sa, sb);
    [
        (p0 + 0.5) / ax - 0.5,
        (p1 + 0.5) / ay - 0.5,
        (q0 + 0.5) / bx - 0.5,
        (q1 + 0.5) / by - 0.5,
        m0 * ax / bx,
        m1 * ay / bx,
        m2 * ax / by,
        m3 * ay / by,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_images_are_borrowed() {
        let img = GrayImage::new(4, 3, vec![0.5; 12]).unwrap();
        let (out, s) = limit_side(&img, Some(4));
        assert!(matches!(out, Cow::Borrowed(_)) && s == [1.0, 1.0]);
        let (out, _) = limit_side(&img, None);
        assert!(matches!(out, Cow::Borrowed(_)));
    }

    #[test]
    fn large_images_shrink_to_max_side_keeping_the_aspect() {
        let img = GrayImage::new(200, 100, vec![0.25; 20_000]).unwrap();
        let (out, s) = limit_side(&img, Some(50));
        assert_eq!((out.width(), out.height()), (50, 25));
        assert_eq!(s, [0.25, 0.25]);
        assert!(out.data().iter().all(|v| (v - 0.25).abs() < 1e-6));
    }

    /// A linear map downscaled and mapped back is the original: the working-image AC of
    /// x2 = M x1 + c is x2′ = S_B (M ((x1′ + ½)/S_A − ½) + c) + ½ S_B − ½ with
    /// A′ = S_B M S_A⁻¹; `ac_to_original` must return (x1, M x1 + c, M).
    #[test]
    fn acs_map_back_to_the_original_pixels() {
        let (sa, sb) = ([0.5, 0.25], [0.4, 0.8]);
        let m = [1.2, -0.3, 0.1, 0.9];
        let c = [3.0, -7.0];
        let x1 = [40.0, 12.0];
        let x2 = [
            m[0] * x1[0] + m[1] * x1[1] + c[0],
            m[2] * x1[0] + m[3] * x1[1] + c[1],
        ];
        let work =
            |p: [f64; 2], s: [f64; 2]| [(p[0] + 0.5) * s[0] - 0.5, (p[1] + 0.5) * s[1] - 0.5];
        let (w1, w2) = (work(x1, sa), work(x2, sb));
        let a = [
            m[0] * sb[0] / sa[0],
            m[1] * sb[0] / sa[1],
            m[2] * sb[1] / sa[0],
            m[3] * sb[1] / sa[1],
        ];
        let back = ac_to_original(
            &[w1[0], w1[1], w2[0], w2[1], a[0], a[1], a[2], a[3]],
            sa,
            sb,
        );
        let want = [x1[0], x1[1], x2[0], x2[1], m[0], m[1], m[2], m[3]];
        for (g, w) in back.iter().zip(want) {
            assert!((g - w).abs() < 1e-12, "{back:?} vs {want:?}");
        }
    }
}
