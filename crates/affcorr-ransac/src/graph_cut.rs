//! Graph-cut inlier labelling with spatial coherence, for local optimisation as in GC-RANSAC
//! (Barath & Matas, CVPR 2018).
//!
//! Inliers of a model tend to be close to other inliers: in the 4-D space of (x1, y1, x2, y2),
//! correspondences of one rigid motion form dense clusters, while outliers (random x2) are
//! scattered. The labelling L ∈ {inlier, outlier}ᴺ minimises
//!
//! E(L) = Σ_p D_p(L_p) + λ Σ_{(p,q) ∈ 𝒩} [L_p ≠ L_q],
//!
//! with D_p(inlier) = 1 − K(r_p), D_p(outlier) = K(r_p) and the kernel K(r) = 2^(−r²/τ²), so that
//! alone, a datum is an inlier exactly when r < τ (K(τ) = 1/2); its neighbours pull data just
//! beyond τ in and push isolated data just below it out. E is submodular (Potts on two labels)
//! and its exact minimum is a minimum s–t cut (Kolmogorov & Zabih, PAMI 2004): an arc s → p of
//! capacity max(D_p(out) − D_p(in), 0), an arc p → t of capacity max(D_p(in) − D_p(out), 0),
//! and arcs p ↔ q of capacity λ; the inliers are the nodes still reachable from s after a
//! maximum flow.
//!
//! - Neighbourhood 𝒩: the grid graph of GC-RANSAC and MAGSAC++ — the bounding box of the data
//!   in each of the 4 coordinates split into [`CELLS`] cells; data in the same 4-D cell are
//!   neighbours (each joined to the next [`MAX_NEIGHBOURS`] in index order, so a crowded cell
//!   costs O(N), not O(N²)). Built once per estimation in O(N log N).
//! - Maximum flow: Dinic's algorithm (blocking flows on BFS level graphs, O(V²E) at worst; a
//!   few BFS phases here, since every s–t path has 2 or 3 arcs plus neighbour hops). No max-flow
//!   crate is in the workspace's dependency tree and the graphs are small (N + 2 nodes, ≤ 3N +
//!   [`MAX_NEIGHBOURS`]·N arcs), so a compact implementation over flat arrays is used: every
//!   buffer is allocated once, and each labelling only resets capacities.
//! - λ = [`COHERENCE`]: with at most 2·[`MAX_NEIGHBOURS`] neighbours a datum's neighbours can
//!   outweigh at most 2·4·0.05 = 0.4 of its data term, so only data with K(r) > 0.3
//!   (r < 1.32τ) can be pulled in, and only data with K(r) < 0.7 (r > 0.72τ) pushed out.

use affcorr_geom::Vec2;

/// Cells per coordinate of the neighbourhood grid (GC-RANSAC's default).
pub const CELLS: usize = 8;
/// Each datum is joined to at most this many later data of its cell.
pub const MAX_NEIGHBOURS: usize = 4;
/// λ, the weight of a neighbour with another label.
pub const COHERENCE: f64 = 0.05;

/// Arc capacities below this are treated as saturated.
const EPS: f64 = 1e-12;

/// The neighbourhood graph and the max-flow buffers of one estimation.
pub struct GraphCut {
    n: usize,
    /// CSR arcs: node u's arcs are `first[u]..first[u + 1]`.
    first: Vec<usize>,
    head: Vec<usize>,
    /// Index of the reverse arc.
    reverse: Vec<usize>,
    capacity: Vec<f64>,
    /// Arc s → p and arc p → t of datum p.
    source_arc: Vec<usize>,
    sink_arc: Vec<usize>,
    level: Vec<u32>,
    next_arc: Vec<usize>,
    queue: Vec<usize>,
    /// (arc index, node) of the current DFS path.
    stack: Vec<(usize, usize)>,
}

/// Grid cell of a value in [lo, lo + span].
fn cell(v: f64, lo: f64, span: f64) -> usize {
    (((v - lo) / span * CELLS as f64) as usize).min(CELLS - 1)
}

