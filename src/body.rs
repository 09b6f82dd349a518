//! The rigged body (mesh, normals, skin on a skeleton), the body in one pose, and where points
//! lie relative to it. Every model, metric and simulation collides with this one body.

use crate::geometry::{v3, PointIndex, TriMesh};
use crate::rig::{JointTransform, Skeleton, Skin};
use rayon::prelude::*;

/// A rigged body: welded-or-not triangle mesh, per-vertex normals and a skin on a skeleton.
#[derive(Clone, Debug)]
pub struct Body {
    pub name: String,
    pub mesh: TriMesh,
    pub normals: Vec<[f32; 3]>,
    pub skeleton: Skeleton,
    pub skin: Skin,
}

/// Signed distance of each point along the normal of its nearest body vertex (negative: inside).
pub fn body_offsets(
    points: &[[f32; 3]],
    body_points: &[[f32; 3]],
    body_normals: &[[f32; 3]],
    index: &PointIndex,
) -> Vec<f32> {
    nearest_offsets(points, body_points, body_normals, index)
        .into_iter()
        .map(|(_, d)| d)
        .collect()
}

/// Each point's nearest body vertex and its signed distance along that vertex's normal.
pub fn nearest_offsets(
    points: &[[f32; 3]],
    body_points: &[[f32; 3]],
    body_normals: &[[f32; 3]],
    index: &PointIndex,
) -> Vec<(u32, f32)> {
    points
        .iter()
        .map(|p| {
            let (b, _) = index.nearest(*p);
            (b, offset(*p, body_points, body_normals, b))
        })
        .collect()
}

/// Signed distance of `p` along the normal of body vertex `b`.
fn offset(p: [f32; 3], body_points: &[[f32; 3]], body_normals: &[[f32; 3]], b: u32) -> f32 {
    (v3(p) - v3(body_points[b as usize])).dot(&v3(body_normals[b as usize]))
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
    /// Signed distance of `p` along the normal of body vertex `b` (negative: behind it).
    pub fn offset(&self, p: [f32; 3], b: u32) -> f32 {
        offset(p, &self.points, &self.normals, b)
    }

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
