//! Real roots of univariate polynomials of degree ≤ [`MAX_DEGREE`], without allocation.
//!
//! Degrees 1–2 are closed form (the quadratic in its cancellation-free form). Higher degrees use
//! a Sturm sequence (Sturm's theorem: the number of distinct real roots in (a, b] is
//! V(a) − V(b), V = sign changes of the sequence p, p′, −rem(p, p′), …) to isolate each root in
//! an interval, then safeguarded Newton iterations (falling back to bisection) to refine it.
//! Coefficients are in ascending order: `c[0] + c[1]·x + … + c[d]·x^d`.

/// Largest supported degree (the 5-point essential solver needs 10).
pub const MAX_DEGREE: usize = 10;
const LEN: usize = MAX_DEGREE + 1;

/// p(x) by Horner's rule.
#[inline]
pub fn eval(c: &[f64], x: f64) -> f64 {
    c.iter().rev().fold(0.0, |acc, &v| acc * x + v)
}

/// p(x) and p′(x) together.
#[inline]
fn eval_with_derivative(c: &[f64], x: f64) -> (f64, f64) {
    let (mut p, mut dp) = (0.0, 0.0);
    for &v in c.iter().rev() {
        dp = dp * x + p;
        p = p * x + v;
    }
    (p, dp)
}

/// Writes the distinct real roots of the polynomial `c` (ascending coefficients, degree ≤
/// [`MAX_DEGREE`]) in ascending order into `roots` and returns how many there are. Leading
/// coefficients that vanish relative to the others are dropped; a zero polynomial has no roots.
/// `roots` must hold at least the degree's count.
pub fn real_roots(c: &[f64], roots: &mut [f64]) -> usize {
    assert!(c.len() <= LEN, "degree above MAX_DEGREE");
    let scale = c.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if !(scale > 0.0) || c.iter().any(|v| !v.is_finite()) {
        return 0;
    }
    let mut d = c.len() - 1;
    while d > 0 && c[d].abs() <= 1e-14 * scale {
        d -= 1;
    }
    match d {
        0 => 0,
        1 => {
            roots[0] = -c[0] / c[1];
            1
        }
        // Scaled to max |c_i| = 1: b² − 4ac of huge (or tiny) coefficients would overflow to
        // an infinite root (or underflow to a false double root); the roots do not change.
        2 => quadratic(c[2] / scale, c[1] / scale, c[0] / scale, roots),
        _ => sturm_roots(&c[..=d], roots),
    }
}

/// Roots of a x² + b x + c, a ≠ 0, ascending.
fn quadratic(a: f64, b: f64, c: f64, roots: &mut [f64]) -> usize {
    let disc = b * b - 4.0 * a * c;
    if disc < 0.0 {
        return 0;
    }
    if disc == 0.0 {
        roots[0] = -b / (2.0 * a);
        return 1;
    }
    // q = −(b + sign(b)√disc)/2 avoids cancellation; the roots are q/a and c/q.
    let q = -0.5 * (b + b.signum() * disc.sqrt());
    let (r0, r1) = if q == 0.0 { (0.0, 0.0) } else { (q / a, c / q) };
    roots[0] = r0.min(r1);
    roots[1] = r0.max(r1);
    2
}

/// Lanes of the transposed Sturm sequence (LEN rounded up to an even count for SIMD).
const LANES: usize = LEN + 1;

/// The Sturm sequence of `p`, stored transposed for evaluation: `t[i][k]` is the coefficient of
/// xⁱ in the k-th polynomial (zero above its degree and for k ≥ `len`), so all members are
/// evaluated together by one lane-parallel Horner scheme of `top + 1` steps.
struct Sturm {
    seq: [[f64; LEN]; LEN],
    deg: [usize; LEN],
    len: usize,
    t: [[f64; LANES]; LEN],
}

