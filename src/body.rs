//! The rigged body (mesh, normals, skin on a skeleton), the body in one pose, and where points
//! lie relative to it. Every model, metric and simulation collides with this one body.

use crate::geometry::{distance, distance2, v3, PointIndex, TriMesh};
use crate::rig::{JointTransform, Skeleton, Skin};
use rayon::prelude::*;
use std::sync::OnceLock;

/// A rigged body: welded-or-not triangle mesh, per-vertex normals and a skin on a skeleton.
#[derive(Clone, Debug)]
pub struct Body {
    pub name: String,
    /// Private: the patch cache below is built from it, so it must not change after [`Body::new`].
    mesh: TriMesh,
    pub normals: Vec<[f32; 3]>,
    pub skeleton: Skeleton,
    pub skin: Skin,
    /// The rest surface in patches for [`self_overlap`], built on first use: it depends on the
    /// body alone, and every posed frame needs it.
    patches: OnceLock<RestPatches>,
}

impl Body {
    /// A body from its parts (the readers' one constructor: the patch cache starts empty).
    pub fn new(
        name: String,
        mesh: TriMesh,
        normals: Vec<[f32; 3]>,
        skeleton: Skeleton,
        skin: Skin,
    ) -> Body {
        Body {
            name,
            mesh,
            normals,
            skeleton,
            skin,
            patches: OnceLock::new(),
        }
    }

    /// The rest mesh (metres, bind pose).
    pub fn mesh(&self) -> &TriMesh {
        &self.mesh
    }

    fn rest_patches(&self) -> &RestPatches {
        self.patches
            .get_or_init(|| RestPatches::new(&self.mesh.positions))
    }
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
///
/// Searched patch by patch ([`RestPatches`]): a vertex's posed neighbourhood is mostly its own
/// part of the surface, so patches that were certainly within [`SAME_PART`] at rest are skipped
/// whole, and only the vertices of the others are measured.
fn self_overlap(
    patches: &RestPatches,
    rest: &[[f32; 3]],
    points: &[[f32; 3]],
    normals: &[[f32; 3]],
) -> Vec<bool> {
    let posed = patches.posed(points);
    let farthest = posed.radius.iter().copied().fold(0.0, f32::max);
    let Ok(centres) = PointIndex::new(&posed.centre) else {
        return vec![false; points.len()];
    };
    let mut overlap = vec![false; points.len()];
    let found: Vec<Vec<(u32, bool)>> = (0..patches.members.len())
        .into_par_iter()
        .map(|a| {
            let reach = OVERLAP_REACH + posed.radius[a] + farthest + BOUND_SLACK;
            let others: Vec<usize> = centres
                .within(posed.centre[a], reach)
                .into_iter()
                .map(|(b, _)| b as usize)
                .filter(|&b| patches.may_be_apart(a, b))
                .collect();
            patches.members[a]
                .iter()
                .map(|&v| {
                    let p = points[v as usize];
                    let other = others
                        .iter()
                        .flat_map(|&b| patches.members[b].iter().copied())
                        .filter_map(|u| {
                            let d2 = distance2(p, points[u as usize]);
                            (d2 <= OVERLAP_REACH * OVERLAP_REACH).then(|| (u, d2.sqrt()))
                        })
                        .filter(|&(u, _)| distance(rest[u as usize], rest[v as usize]) > SAME_PART)
                        .min_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
                    let inside = other.is_some_and(|(u, _)| {
                        let u = u as usize;
                        (v3(p) - v3(points[u])).dot(&v3(normals[u])) < 0.0
                    });
                    (v, inside)
                })
                .collect()
        })
        .collect();
    for (v, inside) in found.into_iter().flatten() {
        overlap[v as usize] = inside;
    }
    overlap
}

/// Rest vertices within this of a patch's seed vertex join its patch.
const PATCH: f32 = 0.02;
/// Room for rounding in the patch bounds (metres): a patch is skipped only when certainly out.
const BOUND_SLACK: f32 = 1e-4;

/// The body's vertices in small patches at rest (each vertex with the first unassigned vertex
/// within [`PATCH`] of it, in vertex order): bounds on the distances between two patches'
/// vertices, at rest and posed, from each patch's seed and radius.
#[derive(Clone, Debug)]
struct RestPatches {
    seed: Vec<u32>,
    members: Vec<Vec<u32>>,
    /// Each patch's farthest member from its seed at rest.
    radius: Vec<f32>,
    /// Each patch's seed at rest.
    seed_rest: Vec<[f32; 3]>,
}

/// A posed body's patch seeds and the farthest member from each.
struct PosedPatches {
    centre: Vec<[f32; 3]>,
    radius: Vec<f32>,
}

impl RestPatches {
    fn new(rest: &[[f32; 3]]) -> RestPatches {
        let mut patch = vec![u32::MAX; rest.len()];
        let (mut seed, mut members) = (Vec::new(), Vec::<Vec<u32>>::new());
        if let Ok(index) = PointIndex::new(rest) {
            for v in 0..rest.len() {
                if patch[v] != u32::MAX {
                    continue;
                }
                let id = seed.len() as u32;
                let mut group: Vec<u32> = index
                    .within(rest[v], PATCH)
                    .into_iter()
                    .map(|(u, _)| u)
                    .filter(|&u| patch[u as usize] == u32::MAX)
                    .collect();
                group.sort_unstable();
                for &u in &group {
                    patch[u as usize] = id;
                }
                seed.push(v as u32);
                members.push(group);
            }
        }
        let radius = spread(rest, &seed, &members);
        let seed_rest = seed.iter().map(|&s| rest[s as usize]).collect();
        RestPatches {
            seed,
            members,
            radius,
            seed_rest,
        }
    }

    fn posed(&self, points: &[[f32; 3]]) -> PosedPatches {
        PosedPatches {
            centre: self.seed.iter().map(|&s| points[s as usize]).collect(),
            radius: spread(points, &self.seed, &self.members),
        }
    }

    /// Whether some vertex of patch `a` may have been farther than [`SAME_PART`] from some
    /// vertex of patch `b` at rest.
    fn may_be_apart(&self, a: usize, b: usize) -> bool {
        let d = distance(self.seed_rest[a], self.seed_rest[b]);
        d + self.radius[a] + self.radius[b] > SAME_PART - BOUND_SLACK
    }
}

/// Each patch's farthest member from its seed.
fn spread(points: &[[f32; 3]], seed: &[u32], members: &[Vec<u32>]) -> Vec<f32> {
    seed.iter()
        .zip(members)
        .map(|(&s, m)| {
            m.iter()
                .map(|&u| distance(points[s as usize], points[u as usize]))
                .fold(0.0, f32::max)
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
        let overlap = self_overlap(body.rest_patches(), &body.mesh.positions, &points, &normals);
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
