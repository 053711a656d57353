//! Samplers: which minimal sample to try next.
//!
//! - [`UniformSampler`]: every sample equally likely (classic RANSAC).
//! - [`ProsacSampler`]: PROSAC (Chum & Matas, CVPR 2005): draws first from the best-ranked data
//!   (e.g. by matcher certainty), growing the pool with the iteration count, so good data are
//!   tried early; it becomes uniform after enough iterations.

use rand::Rng;
use rand_pcg::Pcg64;

/// A source of minimal samples.
pub trait Sampler {
    /// Writes `sample.len()` distinct indices in `0..n` into `sample`.
    fn sample(&mut self, rng: &mut Pcg64, n: usize, sample: &mut [usize]);
}

/// Uniform sampling without replacement.
#[derive(Debug, Default, Clone, Copy)]
pub struct UniformSampler;

/// `sample.len()` distinct indices drawn uniformly from `0..pool` (rejection: samples are tiny).
#[inline]
fn draw_distinct(rng: &mut Pcg64, pool: usize, sample: &mut [usize]) {
    for i in 0..sample.len() {
        loop {
            let v = rng.random_range(0..pool);
            if !sample[..i].contains(&v) {
                sample[i] = v;
                break;
            }
        }
    }
}

impl Sampler for UniformSampler {
    fn sample(&mut self, rng: &mut Pcg64, n: usize, sample: &mut [usize]) {
        draw_distinct(rng, n, sample);
    }
}

/// PROSAC over data ranked by quality (best first).
#[derive(Debug, Clone)]
pub struct ProsacSampler {
    /// Data indices sorted by decreasing quality.
    order: Vec<usize>,
    m: usize,
    /// Iterations so far (t in the paper).
    t: usize,
    /// Current pool size (n in the paper).
    pool: usize,
    /// T_n (real-valued, eq. 3 of the paper) for the current pool.
    t_n: f64,
    /// T'_n: the iteration at which the pool grows.
    t_n_prime: usize,
    /// Iterations after which PROSAC is plain uniform sampling.
    max_growth: usize,
}

impl ProsacSampler {
    /// `quality[i]` ranks datum i (higher is better); `m` is the sample size. Ties keep the
    /// original order, so the sampler is deterministic.
    pub fn new(quality: &[f64], m: usize) -> Self {
        let mut order: Vec<usize> = (0..quality.len()).collect();
        order.sort_by(|&a, &b| quality[b].total_cmp(&quality[a]));
        let n = quality.len();
        // T_N: the number of uniform samples after which the growth schedule ends; 200k as in
        // the reference implementation of the paper.
        let max_growth = 200_000;
        // T_m = T_N · C(m, m) / C(N, m) = T_N Π_{i<m} (m − i)/(N − i).
        let mut t_n = max_growth as f64;
        for i in 0..m {
            t_n *= (m - i) as f64 / (n.max(m) - i) as f64;
        }
        Self {
            order,
            m,
            t: 0,
            pool: m.min(n),
            t_n,
            t_n_prime: 1,
            max_growth,
        }
    }
}

impl Sampler for ProsacSampler {
    fn sample(&mut self, rng: &mut Pcg64, n: usize, sample: &mut [usize]) {
        debug_assert_eq!(n, self.order.len());
        self.t += 1;
        if self.t > self.max_growth || self.pool >= n {
            draw_distinct(rng, n, sample);
            for s in sample.iter_mut() {
                *s = self.order[*s];
            }
            return;
        }
        // Grow the pool when t reaches T'_n (eqs. 3–4 of the paper).
        while self.t >= self.t_n_prime && self.pool < n {
            let next = self.t_n * (self.pool + 1) as f64 / (self.pool + 1 - self.m) as f64;
            self.t_n_prime += (next - self.t_n).ceil().max(1.0) as usize;
            self.t_n = next;
            self.pool += 1;
        }
        // Semi-random sample: m − 1 points from the first pool − 1, plus the pool's newest one.
        let (head, last) = sample.split_at_mut(self.m - 1);
        draw_distinct(rng, self.pool - 1, head);
        last[0] = self.pool - 1;
        for s in sample.iter_mut() {
            *s = self.order[*s];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn uniform_samples_are_distinct_and_in_range() {
        let mut rng = Pcg64::seed_from_u64(0);
        let mut s = [0usize; 5];
        let mut hits = [0usize; 7];
        for _ in 0..2000 {
            UniformSampler.sample(&mut rng, 7, &mut s);
            for (i, a) in s.iter().enumerate() {
                assert!(*a < 7 && !s[..i].contains(a));
                hits[*a] += 1;
            }
        }
        // Each index appears in 5/7 of the samples.
        assert!(
            hits.iter()
                .all(|&h| (h as f64 / 2000.0 - 5.0 / 7.0).abs() < 0.05),
            "{hits:?}"
        );
    }

    #[test]
    fn prosac_starts_with_the_best_ranked_data() {
        let quality: Vec<f64> = (0..1000).map(|i| -(i as f64)).collect();
        let mut p = ProsacSampler::new(&quality, 2);
        let mut rng = Pcg64::seed_from_u64(1);
        let mut s = [0usize; 2];
        p.sample(&mut rng, 1000, &mut s);
        // The pool starts at m + 1 (T'_m = 1, the paper's growth rule) and the newest member
        // is always in the sample.
        assert!(s.contains(&2) && s.iter().all(|&i| i < 3), "{s:?}");
        // Early samples stay among the top ranks; late ones cover everything.
        let mut max_early = 0;
        for _ in 0..50 {
            p.sample(&mut rng, 1000, &mut s);
            max_early = max_early.max(s[0].max(s[1]));
        }
        assert!(max_early < 200, "{max_early}");
        let mut max_late = 0;
        for _ in 0..300_000 {
            p.sample(&mut rng, 1000, &mut s);
            assert_ne!(s[0], s[1]);
            max_late = max_late.max(s[0].max(s[1]));
        }
        assert!(max_late > 900);
    }
}