impl Sturm {
    fn new(p: &[f64]) -> Self {
        let mut s = Sturm {
            seq: [[0.0; LEN]; LEN],
            deg: [0; LEN],
            len: 2,
            t: [[0.0; LANES]; LEN],
        };
        let d = p.len() - 1;
        // Monic p keeps the remainders well scaled.
        let lead = p[d];
        for i in 0..=d {
            s.seq[0][i] = p[i] / lead;
        }
        s.deg[0] = d;
        for i in 1..=d {
            s.seq[1][i - 1] = s.seq[0][i] * i as f64 / d as f64;
        }
        s.deg[1] = d - 1;
        while s.deg[s.len - 1] > 0 {
            let k = s.len;
            let (prev2, prev1) = (s.seq[k - 2], s.seq[k - 1]);
            let (d2, d1) = (s.deg[k - 2], s.deg[k - 1]);
            // Remainder of prev2 / prev1 by long division.
            let mut r = prev2;
            for shift in (0..=d2 - d1).rev() {
                let q = r[shift + d1] / prev1[d1];
                for i in 0..=d1 {
                    r[shift + i] -= q * prev1[i];
                }
                r[shift + d1] = 0.0;
            }
            let mut rd = d1 - 1;
            let rscale = r[..d1].iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let pscale = prev1[..=d1].iter().fold(0.0f64, |m, v| m.max(v.abs()));
            if rscale <= 1e-13 * pscale {
                // p has a repeated root: the sequence ends at gcd(p, p′).
                break;
            }
            while rd > 0 && r[rd].abs() <= 1e-14 * rscale {
                rd -= 1;
            }
            // Negated remainder, normalised so its leading coefficient has magnitude 1.
            let norm = -1.0 / r[rd].abs();
            for i in 0..=rd {
                s.seq[k][i] = r[i] * norm;
            }
            s.deg[k] = rd;
            s.len += 1;
        }
        for k in 0..s.len {
            for i in 0..=s.deg[k] {
                s.t[i][k] = s.seq[k][i];
            }
        }
        s
    }

    /// Sign changes of the sequence at x.
    fn sign_changes(&self, x: f64) -> u32 {
        let mut acc = [0.0; LANES];
        for row in self.t[..=self.deg[0]].iter().rev() {
            for k in 0..LANES {
                acc[k] = acc[k] * x + row[k];
            }
        }
        let mut changes = 0;
        let mut last = 0.0f64;
        for &v in &acc[..self.len] {
            if v != 0.0 {
                if last != 0.0 && (v > 0.0) != (last > 0.0) {
                    changes += 1;
                }
                last = v;
            }
        }
        changes
    }
}

fn sturm_roots(p: &[f64], roots: &mut [f64]) -> usize {
    let d = p.len() - 1;
    let sturm = Sturm::new(p);
    let monic = &sturm.seq[0][..=d];
    // Fujiwara's bound: every root has |x| ≤ 2·max(|c_{d−k}/c_d|^{1/k}, |c_0/(2c_d)|^{1/d}),
    // far tighter than Cauchy's 1 + max |c_i/c_d| when the leading coefficient is small, which
    // saves bisection levels. Slightly enlarged so a root on the bound stays inside (lo, hi].
    // Each c^{1/k} is bounded by the power of two 2^⌈e/k⌉ with c < 2^e read off the exponent
    // bits (at most 2× looser, one more bisection level, but no `powf`).
    let mut exp = i32::MIN;
    for k in 1..=d {
        let c = if k == d {
            0.5 * monic[0].abs()
        } else {
            monic[d - k].abs()
        };
        if c > 0.0 {
            let e = ((c.to_bits() >> 52) & 0x7ff) as i32 - 1022;
            exp = exp.max(-((-e).div_euclid(k as i32)));
        }
    }
    let fujiwara = if exp == i32::MIN {
        0.0
    } else {
        2.0f64.powi(exp.min(1023))
    };
    let bound = 2.0 * fujiwara * (1.0 + 1e-10) + f64::MIN_POSITIVE;
    let (lo, hi) = (-bound, bound);
    let mut stack = [(0.0, 0.0, 0u32, 0u32, 0u32); 4 * LEN];
    stack[0] = (lo, hi, sturm.sign_changes(lo), sturm.sign_changes(hi), 0);
    let mut top = 1;
    let mut count = 0;
    while top > 0 {
        top -= 1;
        let (a, b, va, vb, depth) = stack[top];
        let n = va.saturating_sub(vb);
        if n == 0 {
            continue;
        }
        if n == 1 || depth > 60 {
            // Rounding can make the sign counts of a badly scaled sequence non-monotonic, so
            // that the leaves claim more roots than the degree (found by fuzzing): keep d.
            if count == d.min(roots.len()) {
                break;
            }
            roots[count] = refine(monic, a, b);
            count += 1;
            continue;
        }
        let m = 0.5 * (a + b);
        let vm = sturm.sign_changes(m);
        // Push the upper half first so roots come out ascending.
        if top + 2 <= stack.len() {
            stack[top] = (m, b, vm, vb, depth + 1);
            stack[top + 1] = (a, m, va, vm, depth + 1);
            top += 2;
        }
    }
    count
}

