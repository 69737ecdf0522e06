//! The pairwise-consistency graph of correspondences and its maximum clique
//! (TEASER++, Yang, Shi, Carlone 2020, §V; KISS-Matcher's k-core pruning).
//!
//! Two correspondences `(s_i, t_i)`, `(s_j, t_j)` are consistent when a rigid
//! motion could map both, up to the noise bound `β` on each point:
//! `| |s_i − s_j| − |t_i − t_j| | ≤ 2β`. With gravity (`max_tilt_rad` set),
//! a rotation about the vertical also keeps height differences:
//! `|(s_i − s_j)_z − (t_i − t_j)_z| ≤ 2β + |s_i − s_j|_xy sin(2 tilt)`, which
//! removes most of the chance consistencies of a flat site.
//!
//! True correspondences are all pairwise consistent, so they form a clique;
//! outliers are consistent with each other only by chance, so their cliques
//! stay small. The maximum clique is found exactly by branch and bound
//! (Tomita's greedy-colouring bound) over the vertices in degeneracy order,
//! skipping vertices whose core number cannot beat the best clique so far;
//! a node budget bounds the worst case (the result is then the best clique
//! found, flagged as not proven maximum).

use nalgebra::Vector3;
use rayon::prelude::*;

/// An undirected graph as sorted adjacency lists, plus an adjacency bit
/// matrix for constant-time edge tests when it is small enough.
#[derive(Debug, Clone)]
pub struct Graph {
    pub adj: Vec<Vec<u32>>,
    /// Row-major `n × n` bits (`words` u64 per row), for n ≤ [`DENSE_MAX`].
    dense: Option<(usize, Vec<u64>)>,
}

/// Largest vertex count with a dense adjacency matrix (20 000² bits = 50 MB).
pub const DENSE_MAX: usize = 20_000;

impl Graph {
    /// A graph from adjacency lists (sorted here).
    pub fn new(mut adj: Vec<Vec<u32>>) -> Graph {
        adj.iter_mut().for_each(|a| a.sort_unstable());
        let n = adj.len();
        let dense = (n <= DENSE_MAX).then(|| {
            let words = n.div_ceil(64);
            let mut bits = vec![0u64; n * words];
            for (a, row) in adj.iter().enumerate() {
                for &b in row {
                    bits[a * words + b as usize / 64] |= 1 << (b % 64);
                }
            }
            (words, bits)
        });
        Graph { adj, dense }
    }

    pub fn len(&self) -> usize {
        self.adj.len()
    }

    pub fn is_empty(&self) -> bool {
        self.adj.is_empty()
    }

    pub fn edges(&self) -> usize {
        self.adj.iter().map(Vec::len).sum::<usize>() / 2
    }

    #[inline]
    pub fn has_edge(&self, a: u32, b: u32) -> bool {
        match &self.dense {
            Some((words, bits)) => bits[a as usize * words + b as usize / 64] >> (b % 64) & 1 == 1,
            None => self.adj[a as usize].binary_search(&b).is_ok(),
        }
    }
}

/// The consistency graph of correspondences `src[k] ↔ tgt[k]`.
pub fn consistency_graph(
    src: &[Vector3<f64>],
    tgt: &[Vector3<f64>],
    noise_bound_m: f64,
    max_tilt_rad: Option<f64>,
) -> Graph {
    let n = src.len().min(tgt.len());
    let bound = 2.0 * noise_bound_m;
    let tilt_slope = max_tilt_rad.map(|t| (2.0 * t).min(std::f64::consts::FRAC_PI_2).sin());
    let adj = (0..n)
        .into_par_iter()
        .map(|i| {
            (0..n)
                .filter(|&j| {
                    if j == i {
                        return false;
                    }
                    let (ds, dt) = (src[i] - src[j], tgt[i] - tgt[j]);
                    if (ds.norm() - dt.norm()).abs() > bound {
                        return false;
                    }
                    match tilt_slope {
                        Some(slope) => (ds.z - dt.z).abs() <= bound + ds.xy().norm() * slope,
                        None => true,
                    }
                })
                .map(|j| j as u32)
                .collect()
        })
        .collect();
    Graph::new(adj)
}

/// A maximum clique of the subgraph of `active` vertices, and whether it is
/// proven maximum (false when `node_budget` branch-and-bound nodes ran out).
pub fn max_clique(g: &Graph, active: &[bool], node_budget: usize) -> (Vec<u32>, bool) {
    let n = g.len();
    let (order, core) = degeneracy_order(g, active);
    let mut pos = vec![usize::MAX; n];
    for (k, &v) in order.iter().enumerate() {
        pos[v as usize] = k;
    }
    let mut best = greedy_clique(g, active, &order, &core);
    let mut budget = Budget { left: node_budget, exhausted: false };
    let mut cand: Vec<u32> = Vec::new();
    // Later vertices in the degeneracy order have the larger cores, and each
    // vertex's later neighbours number at most its core: the subproblems
    // stay small.
    for &v in &order {
        let v_us = v as usize;
        if core[v_us] < best.len() || budget.exhausted {
            continue;
        }
        cand.clear();
        cand.extend(
            g.adj[v_us]
                .iter()
                .copied()
                .filter(|&u| active[u as usize] && pos[u as usize] > pos[v_us] && core[u as usize] >= best.len()),
        );
        if cand.len() < best.len() {
            continue;
        }
        let local = LocalGraph::new(g, &cand);
        let mut r = vec![v];
        let all = Bits::full(cand.len());
        expand(&local, &cand, &mut r, all, &mut best, &mut budget);
    }
    best.sort_unstable();
    (best, !budget.exhausted)
}