impl GraphCut {
    /// The grid neighbourhood graph of the correspondences (x1\[i\], x2\[i\]).
    pub fn new(x1: &[Vec2], x2: &[Vec2]) -> Self {
        let n = x1.len();
        let coords = |i: usize| [x1[i].x, x1[i].y, x2[i].x, x2[i].y];
        let (mut lo, mut hi) = ([f64::INFINITY; 4], [f64::NEG_INFINITY; 4]);
        for i in 0..n {
            for (d, v) in coords(i).into_iter().enumerate() {
                lo[d] = lo[d].min(v);
                hi[d] = hi[d].max(v);
            }
        }
        let span: [f64; 4] = std::array::from_fn(|d| (hi[d] - lo[d]).max(1e-9));
        let key = |i: usize| {
            coords(i)
                .into_iter()
                .enumerate()
                .fold(0, |k, (d, v)| k * CELLS + cell(v, lo[d], span[d]))
        };
        let mut order: Vec<(usize, usize)> = (0..n).map(|i| (key(i), i)).collect();
        order.sort_unstable();
        let mut pairs = Vec::new();
        for (a, &(ka, i)) in order.iter().enumerate() {
            for &(kb, j) in order[a + 1..].iter().take(MAX_NEIGHBOURS) {
                if kb != ka {
                    break;
                }
                pairs.push((i, j));
            }
        }
        // Nodes 0..n are the data, n the source, n + 1 the sink. Arc list: for each datum the
        // pair (s → p, p → s), the pair (p → t, t → p); for each neighbour pair (p → q, q → p).
        let (s, t) = (n, n + 1);
        let mut arcs: Vec<(usize, usize)> = Vec::with_capacity(4 * n + 2 * pairs.len());
        for p in 0..n {
            arcs.extend([(s, p), (p, s), (p, t), (t, p)]);
        }
        for &(p, q) in &pairs {
            arcs.extend([(p, q), (q, p)]);
        }
        // CSR by tail node, keeping the arc list's order within a node (deterministic).
        let mut first = vec![0usize; n + 3];
        for &(u, _) in &arcs {
            first[u + 1] += 1;
        }
        for u in 0..n + 2 {
            first[u + 1] += first[u];
        }
        let mut fill = first.clone();
        let mut position = vec![0usize; arcs.len()];
        let mut head = vec![0usize; arcs.len()];
        for (a, &(u, v)) in arcs.iter().enumerate() {
            position[a] = fill[u];
            head[fill[u]] = v;
            fill[u] += 1;
        }
        // Arcs come in (forward, reverse) pairs at even/odd list positions.
        let mut reverse = vec![0usize; arcs.len()];
        for a in 0..arcs.len() {
            reverse[position[a]] = position[a ^ 1];
        }
        let mut capacity = vec![0.0; arcs.len()];
        for k in 0..pairs.len() {
            capacity[position[4 * n + 2 * k]] = COHERENCE;
            capacity[position[4 * n + 2 * k + 1]] = COHERENCE;
        }
        Self {
            n,
            first,
            head,
            reverse,
            capacity,
            source_arc: (0..n).map(|p| position[4 * p]).collect(),
            sink_arc: (0..n).map(|p| position[4 * p + 2]).collect(),
            level: vec![0; n + 2],
            next_arc: vec![0; n + 2],
            queue: Vec::with_capacity(n + 2),
            stack: Vec::with_capacity(n + 2),
        }
    }

    /// Number of neighbour pairs in the graph.
    pub fn edges(&self) -> usize {
        (self.head.len() - 4 * self.n) / 2
    }

    /// The minimum-energy labelling for squared residuals `r2` at squared threshold
    /// `threshold_sq`: pushes the indices of the inliers (ascending) into `inliers`.
    pub fn label(&mut self, r2: &[f64], threshold_sq: f64, inliers: &mut Vec<usize>) {
        debug_assert_eq!(r2.len(), self.n);
        let n = self.n;
        // Reset: neighbour arcs back to λ, terminal arcs from the data term.
        for p in 0..n {
            for a in self.first[p]..self.first[p + 1] {
                if self.head[a] < n {
                    self.capacity[a] = COHERENCE;
                }
            }
        }
        for (p, &r) in r2.iter().enumerate() {
            // NaN residuals (degenerate models) give K = 0: outliers.
            let k = if r.is_nan() {
                0.0
            } else {
                (-r / threshold_sq).exp2()
            };
            let (d_in, d_out) = (1.0 - k, k);
            let (sa, ta) = (self.source_arc[p], self.sink_arc[p]);
            self.capacity[sa] = (d_out - d_in).max(0.0);
            self.capacity[self.reverse[sa]] = 0.0;
            self.capacity[ta] = (d_in - d_out).max(0.0);
            self.capacity[self.reverse[ta]] = 0.0;
        }
        while self.bfs() {
            self.next_arc.copy_from_slice(&self.first[..n + 2]);
            while self.augment() {}
        }
        // The source side of the minimum cut: nodes with a level after the last (failed) BFS.
        inliers.clear();
        inliers.extend((0..n).filter(|&p| self.level[p] != u32::MAX));
    }

    /// Levels of the residual graph from the source; true if the sink is reachable.
    fn bfs(&mut self) -> bool {
        let (s, t) = (self.n, self.n + 1);
        self.level.fill(u32::MAX);
        self.level[s] = 0;
        self.queue.clear();
        self.queue.push(s);
        let mut k = 0;
        while k < self.queue.len() {
            let u = self.queue[k];
            k += 1;
            for a in self.first[u]..self.first[u + 1] {
                let v = self.head[a];
                if self.capacity[a] > EPS && self.level[v] == u32::MAX {
                    self.level[v] = self.level[u] + 1;
                    self.queue.push(v);
                }
            }
        }
        self.level[t] != u32::MAX
    }