/// The single root of p in (a, b]: Newton steps kept inside a shrinking bracket, with a
/// bisection whenever Newton leaves the bracket or fails to halve the step (Numerical Recipes'
/// `rtsafe`). Without the fallback, Newton from far outside a root of a degree-d polynomial
/// only gains a factor (1 − 1/d) per step and can stop short of the root.
fn refine(p: &[f64], mut a: f64, mut b: f64) -> f64 {
    let fa = eval(p, a);
    if (fa > 0.0) == (eval(p, b) > 0.0) {
        // No sign change: a root of even multiplicity; plain Newton inside the bracket.
        return newton_even(p, a, b);
    }
    let mut x = 0.5 * (a + b);
    let mut step_old = b - a;
    let mut step = step_old;
    for _ in 0..200 {
        let (f, df) = eval_with_derivative(p, x);
        if f == 0.0 {
            return x;
        }
        // Keep the bracket: the root lies where the sign differs from p(a).
        if (f > 0.0) == (fa > 0.0) {
            a = x;
        } else {
            b = x;
        }
        let newton = x - f / df;
        let next =
            if df != 0.0 && newton > a && newton < b && (2.0 * f).abs() <= (step_old * df).abs() {
                step_old = step;
                newton
            } else {
                step_old = step;
                0.5 * (a + b)
            };
        step = next - x;
        // A Newton step of relative size 1e-11 leaves an error of order its square: converged.
        if step.abs() <= 1e-11 * x.abs().max(1e-300) || b - a <= 1e-15 * a.abs().max(b.abs()) {
            return next;
        }
        x = next;
    }
    x
}

