//! Affine correspondences and their row layouts (docs/design.md §2).
//!
//! - An AC is `(x1, x2, A)` with `A = ∂x2/∂x1`, the Jacobian of the map image 1 → image 2 at x1.
//! - Row layout `(N, 8)`: `[x1, y1, x2, y2, a11, a12, a21, a22]` (the same as GC-RANSAC's).
//! - Row layout `(N, 4)`: `[x1, y1, x2, y2]`.
//!
//! Batched functions take `&[[f64; 8]]` / `&[[f64; 4]]`; a flat `&[f64]` of length `8N` becomes
//! one with [`slice::as_chunks`] at no cost.

/// 2-vector.
pub type Vec2 = nalgebra::Vector2<f64>;
/// 3-vector.
pub type Vec3 = nalgebra::Vector3<f64>;
/// 2×2 matrix.
pub type Mat2 = nalgebra::Matrix2<f64>;
/// 3×3 matrix.
pub type Mat3 = nalgebra::Matrix3<f64>;

/// One row of the `(N, 8)` layout.
pub type AcRow = [f64; 8];
/// One row of the `(N, 4)` layout.
pub type PointRow = [f64; 4];

/// A point correspondence `x1 ↔ x2`, in pixels or normalised coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointCorrespondence {
    /// Point in image 1.
    pub x1: Vec2,
    /// Point in image 2.
    pub x2: Vec2,
}

/// An affine correspondence `(x1, x2, A)`, `A = ∂x2/∂x1`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AffineCorrespondence {
    /// Point in image 1.
    pub x1: Vec2,
    /// Point in image 2.
    pub x2: Vec2,
    /// Local affine map, `A = ∂x2/∂x1`.
    pub a: Mat2,
}

impl AffineCorrespondence {
    /// Reads a row of the `(N, 8)` layout.
    #[inline]
    pub fn from_row(r: &AcRow) -> Self {
        Self {
            x1: Vec2::new(r[0], r[1]),
            x2: Vec2::new(r[2], r[3]),
            a: Mat2::new(r[4], r[5], r[6], r[7]),
        }
    }

    /// Writes the `(N, 8)` row.
    #[inline]
    pub fn to_row(&self) -> AcRow {
        let a = &self.a;
        [
            self.x1.x,
            self.x1.y,
            self.x2.x,
            self.x2.y,
            a[(0, 0)],
            a[(0, 1)],
            a[(1, 0)],
            a[(1, 1)],
        ]
    }

    /// The point part.
    #[inline]
    pub fn points(&self) -> PointCorrespondence {
        PointCorrespondence {
            x1: self.x1,
            x2: self.x2,
        }
    }
}

impl PointCorrespondence {
    /// Reads the first four entries of a row (`(N, 4)` or `(N, 8)` layout).
    #[inline]
    pub fn from_row(r: &[f64]) -> Self {
        Self {
            x1: Vec2::new(r[0], r[1]),
            x2: Vec2::new(r[2], r[3]),
        }
    }
}

/// Rows that carry a point correspondence in their first four entries: both layouts.
pub trait CorrespondenceRow: Copy + Send + Sync {
    /// The point correspondence of this row.
    fn points(&self) -> PointCorrespondence;
}

impl CorrespondenceRow for PointRow {
    #[inline]
    fn points(&self) -> PointCorrespondence {
        PointCorrespondence::from_row(self)
    }
}

impl CorrespondenceRow for AcRow {
    #[inline]
    fn points(&self) -> PointCorrespondence {
        PointCorrespondence::from_row(self)
    }
}

/// Row-major 2×2 matrix from `[a11, a12, a21, a22]`.
#[inline]
pub fn mat2_from_row(r: &[f64; 4]) -> Mat2 {
    Mat2::new(r[0], r[1], r[2], r[3])
}

