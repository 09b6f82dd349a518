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

use crate::geometry::normals::vertex_normals;
use nalgebra::{DMatrix, Matrix4, Vector3};
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
    // The corner angles' triangles as index lanes, once for every sample.
    let corners = Corners::new(triangles, base.len());
    let mut y = vec![0.0f64; CHUNK.min(samples.len()) * n3];
    // The targets as one `[K, 3N]` matrix, once: each chunk's offsets are one product with it.
    let shapes: Vec<f32> = targets.iter().flatten().flatten().copied().collect();
    let shapes = Tensor::from_slice(&shapes).view([k as i64, n3 as i64]);
    let mut offsets = vec![0.0f32; CHUNK.min(samples.len()) * n3];
    for chunk in samples.chunks(CHUNK) {
        let weights: Vec<f32> = chunk.iter().flat_map(|w| w.1.iter().copied()).collect();
        let weights = Tensor::from_slice(&weights).view([chunk.len() as i64, k as i64]);
        let offsets = &mut offsets[..chunk.len() * n3];
        weights.matmul(&shapes).copy_data(offsets, chunk.len() * n3);
        let x =
            Tensor::cat(&[&weights, &weights.ones_like().narrow(1, 0, 1)], 1).to_kind(Kind::Double);
        // Samples as rows (frames × 3N, f64), so XᵀY is one matrix product.
        let rows = &mut y[..chunk.len() * n3];
        rows.par_chunks_mut(n3).enumerate().for_each_init(
            || Scratch::new(base.len()),
            |scratch, (f, row)| {
                let column = &offsets[f * n3..(f + 1) * n3];
                for ((p, b), d) in scratch
                    .points
                    .iter_mut()
                    .zip(base)
                    .zip(column.chunks_exact(3))
                {
                    *p = [b[0] + d[0], b[1] + d[1], b[2] + d[2]];
                }
                match chunk[f].0 {
                    Some(frame) => unskinned_normals(scratch, &corners, &blended(frame), row),
                    None => {
                        corners.normals(&scratch.points, &mut scratch.sums);
                        for (out, n) in row.chunks_exact_mut(3).zip(&scratch.sums) {
                            out.copy_from_slice(&n.map(f64::from));
                        }
                    }
                }
            },
        );
        // SAFETY: `rows` is a live f64 buffer of exactly chunk × 3N values, row-major as the
        // strides say; the tensor viewing it is only read by the product below and dropped at
        // the end of this iteration, before `rows` is written again.
        let y = unsafe {
            Tensor::from_blob(
                rows.as_ptr().cast::<u8>(),
                &[chunk.len() as i64, n3 as i64],
                &[n3 as i64, 1],
                Kind::Double,
                tch::Device::Cpu,
            )
        };
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

/// One worker's buffers for the samples it fits, reused from sample to sample.
struct Scratch {
    /// The sample's rest-space points.
    points: Vec<[f32; 3]>,
    /// Those points skinned.
    world: Vec<[f32; 3]>,
    /// Per vertex, the corner-angle sum, then the unit normal.
    sums: Vec<[f32; 3]>,
}

impl Scratch {
    fn new(vertices: usize) -> Scratch {
        Scratch {
            points: vec![[0.0; 3]; vertices],
            world: vec![[0.0; 3]; vertices],
            sums: vec![[0.0; 3]; vertices],
        }
    }
}

/// The world-space normals of `scratch.points` skinned by `blended`, each taken back through
/// its vertex's matrix (`A⁻¹ n`, unit): the rest-space normal that skinning turns into `n`;
/// written to `out` (`[N * 3]`).
fn unskinned_normals(
    scratch: &mut Scratch,
    corners: &Corners,
    blended: &[Matrix4<f32>],
    out: &mut [f64],
) {
    for ((q, p), m) in scratch.world.iter_mut().zip(&scratch.points).zip(blended) {
        let r = m.fixed_view::<3, 3>(0, 0) * Vector3::from(*p) + m.fixed_view::<3, 1>(0, 3);
        *q = [r.x, r.y, r.z];
    }
    corners.normals(&scratch.world, &mut scratch.sums);
    for ((out, n), m) in out.chunks_exact_mut(3).zip(&scratch.sums).zip(blended) {
        let back = back_through(m, *n);
        out.copy_from_slice(&back.map(f64::from));
    }
}

/// `A⁻¹ n` made unit (left as it is when shorter than 1e-12), `A` the upper-left 3 × 3 of `m`,
/// through its adjugate; `n` itself where `A` is singular.
#[inline]
fn back_through(m: &Matrix4<f32>, n: [f32; 3]) -> [f32; 3] {
    let a = |r: usize, c: usize| m[(r, c)];
    // Cofactors C[r][c] of A.
    let c = [
        [
            a(1, 1) * a(2, 2) - a(1, 2) * a(2, 1),
            a(1, 2) * a(2, 0) - a(1, 0) * a(2, 2),
            a(1, 0) * a(2, 1) - a(1, 1) * a(2, 0),
        ],
        [
            a(0, 2) * a(2, 1) - a(0, 1) * a(2, 2),
            a(0, 0) * a(2, 2) - a(0, 2) * a(2, 0),
            a(0, 1) * a(2, 0) - a(0, 0) * a(2, 1),
        ],
        [
            a(0, 1) * a(1, 2) - a(0, 2) * a(1, 1),
            a(0, 2) * a(1, 0) - a(0, 0) * a(1, 2),
            a(0, 0) * a(1, 1) - a(0, 1) * a(1, 0),
        ],
    ];
    let det = a(0, 0) * c[0][0] + a(0, 1) * c[0][1] + a(0, 2) * c[0][2];
    if det == 0.0 {
        return n;
    }
    // A⁻¹ = Cᵀ / det.
    let back = [0, 1, 2].map(|i| (c[0][i] * n[0] + c[1][i] * n[1] + c[2][i] * n[2]) / det);
    let length = back.iter().map(|x| x * x).sum::<f32>().sqrt();
    if length > 1e-12 {
        back.map(|x| x / length)
    } else {
        back
    }
}

/// Triangles in lanes of [`LANES`], padded with degenerate ones (which add nothing).
const LANES: usize = 8;

/// A mesh's triangles as index lanes, for [`Corners::normals`].
struct Corners {
    /// Per lane chunk, the first, second and third corners of its triangles.
    lanes: Vec<[[u32; LANES]; 3]>,
    vertices: usize,
}

impl Corners {
    fn new(triangles: &[[u32; 3]], vertices: usize) -> Corners {
        let lanes = triangles
            .chunks(LANES)
            .map(|chunk| {
                let mut out = [[0u32; LANES]; 3];
                for (l, tri) in chunk.iter().enumerate() {
                    (0..3).for_each(|c| out[c][l] = tri[c]);
                }
                out
            })
            .collect();
        Corners { lanes, vertices }
    }

    /// [`vertex_normals`] of `positions` (each face's unit normal weighted by its corner angle at
    /// the vertex) into `out`, with a polynomial arctangent (within 1e-5 rad), the third
    /// corner's angle as π minus the other two, and every corner's `|u × v|` the face's
    /// doubled area: the fit computes the normals of a few hundred frames, and `atan2` was most
    /// of it. Eight triangles at a time in SIMD lanes, summed into the vertices in triangle
    /// order.
    fn normals(&self, positions: &[[f32; 3]], out: &mut Vec<[f32; 3]>) {
        assert_eq!(positions.len(), self.vertices, "one position per vertex");
        out.clear();
        out.resize(self.vertices, [0.0; 3]);
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2 (checked just above), the function's only requirement.
            unsafe { self.sums_avx2(positions, out) };
            normalize(out);
            return;
        }
        self.sums(positions, out);
        normalize(out);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn sums_avx2(&self, positions: &[[f32; 3]], out: &mut [[f32; 3]]) {
        self.sums(positions, out)
    }

    #[inline(always)]
    fn sums(&self, positions: &[[f32; 3]], out: &mut [[f32; 3]]) {
        type Lane = [f32; LANES];
        for corners in &self.lanes {
            // Per axis, the corners' coordinates in lanes.
            let gather = |c: usize| -> [Lane; 3] {
                let mut p = [[0.0; LANES]; 3];
                for (l, &v) in corners[c].iter().enumerate() {
                    let q = positions[v as usize];
                    (0..3).for_each(|axis| p[axis][l] = q[axis]);
                }
                p
            };
            let (a, b, c) = (gather(0), gather(1), gather(2));
            let sub = |p: &[Lane; 3], q: &[Lane; 3]| -> [Lane; 3] {
                std::array::from_fn(|axis| std::array::from_fn(|l| p[axis][l] - q[axis][l]))
            };
            let dot = |p: &[Lane; 3], q: &[Lane; 3]| -> Lane {
                std::array::from_fn(|l| p[0][l] * q[0][l] + p[1][l] * q[1][l] + p[2][l] * q[2][l])
            };
            let (ab, ac, bc, ba) = (sub(&b, &a), sub(&c, &a), sub(&c, &b), sub(&a, &b));
            let n: [Lane; 3] = [
                std::array::from_fn(|l| ab[1][l] * ac[2][l] - ab[2][l] * ac[1][l]),
                std::array::from_fn(|l| ab[2][l] * ac[0][l] - ab[0][l] * ac[2][l]),
                std::array::from_fn(|l| ab[0][l] * ac[1][l] - ab[1][l] * ac[0][l]),
            ];
            let length: Lane = dot(&n, &n).map(f32::sqrt);
            let (cos_a, cos_b) = (dot(&ab, &ac), dot(&bc, &ba));
            let mut weights = [[0.0f32; LANES]; 3];
            let mut unit = [[0.0f32; LANES]; 3];
            for l in 0..LANES {
                let at_a = atan2_lane(length[l], cos_a[l]);
                let at_b = atan2_lane(length[l], cos_b[l]);
                let at_c = std::f32::consts::PI - at_a - at_b;
                weights[0][l] = at_a;
                weights[1][l] = at_b;
                weights[2][l] = if at_c > 0.0 { at_c } else { 0.0 };
                (0..3).for_each(|axis| unit[axis][l] = n[axis][l] / length[l]);
            }
            for l in 0..LANES {
                if !(length[l] > f32::MIN_POSITIVE && length[l].is_finite()) {
                    continue;
                }
                for (c, weight) in weights.iter().enumerate() {
                    let sum = &mut out[corners[c][l] as usize];
                    (0..3).for_each(|axis| sum[axis] += unit[axis][l] * weight[l]);
                }
            }
        }
    }
}

/// Each corner-angle sum made unit (zero where it has no length).
fn normalize(sums: &mut [[f32; 3]]) {
    for s in sums {
        let length = (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]).sqrt();
        *s = if length > f32::MIN_POSITIVE && length.is_finite() {
            s.map(|x| x / length)
        } else {
            [0.0; 3]
        };
    }
}

