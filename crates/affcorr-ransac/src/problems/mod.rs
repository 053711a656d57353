//! The three problems people use: homography, fundamental matrix, relative pose.
//!
//! Each keeps its data as structure of arrays ([`Correspondences`]) so residual loops stream
//! through memory, and takes its minimal samples either as points or as ACs ([`SampleKind`]).

pub(crate) mod epipolar_lm;
pub mod fundamental;
pub mod homography;
mod homography_affine;
mod normal_eq;
pub mod relpose;
mod simd;

use crate::error::{RansacError, Result};
use affcorr_geom::types::{AcRow, PointRow};
use affcorr_geom::{AffineCorrespondence, Mat2, Vec2};

/// Weight (px²) of the affine residual in the test of whether an AC can seed a good minimal
/// sample ([`crate::Problem::sample_support`]): the point residual plus this times the affine
/// one must be within the inlier threshold². With λ = ρ²/2 the affine term of a homography is
/// the mean squared displacement of a circle of radius ρ px mapped by A instead of A_H; ρ = 10 px
/// is about a 32×32 patch's inscribed circle. The affine Sampson error SD_A (docs/design.md §4) is,
/// to first order, the squared error of A along the epipolar constraint's two rows, so the same
/// λ serves F and E.
pub(crate) const SEED_AFFINE_WEIGHT: f64 = 50.0;

/// The most inliers on which the noise ratio λ of the affine terms is estimated (the medians
/// of their squared point and affine residuals). The median of n samples has a relative spread
/// of about 1.25/√n of the spread of the data, so 512 ACs (1024–2048 residuals) give λ to a few
/// percent, well inside the 0.8–1.25 band in which the refinements take λ as settled, and
/// the selection no longer grows with the inlier count.
pub(crate) const NOISE_RATIO_SAMPLE: usize = 512;

/// `indices` thinned by a regular stride to at most [`NOISE_RATIO_SAMPLE`] entries, spread
/// over the whole list.
pub(crate) fn noise_ratio_sample(indices: &[usize]) -> impl Iterator<Item = &usize> {
    indices
        .iter()
        .step_by(indices.len().div_ceil(NOISE_RATIO_SAMPLE).max(1))
}

/// The upper median (the element at `len / 2` in sorted order) of `v`, whose entries are ≥ 0
/// (squared residuals; +∞ and NaN allowed); `v` must not be empty. Such floats order as their
/// bit patterns, so the selection compares integers instead of calling `total_cmp`.
pub(crate) fn median_of_squares(v: &[f64]) -> f64 {
    let mut bits: Vec<u64> = v.iter().map(|x| x.to_bits()).collect();
    let k = bits.len() / 2;
    f64::from_bits(*bits.select_nth_unstable(k).1)
}

/// Counts the data whose residual `r2(i)` is below `threshold_sq`.
pub(crate) fn count_below(n: usize, threshold_sq: f64, r2: impl Fn(usize) -> f64) -> usize {
    (0..n).filter(|&i| r2(i) < threshold_sq).count()
}

/// What a minimal sample is made of.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SampleKind {
    /// Point correspondences (4 for H, 7 for F, 5 for E).
    Points,
    /// Affine correspondences (2 for H, 3 for F, 2 for E).
    Affine,
    /// One AC and points (1 + 2 for H, 1 + 4 for F, 1 + 2 for E): the first index of a sample
    /// is used with its A, the others as points. Fewer affine equations than an AC sample
    /// (2 for E and F, 4 for H, against 4, 6 and 8), fewer correspondences than a point
    /// sample.
    Hybrid,
}

impl SampleKind {
    /// Whether the minimal samples use A (so the data must carry it).
    pub fn uses_affine(self) -> bool {
        self != SampleKind::Points
    }
}

/// The largest of `sizes`: the buffer a problem's minimal solvers write into must hold the
/// most models any of them returns.
pub(crate) const fn most_models(sizes: &[usize]) -> usize {
    let (mut most, mut k) = (0, 0);
    while k < sizes.len() {
        if sizes[k] > most {
            most = sizes[k];
        }
        k += 1;
    }
    most
}

