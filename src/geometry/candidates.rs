//! Short k-nearest lists over a fixed point set, for the millions of queries of a training
//! refresh: a k-d tree with a bounding box per node, queried without allocation and optionally
//! from a known radius (where the previous lists put it), so a query touches a few leaves.
//! [`super::PointIndex`] stays the general index; this one answers only "the k nearest".

use super::nearest::group_duplicates;

/// Points per leaf: small leaves keep the boxes tight for the short radii training asks for.
const LEAF: usize = 32;

/// Node of the tree: its points' box, and either two children or a leaf range.
#[derive(Clone, Copy)]
struct Node {
    lo: [f32; 3],
    hi: [f32; 3],
    /// Leaf: `start..end` of `points`; inner: `start` and `end` are the children.
    start: u32,
    end: u32,
    leaf: bool,
}

/// A k-d tree answering "the k nearest points" as lists of indices.
#[derive(Clone)]
pub struct CandidateTree {
    /// Distinct positions in tree order, one array per axis (a leaf's distances vectorise).
    axes: [Vec<f32>; 3],
    /// The lowest input index at each position, in the same order.
    ids: Vec<u32>,
    nodes: Vec<Node>,
}

/// The best `k` found so far, nearest first, ordered by (squared distance, index).
struct Best<'a> {
    d2: &'a mut [f32],
    id: &'a mut [u32],
    len: usize,
    /// Nothing beyond this squared distance is wanted (the caller's bound, then the k-th best).
    limit: f32,
}

impl CandidateTree {
    /// Builds the tree over `points` (finite; exact duplicates are kept once, lowest index).
    pub fn new(points: &[[f32; 3]]) -> CandidateTree {
        let (distinct, duplicates) = group_duplicates(points);
        let mut order: Vec<u32> = (0..distinct.len() as u32).collect();
        let mut nodes = Vec::with_capacity(2 * distinct.len() / LEAF + 1);
        build(&distinct, &mut order, 0, &mut nodes);
        CandidateTree {
            axes: [0, 1, 2].map(|k| order.iter().map(|&i| distinct[i as usize][k]).collect()),
            ids: order.iter().map(|&i| duplicates[i as usize][0]).collect(),
            nodes,
        }
    }

    /// The `k` points nearest `p` (all if there are fewer), nearest first, ties by index,
    /// written to `out`. `bound`: a squared distance within which at least `k` points are known
    /// to lie (infinite when nothing is known); it only speeds the search up.
    pub fn nearest(&self, p: [f32; 3], k: usize, bound: f32, out: &mut Vec<u32>) {
        out.clear();
        let k = k.min(self.ids.len());
        if k == 0 {
            return;
        }
        let mut d2 = [0.0f32; 32];
        let mut id = [0u32; 32];
        let (mut heap_d2, mut heap_id);
        let (d2, id): (&mut [f32], &mut [u32]) = if k <= 32 {
            (&mut d2[..k], &mut id[..k])
        } else {
            heap_d2 = vec![0.0f32; k];
            heap_id = vec![0u32; k];
            (&mut heap_d2, &mut heap_id)
        };
        // Widened by a few ulps: the bound was summed in another order than here.
        let limit = if bound.is_finite() {
            bound * (1.0 + 1e-5) + f32::MIN_POSITIVE
        } else {
            f32::INFINITY
        };
        let mut best = Best {
            d2,
            id,
            len: 0,
            limit,
        };
        self.visit(0, p, &mut best);
        if best.len < k && limit.is_finite() {
            // The bound was wrong (a caller's mistake): search without it.
            return self.nearest(p, k, f32::INFINITY, out);
        }
        out.extend_from_slice(&best.id[..best.len]);
    }

    /// The nearest point's index (the lowest of equally near ones).
    pub fn nearest_one(&self, p: [f32; 3]) -> u32 {
        let (mut d2, mut id) = ([0.0f32], [0u32]);
        let mut best = Best {
            d2: &mut d2,
            id: &mut id,
            len: 0,
            limit: f32::INFINITY,
        };
        self.visit(0, p, &mut best);
        id[0]
    }

    fn visit(&self, node: usize, p: [f32; 3], best: &mut Best) {
        let n = self.nodes[node];
        if n.leaf {
            let range = n.start as usize..n.end as usize;
            let [xs, ys, zs] = &self.axes;
            let mut d2 = [0.0f32; LEAF];
            let (xs, ys, zs) = (&xs[range.clone()], &ys[range.clone()], &zs[range.clone()]);
            for (d, ((x, y), z)) in d2.iter_mut().zip(xs.iter().zip(ys).zip(zs)) {
                *d = (x - p[0]) * (x - p[0]) + (y - p[1]) * (y - p[1]) + (z - p[2]) * (z - p[2]);
            }
            for (&d, &id) in d2.iter().zip(&self.ids[range]) {
                if d <= best.limit {
                    best.offer(d, id);
                }
            }
            return;
        }
        let (a, b) = (n.start as usize, n.end as usize);
        let (da, db) = (
            box_distance(&self.nodes[a], p),
            box_distance(&self.nodes[b], p),
        );
        let ((near, dn), (far, df)) = if da <= db {
            ((a, da), (b, db))
        } else {
            ((b, db), (a, da))
        };
        if dn <= best.limit {
            self.visit(near, p, best);
        }
        if df <= best.limit {
            self.visit(far, p, best);
        }
    }
}

