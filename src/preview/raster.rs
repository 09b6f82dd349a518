//! Z-buffered triangle rasteriser with two-sided Gouraud-Lambert shading.
//!
//! Vertices are snapped to 1/256 px fixed point so edge functions are exact
//! integers: shared edges get the same sign from both triangles and the top-left
//! rule leaves no cracks or double hits.

use nalgebra::Vector3;

use super::framing::{dot, Framing, View};
use super::DrawMesh;

const SUB_BITS: u32 = 8;
const ONE: i64 = 1 << SUB_BITS;
const HALF: i64 = ONE / 2;
/// Far-off vertices are clamped (in px) so fixed-point products cannot overflow i64.
const MAX_PX: f32 = 1.0e6;

const AMBIENT: f32 = 0.28;
const DIFFUSE: f32 = 0.72;
/// Back faces (e.g. the inside of a skirt) are drawn a bit darker so they read as inside.
const BACK_FACE: f32 = 0.72;
/// Outline pixels are multiplied by this.
const EDGE_DARKEN: f32 = 0.62;

/// Orthographic camera mapping world points to fixed-point screen pixels (y down).
pub(crate) struct Camera {
    view: View,
    center: [f32; 2],
    scale: f32,
    half: [f32; 2],
    light: [f32; 3],
}

#[derive(Clone, Copy)]
struct ScreenVertex {
    x: i64,
    y: i64,
    depth: f32,
}

impl Camera {
    pub(crate) fn new(view: View, framing: &Framing, w: usize, h: usize) -> Camera {
        Camera {
            view,
            center: framing.center(),
            scale: framing.scale_for(w as u32, h as u32),
            half: [w as f32 * 0.5, h as f32 * 0.5],
            light: headlight(view),
        }
    }

    /// Screen row (float px, y down) of world height `y`.
    pub(crate) fn row_of(&self, y: f32) -> f32 {
        self.half[1] - (y - self.center[1]) * self.scale
    }

    /// Pixels per metre.
    pub(crate) fn scale(&self) -> f32 {
        self.scale
    }

    fn to_screen(&self, p: [f32; 3]) -> Option<ScreenVertex> {
        let [u, v, depth] = self.view.project(p);
        let x = self.half[0] + (u - self.center[0]) * self.scale;
        let y = self.row_of(v);
        if !(x.is_finite() && y.is_finite() && depth.is_finite()) {
            return None;
        }
        let fix = |c: f32| (c.clamp(-MAX_PX, MAX_PX) * ONE as f32).round() as i64;
        Some(ScreenVertex {
            x: fix(x),
            y: fix(y),
            depth,
        })
    }
}

/// Light from slightly above and to the left of the camera: reads like a headlight
/// but still gives shape to surfaces facing the viewer.
fn headlight(view: View) -> [f32; 3] {
    let (r, c) = (view.right(), view.toward_camera());
    let l = Vector3::new(-0.35 * r[0] + c[0], 0.55 + c[1], -0.35 * r[2] + c[2]).normalize();
    [l.x, l.y, l.z]
}

/// Colour and depth buffers at render (possibly supersampled) resolution.
pub(crate) struct Target {
    pub(crate) w: usize,
    pub(crate) h: usize,
    pub(crate) color: Vec<[u8; 3]>,
    /// Larger = nearer the camera; `-inf` where nothing was drawn.
    pub(crate) depth: Vec<f32>,
}

impl Target {
    pub(crate) fn new(w: usize, h: usize, background: [u8; 3]) -> Target {
        Target {
            w,
            h,
            color: vec![background; w * h],
            depth: vec![f32::NEG_INFINITY; w * h],
        }
    }

    /// Paint rows `[y0, y1)` where nothing has been drawn (used for the floor line).
    pub(crate) fn fill_rows(&mut self, y0: i64, y1: i64, color: [u8; 3]) {
        for y in y0.max(0)..y1.min(self.h as i64) {
            let row = y as usize * self.w;
            for i in row..row + self.w {
                if self.depth[i] == f32::NEG_INFINITY {
                    self.color[i] = color;
                }
            }
        }
    }