/// The support that the stopping rule counts for a hybrid sample of `m` correspondences: its
/// first must be a good AC (`seeds` of the `n` data can be, [`crate::Problem::sample_support`])
/// and the other `m − 1` good points (`inliers`). An all-good draw comes with probability
/// (s/n)·(i/n)^(m−1); the count returned, n·(s/n)^(1/m)·(i/n)^((m−1)/m), gives the same
/// probability when raised to the m-th power as the rule does.
pub(crate) fn hybrid_support(seeds: usize, inliers: usize, n: usize, m: usize) -> usize {
    if n == 0 || m == 0 {
        return 0;
    }
    let (s, i) = (seeds as f64 / n as f64, inliers as f64 / n as f64);
    let p = s.powf(1.0 / m as f64) * i.powf((m - 1) as f64 / m as f64);
    (p * n as f64).floor() as usize
}

/// Correspondences in structure-of-arrays form; `a` is empty for point-only data.
#[derive(Debug, Clone, Default)]
pub struct Correspondences {
    /// Points in image 1.
    pub x1: Vec<Vec2>,
    /// Points in image 2.
    pub x2: Vec<Vec2>,
    /// Affine maps A = ∂x2/∂x1 (empty for point-only data).
    pub a: Vec<Mat2>,
}

impl Correspondences {
    /// From `(N, 8)` AC rows; non-finite rows are an error naming the row.
    pub fn from_ac_rows(rows: &[AcRow]) -> Result<Self> {
        check_finite(rows)?;
        Ok(Self {
            x1: rows.iter().map(|r| Vec2::new(r[0], r[1])).collect(),
            x2: rows.iter().map(|r| Vec2::new(r[2], r[3])).collect(),
            a: rows
                .iter()
                .map(|r| Mat2::new(r[4], r[5], r[6], r[7]))
                .collect(),
        })
    }

    /// From ACs (the synthetic generators' and the solvers' type); a non-finite AC is an error
    /// naming its index, as for [`Self::from_ac_rows`].
    pub fn from_acs(acs: &[AffineCorrespondence]) -> Result<Self> {
        let data = Self {
            x1: acs.iter().map(|ac| ac.x1).collect(),
            x2: acs.iter().map(|ac| ac.x2).collect(),
            a: acs.iter().map(|ac| ac.a).collect(),
        };
        data.validate()?;
        Ok(data)
    }

    /// From `(N, 4)` point rows.
    pub fn from_point_rows(rows: &[PointRow]) -> Result<Self> {
        check_finite(rows)?;
        Ok(Self {
            x1: rows.iter().map(|r| Vec2::new(r[0], r[1])).collect(),
            x2: rows.iter().map(|r| Vec2::new(r[2], r[3])).collect(),
            a: Vec::new(),
        })
    }

    /// The same points without their affine maps: what an estimator sees of point matches.
    pub fn points_only(&self) -> Self {
        Self {
            x1: self.x1.clone(),
            x2: self.x2.clone(),
            a: Vec::new(),
        }
    }

    /// Checks what [`Self::from_ac_rows`] guarantees, for data built from the public fields:
    /// `x2` (and `a`, unless empty) as long as `x1`, every value finite.
    pub fn validate(&self) -> Result<()> {
        let n = self.x1.len();
        let bad_len = |field: &str, got: usize| RansacError::InvalidOption {
            name: "corrs",
            value: format!("x1 has {n} points, {field} has {got}"),
            reason: "x2 and a (unless empty) need one entry per x1",
        };
        if self.x2.len() != n {
            return Err(bad_len("x2", self.x2.len()));
        }
        if !self.a.is_empty() && self.a.len() != n {
            return Err(bad_len("a", self.a.len()));
        }
        let finite = |v: &Vec2| v.x.is_finite() && v.y.is_finite();
        let bad = (0..n).find(|&i| {
            !(finite(&self.x1[i])
                && finite(&self.x2[i])
                && self
                    .a
                    .get(i)
                    .is_none_or(|a| a.iter().all(|v| v.is_finite())))
        });
        match bad {
            Some(index) => Err(RansacError::NonFinite {
                what: "corrs",
                index,
            }),
            None => Ok(()),
        }
    }

