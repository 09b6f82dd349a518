//! The posed body a frame's garment must stay outside of, and per garment vertex the plane it is
//! measured against: the nearest posed body vertex and its normal (the paper's `o = (g − b)·n`).

use crate::body::Body;
use crate::geometry::{arr3, v3, PointIndex};
use crate::rig::JointTransform;
use anyhow::Result;
use nalgebra::Matrix4;

/// The posed body of one frame: points, nearest-point index, and what its normals need.
pub struct PosedSurface<'a> {
    body: &'a Body,
    skinning: Vec<Matrix4<f32>>,
    points: Vec<[f32; 3]>,
    index: PointIndex,
}

impl<'a> PosedSurface<'a> {
    pub fn new(body: &'a Body, pose: &[JointTransform]) -> Result<PosedSurface<'a>> {
        let skinning = body.skeleton.skinning_matrices(pose);
        let points = body.skin.skin_points(&body.mesh().positions, &skinning);
        let index = PointIndex::new(&points)?;
        Ok(PosedSurface {
            body,
            skinning,
            points,
            index,
        })
    }

    /// The posed normal of body vertex `b` (as `Skin::skin_normals`; only the few thousand
    /// vertices nearest the garment are needed, not the whole body's).
    fn normal(&self, b: usize) -> [f32; 3] {
        let m = self.body.skin.blended(b, &self.skinning);
        let q = m.fixed_view::<3, 3>(0, 0) * v3(self.body.normals[b]);
        arr3(q / q.norm().max(f32::MIN_POSITIVE))
    }
}

/// Per garment vertex, the nearest posed body vertex and its normal, found once per frame (the
/// fix moves vertices by millimetres; re-finding them every pass costs more than it changes).
pub struct Planes {
    pub points: Vec<[f32; 3]>,
    pub normals: Vec<[f32; 3]>,
}

impl Planes {
    pub fn of(garment: &[[f32; 3]], surface: &PosedSurface) -> Planes {
        let (points, normals) = garment
            .iter()
            .map(|&p| {
                let b = surface.index.nearest_fast(p) as usize;
                (surface.points[b], surface.normal(b))
            })
            .unzip();
        Planes { points, normals }
    }

    /// `o = (g − b)·n` of vertex `v` at `p`.
    pub fn offset(&self, v: usize, p: [f32; 3]) -> f32 {
        let (b, n) = (self.points[v], self.normals[v]);
        (p[0] - b[0]) * n[0] + (p[1] - b[1]) * n[1] + (p[2] - b[2]) * n[2]
    }

    /// The collision loss `Σ ReLU(margin − o)` (metres).
    pub fn loss(&self, garment: &[[f32; 3]], margin: f32) -> f64 {
        garment
            .iter()
            .enumerate()
            .map(|(v, &p)| f64::from((margin - self.offset(v, p)).max(0.0)))
            .sum()
    }
}
