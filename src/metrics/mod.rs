//! Garment metrics of posed frames against the posed body: edge error and strain, bending,
//! collided vertices (split at body self-overlap), gravity energy. Plain arrays on the CPU,
//! exact nearest neighbours: shared by training validation, `eval` and the exporters' checks.
//! `deviation`: frames against a reference's, vertex by vertex (reconstructions, replays);
//! `reference_error`: a played garment against simulated reference caches; `ensemble`, `hem`,
//! `plausibility`: what `compare` measures of caches against perturbed simulations.

use crate::body::{Body, PosedBody};
use crate::fabric::GRAVITY;
use crate::geometry::{face_normals, PointIndex, SurfaceIndex, Topology, TriMesh};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

pub mod deviation;
pub mod ensemble;
pub mod hem;
pub mod plausibility;
pub mod reference_error;

/// The PBNS metrics, averaged over frames.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// Mean |e − e_T| over edges, millimetres.
    pub edge_mm: f64,
    /// Mean 1 − cos between the normals of face-adjacent triangles.
    pub bend: f64,
    /// Percentage of vertices inside the body (d·n < 0 w.r.t. the nearest body vertex).
    pub collided_pct: f64,
    /// The part of `collided_pct` whose nearest body vertex is itself inside the body (the body
    /// overlaps itself there, e.g. a bowed head's chin sunk into the chest): no garment can be
    /// outside both parts. Computed against posed bodies only (0 in training-step metrics).
    #[serde(default)]
    pub collided_overlap_pct: f64,
    /// Gravitational potential energy Σ m g y, joules.
    pub gravity_j: f64,
}

impl Metrics {
    pub fn mean(frames: &[Metrics]) -> Metrics {
        let n = frames.len().max(1) as f64;
        let sum = |f: fn(&Metrics) -> f64| frames.iter().map(f).sum::<f64>() / n;
        Metrics {
            edge_mm: sum(|m| m.edge_mm),
            bend: sum(|m| m.bend),
            collided_pct: sum(|m| m.collided_pct),
            collided_overlap_pct: sum(|m| m.collided_overlap_pct),
            gravity_j: sum(|m| m.gravity_j),
        }
    }
}

/// Edges and their rest lengths: the edge-length metrics of a mesh.
pub struct Edges {
    pairs: Vec<[u32; 2]>,
    rest: Vec<f32>,
}

impl Edges {
    pub fn new(rest: &[[f32; 3]], pairs: Vec<[u32; 2]>) -> Edges {
        Edges {
            rest: pairs.iter().map(|&e| length(rest, e)).collect(),
            pairs,
        }
    }

    /// Mean |e − e_T| (metres).
    pub fn mean_error(&self, x: &[[f32; 3]]) -> f64 {
        let sum: f64 = self
            .pairs
            .iter()
            .zip(&self.rest)
            .map(|(&e, &r)| (length(x, e) - r).abs() as f64)
            .sum();
        sum / self.pairs.len().max(1) as f64
    }

    /// Mean |e − e_T| / e_T, percent (edges of zero rest length are skipped).
    pub fn mean_strain_pct(&self, x: &[[f32; 3]]) -> f64 {
        let (sum, n) = self
            .pairs
            .iter()
            .zip(&self.rest)
            .filter(|(_, &r)| r > 0.0)
            .fold((0.0, 0usize), |(s, n), (&e, &r)| {
                (s + ((length(x, e) - r).abs() / r) as f64, n + 1)
            });
        100.0 * sum / n.max(1) as f64
    }
}

/// Body edges whose both ends lie within `reach` of the garment at rest: the skin under it.
pub fn body_edges_under(body: &Body, garment_rest: &[[f32; 3]], reach: f32) -> Edges {
    let index = PointIndex::new(garment_rest).expect("garment is finite and non-empty");
    let p = &body.mesh().positions;
    let near: Vec<bool> = p.par_iter().map(|&v| index.nearest(v).1 < reach).collect();
    let pairs = Topology::new(body.mesh())
        .edges
        .into_iter()
        .filter(|e| e.iter().all(|&v| near[v as usize]))
        .collect();
    Edges::new(p, pairs)
}

