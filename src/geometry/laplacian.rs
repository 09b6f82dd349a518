//! Sparse mesh Laplacians (uniform and cotangent) and explicit Laplacian smoothing.
//!
//! Convention: `(L x)_i = Σ_j w_ij (x_j − x_i) / Σ_j w_ij`, the *normalised* ("umbrella")
//! Laplacian: the offset from a vertex to the weighted mean of its neighbours. It is zero on
//! flat regions (cotangent weights: for any flat triangulation without obtuse angles; uniform:
//! for regular ones) and points inward on convex surfaces. Normalising makes explicit smoothing
//! `x ← x + λ L x` a convex blend for `0 < λ ≤ 1`, so it cannot overshoot whatever the mesh
//! density, which is what relaxing pushed-out garments needs.

use crate::geometry::mesh::TriMesh;
use crate::geometry::{arr3, v3, Vec3};

/// Off-diagonal weights in compressed sparse row form; the diagonal is implied (see module doc).
#[derive(Clone, Debug, PartialEq)]
pub struct Laplacian {
    /// Row `i`'s entries are `offsets[i]..offsets[i + 1]` (length `n_vertices + 1`).
    pub offsets: Vec<u32>,
    /// Neighbour vertex of each entry, increasing within a row.
    pub columns: Vec<u32>,
    /// Non-negative weight `w_ij` of each entry.
    pub weights: Vec<f32>,
}

impl Laplacian {
    /// Every edge neighbour weighs 1 (graph Laplacian). Robust to any triangle shape.
    pub fn uniform(mesh: &TriMesh) -> Laplacian {
        let triplets = mesh
            .triangles
            .iter()
            .flat_map(|&[a, b, c]| [(a, b), (b, c), (c, a)])
            .map(|(i, j)| (i, j, 1.0));
        // Each interior edge is seen twice; weights are reset to 1 after summing.
        let mut lap = Laplacian::from_symmetric_triplets(mesh.vertex_count(), triplets);
        lap.weights.iter_mut().for_each(|w| *w = 1.0);
        lap
    }

    /// Cotangent weights `w_ij = (cot α_ij + cot β_ij) / 2` over the (one or two) angles facing
    /// edge `ij`. A negative summed weight (obtuse opposite angles) is clamped to 0 so the row
    /// stays a convex combination; a degenerate triangle contributes nothing; a row whose
    /// weights sum to ~0 falls back to uniform weights, so every vertex with edges still moves.
    pub fn cotangent(mesh: &TriMesh) -> Laplacian {
        let mut triplets = Vec::with_capacity(mesh.triangle_count() * 3);
        for tri in &mesh.triangles {
            let p = tri.map(|i| v3(mesh.positions[i as usize]));
            for k in 0..3 {
                let (i, j) = ((k + 1) % 3, (k + 2) % 3);
                let w = 0.5 * cotangent(p[k], p[i], p[j]);
                triplets.push((tri[i], tri[j], w));
            }
        }
        let mut lap = Laplacian::from_symmetric_triplets(mesh.vertex_count(), triplets);
        lap.weights.iter_mut().for_each(|w| *w = w.max(0.0));
        lap.uniform_fallback_for_empty_rows();
        lap
    }