/// [`Corners::normals`] of one mesh.
#[cfg(test)]
fn corner_angle_normals(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> Vec<[f32; 3]> {
    let mut out = Vec::new();
    Corners::new(triangles, positions.len()).normals(positions, &mut out);
    out
}

/// `atan2(y, x)` for `y ≥ 0` (an angle in [0, π]) within 1e-5 rad (Abramowitz & Stegun 4.4.49's
/// polynomial on [0, 1]), without branches, for the lanes.
#[inline(always)]
fn atan2_lane(y: f32, x: f32) -> f32 {
    let ax = x.abs();
    let (small, large) = if ax >= y { (y, ax) } else { (ax, y) };
    let t = if large > 0.0 { small / large } else { 0.0 };
    let t2 = t * t;
    let a = t
        * (0.999_977_26
            + t2 * (-0.332_623_47
                + t2 * (0.193_543_46
                    + t2 * (-0.116_432_87 + t2 * (0.052_653_32 - t2 * 0.011_721_2)))));
    let a = if ax >= y {
        a
    } else {
        std::f32::consts::FRAC_PI_2 - a
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
            assert!((atan2_lane(y, x) - y.atan2(x)).abs() < 2e-5, "{t}");
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
    fn the_adjugate_takes_a_normal_back_as_the_inverse_does() {
        // `back_through` against nalgebra's inverse, made unit, on skinning-like matrices
        // (rotation-ish, scaled, sheared, mirrored), and the singular case keeping the normal.
        let noise = |i: usize| ((i.wrapping_mul(2_654_435_761) >> 7) % 2000) as f32 / 1000.0 - 1.0;
        for case in 0..200 {
            let mut m = Matrix4::identity() * (0.5 + case as f32 / 200.0);
            for r in 0..3 {
                for c in 0..4 {
                    m[(r, c)] += noise(16 * case + 4 * r + c) * 0.4;
                }
            }
            if case % 7 == 0 {
                m[(0, 0)] = -m[(0, 0)];
            }
            let n = [0, 1, 2].map(|a| noise(5000 + 3 * case + a));
            let a: nalgebra::Matrix3<f32> = m.fixed_view::<3, 3>(0, 0).into_owned();
            let expected: Vector3<f32> = (a.try_inverse().unwrap() * Vector3::from(n)).normalize();
            let got = back_through(&m, n);
            for k in 0..3 {
                assert!(
                    (got[k] - expected[k]).abs() < 1e-4,
                    "{case}: {got:?} {expected:?}"
                );
            }
        }
        let mut flat = Matrix4::identity();
        flat[(2, 2)] = 0.0;
        assert_eq!(back_through(&flat, [0.0, 0.6, 0.8]), [0.0, 0.6, 0.8]);
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
