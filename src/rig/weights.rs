//! Blend weights for a garment: transferred from the body by proximity, then, for the vertices
//! that hang away from the body, inpainted harmonically over the garment surface.
//!
//! Proximity alone rigs a long skirt like trousers: its lower part is nearest to one leg or the
//! other, follows it, tears between the legs and wraps each knee. Copying weights only where
//! the garment touches the body (within `reach`) and interpolating the rest smoothly from there
//! (a discrete harmonic function: each free vertex is the mean of its neighbours) lets the lower
//! part blend hips and both legs, as a skirt rig does (Abdrashitov et al. 2023, "Robust skin
//! weights transfer via weight inpainting"). Harmonic interpolation keeps weights non-negative
//! and summing to one. Training then refines them inside the sparsity pattern.

use super::Skin;
use crate::geometry::{Laplacian, PointIndex, TriMesh};

/// Dense `[N][J]` weights: the inverse-distance average of the skins of the `neighbours`
/// nearest surface points, normalised. Averaging several points matters: copying the single
/// nearest body vertex tears a skirt between the legs.
pub fn proximity(
    points: &[[f32; 3]],
    surface: &Skin,
    joints: usize,
    index: &PointIndex,
    neighbours: usize,
) -> Vec<Vec<f32>> {
    // Keeps the weights finite for a point exactly on the surface.
    const SOFTEN: f32 = 1.0e-3;
    points
        .iter()
        .map(|&p| {
            let mut w = vec![0.0f32; joints];
            for (b, d) in index.k_nearest(p, neighbours) {
                let s = 1.0 / (d + SOFTEN);
                for (j, x) in surface.vertex(b as usize) {
                    w[j] += s * x;
                }
            }
            let total: f32 = w.iter().sum();
            w.iter_mut()
                .for_each(|x| *x /= total.max(f32::MIN_POSITIVE));
            w
        })
        .collect()
}

/// Replaces the weights of the vertices not `known` by the harmonic interpolation of the known
/// ones over the mesh graph (uniform Laplacian, solved by conjugate gradients per joint). A
/// connected part without any known vertex keeps its weights. Returns how many changed.
pub fn inpaint(mesh: &TriMesh, weights: &mut [Vec<f32>], known: &[bool]) -> usize {
    let lap = Laplacian::uniform(mesh);
    let known = reachable_or_known(&lap, known);
    let free: Vec<usize> = (0..known.len()).filter(|&v| !known[v]).collect();
    if free.is_empty() {
        return 0;
    }
    let mut slot = vec![usize::MAX; known.len()];
    for (i, &v) in free.iter().enumerate() {
        slot[v] = i;
    }
    let joints = weights.first().map_or(0, Vec::len);
    #[allow(clippy::needless_range_loop)] // j indexes a column across all rows
    for j in 0..joints {
        // A x = b with A = D − adjacency on the free vertices, b = the known neighbours' sum.
        let b: Vec<f64> = free
            .iter()
            .map(|&v| {
                let (cols, _) = lap.row(v);
                cols.iter()
                    .filter(|&&u| known[u as usize])
                    .map(|&u| weights[u as usize][j] as f64)
                    .sum()
            })
            .collect();
        if b.iter().all(|&x| x == 0.0) {
            free.iter().for_each(|&v| weights[v][j] = 0.0);
            continue;
        }
        let x0: Vec<f64> = free.iter().map(|&v| weights[v][j] as f64).collect();
        let x = conjugate_gradient(&lap, &free, &slot, &b, x0);
        for (i, &v) in free.iter().enumerate() {
            weights[v][j] = x[i].max(0.0) as f32;
        }
    }
    for &v in &free {
        let total: f32 = weights[v].iter().sum();
        weights[v]
            .iter_mut()
            .for_each(|x| *x /= total.max(f32::MIN_POSITIVE));
    }
    free.len()
}

/// `known`, plus every vertex of a connected part that has no known vertex (nothing to
/// interpolate from there).
fn reachable_or_known(lap: &Laplacian, known: &[bool]) -> Vec<bool> {
    let n = known.len();
    let mut reached = known.to_vec();
    let mut stack: Vec<usize> = (0..n).filter(|&v| known[v]).collect();
    while let Some(v) = stack.pop() {
        for &u in lap.row(v).0 {
            if !reached[u as usize] {
                reached[u as usize] = true;
                stack.push(u as usize);
            }
        }
    }
    (0..n).map(|v| known[v] || !reached[v]).collect()
}

