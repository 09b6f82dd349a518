//! Nearest-point queries over a fixed point set (body vertices), through a kiddo k-d tree.
//!
//! Determinism: exact duplicate points (common at UV seams and in welded bodies) are stored once
//! and always report their lowest index, and results are ordered by (distance, index). For
//! distinct points at exactly equal distance the tree's choice is still deterministic: the tree is
//! built the same way from the same input.

use std::collections::HashMap;
use std::num::NonZeroUsize;

use kiddo::immutable::float::kdtree::ImmutableKdTree;
use kiddo::{NearestNeighbour, SquaredEuclidean};
use thiserror::Error;

/// Leaf bucket size: kiddo's default; a good trade-off for 3-D body meshes.
const BUCKET: usize = 32;

type Tree = ImmutableKdTree<f32, u32, 3, BUCKET>;

#[derive(Clone, Debug, PartialEq, Error)]
pub enum NearestError {
    #[error("cannot build a nearest-point index over zero points")]
    Empty,
    #[error("point {index} has a non-finite position {position:?}")]
    NonFinite { index: usize, position: [f32; 3] },
    #[error("{0} points are too many for a nearest-point index (32-bit indices)")]
    TooMany(usize),
}

/// An immutable nearest-neighbour index over points; distances are Euclidean.
#[derive(Clone)]
pub struct PointIndex {
    tree: Tree,
    /// For each distinct point in the tree: the original indices at that position, increasing.
    duplicates: Vec<Vec<u32>>,
    len: usize,
}

impl PointIndex {
    /// Builds the index. Fails on an empty set or non-finite coordinates (a NaN would make every
    /// query answer arbitrary).
    pub fn new(points: &[[f32; 3]]) -> Result<PointIndex, NearestError> {
        if points.is_empty() {
            return Err(NearestError::Empty);
        }
        if points.len() > u32::MAX as usize {
            return Err(NearestError::TooMany(points.len()));
        }
        if let Some((index, &position)) = points
            .iter()
            .enumerate()
            .find(|(_, p)| !p.iter().all(|c| c.is_finite()))
        {
            return Err(NearestError::NonFinite { index, position });
        }
        let (distinct, duplicates) = group_duplicates(points);
        Ok(PointIndex {
            tree: Tree::new_from_slice(&distinct),
            duplicates,
            len: points.len(),
        })
    }

    /// Number of points indexed (duplicates included).
    pub fn len(&self) -> usize {
        self.len
    }

    /// Always false: an index is never empty.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The closest point's index and its Euclidean distance to `p` (lowest index on a tie).
    pub fn nearest(&self, p: [f32; 3]) -> (u32, f32) {
        // The index is never empty, so there is always one result.
        self.k_nearest(p, 1)[0]
    }

    /// The closest point's index, with a tie between distinct positions broken by the tree
    /// (deterministic, but not always the lowest index): one tree descent and no allocation,
    /// for per-frame loops over thousands of points (a roll-out's collision check).
    pub fn nearest_fast(&self, p: [f32; 3]) -> u32 {
        let hit = self.tree.nearest_one::<SquaredEuclidean>(&p);
        self.duplicates[hit.item as usize][0]
    }

    /// The `k` closest points (fewer if the set is smaller), nearest first, ties by index.
    pub fn k_nearest(&self, p: [f32; 3], k: usize) -> Vec<(u32, f32)> {
        if k == 0 {
            return Vec::new();
        }
        // Capped by the number of distinct points so a huge `k` does not allocate a huge heap.
        let want = NonZeroUsize::MIN.saturating_add(k.min(self.duplicates.len()));
        // One distinct point more than needed tells whether the tree may have cut a tie short:
        // every point it left out is at least as far as hits[k].
        let mut hits = self.tree.nearest_n::<SquaredEuclidean>(&p, want);
        if hits.len() == k + 1 && hits[k].distance <= hits[k - 1].distance {
            hits = self.tree.within::<SquaredEuclidean>(&p, hits[k].distance);
        }
        let mut out = self.expand(&hits);
        out.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
        out.truncate(k);
        out
    }

    /// Every point within `radius` of `p` (duplicates included) with its distance, unordered.
    pub fn within(&self, p: [f32; 3], radius: f32) -> Vec<(u32, f32)> {
        self.expand(
            &self
                .tree
                .within_unsorted::<SquaredEuclidean>(&p, radius * radius),
        )
    }

    /// Tree hits (squared distances over distinct positions) as every point index sharing the
    /// position, with its Euclidean distance.
    fn expand(&self, hits: &[NearestNeighbour<f32, u32>]) -> Vec<(u32, f32)> {
        hits.iter()
            .flat_map(|hit| {
                let d = hit.distance.sqrt();
                self.duplicates[hit.item as usize]
                    .iter()
                    .map(move |&i| (i, d))
            })
            .collect()
    }

    /// [`PointIndex::nearest`] for each query point, in order.
    pub fn nearest_many(&self, points: &[[f32; 3]]) -> Vec<(u32, f32)> {
        points.iter().map(|&p| self.nearest(p)).collect()
    }
}

impl std::fmt::Debug for PointIndex {
    /// Sizes only: the tree itself is large and not informative.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PointIndex")
            .field("points", &self.len)
            .field("distinct", &self.duplicates.len())
            .finish()
    }
}

