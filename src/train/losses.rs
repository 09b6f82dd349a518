//! The physical potential PBNS minimises, as tensor ops over a batch of posed garments
//! `x: [B, N, 3]`. Every energy is summed over the garment and averaged over the batch; the
//! metric next to it is the figure the papers report (and `eval` prints).

use crate::fabric::{Fabric, GRAVITY};
use crate::geometry::{Topology, TriMesh};
use anyhow::Result;
use tch::{Device, Kind, Tensor};

/// Constant tensors describing the garment for the losses.
pub struct Cloth {
    edge_a: Tensor,
    edge_b: Tensor,
    rest_length: Tensor,
    edge_weight: Tensor,
    face: [Tensor; 3],
    hinge_a: Tensor,
    hinge_b: Tensor,
    hinge_weight: Tensor,
    /// Lumped vertex mass, kg.
    mass: Tensor,
    pinned: Tensor,
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
        Ok(Cloth {
            edge_a: idx(e.iter().map(|e| e[0] as i64).collect()),
            edge_b: idx(e.iter().map(|e| e[1] as i64).collect()),
            rest_length: f32s(e.iter().map(|&e| len(e)).collect()),
            edge_weight: f32s(e.iter().map(|&e| mean(&edge_mul, e)).collect()),
            face: [0, 1, 2].map(|k| idx(mesh.triangles.iter().map(|t| t[k] as i64).collect())),
            hinge_a: idx(h.iter().map(|h| h.faces[0] as i64).collect()),
            hinge_b: idx(h.iter().map(|h| h.faces[1] as i64).collect()),
            hinge_weight: f32s(h.iter().map(|h| mean(&bend_mul, h.edge)).collect()),
            mass: f32s(mass),
            pinned: idx(pinned.iter().map(|&v| v as i64).collect()),
        })
    }

    /// `Σ w_e (|e| − |e_T|)²`; metric: mean |e − e_T| (m).
    pub fn edge(&self, x: &Tensor) -> (Tensor, Tensor) {
        let d = x.index_select(1, &self.edge_a) - x.index_select(1, &self.edge_b);
        let length = (d.square().sum_dim_intlist(-1, false, Kind::Float) + 1e-12).sqrt();
        let error = length - &self.rest_length;
        let energy = (error.square() * &self.edge_weight)
            .sum_dim_intlist(1, false, Kind::Float)
            .mean(Kind::Float);
        (energy, error.detach().abs().mean(Kind::Float))
    }

    /// Unit face normals `[B, F, 3]`.
    pub fn face_normals(&self, x: &Tensor) -> Tensor {
        let [a, b, c] = self.face.each_ref().map(|f| x.index_select(1, f));
        let n = (&b - &a).linalg_cross(&(c - a), -1);
        let len = n
            .square()
            .sum_dim_intlist(-1, true, Kind::Float)
            .clamp_min(1e-20)
            .sqrt();
        n / len
    }

    /// `Σ w_h |n_a − n_b|²` over face-adjacent pairs; metric: mean (1 − cos).
    pub fn bend(&self, x: &Tensor) -> (Tensor, Tensor) {
        let n = self.face_normals(x);
        let (na, nb) = (
            n.index_select(1, &self.hinge_a),
            n.index_select(1, &self.hinge_b),
        );
        let energy = ((&na - &nb).square().sum_dim_intlist(-1, false, Kind::Float)
            * &self.hinge_weight)
            .sum_dim_intlist(1, false, Kind::Float)
            .mean(Kind::Float);
        let cos = (na.detach() * nb.detach()).sum_dim_intlist(-1, false, Kind::Float);
        (energy, (cos.neg() + 1.0).mean(Kind::Float))
    }

    /// `Σ m_i g y_i` (J); the metric is the same energy.
    pub fn gravity(&self, x: &Tensor) -> (Tensor, Tensor) {
        let energy = (x.select(2, 1) * &self.mass)
            .sum_dim_intlist(1, false, Kind::Float)
            .mean(Kind::Float)
            * GRAVITY as f64;
        let metric = energy.detach();
        (energy, metric)
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
