//! Guided re-matching: more matches around the verified ones, found by their ACs rather than by
//! descriptors ("match propagation", Lhuillier & Quan, *Match propagation for image-based
//! modeling and rendering*, TPAMI 2002; the AC-guided step of issue 20).
//!
//! An AC (x1, x2, A) predicts where any point p near x1 lies in the other image:
//! x2 + A (p − x1), with the local map A (the first-order Taylor expansion of the true map,
//! A = ∂x2/∂x1). So each keypoint of image A that has no match, but lies within
//! [`GrowOptions::radius`] of a verified AC, gets a predicted AC (p, x2 + A (p − x1), A) from
//! its nearest one, which the affine Lucas–Kanade refinement ([`affcorr_image::refine_affine`],
//! x2 moving) then fits to the images. A predicted AC is kept when the refinement accepts and
//! calls it reliable, and when it agrees (point and A) with the fundamental matrix that verified
//! the seeds; the kept ones seed the next round. Descriptors play no part, so this works where
//! the matcher's descriptors do not (rotated, zoomed and tilted pairs), and it adds matches
//! exactly where the verified ones say the images overlap.

use affcorr_geom::types::AffineCorrespondence;
use affcorr_geom::{Mat3, sampson};
use affcorr_image::{AffineRefineOptions, GrayImage, refine_affine};

use crate::error::{PipelineError, Result};
use crate::views::{VERIFY_AFFINE_WEIGHT, VERIFY_THRESHOLD};

/// Options of guided re-matching.
#[derive(Debug, Clone, PartialEq)]
pub struct GrowOptions {
    /// A keypoint is predicted from its nearest verified AC within this distance in image A,
    /// pixels (the first-order prediction degrades with distance: perspective, depth edges).
    pub radius: f64,
    /// Rounds of growth: the ACs kept in a round seed the next one.
    pub rounds: usize,
    /// A keypoint closer than this to a matched point (in A) or a prediction closer than this
    /// to one (in B) is a match already, pixels.
    pub min_separation: f64,
    /// The refinement may move the predicted x2 by at most this, pixels: further, it has
    /// slid to another part of the texture (F does not see a slide along the epipolar line).
    pub max_shift: f64,
}

impl Default for GrowOptions {
    fn default() -> Self {
        Self {
            radius: 40.0,
            rounds: 2,
            min_separation: 3.0,
            max_shift: 4.0,
        }
    }
}

impl GrowOptions {
    pub(crate) fn validate(&self) -> Result<()> {
        for (name, v) in [
            ("radius", self.radius),
            ("min_separation", self.min_separation),
            ("max_shift", self.max_shift),
        ] {
            if !(v > 0.0 && v.is_finite()) {
                return Err(PipelineError::invalid(
                    name,
                    format!("must be a positive number of pixels, got {v}"),
                ));
            }
        }
        Ok(())
    }
}

/// New ACs that grow from the verified ones.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Grown {
    /// The new ACs, in the images' pixels.
    pub corrs: Vec<[f64; 8]>,
    /// For each, the index (into the seeds given) of the AC it grew from, through earlier
    /// rounds' ACs.
    pub seed: Vec<usize>,
    /// The refinement's confidence of each ([`affcorr_image::AffineRefinement`]).
    pub affine_confidence: Vec<f64>,
}

/// Whether an AC agrees with `f`: its point and affine Sampson errors, weighted as in the
/// view cascade's verification, within [`VERIFY_THRESHOLD`].
fn agrees(f: &Mat3, row: &[f64; 8]) -> bool {
    let ac = AffineCorrespondence::from_row(row);
    let (point, affine) = sampson::sampson_point_affine(f, &ac);
    let err = point + VERIFY_AFFINE_WEIGHT * (affine[0] + affine[1]);
    err.is_finite() && err < VERIFY_THRESHOLD * VERIFY_THRESHOLD
}

