//! What the fuzz targets share: a reader that turns the fuzzer's bytes into the numbers the
//! geometry code sees, and the sanity checks on what comes back.

use affcorr_geom::{AffineCorrespondence, Mat2, Mat3, Vec2};

/// Values that break numerical code: signed zeros, NaN, infinities, the extremes of f64,
/// subnormals, and numbers whose squares or products overflow.
const SPECIAL: [f64; 16] = [
    0.0,
    -0.0,
    1.0,
    -1.0,
    f64::NAN,
    f64::INFINITY,
    f64::NEG_INFINITY,
    f64::MAX,
    f64::MIN,
    f64::MIN_POSITIVE,
    5e-324,
    1e-300,
    1e154,
    -1e154,
    1e300,
    f64::EPSILON,
];

/// Reads numbers from fuzz input; past its end every read is 0 (or false).
pub struct Reader<'a> {
    data: &'a [u8],
}

impl<'a> Reader<'a> {
    /// A reader of `data`.
    pub fn new(data: &'a [u8]) -> Self {
        Self { data }
    }

    /// The next byte (0 past the end).
    pub fn u8(&mut self) -> u8 {
        match self.data.split_first() {
            Some((&b, rest)) => {
                self.data = rest;
                b
            }
            None => 0,
        }
    }

    /// The next little-endian u64 from 8 bytes.
    pub fn u64(&mut self) -> u64 {
        let mut b = [0u8; 8];
        for v in &mut b {
            *v = self.u8();
        }
        u64::from_le_bytes(b)
    }

    /// A bool from one byte.
    pub fn bool(&mut self) -> bool {
        self.u8() & 1 == 1
    }

    /// An f64 of one of four kinds chosen by a tag byte, so that the fuzzer reaches both
    /// plausible geometry and hostile values: a raw bit pattern (any NaN payload, subnormals,
    /// infinities), a pixel-like value (i16 / 8: coordinates up to ±4096 in 1/8 px), one of
    /// [`SPECIAL`], or a small integer (which repeats, making duplicate and collinear points).
    pub fn f64(&mut self) -> f64 {
        match self.u8() % 4 {
            0 => f64::from_bits(self.u64()),
            1 => f64::from(i16::from_le_bytes([self.u8(), self.u8()])) / 8.0,
            2 => SPECIAL[usize::from(self.u8()) % SPECIAL.len()],
            _ => f64::from(self.u8() as i8),
        }
    }

    /// A point.
    pub fn vec2(&mut self) -> Vec2 {
        Vec2::new(self.f64(), self.f64())
    }

    /// A 2×2 matrix.
    pub fn mat2(&mut self) -> Mat2 {
        Mat2::new(self.f64(), self.f64(), self.f64(), self.f64())
    }

    /// A 3×3 matrix.
    pub fn mat3(&mut self) -> Mat3 {
        Mat3::from_fn(|_, _| self.f64())
    }

    /// An AC.
    pub fn ac(&mut self) -> AffineCorrespondence {
        AffineCorrespondence {
            x1: self.vec2(),
            x2: self.vec2(),
            a: self.mat2(),
        }
    }

    /// `n` points.
    pub fn points(&mut self, n: usize) -> Vec<Vec2> {
        (0..n).map(|_| self.vec2()).collect()
    }

    /// `n` ACs.
    pub fn acs(&mut self, n: usize) -> Vec<AffineCorrespondence> {
        (0..n).map(|_| self.ac()).collect()
    }

    /// True when the input is used up.
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }
}

/// Panics (a fuzz finding) unless every entry of `m` is finite; `what` names the model.
pub fn assert_finite(m: &Mat3, what: &str) {
    assert!(
        m.iter().all(|v| v.is_finite()),
        "{what} has a non-finite entry: {m}"
    );
}
