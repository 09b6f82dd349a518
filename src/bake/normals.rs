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
use nalgebra::{DMatrix, Matrix3, Matrix4, Vector3};
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
    // Regressors [w_1 … w_K, 1] per sample: G = XᵀX, B = XᵀY with Y the samples' normals
    // (libtorch's BLAS, f64).
    use tch::{Kind, Tensor};
    let mut gram = Tensor::zeros(
        [k as i64 + 1, k as i64 + 1],
        (Kind::Double, tch::Device::Cpu),
    );
    let mut xty = Tensor::zeros([k as i64 + 1, n3 as i64], (Kind::Double, tch::Device::Cpu));
    for chunk in samples.chunks(CHUNK) {
        let x: Vec<f32> = chunk
            .iter()
            .flat_map(|w| (0..=k).map(|c| w.1.get(c).copied().unwrap_or(1.0)))
            .collect();
        let x = Tensor::from_slice(&x)
            .view([chunk.len() as i64, k as i64 + 1])
            .to_kind(Kind::Double);
        let owned: Vec<Vec<f32>> = chunk.iter().map(|w| w.1.to_vec()).collect();
        let offsets = offset_matrix(targets, &owned);
        let normals: Vec<Vec<[f32; 3]>> = (0..chunk.len())
            .into_par_iter()
            .map(|f| {
                let column = offsets.column(f);
                let points: Vec<[f32; 3]> = base
                    .iter()
                    .zip(column.as_slice().chunks_exact(3))
                    .map(|(p, d)| [p[0] + d[0], p[1] + d[1], p[2] + d[2]])
                    .collect();
                match chunk[f].0 {
                    Some(frame) => unskinned_normals(&points, triangles, &blended(frame)),
                    None => corner_angle_normals(&points, triangles),
                }
            })
            .collect();
        // Samples as rows (frames × 3N), so XᵀY is one matrix product.
        let y = Tensor::from_slice(normals.concat().as_flattened())
            .view([chunk.len() as i64, n3 as i64])
            .to_kind(Kind::Double);
        gram += x.tr().matmul(&x);
        xty += x.tr().matmul(&y);
    }
    // A target whose weight never moves is a copy of the constant column: a small ridge keeps
    // the system solvable and gives such a target no normal delta.
    let mut gram = DMatrix::from_row_slice(
        k + 1,
        k + 1,
        &Vec::<f64>::try_from(&gram.view([-1])).expect("f64"),
    );
    let ridge = 1e-9 * gram.trace() / (k + 1) as f64;
    for d in 0..=k {
        gram[(d, d)] += ridge;
    }
    let Some(inverse) = gram.cholesky().map(|c| c.inverse()) else {
        return fit(base, triangles, &[], &[], &[], blended).with_zero_deltas(k);
    };
    // β = G⁻¹ XᵀY, `[K + 1][3N]` row-major.
    let inverse =
        Tensor::from_slice(inverse.transpose().as_slice()).view([k as i64 + 1, k as i64 + 1]);
    let beta: Vec<f64> = Vec::try_from(&inverse.matmul(&xty).contiguous().view([-1])).expect("f64");
    let beta = |t: usize, r: usize| beta[t * n3 + r];
    // Per vertex, intercept and deltas scaled by one factor so the intercept is unit (validators
    // want a unit NORMAL); readers normalise the sum, so the played direction is unchanged.
    let mut normals = vec![[0.0f32; 3]; base.len()];
    let mut deltas = vec![vec![[0.0f32; 3]; base.len()]; k];
    let fallback = vertex_normals(base, triangles);
    for v in 0..base.len() {
        let c = [0, 1, 2].map(|a| beta(k, 3 * v + a));
        let length = c.iter().map(|x| x * x).sum::<f64>().sqrt();
        if length < 1e-6 {
            normals[v] = fallback[v];
            continue;
        }
        normals[v] = c.map(|x| (x / length) as f32);
        for (t, delta) in deltas.iter_mut().enumerate() {
            delta[v] = [0, 1, 2].map(|a| (beta(t, 3 * v + a) / length) as f32);
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
        .map(|(p, m)| {
            let q = m.fixed_view::<3, 3>(0, 0) * Vector3::from(*p) + m.fixed_view::<3, 1>(0, 3);
            [q.x, q.y, q.z]
        })
        .collect();
    corner_angle_normals(&world, triangles)
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

/// [`vertex_normals`] (each face's unit normal weighted by its corner angle at the vertex) with a
/// polynomial arctangent (within 1e-5 rad) and the third corner's angle as π minus the other
/// two: the fit computes the normals of a few hundred frames, and `atan2` was most of it.
fn corner_angle_normals(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> Vec<[f32; 3]> {
    let sub = |a: [f32; 3], b: [f32; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let cross = |a: [f32; 3], b: [f32; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let dot = |a: [f32; 3], b: [f32; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let norm = |a: [f32; 3]| dot(a, a).sqrt();
    // The angle between u and v: atan2(|u × v|, u · v).
    let angle = |u: [f32; 3], v: [f32; 3]| atan2_nonnegative(norm(cross(u, v)), dot(u, v));
    let mut sums = vec![[0.0f32; 3]; positions.len()];
    for tri in triangles {
        let [a, b, c] = tri.map(|i| positions[i as usize]);
        let n = cross(sub(b, a), sub(c, a));
        let length = norm(n);
        if !(length > f32::MIN_POSITIVE && length.is_finite()) {
            continue;
        }
        let n = n.map(|x| x / length);
        let at_a = angle(sub(b, a), sub(c, a));
        let at_b = angle(sub(c, b), sub(a, b));
        let at_c = (std::f32::consts::PI - at_a - at_b).max(0.0);
        for (&v, weight) in tri.iter().zip([at_a, at_b, at_c]) {
            let sum = &mut sums[v as usize];
            (0..3).for_each(|k| sum[k] += n[k] * weight);
        }
    }
    sums.into_iter()
        .map(|s| {
            let length = norm(s);
            if length > f32::MIN_POSITIVE && length.is_finite() {
                s.map(|x| x / length)
            } else {
                [0.0; 3]
            }
        })
        .collect()
}

/// `atan2(y, x)` for `y ≥ 0` (an angle in [0, π]) within 1e-5 rad (Abramowitz & Stegun 4.4.49's
/// polynomial on [0, 1]).
fn atan2_nonnegative(y: f32, x: f32) -> f32 {
    let atan_unit = |t: f32| {
        let t2 = t * t;
        t * (0.999_977_26
            + t2 * (-0.332_623_47
                + t2 * (0.193_543_46
                    + t2 * (-0.116_432_87 + t2 * (0.052_653_32 - t2 * 0.011_721_2)))))
    };
    let ax = x.abs();
    let a = if y == 0.0 && ax == 0.0 {
        0.0
    } else if ax >= y {
        atan_unit(y / ax)
    } else {
        std::f32::consts::FRAC_PI_2 - atan_unit(ax / y)
    };
    if x < 0.0 {
        std::f32::consts::PI - a
    } else {
        a
    }
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
    fn the_fast_corner_angle_normals_are_the_geometry_modules() {
        // The same normals as `vertex_normals` (to f32 and the arctangent's 1e-5 rad), on a
        // crumpled grid; and the arctangent itself over every quadrant it is used in.
        for i in 0..=2000 {
            let t = i as f32 / 2000.0 * std::f32::consts::PI;
            let (y, x) = (t.sin().abs() * 3.0, t.cos() * 3.0);
            assert!((atan2_nonnegative(y, x) - y.atan2(x)).abs() < 2e-5, "{t}");
        }
        let mut mesh = grid(12, 9, 0.1);
        for (i, p) in mesh.positions.iter_mut().enumerate() {
            p[2] = ((i * 7919) % 13) as f32 * 0.013 - 0.08;
        }
        let exact = vertex_normals(&mesh.positions, &mesh.triangles);
        let fast = corner_angle_normals(&mesh.positions, &mesh.triangles);
        let worst = exact
            .iter()
            .zip(&fast)
            .map(|(a, b)| angle(*a, *b))
            .fold(0.0f32, f32::max);
        assert!(worst < 0.01, "{worst}°");
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
