//! Blocked, vectorisable accumulation for the least-squares kernels, and the run-time choice
//! of AVX2 for them.
//!
//! A kernel gathers [`BLOCK`] data into structure-of-arrays buffers, computes residuals and
//! gradients lane by lane (branch-free, so the compiler vectorises the loop) and accumulates
//! its sums as [`dot`] products over the block. Wheels target baseline x86-64 (SSE2, 2 lanes
//! of f64); [`dispatch`] runs the same code compiled for AVX2 (4 lanes) where the CPU has it.

/// Data per block.
pub(crate) const BLOCK: usize = 16;

/// The upper triangle (00, 01, 02, 11, 12, 22) of a symmetric 3×3 matrix: the order in which
/// the kernels keep such sums.
pub(crate) const UPPER_3X3: [(usize, usize); 6] = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];

/// Σ aⱼ bⱼ in 4 interleaved partial sums, which the compiler maps onto SIMD lanes.
#[inline(always)]
pub(crate) fn dot(a: &[f64; BLOCK], b: &[f64; BLOCK]) -> f64 {
    let mut acc = [0.0; 4];
    for j in (0..BLOCK).step_by(4) {
        for l in 0..4 {
            acc[l] += a[j + l] * b[j + l];
        }
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3])
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

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn with_avx2<R>(kernel: impl FnOnce() -> R) -> R {
    kernel()
}
