//! Patch extraction against an independent reference: bilinear interpolation of the image padded
//! by edge replication (the implementation clamps coordinates instead).

use affcorr_image::{GrayImage, ImageError, PATCH_SIZE, extract_patches};
use rand::{Rng, SeedableRng};

fn random_image(w: usize, h: usize, seed: u64) -> GrayImage {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    GrayImage::new(w, h, (0..w * h).map(|_| rng.random::<f32>()).collect()).unwrap()
}

/// I at (u, v) by bilinear interpolation, reading pixels outside through edge replication.
fn reference(img: &GrayImage, u: f64, v: f64) -> f64 {
    let pix = |i: i64, j: i64| {
        let x = i.clamp(0, img.width() as i64 - 1) as usize;
        let y = j.clamp(0, img.height() as i64 - 1) as usize;
        img.get(x, y) as f64
    };
    let (i, j) = (u.floor() as i64, v.floor() as i64);
    let (a, b) = (u - u.floor(), v - v.floor());
    (1.0 - a) * (1.0 - b) * pix(i, j)
        + a * (1.0 - b) * pix(i + 1, j)
        + (1.0 - a) * b * pix(i, j + 1)
        + a * b * pix(i + 1, j + 1)
}

fn check_against_reference(img: &GrayImage, centres: &[[f64; 2]]) {
    let p = extract_patches(img, centres).unwrap();
    assert_eq!(p.len(), centres.len());
    assert_eq!(p.as_slice().len(), centres.len() * PATCH_SIZE * PATCH_SIZE);
    for (k, &[x, y]) in centres.iter().enumerate() {
        let patch = p.patch(k);
        for r in 0..PATCH_SIZE {
            for c in 0..PATCH_SIZE {
                let want = reference(img, x + c as f64 - 15.5, y + r as f64 - 15.5);
                let got = patch[r * PATCH_SIZE + c] as f64;
                assert!(
                    (got - want).abs() < 2e-6,
                    "centre {k} ({x}, {y}), pixel ({r}, {c}): {got} vs {want}"
                );
            }
        }
    }
}

#[test]
fn matches_the_reference_inside_across_and_outside_the_border() {
    let img = random_image(97, 71, 1);
    let mut rng = rand_pcg::Pcg64::seed_from_u64(2);
    let mut centres: Vec<[f64; 2]> = (0..40)
        .map(|_| {
            [
                rng.random_range(-30.0..127.0),
                rng.random_range(-30.0..101.0),
            ]
        })
        .collect();
    centres.extend([
        [48.0, 35.0],     // integer centre: half-pixel sample positions
        [15.5, 15.5],     // first patch pixel exactly on pixel (0, 0)
        [80.5, 54.5],     // last patch pixel exactly on the last pixel (96, 70)
        [-1e6, 1e6],      // far outside: the corner pixel everywhere
        [48.25, -0.75],   // straddling the top edge
        [96.999, 70.001], // the bottom-right corner
    ]);
    check_against_reference(&img, &centres);
}

#[test]
fn parallel_batches_equal_single_patches() {
    let img = random_image(200, 150, 3);
    let mut rng = rand_pcg::Pcg64::seed_from_u64(4);
    let centres: Vec<[f64; 2]> = (0..300)
        .map(|_| {
            [
                rng.random_range(-10.0..210.0),
                rng.random_range(-10.0..160.0),
            ]
        })
        .collect();
    let all = extract_patches(&img, &centres).unwrap();
    for (k, c) in centres.iter().enumerate().step_by(7) {
        assert_eq!(all.patch(k), extract_patches(&img, &[*c]).unwrap().patch(0));
    }
    check_against_reference(&img, &centres[..20]);
}

#[test]
fn half_integer_centres_copy_pixels_and_ramps_are_reproduced() {
    let (w, h) = (80, 60);
    let img = GrayImage::new(
        w,
        h,
        (0..w * h)
            .map(|i| 0.003 * (i % w) as f32 + 0.011 * (i / w) as f32 + 0.1)
            .collect(),
    )
    .unwrap();
    // (x, y) = (20.5, 30.5): sample positions are the integers 5..36 and 15..46.
    let p = extract_patches(&img, &[[20.5, 30.5]]).unwrap();
    for r in 0..PATCH_SIZE {
        for c in 0..PATCH_SIZE {
            assert_eq!(p.patch(0)[r * PATCH_SIZE + c], img.get(5 + c, 15 + r));
        }
    }
    // Bilinear sampling reproduces an affine image exactly (inside).
    let (x, y) = (40.3, 29.8);
    let p = extract_patches(&img, &[[x, y]]).unwrap();
    for r in 0..PATCH_SIZE {
        for c in 0..PATCH_SIZE {
            let want = 0.003 * (x + c as f64 - 15.5) + 0.011 * (y + r as f64 - 15.5) + 0.1;
            assert!((p.patch(0)[r * PATCH_SIZE + c] as f64 - want).abs() < 1e-6);
        }
    }
}

#[test]
fn empty_and_non_finite_centres() {
    let img = random_image(10, 10, 5);
    assert!(extract_patches(&img, &[]).unwrap().is_empty());
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let e = extract_patches(&img, &[[1.0, 1.0], [2.0, 2.0], [3.0, bad]]).unwrap_err();
        assert!(
            matches!(
                e,
                ImageError::NonFinite {
                    what: "centres",
                    row: 2
                }
            ),
            "{e:?}"
        );
        assert_eq!(e.to_string(), "centres[2] contains NaN or infinity");
    }
}