/// Grows ACs from `seeds` (verified ACs of `image_a` ↔ `image_b`, in their pixels) to the
/// `keypoints` of image A that have no match in `matched_a` / `matched_b` (the pair's matched
/// points in A and B), keeping those that agree with the fundamental matrix `f`; see the
/// module docs.
pub fn grow(
    image_a: &GrayImage,
    image_b: &GrayImage,
    seeds: &[[f64; 8]],
    matched: &[[f64; 8]],
    keypoints: &[[f32; 2]],
    f: &Mat3,
    options: &GrowOptions,
) -> Result<Grown> {
    options.validate()?;
    let refine = AffineRefineOptions {
        // The neighbour's A is the prior; the identity is not (rotated and zoomed pairs), and
        // the neighbourhood's similarity is that prior's source already.
        try_identity: false,
        try_neighbours: false,
        ..AffineRefineOptions::default()
    };
    let sep2 = options.min_separation * options.min_separation;
    let near =
        |p: [f64; 2], q: [f64; 2], d2: f64| (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) < d2;
    let (w, h) = (image_b.width() as f64, image_b.height() as f64);
    // Points taken, in A and in B.
    let mut taken_a: Vec<[f64; 2]> = matched.iter().map(|r| [r[0], r[1]]).collect();
    let mut taken_b: Vec<[f64; 2]> = matched.iter().map(|r| [r[2], r[3]]).collect();
    let mut open: Vec<[f64; 2]> = keypoints
        .iter()
        .map(|k| [k[0] as f64, k[1] as f64])
        .filter(|&p| !taken_a.iter().any(|&q| near(p, q, sep2)))
        .collect();
    // The seeds of this round and the original seed each descends from.
    let mut round: Vec<([f64; 8], usize)> = seeds.iter().copied().zip(0..seeds.len()).collect();
    let mut out = Grown::default();
    let r2 = options.radius * options.radius;
    for _ in 0..options.rounds {
        if round.is_empty() || open.is_empty() {
            break;
        }
        // Each open keypoint's prediction from its nearest seed within the radius.
        let mut predicted: Vec<[f64; 8]> = Vec::new();
        let mut origin: Vec<usize> = Vec::new();
        let mut which: Vec<usize> = Vec::new();
        for (k, p) in open.iter().enumerate() {
            let nearest = round
                .iter()
                .map(|(s, o)| ((s[0] - p[0]).powi(2) + (s[1] - p[1]).powi(2), s, *o))
                .filter(|(d2, _, _)| *d2 < r2)
                .min_by(|a, b| a.0.total_cmp(&b.0));
            let Some((_, s, o)) = nearest else { continue };
            let (dx, dy) = (p[0] - s[0], p[1] - s[1]);
            let q = [s[2] + s[4] * dx + s[5] * dy, s[3] + s[6] * dx + s[7] * dy];
            if !(q[0] >= 0.0 && q[1] >= 0.0 && q[0] <= w - 1.0 && q[1] <= h - 1.0) {
                continue;
            }
            predicted.push([p[0], p[1], q[0], q[1], s[4], s[5], s[6], s[7]]);
            origin.push(o);
            which.push(k);
        }
        if predicted.is_empty() {
            break;
        }
        let refined = refine_affine(image_a, image_b, &predicted, &refine)?;
        let mut next = Vec::new();
        let mut used = vec![false; open.len()];
        let shift2 = options.max_shift * options.max_shift;
        for (i, row) in refined.corrs.iter().enumerate() {
            let q = [row[2], row[3]];
            let moved = !near(q, [predicted[i][2], predicted[i][3]], shift2);
            if !refined.reliable[i]
                || moved
                || !agrees(f, row)
                || taken_b.iter().any(|&t| near(q, t, sep2))
            {
                continue;
            }
            used[which[i]] = true;
            taken_a.push([row[0], row[1]]);
            taken_b.push(q);
            out.corrs.push(*row);
            out.seed.push(origin[i]);
            out.affine_confidence.push(refined.affine_confidence[i]);
            next.push((*row, origin[i]));
        }
        open = open
            .into_iter()
            .zip(used)
            .filter(|(_, u)| !u)
            .map(|(p, _)| p)
            .collect();
        round = next;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_options_are_named() {
        let o = GrowOptions {
            radius: 0.0,
            ..Default::default()
        };
        assert!(o.validate().unwrap_err().to_string().contains("radius"));
        let o = GrowOptions {
            min_separation: f64::NAN,
            ..Default::default()
        };
        assert!(
            o.validate()
                .unwrap_err()
                .to_string()
                .contains("min_separation")
        );
    }
}
