//! The garment's UV layout as a W×H map: which texels each triangle covers (per-vertex values
//! are scattered into the map by barycentric weights) and where each vertex reads the map back
//! (bilinear at its UV). The layout's bounding box is stretched to fill the map (the sample
//! skirt's UVs use a 0.06 × 0.04 corner of MakeHuman's atlas).

use crate::geometry::TriMesh;
use anyhow::{bail, Result};

/// Texels kept off the map's border (the 3×3 convolutions see the whole layout).
const MARGIN_TEXELS: f32 = 1.0;

#[derive(Clone, Debug, PartialEq)]
pub struct UvRaster {
    pub size: usize,
    /// Per texel (row-major, row 0 at v = 0): the three position vertices of the covering
    /// triangle and their barycentric weights; uncovered texels have weights 0.
    pub texel_vertices: Vec<[u32; 3]>,
    pub texel_weights: Vec<[f32; 3]>,
    /// Per position vertex: its UV in map units [0, 1]² (the first of a seam vertex's UVs).
    pub vertex_uv: Vec<[f32; 2]>,
}

impl UvRaster {
    pub fn new(mesh: &TriMesh, size: usize, name: &str) -> Result<UvRaster> {
        let Some(uv) = &mesh.uv else {
            bail!("{name} has no UVs: the dynamic model reads garments in their UV layout (unwrap it in a DCC, e.g. Blender's Smart UV Project, and export the OBJ with UVs)");
        };
        let (lo, hi) = bounds(&uv.coords);
        let span = [hi[0] - lo[0], hi[1] - lo[1]];
        if !(span[0] > 0.0 && span[1] > 0.0) {
            bail!("{name}: its UVs are degenerate (all on one line or point)");
        }
        let m = MARGIN_TEXELS / size as f32;
        let to_map = |c: [f32; 2]| {
            [
                m + (1.0 - 2.0 * m) * (c[0] - lo[0]) / span[0],
                m + (1.0 - 2.0 * m) * (c[1] - lo[1]) / span[1],
            ]
        };
        let mut vertex_uv = vec![[f32::NAN; 2]; mesh.vertex_count()];
        for (pt, ut) in mesh.triangles.iter().zip(&uv.triangles) {
            for k in 0..3 {
                let v = &mut vertex_uv[pt[k] as usize];
                if v[0].is_nan() {
                    *v = to_map(uv.coords[ut[k] as usize]);
                }
            }
        }
        if let Some(v) = vertex_uv.iter().position(|p| p[0].is_nan()) {
            bail!("{name}: vertex {v} is in no UV triangle");
        }
        let mut raster = UvRaster {
            size,
            texel_vertices: vec![[0; 3]; size * size],
            texel_weights: vec![[0.0; 3]; size * size],
            vertex_uv,
        };
        for (pt, ut) in mesh.triangles.iter().zip(&uv.triangles) {
            let corners = ut.map(|i| to_map(uv.coords[i as usize]));
            raster.cover(*pt, corners);
        }
        Ok(raster)
    }

    /// Marks the texels whose centres lie in the UV triangle `c` (map units).
    fn cover(&mut self, vertices: [u32; 3], c: [[f32; 2]; 3]) {
        let n = self.size as f32;
        let px = c.map(|p| [p[0] * n - 0.5, p[1] * n - 0.5]);
        let (lo, hi) = bounds(&px);
        let area = cross(px[0], px[1], px[2]);
        if area.abs() < 1e-12 {
            return;
        }
        for y in texels(lo[1], hi[1], self.size) {
            for x in texels(lo[0], hi[0], self.size) {
                let p = [x as f32, y as f32];
                let w = [
                    cross(p, px[1], px[2]) / area,
                    cross(px[0], p, px[2]) / area,
                    cross(px[0], px[1], p) / area,
                ];
                if w.iter().all(|&w| w >= -1e-6) {
                    let t = y * self.size + x;
                    self.texel_vertices[t] = vertices;
                    self.texel_weights[t] = w;
                }
            }
        }
    }

    /// Share of the map's texels the layout covers.
    pub fn coverage(&self) -> f64 {
        let covered = self
            .texel_weights
            .iter()
            .filter(|w| w.iter().sum::<f32>() > 0.5)
            .count();
        covered as f64 / self.texel_weights.len() as f64
    }
}

/// Texel indices whose centres lie in [lo, hi] (texel units), clipped to the map.
fn texels(lo: f32, hi: f32, size: usize) -> std::ops::Range<usize> {
    let start = lo.ceil().max(0.0) as usize;
    let end = (hi.floor() + 1.0).clamp(0.0, size as f32) as usize;
    start..end.max(start)
}

fn cross(a: [f32; 2], b: [f32; 2], c: [f32; 2]) -> f32 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

fn bounds(points: &[[f32; 2]]) -> ([f32; 2], [f32; 2]) {
    points
        .iter()
        .fold(([f32::MAX; 2], [f32::MIN; 2]), |(lo, hi), p| {
            (
                [lo[0].min(p[0]), lo[1].min(p[1])],
                [hi[0].max(p[0]), hi[1].max(p[1])],
            )
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::FaceVaryingUv;

    #[test]
    fn a_square_layout_covers_the_map_and_interpolates_exactly() {
        // Two triangles over the unit square; UV = xz.
        let mut mesh = TriMesh::new(
            vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 0.0, 1.0],
                [1.0, 0.0, 1.0],
            ],
            vec![[0, 2, 1], [1, 2, 3]],
        );
        mesh.uv = Some(FaceVaryingUv {
            coords: vec![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]],
            triangles: vec![[0, 2, 1], [1, 2, 3]],
        });
        let r = UvRaster::new(&mesh, 16, "square").unwrap();
        // The inner 14×14 texels (one-texel margin) are covered.
        assert!(
            (r.coverage() - 14.0 * 14.0 / 256.0).abs() < 1e-9,
            "{}",
            r.coverage()
        );
        // Interpolating x reproduces the texel's map position.
        for y in 1..15 {
            for x in 1..15 {
                let t = y * 16 + x;
                let value: f32 = (0..3)
                    .map(|k| {
                        r.texel_weights[t][k] * mesh.positions[r.texel_vertices[t][k] as usize][0]
                    })
                    .sum();
                let expect = ((x as f32 + 0.5) / 16.0 - 1.0 / 16.0) / (14.0 / 16.0);
                assert!(
                    (value - expect).abs() < 1e-5,
                    "texel {x},{y}: {value} vs {expect}"
                );
            }
        }
        mesh.uv = None;
        assert!(UvRaster::new(&mesh, 16, "bare.obj")
            .unwrap_err()
            .to_string()
            .contains("bare.obj has no UVs"));
    }
}
