//! Blocked, vectorisable accumulation for the least-squares kernels, and the run-time choice
//! of AVX2 for them.
//!
//! A kernel gathers [`BLOCK`] data into structure-of-arrays buffers, computes residuals and
//! gradients lane by lane (branch-free, so the compiler vectorises the loop) and accumulates
//! its sums as dot products over the block into [`Lanes`], which stay 4 partial sums until the
//! kernel has visited all its data. Wheels target baseline x86-64 (SSE2, 2 lanes
//! of f64); [`dispatch`] runs the same code compiled for AVX2 (4 lanes) where the CPU has it.

/// Data per block.
pub(crate) const BLOCK: usize = 16;

/// The upper triangle (00, 01, 02, 11, 12, 22) of a symmetric 3×3 matrix: the order in which
/// the kernels keep such sums.
pub(crate) const UPPER_3X3: [(usize, usize); 6] = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];

/// One sum kept as 4 interleaved partial sums, which the compiler maps onto SIMD lanes. A
/// kernel adds a block's dot products with [`Lanes::add_dot`] and reduces once, after its last
/// block ([`Lanes::sum`]): a block then costs the multiply–adds only, not a horizontal
/// reduction and a scalar update per sum.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Lanes([f64; 4]);

impl Lanes {
    /// Adds Σⱼ aⱼ bⱼ over the block.
    #[inline(always)]
    pub(crate) fn add_dot(&mut self, a: &[f64; BLOCK], b: &[f64; BLOCK]) {
        for j in (0..BLOCK).step_by(4) {
            for l in 0..4 {
                self.0[l] += a[j + l] * b[j + l];
            }
        }
    }

    /// The sum of the partial sums.
    #[inline(always)]
    pub(crate) fn sum(&self) -> f64 {
        (self.0[0] + self.0[1]) + (self.0[2] + self.0[3])
    }
}

/// Adds each of `lanes`' sums to the matching entry of `out`.
#[inline(always)]
pub(crate) fn add_sums<const N: usize>(out: &mut [f64; N], lanes: &[Lanes; N]) {
    for (o, l) in out.iter_mut().zip(lanes) {
        *o += l.sum();
    }
}

/// Runs `kernel` compiled for AVX2 when the CPU has it, else as built. The kernel must be an
/// `#[inline(always)]` closure so that it is compiled inside the AVX2 function.
#[inline(always)]
pub(crate) fn dispatch<R>(kernel: impl FnOnce() -> R) -> R {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // The crate's one unsafe call. SAFETY: the CPU supports AVX2 (checked just above),
        // the only requirement of calling a `#[target_feature(enable = "avx2")]` function.
        #[allow(unsafe_code)]
        return unsafe { with_avx2(kernel) };
    }
    kernel()
}

/// The data of `indices` (1 to [`BLOCK`] of them) fetched by `at` into a block, the last one
/// repeated to fill it, so that kernels over data in random order (the SPRT's) run blocked and
/// vectorised too.
#[inline(always)]
pub(crate) fn gather<T>(indices: &[usize], at: impl Fn(usize) -> T) -> [T; BLOCK] {
    std::array::from_fn(|k| at(indices[k.min(indices.len() - 1)]))
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn with_avx2<R>(kernel: impl FnOnce() -> R) -> R {
    kernel()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lanes_sum_the_dot_products_of_every_block() {
        let block = |s: f64| -> [f64; BLOCK] { std::array::from_fn(|j| s * (j as f64 - 7.5)) };
        let (a, b, c) = (block(1.0), block(-0.5), block(2.0));
        let mut lanes = Lanes::default();
        lanes.add_dot(&a, &b);
        lanes.add_dot(&c, &c);
        let want: f64 = (0..BLOCK).map(|j| a[j] * b[j] + c[j] * c[j]).sum();
        assert!(
            (lanes.sum() - want).abs() < 1e-12 * want.abs(),
            "{} vs {want}",
            lanes.sum()
        );
        let mut out = [1.0, 2.0];
        add_sums(&mut out, &[lanes, Lanes::default()]);
        assert_eq!(out, [1.0 + lanes.sum(), 2.0]);
    }
}