impl Best<'_> {
    /// Keeps `(d2, id)` if it is among the `k` nearest so far.
    fn offer(&mut self, d2: f32, id: u32) {
        let k = self.d2.len();
        if d2 > self.limit {
            return;
        }
        if self.len == k {
            let (wd, wi) = (self.d2[k - 1], self.id[k - 1]);
            if (d2, id) >= (wd, wi) {
                return;
            }
            self.len -= 1;
        }
        let mut i = self.len;
        while i > 0 && (self.d2[i - 1], self.id[i - 1]) > (d2, id) {
            self.d2[i] = self.d2[i - 1];
            self.id[i] = self.id[i - 1];
            i -= 1;
        }
        self.d2[i] = d2;
        self.id[i] = id;
        self.len += 1;
        if self.len == k {
            self.limit = self.limit.min(self.d2[k - 1]);
        }
    }
}

/// Builds the subtree over `order` (indices into `points`), returns its node index.
fn build(points: &[[f32; 3]], order: &mut [u32], offset: usize, nodes: &mut Vec<Node>) -> usize {
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for &i in order.iter() {
        for k in 0..3 {
            lo[k] = lo[k].min(points[i as usize][k]);
            hi[k] = hi[k].max(points[i as usize][k]);
        }
    }
    let at = nodes.len();
    nodes.push(Node {
        lo,
        hi,
        start: offset as u32,
        end: (offset + order.len()) as u32,
        leaf: true,
    });
    if order.len() <= LEAF {
        return at;
    }
    // Split the widest axis at the median (ties by index: the same input, the same tree).
    let axis = (0..3)
        .max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b])))
        .unwrap_or(0);
    let mid = order.len() / 2;
    order.select_nth_unstable_by(mid, |&a, &b| {
        points[a as usize][axis]
            .total_cmp(&points[b as usize][axis])
            .then(a.cmp(&b))
    });
    let (left, right) = order.split_at_mut(mid);
    let l = build(points, left, offset, nodes);
    let r = build(points, right, offset + mid, nodes);
    nodes[at] = Node {
        start: l as u32,
        end: r as u32,
        leaf: false,
        ..nodes[at]
    };
    at
}

fn box_distance(n: &Node, p: [f32; 3]) -> f32 {
    (0..3)
        .map(|k| {
            let d = (n.lo[k] - p[k]).max(p[k] - n.hi[k]).max(0.0);
            d * d
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::nearest::tests::lcg_points;

    fn squared_distance(a: [f32; 3], b: [f32; 3]) -> f32 {
        (0..3).map(|k| (a[k] - b[k]) * (a[k] - b[k])).sum()
    }

    /// The k nearest by brute force, ties by index, duplicates once (lowest index).
    fn brute_force(points: &[[f32; 3]], p: [f32; 3], k: usize) -> Vec<u32> {
        let mut all: Vec<(f32, u32)> = points
            .iter()
            .enumerate()
            .filter(|(i, q)| !points[..*i].contains(q))
            .map(|(i, &q)| (squared_distance(q, p), i as u32))
            .collect();
        all.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        all.into_iter().take(k).map(|x| x.1).collect()
    }

    #[test]
    fn the_k_nearest_match_brute_force_with_and_without_a_bound() {
        let mut points = lcg_points(2000, 3);
        // Duplicates report their lowest index once.
        points[1500] = points[10];
        points[1700] = points[10];
        let tree = CandidateTree::new(&points);
        let mut out = Vec::new();
        for (q, &p) in lcg_points(300, 11).iter().chain(&[points[10]]).enumerate() {
            for k in [1, 6, 40] {
                let want = brute_force(&points, p, k);
                tree.nearest(p, k, f32::INFINITY, &mut out);
                assert_eq!(out, want, "query {q}, k {k}");
                // A bound from any k points (here: the true k-th, and a loose one) changes nothing.
                let kth = squared_distance(points[*want.last().unwrap() as usize], p);
                for bound in [kth, 4.0 * kth + 0.01] {
                    tree.nearest(p, k, bound, &mut out);
                    assert_eq!(out, want, "query {q}, k {k}, bound {bound}");
                }
                // A wrong (too small) bound falls back to the full search.
                tree.nearest(p, k, 0.0, &mut out);
                assert_eq!(out, want, "query {q}, k {k}, zero bound");
            }
        }
        let q = [0.3, 0.6, 0.2];
        assert_eq!(tree.nearest_one(q), brute_force(&points, q, 1)[0]);
        tree.nearest([0.5; 3], 5000, f32::INFINITY, &mut out);
        assert_eq!(out.len(), 1998, "every distinct point once");
    }
}
