//! The physical potential PBNS minimises, as tensor ops over a batch of posed garments
//! `x: [B, N, 3]`. Every energy is summed over the garment and averaged over the batch; the
//! metric next to it is the figure the papers report (and `eval` prints).

use super::fused::ClothArrays;
use crate::fabric::{Fabric, GRAVITY};
use crate::geometry::{Topology, TriMesh};
use anyhow::Result;
use tch::{Device, Kind, Tensor};

/// Constant tensors describing the garment for the losses. Index lists are concatenated (both
/// ends of every edge, the three corners of every face, both faces of every hinge) so that one
/// gather fetches them all.
pub struct Cloth {
    /// First ends, then second ends `[2E]`.
    edge_ends: Tensor,
    rest_length: Tensor,
    edge_weight: Tensor,
    /// Corners 0, then 1, then 2 of every face `[3F]`.
    face_corners: Tensor,
    /// First faces, then second faces of every hinge `[2H]`.
    hinge_faces: Tensor,
    hinge_weight: Tensor,
    /// Lumped vertex mass, kg.
    mass: Tensor,
    pinned: Tensor,
    /// The same on the CPU, for [`super::fused::potential`].
    pub arrays: ClothArrays,
}

impl Cloth {
    /// Per-edge and per-hinge weights average the per-vertex multipliers of the edge's ends, as
    /// PBNS's outfit config does.
    pub fn new(mesh: &TriMesh, fabric: &Fabric, pinned: &[u32], device: Device) -> Result<Cloth> {
        let topo = Topology::new(mesh);
        let (edge_mul, bend_mul) = fabric.vertex_multipliers(mesh.vertex_count())?;
        let p = &mesh.positions;
        let len = |[a, b]: [u32; 2]| {
            let d: f32 = (0..3)
                .map(|k| (p[a as usize][k] - p[b as usize][k]).powi(2))
                .sum();
            d.sqrt()
        };
        let mean = |m: &[f32], [a, b]: [u32; 2]| 0.5 * (m[a as usize] + m[b as usize]);
        let idx = |v: Vec<i64>| Tensor::from_slice(&v).to_device(device);
        let f32s = |v: Vec<f32>| Tensor::from_slice(&v).to_device(device);
        let e = &topo.edges;
        let h = &topo.hinges;
        let mass: Vec<f32> = mesh
            .vertex_areas()
            .iter()
            .map(|a| a * fabric.density)
            .collect();
        let t = &mesh.triangles;
        let arrays = ClothArrays {
            edges: e.clone(),
            rest_length: e.iter().map(|&e| len(e)).collect(),
            edge_weight: e.iter().map(|&e| mean(&edge_mul, e)).collect(),
            faces: t.clone(),
            hinges: h.iter().map(|h| h.faces).collect(),
            hinge_weight: h.iter().map(|h| mean(&bend_mul, h.edge)).collect(),
            mass,
            pinned: pinned.to_vec(),
        };
        Ok(Cloth {
            edge_ends: idx((0..2)
                .flat_map(|k| e.iter().map(move |e| e[k] as i64))
                .collect()),
            rest_length: f32s(arrays.rest_length.clone()),
            edge_weight: f32s(arrays.edge_weight.clone()),
            face_corners: idx((0..3)
                .flat_map(|k| t.iter().map(move |t| t[k] as i64))
                .collect()),
            hinge_faces: idx((0..2)
                .flat_map(|k| h.iter().map(move |h| h.faces[k] as i64))
                .collect()),
            hinge_weight: f32s(arrays.hinge_weight.clone()),
            mass: f32s(arrays.mass.clone()),
            pinned: idx(pinned.iter().map(|&v| v as i64).collect()),
            arrays,
        })
    }

    /// `Σ w_e (|e| − |e_T|)²`; metric: mean |e − e_T| (m).
    pub fn edge(&self, x: &Tensor) -> (Tensor, Tensor) {
        let [a, b] = split_rows::<2>(&rows(x, &self.edge_ends));
        let length = ((a - b).square().sum_dim_intlist(-1, false, Kind::Float) + 1e-12).sqrt();
        let error = length - &self.rest_length;
        let energy = error.square().matmul(&self.edge_weight).mean(Kind::Float);
        (energy, error.detach().abs().mean(Kind::Float))
    }

    /// Unit face normals `[B, F, 3]`.
    pub fn face_normals(&self, x: &Tensor) -> Tensor {
        let [a, b, c] = split_rows::<3>(&rows(x, &self.face_corners));
        let n = (b - &a).linalg_cross(&(c - a), -1);
        let len = n
            .square()
            .sum_dim_intlist(-1, true, Kind::Float)
            .clamp_min(1e-20)
            .sqrt();
        n / len
    }