/// `[a11, a12, a21, a22]` of a 2×2 matrix.
#[inline]
pub fn mat2_to_row(a: &Mat2) -> [f64; 4] {
    [a[(0, 0)], a[(0, 1)], a[(1, 0)], a[(1, 1)]]
}

/// Row-major 3×3 matrix from 9 numbers.
#[inline]
pub fn mat3_from_row(r: &[f64; 9]) -> Mat3 {
    Mat3::from_row_slice(r)
}

/// The 9 numbers of a 3×3 matrix, row-major.
#[inline]
pub fn mat3_to_row(m: &Mat3) -> [f64; 9] {
    let mut out = [0.0; 9];
    for i in 0..3 {
        for j in 0..3 {
            out[3 * i + j] = m[(i, j)];
        }
    }
    out
}

/// The power of two r with `max_abs · r` in [1, 2) (1 for 0 or non-finite `max_abs`).
///
/// Multiplying by a power of two is exact, so a kernel that is homogeneous in a matrix (the
/// Sampson distances in F, the decomposition of A in A, the factorisation of E) gives the same
/// bits on `M · r` as on `M` whenever `M`'s products neither overflow nor underflow, and finite
/// answers when they would: this is how those kernels keep their scale invariance for any
/// finite input (docs/reliability.md, "Extreme magnitudes").
#[inline]
pub fn power_of_two_normalizer(max_abs: f64) -> f64 {
    if !(max_abs > 0.0 && max_abs.is_finite()) {
        return 1.0;
    }
    // The binary exponent; subnormals (exponent field 0) count as 2^-1023, which leaves their
    // scaled value in [2^-52, 1): still far from underflow.
    let e = ((max_abs.to_bits() >> 52) & 0x7ff) as i32 - 1023;
    // 2^-e in two exact factors, so that 2^1023 (e = -1023) is reachable.
    let half = -e / 2;
    2f64.powi(half) * 2f64.powi(-e - half)
}

/// The largest absolute entry.
#[inline]
pub fn max_abs<'a>(values: impl IntoIterator<Item = &'a f64>) -> f64 {
    values.into_iter().fold(0.0, |m, v| m.max(v.abs()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn row_round_trip_keeps_layout() {
        let row = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0];
        let ac = AffineCorrespondence::from_row(&row);
        assert_eq!(ac.x1, Vec2::new(1.0, 2.0));
        assert_eq!(ac.x2, Vec2::new(3.0, 4.0));
        // a12 is row 0, column 1: the layout is row-major.
        assert_eq!(ac.a[(0, 1)], 6.0);
        assert_eq!(ac.a[(1, 0)], 7.0);
        assert_eq!(ac.to_row(), row);
        assert_eq!(mat2_to_row(&ac.a), [5.0, 6.0, 7.0, 8.0]);
        let m = mat3_from_row(&[1., 2., 3., 4., 5., 6., 7., 8., 9.]);
        assert_eq!(m[(1, 2)], 6.0);
        assert_eq!(mat3_to_row(&m), [1., 2., 3., 4., 5., 6., 7., 8., 9.]);
    }

    #[test]
    fn the_normalizer_is_a_power_of_two_bringing_the_maximum_into_one_to_two() {
        for m in [
            1.0,
            1.5,
            3.0,
            1e-300,
            1e300,
            f64::MAX,
            0.75,
            f64::MIN_POSITIVE,
        ] {
            let r = power_of_two_normalizer(m);
            assert!((1.0..2.0).contains(&(m * r)), "{m:e}: {:e}", m * r);
            assert_eq!(r.log2().fract(), 0.0, "{m:e}: r = {r:e} is a power of two");
        }
        // Subnormals land in [2^-52, 1), far from underflow.
        let tiny = 5e-324 * power_of_two_normalizer(5e-324);
        assert!(tiny >= 2f64.powi(-52) && tiny < 1.0);
        assert_eq!(power_of_two_normalizer(0.0), 1.0);
        assert_eq!(power_of_two_normalizer(f64::NAN), 1.0);
    }
}