/// Vertices in the order of the k-core peeling (smallest degree removed
/// first) and every vertex's core number (0 for inactive vertices).
fn degeneracy_order(g: &Graph, active: &[bool]) -> (Vec<u32>, Vec<usize>) {
    let n = g.len();
    let mut deg: Vec<usize> =
        (0..n).map(|v| if active[v] { g.adj[v].iter().filter(|&&u| active[u as usize]).count() } else { 0 }).collect();
    let max_deg = deg.iter().copied().max().unwrap_or(0);
    let mut buckets: Vec<Vec<u32>> = vec![Vec::new(); max_deg + 1];
    for v in (0..n).filter(|&v| active[v]) {
        buckets[deg[v]].push(v as u32);
    }
    let mut removed = vec![false; n];
    let mut core = vec![0usize; n];
    let mut order = Vec::with_capacity(n);
    let mut k = 0;
    let mut d = 0;
    while d <= max_deg {
        let Some(v) = buckets[d].pop() else {
            d += 1;
            continue;
        };
        let vu = v as usize;
        // Lazy deletion: a vertex may sit in stale buckets.
        if removed[vu] || deg[vu] != d {
            continue;
        }
        removed[vu] = true;
        k = k.max(d);
        core[vu] = k;
        order.push(v);
        for &u in &g.adj[vu] {
            let uu = u as usize;
            if active[uu] && !removed[uu] && deg[uu] > 0 {
                deg[uu] -= 1;
                buckets[deg[uu]].push(u);
                d = d.min(deg[uu]);
            }
        }
    }
    (order, core)
}

/// A quick lower bound: grow a clique greedily from each of the highest-core
/// vertices, adding neighbours in decreasing core order.
fn greedy_clique(g: &Graph, active: &[bool], order: &[u32], core: &[usize]) -> Vec<u32> {
    let mut best: Vec<u32> = Vec::new();
    for &v in order.iter().rev().take(32) {
        let mut nbrs: Vec<u32> = g.adj[v as usize].iter().copied().filter(|&u| active[u as usize]).collect();
        nbrs.sort_by_key(|&u| std::cmp::Reverse(core[u as usize]));
        let mut clique = vec![v];
        for u in nbrs {
            if clique.iter().all(|&w| g.has_edge(u, w)) {
                clique.push(u);
            }
        }
        if clique.len() > best.len() {
            best = clique;
        }
    }
    best
}

struct Budget {
    left: usize,
    exhausted: bool,
}

/// A fixed-size bit set over the local candidate indices.
#[derive(Clone)]
struct Bits(Vec<u64>);

impl Bits {
    fn empty(n: usize) -> Bits {
        Bits(vec![0; n.div_ceil(64)])
    }
    fn full(n: usize) -> Bits {
        let mut b = Bits::empty(n);
        for i in 0..n {
            b.set(i);
        }
        b
    }
    fn set(&mut self, i: usize) {
        self.0[i / 64] |= 1 << (i % 64);
    }
    fn clear(&mut self, i: usize) {
        self.0[i / 64] &= !(1 << (i % 64));
    }
    fn and(&self, o: &Bits) -> Bits {
        Bits(self.0.iter().zip(&o.0).map(|(a, b)| a & b).collect())
    }
    fn is_empty(&self) -> bool {
        self.0.iter().all(|&w| w == 0)
    }
    fn first(&self) -> Option<usize> {
        self.0.iter().enumerate().find(|(_, w)| **w != 0).map(|(k, w)| k * 64 + w.trailing_zeros() as usize)
    }
}

/// The subgraph induced by a candidate set, as bit rows.
struct LocalGraph {
    rows: Vec<Bits>,
}

impl LocalGraph {
    fn new(g: &Graph, cand: &[u32]) -> LocalGraph {
        let rows = cand
            .iter()
            .map(|&a| {
                let mut b = Bits::empty(cand.len());
                for (k, &c) in cand.iter().enumerate() {
                    if g.has_edge(a, c) {
                        b.set(k);
                    }
                }
                b
            })
            .collect();
        LocalGraph { rows }
    }
}