    pub(crate) fn draw_mesh(&mut self, cam: &Camera, mesh: &DrawMesh) {
        let screen: Vec<Option<ScreenVertex>> =
            mesh.positions.iter().map(|&p| cam.to_screen(p)).collect();
        let normals = vertex_normals(mesh.positions, mesh.triangles);
        // Intensity of each vertex seen from the front and from the back side.
        let lit = |n: [f32; 3]| AMBIENT + DIFFUSE * dot(n, cam.light).max(0.0);
        let front: Vec<f32> = normals.iter().map(|&n| lit(n)).collect();
        let back: Vec<f32> = normals
            .iter()
            .map(|&n| BACK_FACE * lit([-n[0], -n[1], -n[2]]))
            .collect();
        let toward = cam.view.toward_camera();
        for tri in mesh.triangles {
            let idx = tri.map(|i| i as usize);
            if idx.iter().any(|&i| i >= mesh.positions.len()) {
                continue; // malformed index: skip rather than panic in a preview
            }
            let (Some(a), Some(b), Some(c)) = (screen[idx[0]], screen[idx[1]], screen[idx[2]])
            else {
                continue;
            };
            let n = face_normal(mesh.positions, idx);
            let shade = if dot(n, toward) >= 0.0 { &front } else { &back };
            self.fill_triangle([a, b, c], idx.map(|i| shade[i]), mesh.color);
        }
    }

    /// Rasterise one triangle with depth test; `shade` is the per-vertex intensity.
    fn fill_triangle(&mut self, v: [ScreenVertex; 3], shade: [f32; 3], color: [u8; 3]) {
        let [a, mut b, mut c] = v;
        let mut s = shade;
        let mut area = edge(a, b, c.x, c.y);
        if area == 0 {
            return; // edge-on or degenerate: covers no area
        }
        if area < 0 {
            // Two-sided: make the winding positive so one inside test serves both.
            std::mem::swap(&mut b, &mut c);
            s.swap(1, 2);
            area = -area;
        }
        let Some((x0, x1, y0, y1)) = self.pixel_range(&[a, b, c]) else {
            return;
        };
        // Edge i is opposite vertex i; its weight is vertex i's barycentric numerator.
        let edges = [(b, c), (c, a), (a, b)];
        let bias = edges.map(|(p, q)| if is_top_left(p, q) { 0 } else { -1 });
        let step_x = edges.map(|(p, q)| -(q.y - p.y) * ONE);
        let step_y = edges.map(|(p, q)| (q.x - p.x) * ONE);
        let (sx, sy) = (x0 as i64 * ONE + HALF, y0 as i64 * ONE + HALF);
        let mut row = edges.map(|(p, q)| edge(p, q, sx, sy));
        let inv = 1.0 / area as f32;
        let depth = [a.depth, b.depth, c.depth];
        for y in y0..=y1 {
            let mut w = row;
            let base = y * self.w;
            for x in x0..=x1 {
                if w[0] + bias[0] >= 0 && w[1] + bias[1] >= 0 && w[2] + bias[2] >= 0 {
                    let l = w.map(|e| e as f32 * inv);
                    let z = l[0] * depth[0] + l[1] * depth[1] + l[2] * depth[2];
                    let i = base + x;
                    if z > self.depth[i] {
                        self.depth[i] = z;
                        let k = l[0] * s[0] + l[1] * s[1] + l[2] * s[2];
                        // `as u8` saturates; +0.5 rounds (k >= 0) without a libm call.
                        self.color[i] = color.map(|ch| (ch as f32 * k + 0.5) as u8);
                    }
                }
                for e in 0..3 {
                    w[e] += step_x[e];
                }
            }
            for e in 0..3 {
                row[e] += step_y[e];
            }
        }
    }

