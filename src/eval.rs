//! Evaluation: posing a model over a clip, and the PBNS metrics over posed frames (shared by
//! training validation and `garmentbake eval`). Plain arrays on the CPU, exact nearest
//! neighbours: this is the reference the exporters are compared with.

use crate::garment::nearest_offsets;
use crate::geometry::{face_normals, PointIndex, Topology, TriMesh};
use crate::io::gltf_body::Body;
use crate::models::pose_features::tensor_points;
use crate::models::Pbns;
use crate::rig::{JointTransform, Skeleton, Skin};
use crate::train::losses::GRAVITY;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use tch::Device;

/// Frames posed per forward pass when evaluating a clip.
const CHUNK: usize = 64;

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
    let p = &body.mesh.positions;
    let near: Vec<bool> = p.par_iter().map(|&v| index.nearest(v).1 < reach).collect();
    let pairs = Topology::new(&body.mesh)
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
        let n = face_normals(x, &self.triangles);
        let bend: f64 = self
            .hinges
            .iter()
            .map(|&[a, b]| {
                let (na, nb) = (n[a as usize], n[b as usize]);
                1.0 - (na[0] * nb[0] + na[1] * nb[1] + na[2] * nb[2]) as f64
            })
            .sum();
        let offsets = nearest_offsets(x, &body.points, &body.normals, &body.index);
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
}

fn length(p: &[[f32; 3]], [a, b]: [u32; 2]) -> f32 {
    let (a, b) = (p[a as usize], p[b as usize]);
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// The body in one pose, with its nearest-point index.
pub struct PosedBody {
    pub points: Vec<[f32; 3]>,
    pub normals: Vec<[f32; 3]>,
    pub index: PointIndex,
    /// Vertices inside another part of the body (see [`self_overlap`]).
    pub overlap: Vec<bool>,
}

/// Body vertices closer than this at rest are the same part of the surface.
const SAME_PART: f32 = 0.1;
/// How deep inside another part a vertex can be found.
const OVERLAP_REACH: f32 = 0.05;

/// Which posed body vertices lie inside another part of the body: behind (d·n < 0) the nearest
/// posed vertex within [`OVERLAP_REACH`] that was farther than [`SAME_PART`] at rest. Skinning
/// lets limbs pass through each other (a chin into the chest when the head bows far); in
/// ordinary poses every close vertex was close at rest too, and nothing is flagged.
pub fn self_overlap(
    rest: &[[f32; 3]],
    points: &[[f32; 3]],
    normals: &[[f32; 3]],
    index: &PointIndex,
) -> Vec<bool> {
    let v3 = |p: [f32; 3]| nalgebra::Vector3::from(p);
    (0..points.len())
        .into_par_iter()
        .map(|v| {
            let other = index
                .within(points[v], OVERLAP_REACH)
                .into_iter()
                .filter(|&(u, _)| (v3(rest[u as usize]) - v3(rest[v])).norm() > SAME_PART)
                .min_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
            other.is_some_and(|(u, _)| {
                let u = u as usize;
                (v3(points[v]) - v3(points[u])).dot(&v3(normals[u])) < 0.0
            })
        })
        .collect()
}

impl PosedBody {
    pub fn new(body: &Body, pose: &[JointTransform]) -> PosedBody {
        let skinning = body.skeleton.skinning_matrices(pose);
        let points = body.skin.skin_points(&body.mesh.positions, &skinning);
        let normals = body.skin.skin_normals(&body.normals, &skinning);
        let index = PointIndex::new(&points).expect("a posed body is finite and non-empty");
        let overlap = self_overlap(&body.mesh.positions, &points, &normals, &index);
        PosedBody {
            points,
            normals,
            index,
            overlap,
        }
    }

    /// Every pose, in parallel.
    pub fn many(body: &Body, poses: &[Vec<JointTransform>]) -> Vec<PosedBody> {
        poses.par_iter().map(|p| PosedBody::new(body, p)).collect()
    }
}

/// The model's garment for every pose (world space), in chunks, without gradients.
pub fn model_frames(
    model: &Pbns,
    skeleton: &Skeleton,
    poses: &[Vec<JointTransform>],
    device: Device,
) -> Vec<Vec<[f32; 3]>> {
    let n = model.shape.vertices;
    let mut out = Vec::with_capacity(poses.len());
    tch::no_grad(|| {
        for chunk in poses.chunks(CHUNK) {
            let batch = model.batch(skeleton, chunk, device);
            let points = tensor_points(&model.forward(&batch).vertices);
            out.extend(points.chunks_exact(n).map(<[_]>::to_vec));
        }
    });
    out
}

/// Plain linear blend skinning of the rest garment (the baseline without PSD).
pub fn lbs_frames(
    skin: &Skin,
    rest: &[[f32; 3]],
    skeleton: &Skeleton,
    poses: &[Vec<JointTransform>],
) -> Vec<Vec<[f32; 3]>> {
    poses
        .par_iter()
        .map(|p| skin.skin_points(rest, &skeleton.skinning_matrices(p)))
        .collect()
}

/// Metrics of several garment series over the same clip, and how much the body overlaps itself.
pub struct Comparison {
    /// Mean metrics, one per series.
    pub metrics: Vec<Metrics>,
    /// Mean edge strain |e − e_T| / e_T (%), one per series.
    pub strain_pct: Vec<f64>,
    /// Mean edge strain (%) of the skinned body under the garment: a garment that does not
    /// slide over the body stretches as much.
    pub body_strain_pct: f64,
    /// Body vertices inside another part of the body (see [`self_overlap`]), per frame.
    pub body_overlap: Vec<usize>,
}

/// Mean metrics of several garment series (e.g. model and plain LBS) over the same poses; the
/// body is posed one frame at a time so long clips need little memory.
pub fn compare(
    geometry: &ClothGeometry,
    series: &[&[Vec<[f32; 3]>]],
    body: &Body,
    body_under: &Edges,
    poses: &[Vec<JointTransform>],
) -> Comparison {
    struct Frame {
        metrics: Vec<Metrics>,
        strain: Vec<f64>,
        body_strain: f64,
        overlap: usize,
    }
    let per_frame: Vec<Frame> = poses
        .par_iter()
        .enumerate()
        .map(|(f, pose)| {
            let posed = PosedBody::new(body, pose);
            Frame {
                metrics: series
                    .iter()
                    .map(|s| geometry.frame(&s[f], &posed))
                    .collect(),
                strain: series
                    .iter()
                    .map(|s| geometry.edges.mean_strain_pct(&s[f]))
                    .collect(),
                body_strain: body_under.mean_strain_pct(&posed.points),
                overlap: posed.overlap.iter().filter(|&&o| o).count(),
            }
        })
        .collect();
    let frames = per_frame.len().max(1) as f64;
    Comparison {
        metrics: (0..series.len())
            .map(|k| Metrics::mean(&per_frame.iter().map(|m| m.metrics[k]).collect::<Vec<_>>()))
            .collect(),
        strain_pct: (0..series.len())
            .map(|k| per_frame.iter().map(|m| m.strain[k]).sum::<f64>() / frames)
            .collect(),
        body_strain_pct: per_frame.iter().map(|m| m.body_strain).sum::<f64>() / frames,
        body_overlap: per_frame.iter().map(|m| m.overlap).collect(),
    }
}