/// What the metrics need to know about the garment.
pub struct ClothGeometry {
    pub edges: Edges,
    triangles: Vec<[u32; 3]>,
    hinges: Vec<[u32; 2]>,
    mass: Vec<f32>,
}

impl ClothGeometry {
    pub fn new(rest: &TriMesh, density: f32) -> ClothGeometry {
        let topo = Topology::new(rest);
        ClothGeometry {
            edges: Edges::new(&rest.positions, topo.edges),
            triangles: rest.triangles.clone(),
            hinges: topo.hinges.iter().map(|h| h.faces).collect(),
            mass: rest.vertex_areas().iter().map(|a| a * density).collect(),
        }
    }

    /// Metrics of one posed frame against the posed body.
    pub fn frame(&self, x: &[[f32; 3]], body: &PosedBody) -> Metrics {
        let nearest: Vec<u32> = x.iter().map(|&p| body.index.nearest(p).0).collect();
        self.frame_with(x, body, &nearest)
    }

    /// The same with each garment vertex's nearest body vertex already known.
    pub fn frame_with(&self, x: &[[f32; 3]], body: &PosedBody, nearest: &[u32]) -> Metrics {
        let n = face_normals(x, &self.triangles);
        let bend: f64 = self
            .hinges
            .iter()
            .map(|&[a, b]| {
                let (na, nb) = (n[a as usize], n[b as usize]);
                1.0 - (na[0] * nb[0] + na[1] * nb[1] + na[2] * nb[2]) as f64
            })
            .sum();
        let offsets: Vec<(u32, f32)> = x
            .iter()
            .zip(nearest)
            .map(|(p, &b)| (b, body.offset(*p, b)))
            .collect();
        let inside = offsets.iter().filter(|&&(_, d)| d < 0.0).count();
        let at_overlap = offsets
            .iter()
            .filter(|&&(b, d)| d < 0.0 && body.overlap[b as usize])
            .count();
        let gravity: f64 = x
            .iter()
            .zip(&self.mass)
            .map(|(p, m)| (m * GRAVITY * p[1]) as f64)
            .sum();
        Metrics {
            edge_mm: 1e3 * self.edges.mean_error(x),
            bend: bend / self.hinges.len().max(1) as f64,
            collided_pct: 100.0 * inside as f64 / x.len().max(1) as f64,
            collided_overlap_pct: 100.0 * at_overlap as f64 / x.len().max(1) as f64,
            gravity_j: gravity,
        }
    }

    /// Mean metrics over frames (in parallel).
    pub fn frames(&self, garment: &[Vec<[f32; 3]>], bodies: &[PosedBody]) -> Metrics {
        let per: Vec<Metrics> = garment
            .par_iter()
            .zip(bodies)
            .map(|(x, b)| self.frame(x, b))
            .collect();
        Metrics::mean(&per)
    }

    /// [`ClothGeometry::frames`] with each frame's nearest body vertices already known.
    pub fn frames_with(
        &self,
        garment: &[Vec<[f32; 3]>],
        bodies: &[PosedBody],
        nearest: &[Vec<u32>],
    ) -> Metrics {
        let per: Vec<Metrics> = garment
            .par_iter()
            .zip(bodies)
            .zip(nearest)
            .map(|((x, b), n)| self.frame_with(x, b, n))
            .collect();
        Metrics::mean(&per)
    }
}

/// Garment vertices of one frame inside the posed body by the generalised winding number of the
/// body mesh (≥ 0.5): exact, robust to the body's open holes, and not what training minimises.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct InsideFrame {
    pub vertices: usize,
    /// Distance to the body surface (metres) of every inside vertex.
    pub depths: Vec<f32>,
    /// Inside vertices whose nearest body vertex lies inside another part of the body.
    pub at_overlap: usize,
}

