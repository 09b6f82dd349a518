//! The physical potential of [`super::losses`] on the CPU with its gradient written out: one pass
//! over the garment's edges, faces, hinges and vertices per pose instead of some sixty tensor ops
//! and their autograd nodes (which were half of a training step). The training step hands the
//! gradient to autograd as `Σ x·∇E`, so the network's backward is unchanged. Same energies,
//! metrics and weighting as the tensor version, which stays the reference (and the GPU path).

use crate::fabric::{Fabric, GRAVITY};

type V3 = [f32; 3];

/// The garment's constant arrays (what [`super::losses::Cloth`] holds as tensors).
pub struct ClothArrays {
    pub edges: Vec<[u32; 2]>,
    pub rest_length: Vec<f32>,
    pub edge_weight: Vec<f32>,
    pub faces: Vec<[u32; 3]>,
    /// The two faces of each hinge.
    pub hinges: Vec<[u32; 2]>,
    pub hinge_weight: Vec<f32>,
    pub mass: Vec<f32>,
    /// Vertices whose rest-space displacement the pinning term holds at zero.
    pub pinned: Vec<u32>,
}

/// Each garment vertex's candidate body vertices in each pose of the batch.
pub struct Contacts<'a> {
    /// Rows of `points`/`normals`, `per_vertex` per garment vertex, one block per batch pose.
    pub candidates: Vec<&'a [i64]>,
    pub per_vertex: usize,
    pub points: &'a [V3],
    pub normals: &'a [V3],
}

/// Weighted energies (edge, bend, collision, gravity; batch means), the metrics (edge error m,
/// 1 − cos, collided fraction, gravity J) and `∂(Σ weighted)/∂x`, laid out like `x`.
pub struct FusedTerms {
    pub weighted: [f64; 4],
    pub metrics: [f64; 4],
    pub grad: Vec<f32>,
}

/// The potential of the garments `x` (`batch` poses × N vertices × 3, row-major).
pub fn potential(
    cloth: &ClothArrays,
    fabric: &Fabric,
    x: &[f32],
    batch: usize,
    contacts: &Contacts,
) -> FusedTerms {
    let n = cloth.mass.len();
    let mut grad = vec![0.0f32; x.len()];
    let mut sums = [0.0f64; 8];
    let mut normals = vec![[0.0f32; 3]; cloth.faces.len()];
    let mut normal_grad = vec![[0.0f32; 3]; cloth.faces.len()];
    let scale = 1.0 / batch as f32;
    for b in 0..batch {
        let xb: &[V3] = as_points(&x[b * n * 3..(b + 1) * n * 3]);
        let gb: &mut [V3] = as_points_mut(&mut grad[b * n * 3..(b + 1) * n * 3]);
        let (e, e_m) = edge(cloth, xb, gb, scale * fabric.edge);
        let (h, h_m) = bend(
            cloth,
            xb,
            gb,
            scale * fabric.bend,
            &mut normals,
            &mut normal_grad,
        );
        let (c, c_m) = collision(xb, gb, scale * fabric.collision, fabric.margin, contacts, b);
        let g = gravity(cloth, xb, gb, scale);
        for (s, v) in sums.iter_mut().zip([e, h, c, g, e_m, h_m, c_m, g]) {
            *s += v;
        }
    }
    let mean = 1.0 / batch as f64;
    let (edges, hinges) = (cloth.edges.len().max(1), cloth.hinges.len().max(1));
    // Summed in f64, reported as the f32 the loss is: a term beyond f32 range is infinite, as
    // in the tensor version, and stops training with its name.
    let f32_range = |v: f64| v as f32 as f64;
    FusedTerms {
        weighted: [
            f32_range(sums[0] * mean * fabric.edge as f64),
            f32_range(sums[1] * mean * fabric.bend as f64),
            f32_range(sums[2] * mean * fabric.collision as f64),
            f32_range(sums[3] * mean),
        ],
        metrics: [
            sums[4] * mean / edges as f64,
            sums[5] * mean / hinges as f64,
            sums[6] * mean / n.max(1) as f64,
            sums[7] * mean,
        ],
        grad,
    }
}

/// The pinning term `weight · mean_b Σ_pinned |D|²` of the rest-space displacement `D`
/// (`batch` × N × 3); adds its gradient to `grad` (laid out like `D`).
pub fn pin(
    cloth: &ClothArrays,
    weight: f32,
    displacement: &[f32],
    batch: usize,
    grad: &mut [f32],
) -> f64 {
    let n = cloth.mass.len();
    let scale = 2.0 * weight / batch as f32;
    let mut sum = 0.0f64;
    for b in 0..batch {
        for &v in &cloth.pinned {
            let i = 3 * (b * n + v as usize);
            for (d, g) in displacement[i..i + 3].iter().zip(&mut grad[i..i + 3]) {
                sum += (d * d) as f64;
                *g += scale * d;
            }
        }
    }
    sum / batch as f64 * weight as f64
}

/// `Σ w_e (|e| − |e_T|)²` and `Σ |e − e_T|`; adds `k ∂/∂x` of the energy to `g`.
fn edge(c: &ClothArrays, x: &[V3], g: &mut [V3], k: f32) -> (f64, f64) {
    let (mut energy, mut error_sum) = (0.0f64, 0.0f64);
    for (i, &[a, b]) in c.edges.iter().enumerate() {
        let d = sub(x[a as usize], x[b as usize]);
        let length = (dot(d, d) + 1e-12).sqrt();
        let error = length - c.rest_length[i];
        energy += (c.edge_weight[i] * error * error) as f64;
        error_sum += error.abs() as f64;
        let f = scaled(d, k * 2.0 * c.edge_weight[i] * error / length);
        add_to(&mut g[a as usize], f);
        add_to(&mut g[b as usize], neg(f));
    }
    (energy, error_sum)
}

