//! The posed body a frame's garment must stay outside of, and per garment vertex the plane it is
//! measured against: the nearest posed body vertex and its normal (the paper's `o = (g − b)·n`).
//! Where that plane is wrong (between the thighs the nearest vertex may be the other thigh's),
//! the body's triangles say what is inside (winding number) and where the surface is.

use crate::body::Body;
use crate::geometry::{arr3, distance, v3, PointIndex, SurfaceIndex};
use crate::rig::JointTransform;
use anyhow::Result;
use nalgebra::Matrix4;

/// Garment vertices whose plane offset is below this (metres) are tested for being inside the
/// body by winding number (the test costs; in a skirt's roll-out 93 % of the inside vertices
/// that their planes called outside were within 1 cm of them).
const INSIDE_REACH: f32 = 0.01;

/// How far around the garment the body's triangles are kept for the inside test (metres).
const CROP: f32 = 0.15;

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

    /// The fix's last word where its planes were wrong: garment vertices left within
    /// [`INSIDE_REACH`] of their plane and inside the body (the side of the closest face, or
    /// by an edge or a corner the winding number of the posed triangles) are put `margin`
    /// outside the closest point of the surface. Returns how many moved.
    pub fn lift_inside(&self, garment: &mut [[f32; 3]], planes: &Planes, margin: f32) -> usize {
        use rayon::prelude::*;
        let near: Vec<usize> = (0..garment.len())
            .filter(|&v| planes.offset(v, garment[v]) < INSIDE_REACH)
            .collect();
        if near.is_empty() {
            return 0;
        }
        let surface = SurfaceIndex::new(&self.points, &self.triangles_around(garment, &near));
        let lifted: Vec<(usize, [f32; 3])> = near
            .par_iter()
            .filter_map(|&v| {
                let p = garment[v];
                let closest = surface.closest(p)?;
                let c = closest.point;
                // Beside a face, its side answers; by an edge or a corner, the winding number.
                let outside = match closest.on_face {
                    true => offset(p, c, closest.normal) > 0.0,
                    false => !surface.is_inside(p),
                };
                if outside {
                    return None;
                }
                let out = margin / distance(p, c).max(f32::MIN_POSITIVE);
                Some((v, std::array::from_fn(|k| c[k] + out * (c[k] - p[k]))))
            })
            .collect();
        for &(v, p) in &lifted {
            garment[v] = p;
        }
        lifted.len()
    }

    /// The body's triangles with a corner within [`CROP`] of the box around `garment[near]`:
    /// the winding number of the cut body is the whole body's to within the solid angle of
    /// the cuts, small when they are this far from every point asked about.
    fn triangles_around(&self, garment: &[[f32; 3]], near: &[usize]) -> Vec<[u32; 3]> {
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for &v in near {
            for k in 0..3 {
                lo[k] = lo[k].min(garment[v][k] - CROP);
                hi[k] = hi[k].max(garment[v][k] + CROP);
            }
        }
        let inside = |p: &[f32; 3]| (0..3).all(|k| (lo[k]..=hi[k]).contains(&p[k]));
        self.body
            .mesh()
            .triangles
            .iter()
            .filter(|t| t.iter().any(|&b| inside(&self.points[b as usize])))
            .copied()
            .collect()
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
        offset(p, self.points[v], self.normals[v])
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

/// `(p − b)·n`.
fn offset(p: [f32; 3], b: [f32; 3], n: [f32; 3]) -> f32 {
    (p[0] - b[0]) * n[0] + (p[1] - b[1]) * n[1] + (p[2] - b[2]) * n[2]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_vertex_inside_the_body_that_its_plane_calls_outside_is_lifted_out() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let body = crate::io::gltf_body::read_body(&root.join("samples/body.glb")).unwrap();
        let surface = PosedSurface::new(&body, &body.skeleton.rest).unwrap();
        let triangles = SurfaceIndex::new(&surface.points, &body.mesh().triangles);
        // Under the skirt: elsewhere the body has inner surfaces (the toes) and overlaps itself,
        // where the closest surface point is inside too.
        let skirt =
            crate::garment::Garment::read(&root.join("samples/garments/skirt.obj")).unwrap();
        let skirt = PointIndex::new(&skirt.mesh.positions).unwrap();
        let under_skirt = |b: usize| skirt.nearest(surface.points[b]).1 < 0.05;
        // Points 5 mm inside the body under every 7th body vertex there (and one outside), each
        // given the plane of its own vertex turned inwards: the planes call them all outside,
        // as the other thigh's vertex does between the legs.
        let normals: Vec<[f32; 3]> = (0..surface.points.len())
            .map(|b| surface.normal(b))
            .collect();
        let under: Vec<usize> = (0..surface.points.len())
            .filter(|&b| under_skirt(b))
            .step_by(7)
            .filter(|&b| {
                let p: [f32; 3] =
                    std::array::from_fn(|k| surface.points[b][k] - 0.005 * normals[b][k]);
                triangles.is_inside(p) && triangles.distance(p) > 0.003
            })
            .collect();
        assert!(under.len() > 50, "{} points", under.len());
        let mut garment: Vec<[f32; 3]> = under
            .iter()
            .map(|&b| std::array::from_fn(|k| surface.points[b][k] - 0.005 * normals[b][k]))
            .collect();
        let outside = std::array::from_fn(|k| surface.points[0][k] + 0.005 * normals[0][k]);
        garment.push(outside);
        let mut planes = Planes {
            points: under.iter().map(|&b| surface.points[b]).collect(),
            normals: under.iter().map(|&b| normals[b].map(|c| -c)).collect(),
        };
        planes.points.push(surface.points[0]);
        planes.normals.push(normals[0]);
        assert_eq!(planes.loss(&garment, 0.002), 0.0);
        let before = garment.clone();
        let margin = 0.002;
        assert_eq!(
            surface.lift_inside(&mut garment, &planes, margin),
            under.len()
        );
        let mut at_margin = 0;
        for (v, p) in garment.iter().enumerate().take(under.len()) {
            assert!(!triangles.is_inside(*p), "vertex {v} still inside");
            // The margin along the way out (less where the surface is concave: fingers, armpits).
            let d = triangles.distance(*p);
            assert!(d < margin + 1e-5, "vertex {v} {d} m from the body");
            at_margin += usize::from(d > 0.95 * margin);
            // Out by the shortest way: about the 5 mm it was in, plus the margin.
            let moved = distance(*p, before[v]);
            assert!(moved < 0.0075, "vertex {v} moved {moved} m");
        }
        eprintln!("{at_margin} of {} lifted to the margin", under.len());
        assert!(at_margin as f64 > 0.9 * under.len() as f64);
        assert_eq!(garment.last(), before.last(), "a vertex outside moved");
    }
}
