//! Morph-target normal deltas, so folds the blend shapes make also light as folds.
//!
//! glTF (and UsdSkel) morph a normal as `normalize(N + Σ_k w_k ΔN_k)`, then skin it with the
//! vertex's blended matrix `A`: linear in the weights, while the true normal of the played points
//! is not (and linear blend skinning bends normals wrongly where the weights change fast, as
//! between the legs). So no exact ΔN exists; the bake fits one: per vertex, the affine
//! least-squares map from the weights to `A⁻¹ n`, `n` the normal of the points the file plays in
//! world space, over the baked frames and the rest mesh. Skinned, the fitted normal then points
//! along `n`, the skinning's own error included. Between two keys the weights move linearly, so
//! the played normal is the blend of two fitted ones, not an extrapolation.

use super::compress::offset_matrix;
use crate::geometry::normals::vertex_normals;
use nalgebra::{DMatrix, Matrix3, Matrix4, Point3, Vector3};
use rayon::prelude::*;

/// The NORMAL attribute and one normal delta set per target, in the welded mesh's vertex order.
pub struct MorphNormals {
    /// Unit normals.
    pub base: Vec<[f32; 3]>,
    pub deltas: Vec<Vec<[f32; 3]>>,
}

/// Frames whose normals are computed and folded into the fit at once (bounds the memory: a
/// 1,247-frame bake of a 2,808-vertex skirt would otherwise hold 42 MB of normals).
const CHUNK: usize = 128;

/// Frames fitted at least (when the bake has them).
const MIN_SAMPLES: usize = 256;

/// Every vertex's blended skinning matrix at a frame of the bake.
pub type Blended<'a> = &'a (dyn Fn(usize) -> Vec<Matrix4<f32>> + Sync);

/// Fits the normal deltas of `targets` played with `weights` (`[frame][target]`, the file's own)
/// on `base` (the file's base points) with `triangles`, skinned at frame f by `blended(f)`.
/// `rest_weights`: the weights that show the rest mesh (on the rest skeleton, unskinned), fitted
/// as one more frame so the file opened without animation shades right too.
pub fn fit(
    base: &[[f32; 3]],
    triangles: &[[u32; 3]],
    targets: &[Vec<[f32; 3]>],
    weights: &[Vec<f32>],
    rest_weights: &[f32],
    blended: Blended,
) -> MorphNormals {
    let k = targets.len();
    let n3 = 3 * base.len();
    // (frame, its weights); frame None: the rest mesh, unskinned. Evenly spread frames, a few
    // times more than the unknowns per vertex: the fit needs no more, and every frame's normals
    // cost a skinning and a normal pass (2.1 s of a 994-frame, 64-target bake with all of them).
    let stride = weights.len().div_ceil(MIN_SAMPLES.max(4 * (k + 1))).max(1);
    let mut samples: Vec<(Option<usize>, &[f32])> = weights
        .iter()
        .enumerate()
        .step_by(stride)
        .map(|(f, w)| (Some(f), w.as_slice()))
        .collect();
    if rest_weights.len() == k {
        samples.push((None, rest_weights));
    }
    if k == 0 || samples.is_empty() {
        return MorphNormals {
            base: vertex_normals(base, triangles),
            deltas: vec![vec![[0.0; 3]; base.len()]; k],
        };
    }
    // Regressors [w_1 … w_K, 1] per sample: G = XᵀX, B = XᵀY with Y the samples' normals.
    let mut gram = DMatrix::<f64>::zeros(k + 1, k + 1);
    let mut xty = DMatrix::<f64>::zeros(k + 1, n3);
    for chunk in samples.chunks(CHUNK) {
        let x = DMatrix::<f32>::from_fn(chunk.len(), k + 1, |f, c| {
            chunk[f].1.get(c).copied().unwrap_or(1.0)
        });
        let owned: Vec<Vec<f32>> = chunk.iter().map(|w| w.1.to_vec()).collect();
        let offsets = offset_matrix(targets, &owned);
        let normals: Vec<Vec<f32>> = (0..chunk.len())
            .into_par_iter()
            .map(|f| {
                let column = offsets.column(f);
                let points: Vec<[f32; 3]> = base
                    .iter()
                    .zip(column.as_slice().chunks_exact(3))
                    .map(|(p, d)| [p[0] + d[0], p[1] + d[1], p[2] + d[2]])
                    .collect();
                match chunk[f].0 {
                    Some(frame) => unskinned_normals(&points, triangles, &blended(frame)).concat(),
                    None => vertex_normals(&points, triangles).concat(),
                }
            })
            .collect();
        // Samples as rows (frames × 3N), so XᵀY is one matrix product.
        let y = DMatrix::<f32>::from_fn(chunk.len(), n3, |f, r| normals[f][r]);
        gram += (x.tr_mul(&x)).cast::<f64>();
        xty += (x.tr_mul(&y)).cast::<f64>();
    }
    // A target whose weight never moves is a copy of the constant column: a small ridge keeps
    // the system solvable and gives such a target no normal delta.
    let ridge = 1e-9 * gram.trace() / (k + 1) as f64;
    for d in 0..=k {
        gram[(d, d)] += ridge;
    }
    let beta = match gram.cholesky() {
        Some(c) => c.solve(&xty),
        None => return fit(base, triangles, &[], &[], &[], blended).with_zero_deltas(k),
    };
    // Per vertex, intercept and deltas scaled by one factor so the intercept is unit (validators
    // want a unit NORMAL); readers normalise the sum, so the played direction is unchanged.
    let mut normals = vec![[0.0f32; 3]; base.len()];
    let mut deltas = vec![vec![[0.0f32; 3]; base.len()]; k];
    let fallback = vertex_normals(base, triangles);
    for v in 0..base.len() {
        let c = [0, 1, 2].map(|a| beta[(k, 3 * v + a)]);
        let length = c.iter().map(|x| x * x).sum::<f64>().sqrt();
        if length < 1e-6 {
            normals[v] = fallback[v];
            continue;
        }
        normals[v] = c.map(|x| (x / length) as f32);
        for (t, delta) in deltas.iter_mut().enumerate() {
            delta[v] = [0, 1, 2].map(|a| (beta[(t, 3 * v + a)] / length) as f32);
        }
    }
    MorphNormals {
        base: normals,
        deltas,
    }
}