/// Newton steps for a root of even multiplicity in (a, b) (no sign change to bracket on).
fn newton_even(p: &[f64], a: f64, b: f64) -> f64 {
    let mut x = 0.5 * (a + b);
    for _ in 0..100 {
        let (f, df) = eval_with_derivative(p, x);
        if f == 0.0 || df == 0.0 {
            return x;
        }
        let next = x - f / df;
        if !(next > a && next < b) || (next - x).abs() <= 1e-15 * x.abs().max(1e-300) {
            return x;
        }
        x = next;
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Ascending coefficients of Π (x − r_i).
    fn from_roots(r: &[f64]) -> Vec<f64> {
        let mut c = vec![1.0];
        for &root in r {
            let mut next = vec![0.0; c.len() + 1];
            for (i, &v) in c.iter().enumerate() {
                next[i + 1] += v;
                next[i] -= root * v;
            }
            c = next;
        }
        c
    }

    #[test]
    fn finds_all_real_roots_of_products_of_linear_factors() {
        let cases: &[&[f64]] = &[
            &[2.0],
            &[-1.0, 3.0],
            &[-3.0, 0.5, 2.0],
            &[-2.0, -1.0, 0.25, 1.0, 4.0],
            &[-5.0, -3.3, -1.0, -0.1, 0.2, 0.7, 1.5, 2.5, 3.0, 9.0],
        ];
        for &r in cases {
            let c = from_roots(r);
            let mut out = [0.0; MAX_DEGREE];
            let n = real_roots(&c, &mut out);
            assert_eq!(n, r.len(), "{r:?}");
            let mut sorted = r.to_vec();
            sorted.sort_by(f64::total_cmp);
            for (got, want) in out[..n].iter().zip(&sorted) {
                assert!(
                    (got - want).abs() < 1e-9 * want.abs().max(1.0),
                    "{got} vs {want}"
                );
            }
        }
    }

    #[test]
    fn complex_pairs_are_skipped() {
        // (x² + 1)(x − 2)(x² + 4x + 5)(x + 0.5)
        let mut c = from_roots(&[2.0, -0.5]);
        for quad in [[1.0, 0.0, 1.0], [5.0, 4.0, 1.0]] {
            let mut next = vec![0.0; c.len() + 2];
            for (i, &v) in c.iter().enumerate() {
                for (j, &q) in quad.iter().enumerate() {
                    next[i + j] += v * q;
                }
            }
            c = next;
        }
        let mut out = [0.0; MAX_DEGREE];
        let n = real_roots(&c, &mut out);
        assert_eq!(n, 2);
        assert!((out[0] + 0.5).abs() < 1e-12 && (out[1] - 2.0).abs() < 1e-12);
    }

    #[test]
    fn far_bracket_converges_to_the_root() {
        // A degree-10 polynomial whose root 2.986 sits in a wide isolating interval: plain
        // Newton from the far end crawled and stopped at 922 before the rtsafe fallback.
        let c = [
            425.15352889230576,
            658.8647576002148,
            501.4546422350122,
            165.03983660181433,
            -8.737505784117275,
            -20.658643927871772,
            -5.526756405254943,
            -0.6775556426820017,
            -0.044444573885050076,
            -0.0010626015839927394,
            -9.368976332859227e-6,
        ];
        let mut out = [0.0; MAX_DEGREE];
        let n = real_roots(&c, &mut out);
        let want = [-3.85000257, -3.12661275, -2.8866058, 2.98644909];
        assert_eq!(n, 4, "{:?}", &out[..n]);
        for (got, w) in out[..n].iter().zip(want) {
            assert!((got - w).abs() < 1e-7, "{got} vs {w}");
            assert!(eval(&c, *got).abs() < 1e-9);
        }
    }

    #[test]
    fn degenerate_inputs() {
        let mut out = [0.0; MAX_DEGREE];
        assert_eq!(real_roots(&[0.0, 0.0, 0.0], &mut out), 0);
        assert_eq!(real_roots(&[f64::NAN, 1.0], &mut out), 0);
        assert_eq!(real_roots(&[1.0, 0.0, 1.0], &mut out), 0);
        // A vanishing leading coefficient lowers the degree.
        assert_eq!(real_roots(&[-4.0, 2.0, 0.0, 0.0], &mut out), 1);
        assert!((out[0] - 2.0).abs() < 1e-15);
        // A double root is found once.
        let n = real_roots(&from_roots(&[1.0, 1.0, 3.0]), &mut out);
        assert!(n >= 1 && out[..n].iter().any(|r| (r - 1.0).abs() < 1e-6));
    }

    #[test]
    fn never_more_roots_than_the_degree() {
        // Found by fuzzing (fuzz/ solvers, through relative_pose_2ac on absurd ACs): rounding
        // made the Sturm sign counts non-monotonic, the bisection leaves claimed 11 roots of
        // this degree-10 polynomial, and the 11th was written past `roots` (out of bounds).
        let c = [
            0.05278499815808909,
            3.284409168811942,
            -16.189001686608805,
            9.411998261010933,
            57.5066543087667,
            -77.6555726653874,
            -47.39870138176423,
            107.19433015151657,
            -7.869398593989665,
            -30.080363355967165,
            0.44782765205510344,
        ];
        let mut out = [0.0; MAX_DEGREE];
        let n = real_roots(&c, &mut out);
        assert!(n <= MAX_DEGREE, "{n} roots");
        assert!(
            out[..n]
                .iter()
                .all(|r| r.is_finite() && eval(&c, *r).abs() < 1e-6 * 300.0)
        );
    }

    #[test]
    fn quadratics_with_huge_or_tiny_coefficients_keep_finite_roots() {
        // Found by fuzzing (fuzz/ solvers): b² overflowed, giving the roots [-inf, 0].
        let mut out = [0.0; MAX_DEGREE];
        for k in [1e200, 1e-200] {
            let c = from_roots(&[-3.0, 0.5])
                .iter()
                .map(|v| v * k)
                .collect::<Vec<_>>();
            assert_eq!(real_roots(&c, &mut out), 2, "scale {k}");
            assert!(
                (out[0] + 3.0).abs() < 1e-12 && (out[1] - 0.5).abs() < 1e-12,
                "{out:?}"
            );
        }
        // 1e150 x² + 1e160 x + 1e150 (b² overflows): roots near -1e10 and -1e-10.
        assert_eq!(real_roots(&[1e150, 1e160, 1e150], &mut out), 2);
        assert!((out[0] / -1e10 - 1.0).abs() < 1e-12, "{:?}", &out[..2]);
        assert!((out[1] / -1e-10 - 1.0).abs() < 1e-12, "{:?}", &out[..2]);
    }
}