    /// Pixels whose centres may fall inside the triangle, clipped to the target.
    fn pixel_range(&self, v: &[ScreenVertex; 3]) -> Option<(usize, usize, usize, usize)> {
        let lo = |c: i64| -((HALF - c).div_euclid(ONE)); // ceil((c - HALF) / ONE)
        let hi = |c: i64| (c - HALF).div_euclid(ONE);
        let x0 = lo(v.iter().map(|p| p.x).min()?).max(0);
        let y0 = lo(v.iter().map(|p| p.y).min()?).max(0);
        let x1 = hi(v.iter().map(|p| p.x).max()?).min(self.w as i64 - 1);
        let y1 = hi(v.iter().map(|p| p.y).max()?).min(self.h as i64 - 1);
        (x0 <= x1 && y0 <= y1).then_some((x0 as usize, x1 as usize, y0 as usize, y1 as usize))
    }

    /// Darken drawn pixels next to background or to something clearly farther away:
    /// a subtle silhouette / overlap line that separates limbs and garment from body.
    pub(crate) fn outline(&mut self, threshold: f32) {
        let (w, h) = (self.w, self.h);
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let d = self.depth[i];
                if d == f32::NEG_INFINITY {
                    continue;
                }
                let farther = |j: usize| self.depth[j] < d - threshold;
                let edge = (x > 0 && farther(i - 1))
                    || (x + 1 < w && farther(i + 1))
                    || (y > 0 && farther(i - w))
                    || (y + 1 < h && farther(i + w));
                if edge {
                    self.color[i] = self.color[i].map(|c| (c as f32 * EDGE_DARKEN) as u8);
                }
            }
        }
    }

    /// Box-filter down by `factor` (which must divide the target size).
    pub(crate) fn downsample(&self, factor: usize) -> image::RgbImage {
        let (ow, oh) = (self.w / factor, self.h / factor);
        let n = (factor * factor) as u32;
        let mut out = Vec::with_capacity(ow * oh * 3);
        let mut sums = vec![[0u32; 3]; ow];
        for block in self.color.chunks_exact(self.w * factor) {
            sums.fill([0; 3]);
            for row in block.chunks_exact(self.w) {
                for (sum, px) in sums.iter_mut().zip(row.chunks_exact(factor)) {
                    for c in px {
                        for k in 0..3 {
                            sum[k] += c[k] as u32;
                        }
                    }
                }
            }
            out.extend(sums.iter().flat_map(|s| s.map(|v| ((v + n / 2) / n) as u8)));
        }
        image::RgbImage::from_raw(ow as u32, oh as u32, out).expect("buffer sized to the image")
    }
}

/// Twice the signed area of (a, b, p); positive when p is on the inner side of a→b
/// for a positively wound triangle (screen y down).
#[inline]
fn edge(a: ScreenVertex, b: ScreenVertex, px: i64, py: i64) -> i64 {
    (b.x - a.x) * (py - a.y) - (b.y - a.y) * (px - a.x)
}

/// Top-left fill rule for positive winding with y down: samples exactly on a top
/// (horizontal, going right) or left (going up) edge belong to this triangle.
fn is_top_left(a: ScreenVertex, b: ScreenVertex) -> bool {
    let (dx, dy) = (b.x - a.x, b.y - a.y);
    (dy == 0 && dx > 0) || dy < 0
}

/// Unnormalised face normal (length = 2 × area), from counter-clockwise winding.
fn face_cross(p: &[[f32; 3]], idx: [usize; 3]) -> Vector3<f32> {
    let v = idx.map(|i| Vector3::from(p[i]));
    (v[1] - v[0]).cross(&(v[2] - v[0]))
}

fn face_normal(p: &[[f32; 3]], idx: [usize; 3]) -> [f32; 3] {
    face_cross(p, idx).into()
}

/// Area-weighted vertex normals (zero for unused vertices, which then get ambient only).
fn vertex_normals(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> Vec<[f32; 3]> {
    let mut acc = vec![Vector3::<f32>::zeros(); positions.len()];
    for tri in triangles {
        let idx = tri.map(|i| i as usize);
        if idx.iter().any(|&i| i >= positions.len()) {
            continue;
        }
        let n = face_cross(positions, idx);
        if n.iter().all(|c| c.is_finite()) {
            for i in idx {
                acc[i] += n;
            }
        }
    }
    acc.into_iter()
        .map(|n| n.try_normalize(1e-20).unwrap_or_else(Vector3::zeros).into())
        .collect()
}