impl InsideFrame {
    /// `x` against the posed body and its surface index (built from the same posed points).
    pub fn of(x: &[[f32; 3]], body: &PosedBody, surface: &SurfaceIndex) -> InsideFrame {
        let mut out = InsideFrame {
            vertices: x.len(),
            ..InsideFrame::default()
        };
        for p in x {
            if surface.is_inside(*p) {
                out.depths.push(surface.distance(*p));
                let (b, _) = body.index.nearest(*p);
                out.at_overlap += usize::from(body.overlap[b as usize]);
            }
        }
        out
    }
}

/// Inside-the-body figures over a clip: share of vertices (mean over frames, %), the part at
/// body self-overlap, and the penetration depth of inside vertices (all frames pooled, mm).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Inside {
    pub inside_pct: f64,
    pub inside_overlap_pct: f64,
    pub depth_p50_mm: f64,
    pub depth_p99_mm: f64,
    pub depth_max_mm: f64,
    /// The frame with the most inside vertices (the first of equals), and how many.
    pub worst_frame: usize,
    pub worst_frame_vertices: usize,
}

impl Inside {
    pub fn of(frames: &[&InsideFrame]) -> Inside {
        let n: usize = frames.iter().map(|f| f.vertices).sum();
        let pct = |k: usize| 100.0 * k as f64 / n.max(1) as f64;
        let mut depths: Vec<f32> = frames
            .iter()
            .flat_map(|f| f.depths.iter().copied())
            .collect();
        depths.sort_by(f32::total_cmp);
        let (worst_frame, worst) = frames
            .iter()
            .enumerate()
            .max_by_key(|(f, x)| (x.depths.len(), std::cmp::Reverse(*f)))
            .map_or((0, 0), |(f, x)| (f, x.depths.len()));
        Inside {
            inside_pct: pct(depths.len()),
            inside_overlap_pct: pct(frames.iter().map(|f| f.at_overlap).sum()),
            depth_p50_mm: 1e3 * percentile(&depths, 0.5),
            depth_p99_mm: 1e3 * percentile(&depths, 0.99),
            depth_max_mm: 1e3 * depths.last().copied().unwrap_or(0.0) as f64,
            worst_frame,
            worst_frame_vertices: worst,
        }
    }
}

/// The nearest-rank `q` quantile of sorted values (0 when there are none).
pub fn percentile(sorted: &[f32], q: f64) -> f64 {
    match sorted.len() {
        0 => 0.0,
        n => sorted[nearest_rank(n, q)] as f64,
    }
}

/// The same quantile of values in any order (reordered in place; NaNs rank above everything,
/// as `f32::total_cmp` sorts them): a selection, not a sort, for millions of distances.
pub fn percentile_unsorted(values: &mut [f32], q: f64) -> f64 {
    match values.len() {
        0 => 0.0,
        n => {
            *values
                .select_nth_unstable_by(nearest_rank(n, q), f32::total_cmp)
                .1 as f64
        }
    }
}

/// The index of the nearest-rank `q` quantile among `n > 0` sorted values.
fn nearest_rank(n: usize, q: f64) -> usize {
    ((q * n as f64).ceil() as usize).clamp(1, n) - 1
}

/// Per-vertex distance (mm) between two frames of one garment.
pub fn vertex_distances_mm(a: &[[f32; 3]], b: &[[f32; 3]]) -> Vec<f64> {
    a.iter()
        .zip(b)
        .map(|(p, q)| 1e3 * f64::from(length(&[*p, *q], [0, 1])))
        .collect()
}

fn length(p: &[[f32; 3]], [a, b]: [u32; 2]) -> f32 {
    let (a, b) = (p[a as usize], p[b as usize]);
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}