/// Tomita's MCQ: colour the candidates greedily, then branch on them from
/// the highest colour down; `|R| + colour` bounds any clique through a vertex.
fn expand(g: &LocalGraph, cand: &[u32], r: &mut Vec<u32>, p: Bits, best: &mut Vec<u32>, budget: &mut Budget) {
    if budget.left == 0 {
        budget.exhausted = true;
        return;
    }
    budget.left -= 1;
    let (verts, colours) = colour_sort(g, &p);
    let mut p = p;
    for k in (0..verts.len()).rev() {
        if r.len() + colours[k] <= best.len() {
            return;
        }
        let v = verts[k];
        r.push(cand[v]);
        let np = p.and(&g.rows[v]);
        if np.is_empty() {
            if r.len() > best.len() {
                *best = r.clone();
            }
        } else {
            expand(g, cand, r, np, best, budget);
        }
        r.pop();
        p.clear(v);
        if budget.exhausted {
            return;
        }
    }
}

/// Greedy sequential colouring of `p`: vertices ordered by colour class, and
/// each one's colour number (1-based), ascending.
fn colour_sort(g: &LocalGraph, p: &Bits) -> (Vec<usize>, Vec<usize>) {
    let mut uncoloured = p.clone();
    let (mut verts, mut colours) = (Vec::new(), Vec::new());
    let mut colour = 0;
    while !uncoloured.is_empty() {
        colour += 1;
        let mut q = uncoloured.clone();
        while let Some(v) = q.first() {
            q.clear(v);
            uncoloured.clear(v);
            // Neighbours of v cannot share its colour.
            for (qw, nw) in q.0.iter_mut().zip(&g.rows[v].0) {
                *qw &= !nw;
            }
            verts.push(v);
            colours.push(colour);
        }
    }
    (verts, colours)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn random_graph(n: usize, p: f64, seed: u64) -> Graph {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut adj = vec![Vec::new(); n];
        for i in 0..n {
            for j in i + 1..n {
                if rng.random_bool(p) {
                    adj[i].push(j as u32);
                    adj[j].push(i as u32);
                }
            }
        }
        Graph::new(adj)
    }

    /// Size of a maximum clique by trying every subset (n ≤ 16).
    fn brute_force_size(g: &Graph) -> usize {
        let n = g.len();
        (0u32..1 << n)
            .filter(|&mask| {
                let vs: Vec<u32> = (0..n as u32).filter(|v| mask >> v & 1 == 1).collect();
                vs.iter().enumerate().all(|(k, &a)| vs[k + 1..].iter().all(|&b| g.has_edge(a, b)))
            })
            .map(|mask| mask.count_ones() as usize)
            .max()
            .unwrap_or(0)
    }

    fn is_clique(g: &Graph, c: &[u32]) -> bool {
        c.iter().enumerate().all(|(k, &a)| c[k + 1..].iter().all(|&b| g.has_edge(a, b)))
    }

    #[test]
    fn exact_on_small_random_graphs() {
        for seed in 0..60 {
            let p = [0.2, 0.5, 0.8][seed as usize % 3];
            let g = random_graph(14, p, seed);
            let (c, exact) = max_clique(&g, &vec![true; g.len()], usize::MAX);
            assert!(exact);
            assert!(is_clique(&g, &c), "seed {seed}: {c:?}");
            assert_eq!(c.len(), brute_force_size(&g), "seed {seed}");
        }
    }

    #[test]
    fn finds_a_planted_clique_and_respects_the_active_set() {
        let g = random_graph(600, 0.02, 7);
        let planted: Vec<u32> = (0..600).step_by(23).collect(); // 27 vertices
        let mut adj = g.adj.clone();
        for &a in &planted {
            for &b in &planted {
                if a != b && !g.has_edge(a, b) {
                    adj[a as usize].push(b);
                }
            }
        }
        let g = Graph::new(adj);
        let mut active = vec![true; g.len()];
        let (c, exact) = max_clique(&g, &active, 1_000_000);
        assert!(exact);
        assert_eq!(c, planted);
        for &v in &planted {
            active[v as usize] = false;
        }
        let (c, _) = max_clique(&g, &active, 1_000_000);
        assert!(c.len() < 8 && c.iter().all(|&v| active[v as usize]), "{c:?}");
    }

    #[test]
    fn core_numbers_match_the_definition() {
        // A 5-clique with a tail: cores 4 on the clique, 1 on the tail.
        let mut adj = vec![Vec::new(); 8];
        let mut edge = |a: usize, b: usize| {
            adj[a].push(b as u32);
            adj[b].push(a as u32);
        };
        for a in 0..5 {
            for b in a + 1..5 {
                edge(a, b);
            }
        }
        edge(4, 5);
        edge(5, 6);
        edge(6, 7);
        let (order, core) = degeneracy_order(&Graph::new(adj), &[true; 8]);
        assert_eq!(order.len(), 8);
        assert_eq!(core, vec![4, 4, 4, 4, 4, 1, 1, 1]);
    }
}
