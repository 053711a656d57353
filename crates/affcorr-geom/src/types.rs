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
}