    /// One augmenting path along the level graph (iterative DFS with per-node arc pointers, so
    /// a blocking flow costs O(VE) per phase); false when none is left.
    fn augment(&mut self) -> bool {
        let (s, t) = (self.n, self.n + 1);
        self.stack.clear();
        let mut u = s;
        loop {
            if u == t {
                let bottleneck = self
                    .stack
                    .iter()
                    .map(|&(a, _)| self.capacity[a])
                    .fold(f64::INFINITY, f64::min);
                for &(a, _) in &self.stack {
                    self.capacity[a] -= bottleneck;
                    self.capacity[self.reverse[a]] += bottleneck;
                }
                return true;
            }
            let end = self.first[u + 1];
            let mut advanced = false;
            while self.next_arc[u] < end {
                let a = self.next_arc[u];
                let v = self.head[a];
                if self.capacity[a] > EPS && self.level[v] == self.level[u] + 1 {
                    self.stack.push((a, u));
                    u = v;
                    advanced = true;
                    break;
                }
                self.next_arc[u] += 1;
            }
            if !advanced {
                // Dead end: retreat and skip the arc that led here.
                let Some((_, parent)) = self.stack.pop() else {
                    return false;
                };
                self.level[u] = u32::MAX - 1;
                u = parent;
                self.next_arc[u] += 1;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The energy of a labelling, for brute force.
    fn energy(g: &GraphCut, r2: &[f64], thr_sq: f64, inlier: &[bool]) -> f64 {
        let mut e = 0.0;
        for (p, &r) in r2.iter().enumerate() {
            let k = (-r / thr_sq).exp2();
            e += if inlier[p] { 1.0 - k } else { k };
        }
        for p in 0..g.n {
            for a in g.first[p]..g.first[p + 1] {
                let q = g.head[a];
                if q < g.n && p < q && inlier[p] != inlier[q] {
                    e += COHERENCE;
                }
            }
        }
        e
    }

    fn line(n: usize) -> (Vec<Vec2>, Vec<Vec2>) {
        // All in one cell: x spans 0..1 of a box stretched to 100 by a far point.
        let mut x1: Vec<Vec2> = (0..n).map(|i| Vec2::new(i as f64 * 0.1, 0.0)).collect();
        let mut x2 = x1.clone();
        x1.push(Vec2::new(100.0, 100.0));
        x2.push(Vec2::new(100.0, 100.0));
        (x1, x2)
    }

    #[test]
    fn the_cut_is_the_minimum_energy_labelling() {
        let (x1, x2) = line(9);
        let mut g = GraphCut::new(&x1, &x2);
        assert!(g.edges() > 0);
        let mut rng_state = 7u64;
        let mut inliers = Vec::new();
        for _ in 0..50 {
            let r2: Vec<f64> = (0..10)
                .map(|_| {
                    rng_state = rng_state.wrapping_mul(6364136223846793005).wrapping_add(1);
                    (rng_state >> 11) as f64 / (1u64 << 53) as f64 * 3.0
                })
                .collect();
            g.label(&r2, 1.0, &mut inliers);
            let mut found = vec![false; 10];
            for &i in &inliers {
                found[i] = true;
            }
            let best = (0..1u32 << 10)
                .map(|m| {
                    let l: Vec<bool> = (0..10).map(|b| m >> b & 1 == 1).collect();
                    energy(&g, &r2, 1.0, &l)
                })
                .fold(f64::INFINITY, f64::min);
            let e = energy(&g, &r2, 1.0, &found);
            assert!((e - best).abs() < 1e-9, "{e} vs {best}");
        }
    }

    #[test]
    fn neighbours_pull_in_a_datum_just_beyond_the_threshold() {
        let (x1, x2) = line(9);
        let mut g = GraphCut::new(&x1, &x2);
        let mut r2 = vec![0.1; 10];
        r2[4] = 1.2; // alone it would be an outlier (K < 1/2)
        r2[9] = 50.0; // the far point, alone in its cell
        let mut inliers = Vec::new();
        g.label(&r2, 1.0, &mut inliers);
        assert_eq!(inliers, vec![0, 1, 2, 3, 4, 5, 6, 7, 8]);
        // Far beyond the threshold, neighbours cannot pull it in.
        r2[4] = 9.0;
        g.label(&r2, 1.0, &mut inliers);
        assert_eq!(inliers, vec![0, 1, 2, 3, 5, 6, 7, 8]);
    }
}