    /// `Σ w_h |n_a − n_b|²` over face-adjacent pairs; metric: mean (1 − cos), which for unit
    /// normals is `|n_a − n_b|² / 2`.
    pub fn bend(&self, x: &Tensor) -> (Tensor, Tensor) {
        let [na, nb] = split_rows::<2>(&rows(&self.face_normals(x), &self.hinge_faces));
        let gap = (na - nb).square().sum_dim_intlist(-1, false, Kind::Float);
        let energy = gap.matmul(&self.hinge_weight).mean(Kind::Float);
        (energy, gap.detach().mean(Kind::Float) * 0.5)
    }

    /// `Σ m_i g y_i` (J); the metric is the same energy.
    pub fn gravity(&self, x: &Tensor) -> (Tensor, Tensor) {
        let energy = x.select(2, 1).matmul(&self.mass).mean(Kind::Float) * GRAVITY as f64;
        let metric = energy.detach();
        (energy, metric)
    }

    /// `Σ m_i/(2Δt²)·|x − 2·last + before|²` (J): the inertia of an implicit Euler step of
    /// `Δt` seconds from the two frames before (what makes a garment lag, swing and settle).
    pub fn inertia(&self, x: &Tensor, last: &Tensor, before: &Tensor, dt: f64) -> Tensor {
        let a = x - last * 2.0 + before;
        a.square()
            .sum_dim_intlist(-1, false, Kind::Float)
            .matmul(&self.mass)
            .mean(Kind::Float)
            / (2.0 * dt * dt)
    }

    /// `Σ |D_i|²` over the pinned vertices (rest-space displacement).
    pub fn pin(&self, displacement: &Tensor) -> Tensor {
        if self.pinned.numel() == 0 {
            return Tensor::zeros([], (Kind::Float, displacement.device()));
        }
        displacement
            .index_select(1, &self.pinned)
            .square()
            .sum_dim_intlist([1i64, 2].as_slice(), false, Kind::Float)
            .mean(Kind::Float)
    }
}

/// Rows `index` of `x: [B, N, 3]` along the vertex axis, `[B, len, 3]`. A gather: its backward
/// is one scatter-add, where `index_select`'s is an `index_add` that runs a kernel per index.
fn rows(x: &Tensor, index: &Tensor) -> Tensor {
    let b = x.size()[0];
    x.gather(1, &index.view([1, -1, 1]).expand([b, -1, 3], false), false)
}

/// `[B, K·L, 3]` rows fetched for K concatenated index lists, as K views `[B, L, 3]`.
fn split_rows<const K: usize>(rows: &Tensor) -> [Tensor; K] {
    let len = rows.size()[1] / K as i64;
    std::array::from_fn(|k| rows.narrow(1, k as i64 * len, len))
}

/// `Σ min(d·n − ε, 0)²` with `d` from each vertex's nearest body vertex and `n` its normal;
/// metric: the fraction of vertices with `d·n < 0` (inside the body).
pub fn collision(
    x: &Tensor,
    body_points: &Tensor,
    body_normals: &Tensor,
    margin: f32,
) -> (Tensor, Tensor) {
    let dot = ((x - body_points) * body_normals).sum_dim_intlist(-1, false, Kind::Float);
    let energy = (&dot - margin as f64)
        .clamp_max(0.0)
        .square()
        .sum_dim_intlist(1, false, Kind::Float)
        .mean(Kind::Float);
    let inside = dot.detach().lt(0.0).to_kind(Kind::Float).mean(Kind::Float);
    (energy, inside)
}

/// Names of the loss terms, in the order of [`Terms::weighted`].
pub const TERM_NAMES: [&str; 5] = ["edge", "bend", "collision", "gravity", "pin"];

/// The weighted terms of one step (scalars) and the metrics (detached scalars).
pub struct Terms {
    pub weighted: [Tensor; 5],
    /// Edge error (m), bending (1 − cos), collided fraction, gravity energy (J).
    pub metrics: [Tensor; 4],
}

impl Terms {
    pub fn total(&self) -> Tensor {
        let [a, b, c, d, e] = &self.weighted;
        a + b + c + d + e
    }
}

/// All terms for a batch.
pub fn potential(
    cloth: &Cloth,
    fabric: &Fabric,
    x: &Tensor,
    displacement: &Tensor,
    body_points: &Tensor,
    body_normals: &Tensor,
) -> Terms {
    let (edge, edge_m) = cloth.edge(x);
    let (bend, bend_m) = cloth.bend(x);
    let (coll, coll_m) = collision(x, body_points, body_normals, fabric.margin);
    let (grav, grav_m) = cloth.gravity(x);
    let pin = cloth.pin(displacement);
    Terms {
        weighted: [
            edge * fabric.edge as f64,
            bend * fabric.bend as f64,
            coll * fabric.collision as f64,
            grav,
            pin * fabric.pin as f64,
        ],
        metrics: [edge_m, bend_m, coll_m, grav_m],
    }
}
