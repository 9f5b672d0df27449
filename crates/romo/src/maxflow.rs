//! Minimum s–t cut by maximum flow: Boykov & Kolmogorov's augmenting-path
//! algorithm ("An Experimental Comparison of Min-Cut/Max-Flow Algorithms
//! for Energy Minimization in Vision", TPAMI 2004), with two search trees
//! (from the source and from the sink) that are reused between
//! augmentations, orphan adoption, and the timestamp / distance heuristic
//! for choosing new parents. Capacities are integers, so the search always
//! terminates and the cut is exact.
//!
//! [`Network`] keeps the compressed graph for repeated cuts with new
//! terminal capacities, each starting from the previous flow.
//!
//! Used by [`crate::objects`] for the graph-cut object refinement: one node
//! per grid pixel and frame, terminal edges from the unary evidence, edges
//! between neighbouring pixels and along the flow between frames.

use std::collections::VecDeque;

const NONE: u32 = u32::MAX;
const TERMINAL: u32 = u32::MAX - 1;
const ORPHAN: u32 = u32::MAX - 2;

const FREE: u8 = 0;
const SOURCE: u8 = 1;
const SINK: u8 = 2;

/// A graph under construction: nodes `0..n`, terminal capacities and
/// pairwise edges.
#[derive(Debug, Clone)]
pub struct Graph {
    /// Source capacity minus sink capacity per node (the flow both can
    /// carry is already counted in `base_flow`).
    tr: Vec<i64>,
    edges: Vec<Edge>,
    base_flow: i64,
}

/// Result of [`Graph::max_flow`].
#[derive(Debug, Clone)]
pub struct Cut {
    /// Value of the maximum flow (= capacity of the minimum cut).
    pub flow: i64,
    /// Per node: on the source side of the minimum cut.
    pub source_side: Vec<bool>,
}

impl Graph {
    /// A graph of `n` nodes without edges.
    pub fn new(n: usize) -> Self {
        Self {
            tr: vec![0; n],
            edges: Vec::new(),
            base_flow: 0,
        }
    }

    /// Number of nodes.
    pub fn len(&self) -> usize {
        self.tr.len()
    }

    /// True when the graph has no nodes.
    pub fn is_empty(&self) -> bool {
        self.tr.is_empty()
    }

    /// Add terminal edges source → i (`source`) and i → sink (`sink`); both
    /// ≥ 0 (negative values count as 0).
    pub fn add_terminal(&mut self, i: usize, source: i32, sink: i32) {
        let (s, t) = (source.max(0) as i64, sink.max(0) as i64);
        self.base_flow += s.min(t);
        self.tr[i] += s - t;
    }

    /// Add the edge i → j with capacity `cap` and j → i with `rev` (≥ 0).
    pub fn add_edge(&mut self, i: usize, j: usize, cap: i32, rev: i32) {
        if i == j || (cap <= 0 && rev <= 0) {
            return;
        }
        self.edges
            .push((i as u32, j as u32, cap.max(0), rev.max(0)));
    }

    /// Maximum flow and the minimum cut's source side.
    pub fn max_flow(self) -> Cut {
        let mut net = Network::new(self.tr.len(), &[self.edges]);
        let source_side = net.solve(&self.tr);
        Cut {
            flow: net.capacity(&self.tr, &source_side) + self.base_flow,
            source_side,
        }
    }
}

/// A pairwise edge `(i, j, cap, rev)`: i → j with `cap`, j → i with `rev`.
pub type Edge = (u32, u32, i32, i32);

/// A graph's pairwise edges in compressed adjacency, cut again and again
/// with different terminal capacities (GrabCut's rounds re-estimate only
/// the unary terms).
///
/// Each solve starts from the flow the previous one left on the pairwise
/// edges (Kohli & Torr, "Dynamic Graph Cuts", TPAMI 2007): the terminals'
/// residuals move by the change of their capacities, which is a valid flow
/// of the new graph up to a constant on both terminal edges of a node, and
/// the search trees are grown afresh. The source side returned is the set
/// of nodes reachable from the source in the final residual graph, which is
/// the same for every maximum flow, so a warm solve gives the cold solve's
/// cut exactly.
#[derive(Debug, Clone)]
pub struct Network {
    s: Solver,
    /// Capacities of the arcs as built.
    cap0: Vec<i32>,
    /// Terminals (source − sink capacity) of the last solve.
    last: Vec<i64>,
}