/// The world-space normals of `points` skinned by `blended`, each taken back through its
/// vertex's matrix (`A⁻¹ n`, unit): the rest-space normal that skinning turns into `n`.
fn unskinned_normals(
    points: &[[f32; 3]],
    triangles: &[[u32; 3]],
    blended: &[Matrix4<f32>],
) -> Vec<[f32; 3]> {
    let world: Vec<[f32; 3]> = points
        .iter()
        .zip(blended)
        .map(|(p, m)| m.transform_point(&Point3::from(*p)).into())
        .collect();
    vertex_normals(&world, triangles)
        .iter()
        .zip(blended)
        .map(|(n, m)| {
            let a: Matrix3<f32> = m.fixed_view::<3, 3>(0, 0).into_owned();
            match a.try_inverse() {
                Some(inverse) => {
                    let back = inverse * Vector3::from(*n);
                    back.try_normalize(1e-12).unwrap_or(back).into()
                }
                None => *n,
            }
        })
        .collect()
}

impl MorphNormals {
    fn with_zero_deltas(mut self, k: usize) -> Self {
        self.deltas = vec![vec![[0.0; 3]; self.base.len()]; k];
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::test_meshes::grid;

    fn angle(a: [f32; 3], b: [f32; 3]) -> f32 {
        let dot: f32 = (0..3).map(|i| a[i] * b[i]).sum();
        let na = a.iter().map(|x| x * x).sum::<f32>().sqrt();
        let nb = b.iter().map(|x| x * x).sum::<f32>().sqrt();
        (dot / (na * nb)).clamp(-1.0, 1.0).acos().to_degrees()
    }

    #[test]
    fn a_bending_target_gets_the_normals_of_its_bend() {
        // A flat grid and one target that lifts it into a ridge along x: the morphed normals
        // tilt with the slope, the rest normals do not.
        let mesh = grid(8, 4, 0.1);
        let ridge: Vec<[f32; 3]> = mesh
            .positions
            .iter()
            .map(|p| [0.0, 0.0, (p[0] * 6.0).sin() * 0.5])
            .collect();
        let weights: Vec<Vec<f32>> = (0..20).map(|f| vec![0.02 * f as f32]).collect();
        let unskinned = |_| vec![Matrix4::identity(); mesh.positions.len()];
        let fitted = fit(
            &mesh.positions,
            &mesh.triangles,
            std::slice::from_ref(&ridge),
            &weights,
            &[0.0],
            &unskinned,
        );
        let (mut with, mut without) = (0.0, 0.0);
        for w in &weights {
            let points: Vec<[f32; 3]> = mesh
                .positions
                .iter()
                .zip(&ridge)
                .map(|(p, d)| [p[0], p[1], p[2] + w[0] * d[2]])
                .collect();
            let truth = vertex_normals(&points, &mesh.triangles);
            for ((n, d), t) in fitted.base.iter().zip(&fitted.deltas[0]).zip(&truth) {
                let played = [0, 1, 2].map(|a| n[a] + w[0] * d[a]);
                with += angle(played, *t);
                without += angle(*n, *t);
            }
        }
        let count = (weights.len() * mesh.positions.len()) as f32;
        let (with, without) = (with / count, without / count);
        eprintln!("{with:.3}° fitted, {without:.2}° without deltas");
        assert!(
            with < 1.0 && without > 5.0,
            "{with:.2}° fitted, {without:.2}° without deltas"
        );
        // Unit NORMAL attribute.
        for n in &fitted.base {
            let l = n.iter().map(|x| x * x).sum::<f32>().sqrt();
            assert!((l - 1.0).abs() < 1e-5, "{l}");
        }
    }
}