/// Distinct points (in order of first appearance) and, for each, the original indices there.
pub(super) fn group_duplicates(points: &[[f32; 3]]) -> (Vec<[f32; 3]>, Vec<Vec<u32>>) {
    let mut slot: HashMap<[u32; 3], usize> = HashMap::with_capacity(points.len());
    let mut distinct = Vec::new();
    let mut duplicates: Vec<Vec<u32>> = Vec::new();
    for (i, p) in points.iter().enumerate() {
        // +0.0 so that -0.0 and 0.0 (equal positions) share one key.
        let key = p.map(|c| (c + 0.0).to_bits());
        let s = *slot.entry(key).or_insert_with(|| {
            distinct.push(*p);
            duplicates.push(Vec::new());
            distinct.len() - 1
        });
        duplicates[s].push(i as u32);
    }
    (distinct, duplicates)
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    /// Small deterministic generator so the test needs no extra crates.
    pub(in crate::geometry) fn lcg_points(n: usize, seed: u64) -> Vec<[f32; 3]> {
        let mut s = seed;
        let mut next = move || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 40) as f32) / (1u64 << 24) as f32
        };
        (0..n).map(|_| [next(), next(), next()]).collect()
    }

    fn brute_force(points: &[[f32; 3]], p: [f32; 3]) -> Vec<(u32, f32)> {
        let mut all: Vec<(u32, f32)> = points
            .iter()
            .enumerate()
            .map(|(i, q)| {
                let d2: f32 = (0..3).map(|k| (q[k] - p[k]) * (q[k] - p[k])).sum();
                (i as u32, d2.sqrt())
            })
            .collect();
        all.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
        all
    }

    #[test]
    fn the_fast_nearest_point_is_as_near_as_the_exact_one() {
        let points = lcg_points(2000, 3);
        let index = PointIndex::new(&points).unwrap();
        for q in lcg_points(500, 11) {
            let (exact, d) = index.nearest(q);
            let fast = index.nearest_fast(q) as usize;
            let e = points[fast];
            let df = ((e[0] - q[0]).powi(2) + (e[1] - q[1]).powi(2) + (e[2] - q[2]).powi(2)).sqrt();
            assert!((df - d).abs() < 1e-6, "{fast} at {df}, {exact} at {d}");
        }
    }

    #[test]
    fn matches_brute_force_on_random_points() {
        let points = lcg_points(3000, 7);
        let queries = lcg_points(200, 99);
        let index = PointIndex::new(&points).unwrap();
        assert_eq!(index.len(), 3000);
        for &q in &queries {
            let expected = brute_force(&points, q);
            let (i, d) = index.nearest(q);
            assert_eq!(i, expected[0].0);
            assert!((d - expected[0].1).abs() < 1e-6);
            let knn = index.k_nearest(q, 8);
            assert_eq!(knn.len(), 8);
            for (got, want) in knn.iter().zip(&expected) {
                assert_eq!(got.0, want.0);
                assert!((got.1 - want.1).abs() < 1e-6);
            }
        }
        let many = index.nearest_many(&queries);
        assert_eq!(many.len(), queries.len());
        assert_eq!(many[17], index.nearest(queries[17]));
    }

    #[test]
    fn distances_are_euclidean_not_squared() {
        let index = PointIndex::new(&[[0.0, 0.0, 0.0], [10.0, 0.0, 0.0]]).unwrap();
        assert_eq!(index.nearest([0.0, 3.0, 4.0]), (0, 5.0));
    }

    #[test]
    fn duplicates_and_planar_points_resolve_to_lowest_index() {
        // A flat grid (all z equal) with every point stored twice: coplanar and coincident
        // points are the cases that break naive k-d trees and tie-breaking.
        let mut points = Vec::new();
        for y in 0..40 {
            for x in 0..40 {
                points.push([x as f32, y as f32, 0.0]);
            }
        }
        let n = points.len() as u32;
        points.extend_from_within(..);
        let index = PointIndex::new(&points).unwrap();
        let (i, d) = index.nearest([5.0, 7.0, 0.25]);
        assert_eq!((i, d), (7 * 40 + 5, 0.25));
        // Exactly between four points: the lowest index wins.
        assert_eq!(index.nearest([5.5, 7.5, 0.0]).0, 7 * 40 + 5);
        let knn = index.k_nearest([5.0, 7.0, 0.0], 3);
        assert_eq!(knn[0].0, 7 * 40 + 5);
        assert_eq!(knn[1].0, 7 * 40 + 5 + n);
        assert_eq!(knn[0].1, 0.0);
        // The next nearest are the four grid neighbours at distance 1; lowest index wins.
        assert_eq!(knn[2].0, 6 * 40 + 5);
        assert!(index.k_nearest([0.0; 3], 0).is_empty());
        assert_eq!(index.k_nearest([0.0; 3], 10_000).len(), points.len());
    }

    #[test]
    fn bad_inputs_are_errors() {
        assert_eq!(PointIndex::new(&[]).err(), Some(NearestError::Empty));
        let err = PointIndex::new(&[[0.0, f32::NAN, 0.0]]).err().unwrap();
        assert!(err
            .to_string()
            .starts_with("point 0 has a non-finite position"));
    }
}