impl Network {
    /// The network of nodes `0..n` with the edges of `parts` (edges with
    /// `i == j` or without capacity are left out, negative capacities
    /// count as 0). Node indices must be below `n`.
    pub fn new(n: usize, parts: &[Vec<Edge>]) -> Self {
        let edges = || {
            parts
                .iter()
                .flatten()
                .filter(|e| e.0 != e.1 && (e.2 > 0 || e.3 > 0))
        };
        // Compressed adjacency: arcs of node i at first[i]..first[i + 1].
        let mut first = vec![0u32; n + 1];
        for &(i, j, _, _) in edges() {
            first[i as usize + 1] += 1;
            first[j as usize + 1] += 1;
        }
        for i in 0..n {
            first[i + 1] += first[i];
        }
        let m = first[n] as usize;
        let mut head = vec![0u32; m];
        let mut cap = vec![0i32; m];
        let mut sister = vec![0u32; m];
        let mut fill: Vec<u32> = first[..n].to_vec();
        for &(i, j, c, r) in edges() {
            let a = fill[i as usize];
            fill[i as usize] += 1;
            let b = fill[j as usize];
            fill[j as usize] += 1;
            head[a as usize] = j;
            cap[a as usize] = c.max(0);
            sister[a as usize] = b;
            head[b as usize] = i;
            cap[b as usize] = r.max(0);
            sister[b as usize] = a;
        }
        Self {
            cap0: cap.clone(),
            last: vec![0; n],
            s: Solver {
                first,
                head,
                cap,
                sister,
                tr: vec![0; n],
                parent: vec![NONE; n],
                tree: vec![FREE; n],
                ts: vec![0; n],
                dist: vec![0; n],
                active: vec![false; n],
                queue: VecDeque::new(),
                orphans: VecDeque::new(),
                time: 0,
            },
        }
    }

    /// Number of nodes.
    pub fn len(&self) -> usize {
        self.last.len()
    }

    /// True when the network has no nodes.
    pub fn is_empty(&self) -> bool {
        self.last.is_empty()
    }

    /// The minimum cut's source side with `terminals[i]` = node i's source
    /// capacity minus its sink capacity (one value per node). Panics when
    /// `terminals` does not hold one value per node.
    pub fn solve(&mut self, terminals: &[i64]) -> Vec<bool> {
        assert_eq!(terminals.len(), self.len(), "one terminal value per node");
        let s = &mut self.s;
        for ((r, new), old) in s.tr.iter_mut().zip(terminals).zip(&mut self.last) {
            *r += new - *old;
            *old = *new;
        }
        s.parent.fill(NONE);
        s.tree.fill(FREE);
        s.ts.fill(0);
        s.dist.fill(0);
        s.active.fill(false);
        s.queue.clear();
        s.orphans.clear();
        s.time = 0;
        s.run();
        s.tree.iter().map(|t| *t == SOURCE).collect()
    }

    /// Capacity of the cut `source_side` with `terminals` as in
    /// [`Network::solve`]: the terminal edges it severs and the arcs from
    /// the source side to the sink side as built, without the part both
    /// terminal edges of a node share (`min(source, sink)`, which every cut
    /// pays).
    pub fn capacity(&self, terminals: &[i64], source_side: &[bool]) -> i64 {
        let s = &self.s;
        let mut c = 0i64;
        for (i, &d) in terminals.iter().enumerate() {
            if source_side[i] {
                c += (-d).max(0);
                for a in s.first[i]..s.first[i + 1] {
                    if !source_side[s.head[a as usize] as usize] {
                        c += i64::from(self.cap0[a as usize]);
                    }
                }
            } else {
                c += d.max(0);
            }
        }
        c
    }
}

