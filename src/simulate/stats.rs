//! Per-frame figures of a simulated garment, by our own metrics (not Blender's): vertices inside
//! the posed body (winding number), edge strain, vertex speed, how far pins drift from the body.

use crate::body::{Body, PosedBody};
use crate::geometry::edges::unique_edges;
use crate::geometry::{distance, SurfaceIndex};
use crate::metrics::{Edges, Inside, InsideFrame};
use crate::rig::JointTransform;
use anyhow::{bail, Result};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameStats {
    pub frame: usize,
    pub inside_vertices: usize,
    pub inside_pct: f64,
    /// Mean |e − e_T| / e_T (%).
    pub strain_pct: f64,
    /// Fastest vertex since the previous frame (m/s).
    pub max_speed: f64,
    /// Farthest pinned vertex from its skinned target (mm).
    pub pinned_error_mm: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    pub frames: usize,
    pub inside: Inside,
    pub mean_strain_pct: f64,
    pub max_strain_pct: f64,
    pub max_speed: f64,
    pub max_speed_frame: usize,
    pub pinned_error_max_mm: f64,
}

/// The setup the stats measure a clip's frames against (not the frames themselves): the body,
/// the garment at rest (its triangles and pinned vertices) and the frame rate.
pub struct ClipSetup<'a> {
    pub body: &'a Body,
    pub rest: &'a [[f32; 3]],
    pub triangles: &'a [[u32; 3]],
    pub pinned: &'a [u32],
    pub fps: f32,
}

impl<'a> ClipSetup<'a> {
    /// A garment with no pinned vertices (a model's output) on `body`.
    pub fn unpinned(
        body: &'a Body,
        garment: &'a crate::geometry::TriMesh,
        fps: f32,
    ) -> ClipSetup<'a> {
        ClipSetup {
            body,
            rest: &garment.positions,
            triangles: &garment.triangles,
            pinned: &[],
            fps,
        }
    }
}

/// Stats of `frames` (the clip's) posed by `poses`; `previous` is the frame before the first
/// (the lead-in's last), for the first frame's speed.
pub fn of(
    s: &ClipSetup,
    frames: &[Vec<[f32; 3]>],
    poses: &[Vec<JointTransform>],
    targets: &[Vec<[f32; 3]>],
    previous: Option<&[[f32; 3]]>,
) -> (Vec<FrameStats>, Summary) {
    let edges = Edges::new(s.rest, unique_edges(s.triangles));
    let per: Vec<(InsideFrame, FrameStats)> = (0..frames.len())
        .into_par_iter()
        .map(|f| {
            let x = &frames[f];
            let posed = PosedBody::new(s.body, &poses[f]);
            let surface = SurfaceIndex::new(&posed.points, &s.body.mesh().triangles);
            let inside = InsideFrame::of(x, &posed, &surface);
            let before = if f == 0 {
                previous
            } else {
                Some(&frames[f - 1][..])
            };
            let stats = FrameStats {
                frame: f,
                inside_vertices: inside.depths.len(),
                inside_pct: 100.0 * inside.depths.len() as f64 / x.len().max(1) as f64,
                strain_pct: edges.mean_strain_pct(x),
                max_speed: before.map_or(0.0, |b| max_step(b, x) * s.fps as f64),
                pinned_error_mm: 1e3
                    * s.pinned
                        .iter()
                        .map(|&v| distance(x[v as usize], targets[f][v as usize]) as f64)
                        .fold(0.0, f64::max),
            };
            (inside, stats)
        })
        .collect();
    let frames_in: Vec<&InsideFrame> = per.iter().map(|(i, _)| i).collect();
    let stats: Vec<FrameStats> = per.iter().map(|(_, s)| s.clone()).collect();
    let (max_speed_frame, max_speed) =
        stats
            .iter()
            .map(|s| s.max_speed)
            .enumerate()
            .fold(
                (0, 0.0),
                |best, (f, v)| if v > best.1 { (f, v) } else { best },
            );
    let summary = Summary {
        frames: stats.len(),
        inside: Inside::of(&frames_in),
        mean_strain_pct: stats.iter().map(|s| s.strain_pct).sum::<f64>()
            / stats.len().max(1) as f64,
        max_strain_pct: stats.iter().map(|s| s.strain_pct).fold(0.0, f64::max),
        max_speed,
        max_speed_frame,
        pinned_error_max_mm: stats.iter().map(|s| s.pinned_error_mm).fold(0.0, f64::max),
    };
    (stats, summary)
}

/// The first frame (of all simulated frames) with a non-finite point or a vertex faster than
/// `limit` m/s, and why.
pub fn first_explosion(frames: &[Vec<[f32; 3]>], fps: f32, limit: f32) -> Option<(usize, String)> {
    frames.iter().enumerate().find_map(|(f, x)| {
        if x.iter().flatten().any(|c| !c.is_finite()) {
            return Some((f, "non-finite vertex positions".to_string()));
        }
        let speed = f
            .checked_sub(1)
            .map_or(0.0, |p| max_step(&frames[p], x) * fps as f64);
        (speed > limit as f64).then(|| {
            (
                f,
                format!("a vertex moved at {speed:.1} m/s (limit {limit} m/s)"),
            )
        })
    })
}

/// Fails when any frame exploded (see [`first_explosion`]), naming it.
pub fn check(frames: &[Vec<[f32; 3]>], fps: f32, limit: f32, lead_in: usize) -> Result<()> {
    match first_explosion(frames, fps, limit) {
        Some((f, why)) => bail!("{}", super::blender::explosion_message(f, lead_in, &why)),
        None => Ok(()),
    }
}

fn max_step(a: &[[f32; 3]], b: &[[f32; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| distance(*p, *q) as f64)
        .fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn explosions_are_found_at_their_frame() {
        let still = vec![[0.0, 0.0, 0.0]; 3];
        let mut frames = vec![still.clone(); 5];
        assert_eq!(first_explosion(&frames, 30.0, 30.0), None);
        frames[3][1] = [2.0, 0.0, 0.0]; // 2 m in 1/30 s = 60 m/s
        let (f, why) = first_explosion(&frames, 30.0, 30.0).unwrap();
        assert_eq!(f, 3);
        assert!(why.contains("60.0 m/s"), "{why}");
        frames[2][0] = [f32::NAN, 0.0, 0.0];
        assert_eq!(first_explosion(&frames, 30.0, 30.0).unwrap().0, 2);
    }
}