fn conjugate_gradient(
    lap: &Laplacian,
    free: &[usize],
    slot: &[usize],
    b: &[f64],
    mut x: Vec<f64>,
) -> Vec<f64> {
    let apply = |p: &[f64]| -> Vec<f64> {
        free.iter()
            .enumerate()
            .map(|(i, &v)| {
                let (cols, _) = lap.row(v);
                let off: f64 = cols
                    .iter()
                    .filter(|&&u| slot[u as usize] != usize::MAX)
                    .map(|&u| p[slot[u as usize]])
                    .sum();
                cols.len() as f64 * p[i] - off
            })
            .collect()
    };
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let ax = apply(&x);
    let mut r: Vec<f64> = b.iter().zip(&ax).map(|(b, a)| b - a).collect();
    let mut p = r.clone();
    let mut rr = dot(&r, &r);
    let tolerance = 1e-20 * dot(b, b).max(1e-30);
    for _ in 0..10 * free.len() {
        if rr <= tolerance {
            break;
        }
        let ap = apply(&p);
        let alpha = rr / dot(&p, &ap);
        for i in 0..x.len() {
            x[i] += alpha * p[i];
            r[i] -= alpha * ap[i];
        }
        let next = dot(&r, &r);
        let beta = next / rr;
        rr = next;
        for i in 0..p.len() {
            p[i] = r[i] + beta * p[i];
        }
    }
    x
}

/// The garment's initial skin: proximity weights, inpainted beyond `reach` (metres from the
/// body surface at rest; `None`: proximity everywhere), pruned to `influences` per vertex.
/// Also returns the number of inpainted vertices.
pub fn garment_skin(
    mesh: &TriMesh,
    surface: &Skin,
    joints: usize,
    index: &PointIndex,
    neighbours: usize,
    influences: usize,
    reach: Option<f32>,
) -> (Skin, usize) {
    let mut dense = proximity(&mesh.positions, surface, joints, index, neighbours);
    let inpainted = match reach {
        Some(reach) => {
            let known: Vec<bool> = mesh
                .positions
                .iter()
                .map(|&p| index.nearest(p).1 <= reach)
                .collect();
            inpaint(mesh, &mut dense, &known)
        }
        None => 0,
    };
    (Skin::from_dense(&dense, influences), inpainted)
}

/// The fixed skin a garment gets when no model learnt one (the dynamic model's LBS baseline and
/// its baked files): proximity to the 8 nearest body vertices, inpainted beyond 2 cm from the
/// body, 4 influences (what every glTF viewer plays).
pub fn smooth_garment_skin(
    mesh: &TriMesh,
    surface: &Skin,
    joints: usize,
    index: &PointIndex,
) -> Skin {
    garment_skin(mesh, surface, joints, index, 8, 4, Some(0.02)).0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::test_meshes::grid;

    #[test]
    fn inpainting_interpolates_linearly_along_a_strip() {
        // A 4×1 strip: the left column is all joint 0, the right all joint 1; the free middle
        // vertices get a harmonic blend (close to linear in x; the diagonals make the graph
        // slightly anisotropic), increasing along x, non-negative, summing to one.
        let mesh = grid(4, 1, 1.0);
        let n = mesh.vertex_count();
        let mut w: Vec<Vec<f32>> = (0..n).map(|_| vec![0.5, 0.5]).collect();
        let mut known = vec![false; n];
        for v in 0..n {
            let x = mesh.positions[v][0];
            if x == 0.0 {
                w[v] = vec![1.0, 0.0];
                known[v] = true;
            } else if x == 4.0 {
                w[v] = vec![0.0, 1.0];
                known[v] = true;
            }
        }
        assert_eq!(inpaint(&mesh, &mut w, &known), n - 4);
        for (v, wv) in w.iter().enumerate() {
            let x = mesh.positions[v][0];
            assert!((wv[1] - x / 4.0).abs() < 0.1, "vertex {v} at x={x}: {wv:?}");
            assert!(wv[0] >= 0.0 && wv[1] >= 0.0);
            if x > 0.0 {
                assert!(wv[1] > w[v - 1][1], "not increasing at vertex {v}");
            }
            assert!((wv[0] + wv[1] - 1.0).abs() < 1e-6);
        }
    }
}