#[derive(Debug, Clone)]
struct Solver {
    first: Vec<u32>,
    head: Vec<u32>,
    cap: Vec<i32>,
    sister: Vec<u32>,
    tr: Vec<i64>,
    parent: Vec<u32>,
    tree: Vec<u8>,
    ts: Vec<u32>,
    dist: Vec<u32>,
    active: Vec<bool>,
    queue: VecDeque<u32>,
    orphans: VecDeque<u32>,
    time: u32,
}

impl Solver {
    fn activate(&mut self, i: u32) {
        if !self.active[i as usize] {
            self.active[i as usize] = true;
            self.queue.push_back(i);
        }
    }

    fn orphan(&mut self, k: u32) {
        self.parent[k as usize] = ORPHAN;
        self.orphans.push_back(k);
    }

    fn run(&mut self) {
        for i in 0..self.tr.len() {
            let t = self.tr[i];
            if t != 0 {
                self.tree[i] = if t > 0 { SOURCE } else { SINK };
                self.parent[i] = TERMINAL;
                self.dist[i] = 1;
                self.activate(i as u32);
            }
        }
        while let Some((s_node, t_node, arc)) = self.grow() {
            self.time += 1;
            self.augment(s_node, t_node, arc);
            self.adopt();
        }
    }

    /// Grow the trees from active nodes until they touch; returns the
    /// source-tree node, the sink-tree node and the arc between them.
    fn grow(&mut self) -> Option<(u32, u32, u32)> {
        while let Some(&i) = self.queue.front() {
            let iu = i as usize;
            let ti = self.tree[iu];
            if ti == FREE {
                self.queue.pop_front();
                self.active[iu] = false;
                continue;
            }
            for a in self.first[iu]..self.first[iu + 1] {
                let au = a as usize;
                let residual = if ti == SOURCE {
                    self.cap[au]
                } else {
                    self.cap[self.sister[au] as usize]
                };
                if residual <= 0 {
                    continue;
                }
                let j = self.head[au];
                let ju = j as usize;
                let tj = self.tree[ju];
                if tj == FREE {
                    self.tree[ju] = ti;
                    self.parent[ju] = self.sister[au];
                    self.ts[ju] = self.ts[iu];
                    self.dist[ju] = self.dist[iu] + 1;
                    self.activate(j);
                } else if tj != ti {
                    // The trees touch: i stays active (at the queue's front).
                    return Some(if ti == SOURCE {
                        (i, j, a)
                    } else {
                        (j, i, self.sister[au])
                    });
                } else if self.ts[ju] <= self.ts[iu] && self.dist[ju] > self.dist[iu] {
                    // A shorter path to the terminal through i.
                    self.parent[ju] = self.sister[au];
                    self.ts[ju] = self.ts[iu];
                    self.dist[ju] = self.dist[iu] + 1;
                }
            }
            self.queue.pop_front();
            self.active[iu] = false;
        }
        None
    }

    fn augment(&mut self, s_node: u32, t_node: u32, mid: u32) {
        let mut b = self.cap[mid as usize] as i64;
        let mut k = s_node as usize;
        loop {
            let p = self.parent[k];
            if p == TERMINAL {
                b = b.min(self.tr[k]);
                break;
            }
            b = b.min(self.cap[self.sister[p as usize] as usize] as i64);
            k = self.head[p as usize] as usize;
        }
        let mut k = t_node as usize;
        loop {
            let p = self.parent[k];
            if p == TERMINAL {
                b = b.min(-self.tr[k]);
                break;
            }
            b = b.min(self.cap[p as usize] as i64);
            k = self.head[p as usize] as usize;
        }
        let bi = b as i32;
        self.cap[mid as usize] -= bi;
        self.cap[self.sister[mid as usize] as usize] += bi;
        let mut k = s_node;
        loop {
            let p = self.parent[k as usize];
            if p == TERMINAL {
                self.tr[k as usize] -= b;
                if self.tr[k as usize] == 0 {
                    self.orphan(k);
                }
                break;
            }
            let sp = self.sister[p as usize] as usize;
            self.cap[p as usize] += bi;
            self.cap[sp] -= bi;
            if self.cap[sp] == 0 {
                self.orphan(k);
            }
            k = self.head[p as usize];
        }
        let mut k = t_node;
        loop {
            let p = self.parent[k as usize];
            if p == TERMINAL {
                self.tr[k as usize] += b;
                if self.tr[k as usize] == 0 {
                    self.orphan(k);
                }
                break;
            }
            let sp = self.sister[p as usize] as usize;
            self.cap[p as usize] -= bi;
            self.cap[sp] += bi;
            if self.cap[p as usize] == 0 {
                self.orphan(k);
            }
            k = self.head[p as usize];
        }
    }