/// `Σ w_h |n_a − n_b|²` and `Σ |n_a − n_b|² / 2` (= 1 − cos for unit normals); adds `k ∂/∂x`.
fn bend(
    c: &ClothArrays,
    x: &[V3],
    g: &mut [V3],
    k: f32,
    normals: &mut [V3],
    normal_grad: &mut [V3],
) -> (f64, f64) {
    for (n, &[a, b, cc]) in normals.iter_mut().zip(&c.faces) {
        let raw = face_normal(x, a, b, cc);
        *n = scaled(raw, 1.0 / dot(raw, raw).max(1e-20).sqrt());
    }
    normal_grad.fill([0.0; 3]);
    let (mut energy, mut gap_sum) = (0.0f64, 0.0f64);
    for (i, &[fa, fb]) in c.hinges.iter().enumerate() {
        let d = sub(normals[fa as usize], normals[fb as usize]);
        let gap = dot(d, d);
        energy += (c.hinge_weight[i] * gap) as f64;
        gap_sum += gap as f64;
        let f = scaled(d, k * 2.0 * c.hinge_weight[i]);
        add_to(&mut normal_grad[fa as usize], f);
        add_to(&mut normal_grad[fb as usize], neg(f));
    }
    for ((&[a, b, cc], n), gn) in c.faces.iter().zip(&*normals).zip(&*normal_grad) {
        let raw = face_normal(x, a, b, cc);
        let len2 = dot(raw, raw);
        // Through n = ñ/|ñ|: (g − n (n·g)) / |ñ|; below the clamp n = ñ/1e-10 is linear.
        let g_raw = if len2 > 1e-20 {
            scaled(sub(*gn, scaled(*n, dot(*n, *gn))), 1.0 / len2.sqrt())
        } else {
            scaled(*gn, 1e10)
        };
        // ñ = u × v with u = b − a, v = c − a: ∂/∂u = v × g, ∂/∂v = g × u.
        let (u, v) = (
            sub(x[b as usize], x[a as usize]),
            sub(x[cc as usize], x[a as usize]),
        );
        let (gu, gv) = (cross(v, g_raw), cross(g_raw, u));
        add_to(&mut g[b as usize], gu);
        add_to(&mut g[cc as usize], gv);
        add_to(
            &mut g[a as usize],
            neg([gu[0] + gv[0], gu[1] + gv[1], gu[2] + gv[2]]),
        );
    }
    (energy, 0.5 * gap_sum)
}

/// `Σ min(d·n − ε, 0)²` against each vertex's nearest candidate body vertex, and the count of
/// vertices behind its normal; adds `k ∂/∂x`.
fn collision(
    x: &[V3],
    g: &mut [V3],
    k: f32,
    margin: f32,
    contacts: &Contacts,
    pose: usize,
) -> (f64, f64) {
    let (mut energy, mut inside) = (0.0f64, 0.0f64);
    let rows = contacts.candidates[pose];
    for (v, (p, gv)) in x.iter().zip(g.iter_mut()).enumerate() {
        let list = &rows[v * contacts.per_vertex..(v + 1) * contacts.per_vertex];
        // The first nearest candidate, as argmin picks it.
        let mut best = (f32::INFINITY, list[0] as usize);
        for &r in list {
            let d = sub(contacts.points[r as usize], *p);
            let d2 = dot(d, d);
            if d2 < best.0 {
                best = (d2, r as usize);
            }
        }
        let normal = contacts.normals[best.1];
        let depth = dot(sub(*p, contacts.points[best.1]), normal);
        if depth < 0.0 {
            inside += 1.0;
        }
        let gap = (depth - margin).min(0.0);
        energy += (gap * gap) as f64;
        add_to(gv, scaled(normal, k * 2.0 * gap));
    }
    (energy, inside)
}

/// `Σ m_i g y_i`; adds `k ∂/∂x`.
fn gravity(c: &ClothArrays, x: &[V3], g: &mut [V3], k: f32) -> f64 {
    let mut energy = 0.0f64;
    for ((p, gv), &m) in x.iter().zip(g.iter_mut()).zip(&c.mass) {
        energy += (m * p[1]) as f64;
        gv[1] += k * m * GRAVITY;
    }
    energy * GRAVITY as f64
}

fn face_normal(x: &[V3], a: u32, b: u32, c: u32) -> V3 {
    let a = x[a as usize];
    cross(sub(x[b as usize], a), sub(x[c as usize], a))
}

fn as_points(x: &[f32]) -> &[V3] {
    let (points, rest) = x.as_chunks::<3>();
    debug_assert!(rest.is_empty());
    points
}

fn as_points_mut(x: &mut [f32]) -> &mut [V3] {
    let (points, rest) = x.as_chunks_mut::<3>();
    debug_assert!(rest.is_empty());
    points
}

fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn neg(a: V3) -> V3 {
    [-a[0], -a[1], -a[2]]
}

fn dot(a: V3, b: V3) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn scaled(a: V3, s: f32) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

fn add_to(a: &mut V3, b: V3) {
    a[0] += b[0];
    a[1] += b[1];
    a[2] += b[2];
}