    pub fn vertex_count(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// Neighbours and weights of row `i`.
    pub fn row(&self, i: usize) -> (&[u32], &[f32]) {
        let range = self.offsets[i] as usize..self.offsets[i + 1] as usize;
        (&self.columns[range.clone()], &self.weights[range])
    }

    /// `L x` per vertex (see the module doc). Isolated vertices get zero.
    pub fn apply(&self, x: &[[f32; 3]]) -> Vec<[f32; 3]> {
        (0..self.vertex_count())
            .map(|i| arr3(self.apply_row(i, x)))
            .collect()
    }

    /// `iterations` steps of explicit smoothing `x ← x + λ L x`; `λ` in `(0, 1]` (0.5 is a good
    /// default). Shrinks closed surfaces slightly per step, as all explicit smoothing does.
    pub fn smooth(&self, x: &[[f32; 3]], lambda: f32, iterations: usize) -> Vec<[f32; 3]> {
        let mut current = x.to_vec();
        for _ in 0..iterations {
            let step = self.apply(&current);
            for (p, d) in current.iter_mut().zip(step) {
                *p = arr3(v3(*p) + v3(d) * lambda);
            }
        }
        current
    }

    fn apply_row(&self, i: usize, x: &[[f32; 3]]) -> Vec3 {
        let (cols, weights) = self.row(i);
        let xi = v3(x[i]);
        let mut sum = Vec3::zeros();
        let mut total = 0.0f32;
        for (&j, &w) in cols.iter().zip(weights) {
            sum += (v3(x[j as usize]) - xi) * w;
            total += w;
        }
        if total > 0.0 {
            sum / total
        } else {
            Vec3::zeros()
        }
    }

    /// Builds CSR from `(i, j, w)` triplets, adding each also as `(j, i, w)` and summing
    /// duplicates; rows and columns come out sorted, hence deterministic.
    fn from_symmetric_triplets(
        n_vertices: usize,
        triplets: impl IntoIterator<Item = (u32, u32, f32)>,
    ) -> Laplacian {
        let mut entries: Vec<(u32, u32, f32)> = triplets
            .into_iter()
            .flat_map(|(i, j, w)| [(i, j, w), (j, i, w)])
            .collect();
        entries.sort_unstable_by_key(|&(i, j, _)| (i, j));
        let mut offsets = vec![0u32; n_vertices + 1];
        let mut columns = Vec::with_capacity(entries.len() / 2);
        let mut weights: Vec<f32> = Vec::with_capacity(entries.len() / 2);
        let mut last = None;
        for (i, j, w) in entries {
            if last == Some((i, j)) {
                if let Some(sum) = weights.last_mut() {
                    *sum += w;
                }
                continue;
            }
            last = Some((i, j));
            offsets[i as usize + 1] += 1;
            columns.push(j);
            weights.push(w);
        }
        for i in 0..n_vertices {
            offsets[i + 1] += offsets[i];
        }
        Laplacian {
            offsets,
            columns,
            weights,
        }
    }

    /// Rows whose weights sum to (nearly) zero get weight 1 per neighbour.
    fn uniform_fallback_for_empty_rows(&mut self) {
        for i in 0..self.vertex_count() {
            let range = self.offsets[i] as usize..self.offsets[i + 1] as usize;
            let total: f32 = self.weights[range.clone()].iter().sum();
            if total <= 1e-12 {
                self.weights[range].iter_mut().for_each(|w| *w = 1.0);
            }
        }
    }
}

/// Cotangent of the angle at `at` in the triangle (`at`, `b`, `c`); 0 if degenerate.
fn cotangent(at: Vec3, b: Vec3, c: Vec3) -> f32 {
    let (u, v) = (b - at, c - at);
    let sin_scaled = u.cross(&v).norm();
    if sin_scaled > 1e-12 * u.norm_squared().max(v.norm_squared()) && sin_scaled > 0.0 {
        u.dot(&v) / sin_scaled
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::test_meshes::{grid, uv_sphere};

    fn interior(w: usize, h: usize) -> impl Iterator<Item = usize> {
        (1..h).flat_map(move |y| (1..w).map(move |x| y * (w + 1) + x))
    }

    #[test]
    fn both_laplacians_vanish_inside_a_flat_grid() {
        let (w, h) = (5, 4);
        let m = grid(w, h, 0.1).transformed(|p| [p[0], p[1], 0.3]);
        for lap in [Laplacian::uniform(&m), Laplacian::cotangent(&m)] {
            let l = lap.apply(&m.positions);
            for i in interior(w, h) {
                let norm = v3(l[i]).norm();
                assert!(norm < 1e-6, "vertex {i}: {:?}", l[i]);
            }
        }
    }

    #[test]
    fn cotangent_weights_of_a_right_triangle_grid() {
        // In a grid of right isosceles triangles the axis edges weigh 1/2 per 45° angle pair
        // (cot 45° = 1, twice, halved) and the diagonals weigh 0 (cot 90° = 0).
        let m = grid(2, 2, 1.0);
        let lap = Laplacian::cotangent(&m);
        let (cols, weights) = lap.row(4);
        assert_eq!(cols, &[0, 1, 3, 5, 7, 8]);
        let expected = [0.0, 1.0, 1.0, 1.0, 1.0, 0.0];
        for (w, e) in weights.iter().zip(expected) {
            assert!((w - e).abs() < 1e-6, "{weights:?}");
        }
        // Symmetric.
        for i in 0..lap.vertex_count() {
            let (cols, weights) = lap.row(i);
            for (&j, &w) in cols.iter().zip(weights) {
                let (cj, wj) = lap.row(j as usize);
                let k = cj.iter().position(|&c| c as usize == i).unwrap();
                assert_eq!(wj[k], w);
            }
        }
    }

    #[test]
    fn laplacian_points_inward_on_a_sphere() {
        let m = uv_sphere(32, 16);
        let l = Laplacian::cotangent(&m).apply(&m.positions);
        for (p, d) in m.positions.iter().zip(&l) {
            assert!(v3(*d).dot(&v3(*p)) < 0.0);
        }
    }

    #[test]
    fn smoothing_removes_a_bump_without_overshoot() {
        let (w, h) = (8, 8);
        let mut m = grid(w, h, 0.1);
        let bump = 4 * (w + 1) + 4;
        m.positions[bump][2] = 0.5;
        for lap in [Laplacian::uniform(&m), Laplacian::cotangent(&m)] {
            let smoothed = lap.smooth(&m.positions, 0.5, 20);
            let max_z = smoothed.iter().map(|p| p[2]).fold(f32::MIN, f32::max);
            let min_z = smoothed.iter().map(|p| p[2]).fold(f32::MAX, f32::min);
            assert!(max_z < 0.1, "bump still {max_z}");
            assert!(min_z >= 0.0, "overshoot {min_z}");
            assert_eq!(lap.smooth(&m.positions, 0.5, 0), m.positions);
        }
    }

    #[test]
    fn isolated_vertex_stays_put() {
        let mut m = grid(1, 1, 1.0);
        m.positions.push([5.0, 5.0, 5.0]);
        let lap = Laplacian::cotangent(&m);
        assert_eq!(lap.vertex_count(), 5);
        assert_eq!(lap.apply(&m.positions)[4], [0.0; 3]);
    }
}