    /// Find each orphan a new parent in its tree whose path reaches the
    /// terminal, or free it (and orphan its children).
    fn adopt(&mut self) {
        while let Some(k) = self.orphans.pop_front() {
            let ku = k as usize;
            let t = self.tree[ku];
            let mut best = NONE;
            let mut dmin = u32::MAX;
            for a in self.first[ku]..self.first[ku + 1] {
                let au = a as usize;
                let residual = if t == SOURCE {
                    self.cap[self.sister[au] as usize]
                } else {
                    self.cap[au]
                };
                let j0 = self.head[au];
                if residual <= 0 || self.tree[j0 as usize] != t {
                    continue;
                }
                // Trace j0's origin.
                let mut d = 0u32;
                let mut j = j0 as usize;
                let valid = loop {
                    if self.ts[j] == self.time {
                        d += self.dist[j];
                        break true;
                    }
                    let p = self.parent[j];
                    d += 1;
                    if p == TERMINAL {
                        self.ts[j] = self.time;
                        self.dist[j] = 1;
                        break true;
                    }
                    if p == ORPHAN || p == NONE {
                        break false;
                    }
                    j = self.head[p as usize] as usize;
                };
                if !valid {
                    continue;
                }
                if d < dmin {
                    best = a;
                    dmin = d;
                }
                let mut j = j0 as usize;
                while self.ts[j] != self.time {
                    self.ts[j] = self.time;
                    self.dist[j] = d;
                    d -= 1;
                    j = self.head[self.parent[j] as usize] as usize;
                }
            }
            if best != NONE {
                self.parent[ku] = best;
                self.ts[ku] = self.time;
                self.dist[ku] = dmin + 1;
                continue;
            }
            for a in self.first[ku]..self.first[ku + 1] {
                let au = a as usize;
                let j = self.head[au];
                let ju = j as usize;
                if self.tree[ju] != t {
                    continue;
                }
                let residual = if t == SOURCE {
                    self.cap[self.sister[au] as usize]
                } else {
                    self.cap[au]
                };
                if residual > 0 {
                    self.activate(j);
                }
                let p = self.parent[ju];
                if p != TERMINAL && p != ORPHAN && p != NONE && self.head[p as usize] == k {
                    self.orphan(j);
                }
            }
            self.tree[ku] = FREE;
            self.parent[ku] = NONE;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Reference: Edmonds–Karp on a dense capacity matrix with the source
    /// n and the sink n + 1.
    fn edmonds_karp(c: &mut [Vec<i64>], s: usize, t: usize) -> i64 {
        let n = c.len();
        let mut flow = 0;
        loop {
            let mut prev = vec![usize::MAX; n];
            prev[s] = s;
            let mut q = VecDeque::from([s]);
            while let Some(u) = q.pop_front() {
                for v in 0..n {
                    if prev[v] == usize::MAX && c[u][v] > 0 {
                        prev[v] = u;
                        q.push_back(v);
                    }
                }
            }
            if prev[t] == usize::MAX {
                return flow;
            }
            let mut b = i64::MAX;
            let mut v = t;
            while v != s {
                b = b.min(c[prev[v]][v]);
                v = prev[v];
            }
            let mut v = t;
            while v != s {
                c[prev[v]][v] -= b;
                c[v][prev[v]] += b;
                v = prev[v];
            }
            flow += b;
        }
    }

    /// On random graphs the flow equals Edmonds–Karp's, and the returned
    /// cut's capacity equals the flow (so it is a minimum cut).
    #[test]
    fn matches_edmonds_karp_and_the_cut_is_minimal() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
        for trial in 0..300 {
            let n = rng.random_range(1..30);
            let mut g = Graph::new(n);
            let mut c = vec![vec![0i64; n + 2]; n + 2];
            let (s, t) = (n, n + 1);
            let mut term = vec![(0i64, 0i64); n];
            for (i, tm) in term.iter_mut().enumerate() {
                let a = if rng.random_bool(0.4) {
                    rng.random_range(0..50)
                } else {
                    0
                };
                let b = if rng.random_bool(0.4) {
                    rng.random_range(0..50)
                } else {
                    0
                };
                g.add_terminal(i, a, b);
                c[s][i] += a as i64;
                c[i][t] += b as i64;
                *tm = (a as i64, b as i64);
            }
            let mut edges = vec![];
            for _ in 0..rng.random_range(0..4 * n + 1) {
                let i = rng.random_range(0..n);
                let j = rng.random_range(0..n);
                let a = rng.random_range(0..30);
                let b = rng.random_range(0..30);
                g.add_edge(i, j, a, b);
                if i != j {
                    c[i][j] += a as i64;
                    c[j][i] += b as i64;
                    edges.push((i, j, a as i64, b as i64));
                }
            }
            let want = edmonds_karp(&mut c, s, t);
            let cut = g.max_flow();
            assert_eq!(cut.flow, want, "trial {trial}");
            let side = &cut.source_side;
            let mut cap = 0;
            for (i, &(a, b)) in term.iter().enumerate() {
                cap += if side[i] { b } else { a };
            }
            for &(i, j, a, b) in &edges {
                if side[i] && !side[j] {
                    cap += a;
                }
                if side[j] && !side[i] {
                    cap += b;
                }
            }
            assert_eq!(cap, want, "trial {trial}: cut capacity");
        }
    }

    /// Cutting one network again with new terminals, from the flow the
    /// previous cut left, gives the cut and the flow of a graph built
    /// afresh with those terminals, on random graphs.
    #[test]
    fn warm_solves_match_cold_ones() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(11);
        for trial in 0..200 {
            let n = rng.random_range(1..40);
            let edges: Vec<Edge> = (0..rng.random_range(0..4 * n + 1))
                .map(|_| {
                    (
                        rng.random_range(0..n) as u32,
                        rng.random_range(0..n) as u32,
                        rng.random_range(0..30),
                        rng.random_range(0..30),
                    )
                })
                .collect();
            let mut net = Network::new(n, std::slice::from_ref(&edges));
            for round in 0..4 {
                let terminals: Vec<i64> = (0..n)
                    .map(|_| {
                        if rng.random_bool(0.6) {
                            rng.random_range(-60..60)
                        } else {
                            0
                        }
                    })
                    .collect();
                let mut g = Graph::new(n);
                for (i, &d) in terminals.iter().enumerate() {
                    g.add_terminal(i, d.max(0) as i32, (-d).max(0) as i32);
                }
                for &(i, j, c, r) in &edges {
                    g.add_edge(i as usize, j as usize, c, r);
                }
                let cold = g.max_flow();
                let warm = net.solve(&terminals);
                assert_eq!(
                    net.capacity(&terminals, &warm),
                    cold.flow,
                    "trial {trial} round {round}: flow"
                );
                assert_eq!(warm, cold.source_side, "trial {trial} round {round}: cut");
            }
        }
    }

    /// A 2-D grid whose left half prefers the source and right half the
    /// sink, joined by strong edges except along one column: the cut
    /// follows the weak column.
    #[test]
    fn grid_cut_follows_the_weak_edges() {
        let (w, h) = (40, 30);
        let mut g = Graph::new(w * h);
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                if x < 5 {
                    g.add_terminal(i, 100, 0);
                }
                if x >= w - 5 {
                    g.add_terminal(i, 0, 100);
                }
                if x + 1 < w {
                    let c = if x == 22 { 1 } else { 50 };
                    g.add_edge(i, i + 1, c, c);
                }
                if y + 1 < h {
                    g.add_edge(i, i + w, 50, 50);
                }
            }
        }
        let cut = g.max_flow();
        assert_eq!(cut.flow, h as i64);
        for y in 0..h {
            for x in 0..w {
                assert_eq!(cut.source_side[y * w + x], x <= 22, "({x}, {y})");
            }
        }
    }
}