    /// Number of correspondences.
    pub fn len(&self) -> usize {
        self.x1.len()
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.x1.is_empty()
    }

    /// True when the data carry affine maps.
    pub fn has_affine(&self) -> bool {
        !self.a.is_empty()
    }

    /// True when the data carry affine maps and some AC has a `confidence` above 0 (all do
    /// when `None`): whether a refinement with affine terms has any to add.
    pub(crate) fn has_usable_affine(&self, confidence: Option<&[f64]>) -> bool {
        self.has_affine() && confidence.is_none_or(|c| c.iter().any(|&v| v > 0.0))
    }

    /// The AC at index `i` (requires affine data).
    #[inline]
    pub fn ac(&self, i: usize) -> AffineCorrespondence {
        AffineCorrespondence {
            x1: self.x1[i],
            x2: self.x2[i],
            a: self.a[i],
        }
    }

    /// Gathers the points of `idx` into the caller's buffers.
    #[inline]
    pub fn gather_points(&self, idx: &[usize], x1: &mut Vec<Vec2>, x2: &mut Vec<Vec2>) {
        x1.clear();
        x2.clear();
        x1.extend(idx.iter().map(|&i| self.x1[i]));
        x2.extend(idx.iter().map(|&i| self.x2[i]));
    }

    /// Gathers the ACs of `idx` into the caller's buffer.
    #[inline]
    pub fn gather_acs(&self, idx: &[usize], out: &mut Vec<AffineCorrespondence>) {
        out.clear();
        out.extend(idx.iter().map(|&i| self.ac(i)));
    }
}

fn check_finite<const W: usize>(rows: &[[f64; W]]) -> Result<()> {
    match rows.iter().position(|r| r.iter().any(|v| !v.is_finite())) {
        Some(index) => Err(RansacError::NonFinite {
            what: "corrs",
            index,
        }),
        None => Ok(()),
    }
}

/// Checks that `kind` can be sampled from `data`.
pub(crate) fn check_kind(data: &Correspondences, kind: SampleKind) -> Result<()> {
    if kind.uses_affine() && !data.has_affine() {
        let value = if kind == SampleKind::Hybrid {
            "hybrid"
        } else {
            "affine"
        };
        return Err(RansacError::InvalidOption {
            name: "sample",
            value: value.into(),
            reason: "affine and hybrid samples need (N, 8) correspondences with their A",
        });
    }
    Ok(())
}

/// Validates an affine weight.
pub(crate) fn check_affine_weight(w: f64, data: &Correspondences) -> Result<()> {
    if !(w >= 0.0 && w.is_finite()) {
        return Err(RansacError::InvalidOption {
            name: "affine_weight",
            value: w.to_string(),
            reason: "must be finite and ≥ 0",
        });
    }
    if w > 0.0 && !data.has_affine() {
        return Err(RansacError::InvalidOption {
            name: "affine_weight",
            value: w.to_string(),
            reason: "affine scoring needs (N, 8) correspondences",
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_noise_ratio_sample_spans_the_inliers_and_keeps_small_sets_whole() {
        let few: Vec<usize> = (0..300).collect();
        assert!(noise_ratio_sample(&few).copied().eq(0..300));
        let many: Vec<usize> = (0..1500).map(|i| 3 * i).collect();
        let s: Vec<usize> = noise_ratio_sample(&many).copied().collect();
        assert!(s.len() <= NOISE_RATIO_SAMPLE && s.len() >= NOISE_RATIO_SAMPLE * 9 / 10);
        assert_eq!(s[0], 0);
        assert!(
            *s.last().unwrap() >= 3 * 1490,
            "ends at {}",
            s.last().unwrap()
        );
    }

    #[test]
    fn the_median_of_squares_is_the_upper_median_with_infinities_and_nans_on_top() {
        assert_eq!(median_of_squares(&[5.0, 1.0, 4.0, 2.0, 3.0]), 3.0);
        assert_eq!(median_of_squares(&[f64::INFINITY, 0.0, 1e-300, 7.5]), 7.5);
        assert_eq!(
            median_of_squares(&[f64::NAN, f64::INFINITY, 2.0]),
            f64::INFINITY
        );
    }
}
