//! Does the file play what the model plays? The file's frames (a glTF evaluated by
//! [`super::scene`], or a point cache read back) against the network's own forward pass on the
//! same clip ([`crate::models::Pbns::forward_points`]; not `eval::model_frames`, which wrote
//! `eval`'s caches and so would agree with any fault of its own), in mm, every frame.

use crate::bake::skinned_mesh_asset;
use crate::geometry::Frames;
use crate::metrics::deviation::{worst_index, Deviation};
use crate::models::file::ModelFile;
use crate::preview::{render_panel, save_png, ErrorBands, Framing, Panel, View};
use crate::rig::SkelAnimation;
use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;
use tch::Device;

/// The model's garment over a clip, and how file vertices map onto it.
pub struct Reference {
    pub clip: String,
    /// `[frame][model vertex]`, world space, metres, at the clip's rate (0: unknown, the
    /// file's own rate is taken).
    pub frames: Frames,
    pub triangles: Vec<[u32; 3]>,
    /// For each vertex of a baked glTF garment, the model vertex it came from (the bake splits
    /// vertices at UV seams; point caches keep the model's order).
    pub baked_vertex: Vec<u32>,
}

impl Reference {
    /// The PBNS network's forward pass on every frame of `clip` (already on the model's
    /// skeleton).
    pub fn of(model: &ModelFile, clip: &SkelAnimation, device: Device) -> Result<Reference> {
        let network = model.pbns()?;
        let poses: Vec<_> = (0..clip.frame_count())
            .map(|f| clip.local_pose(f))
            .collect();
        let frames = network.forward_points(&network.batch(model.skeleton(), &poses, device));
        let baked = skinned_mesh_asset("garment", &model.garment, None, &network.skin(), [0.0; 3]);
        Ok(Reference {
            clip: clip.name.clone(),
            frames: Frames::new(frames, clip.fps),
            triangles: model.garment.triangles.clone(),
            baked_vertex: baked.source_vertex,
        })
    }

    /// Frames the file must play vertex for vertex (a roll-out just computed, or a cache), at
    /// their rate (0: unknown, the file's own rate is taken); `triangles` for the picture.
    pub fn of_frames(name: &str, frames: Frames, triangles: Vec<[u32; 3]>) -> Reference {
        let points = frames.first().map_or(0, Vec::len) as u32;
        Reference {
            clip: name.to_string(),
            frames,
            triangles,
            baked_vertex: (0..points).collect(),
        }
    }

    /// A point cache (.pc2 / .mdd, checked as `validate` checks one) as the reference: a
    /// dynamic model's roll-out or a simulation. Its rate: `fps`, else the MDD's frame times.
    pub fn from_cache(path: &Path, fps: Option<f32>) -> Result<Reference> {
        let bytes =
            std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
        let mut problems = super::Problems::default();
        let cache = match exporters::FileKind::of(path) {
            Some(exporters::FileKind::Pc2) => super::cache::check_pc2(&bytes, &mut problems),
            Some(exporters::FileKind::Mdd) => super::cache::check_mdd(&bytes, &mut problems),
            _ => anyhow::bail!(
                "{}: a reference must be a point cache (.pc2 or .mdd)",
                path.display()
            ),
        };
        match (cache, problems.errors.first()) {
            (Some(cache), None) => {
                let fps = fps.or(cache.fps.map(|f| f as f32)).unwrap_or(0.0);
                let name = path.file_name().unwrap_or_default().to_string_lossy();
                let frames = Frames::new(cache.frames, fps);
                Ok(Reference::of_frames(&name, frames, Vec::new()))
            }
            (_, problem) => anyhow::bail!(
                "{}: the reference is not a sound point cache: {}",
                path.display(),
                problem.map_or("unreadable", |p| p.message.as_str())
            ),
        }
    }

    pub fn vertex_count(&self) -> usize {
        self.frames.first().map_or(0, Vec::len)
    }
}

/// Replay error of a file against the model, in millimetres.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ReplayError {
    pub clip: String,
    pub vertices: usize,
    #[serde(flatten)]
    pub error: Deviation,
    /// The file's vertex of the largest error (for a glTF, its own index after seam splits).
    pub worst_vertex: usize,
    pub tolerance_mm: f64,
    pub passed: bool,
    /// Error per model vertex at the worst frame (mm), for the picture.
    #[serde(skip)]
    pub worst_frame_errors: Vec<f64>,
}

/// Compares `file_frame(f)` (the file's vertices at frame f) with the reference; `map[v]` is
/// the model vertex of file vertex v.
pub fn compare(
    reference: &Reference,
    map: &[u32],
    tolerance_mm: f64,
    file_frame: impl Fn(usize) -> Vec<[f64; 3]> + Sync,
) -> ReplayError {
    use rayon::prelude::*;
    let per_frame: Vec<Vec<f64>> = (0..reference.frames.len())
        .into_par_iter()
        .map(|f| {
            let want = &reference.frames[f];
            file_frame(f)
                .iter()
                .zip(map)
                .map(|(p, &m)| {
                    let q = want[m as usize];
                    1e3 * (0..3)
                        .map(|c| (p[c] - q[c] as f64).powi(2))
                        .sum::<f64>()
                        .sqrt()
                })
                .collect()
        })
        .collect();
    let error = Deviation::of(&per_frame);
    let worst_frame = error.worst_frame;
    let worst_vertex = per_frame
        .get(worst_frame)
        .map_or(0, |errors| worst_index(errors));
    let mut worst_frame_errors = vec![0.0f64; reference.vertex_count()];
    for (v, &e) in per_frame.get(worst_frame).into_iter().flatten().enumerate() {
        let m = map[v] as usize;
        worst_frame_errors[m] = worst_frame_errors[m].max(e);
    }
    ReplayError {
        clip: reference.clip.clone(),
        vertices: map.len(),
        error,
        worst_vertex,
        tolerance_mm,
        passed: error.max_mm <= tolerance_mm,
        worst_frame_errors,
    }
}

/// The model's garment at the worst frame, each triangle coloured by its largest vertex error
/// relative to the tolerance (front view), written atomically as PNG.
pub fn error_png(reference: &Reference, replay: &ReplayError, path: &Path) -> Result<()> {
    let points = &reference.frames[replay.error.worst_frame];
    let bands = ErrorBands::new(
        &reference.triangles,
        &replay.worst_frame_errors,
        replay.tolerance_mm,
    );
    let meshes = bands.meshes(points);
    let panel = Panel {
        meshes,
        view: View::Front,
        label: format!(
            "{} frame {}: max {:.3} mm (tolerance {} mm)",
            replay.clip, replay.error.worst_frame, replay.error.max_mm, replay.tolerance_mm
        ),
    };
    let framing = Framing::fit_meshes(&panel.meshes, View::Front);
    let img = render_panel(&panel, 640, 800, &framing);
    save_png(&img, path).with_context(|| format!("cannot write {}", path.display()))
}

/// Replays a glTF whose structure passed against `reference`: the garment node (the mesh whose
/// vertex count is the bake's, named `garment` when several match) through the animation named
/// after the clip (or the only one), at frame f's time f / fps. Errors say why it cannot.
pub fn replay_gltf(
    doc: &super::container::Document,
    accessors: &super::structure::Accessors,
    reference: &Reference,
    tolerance_mm: f64,
) -> Result<ReplayError, String> {
    let scene = super::scene::Scene::new(doc, accessors);
    let root = &doc.root;
    let (node, map) = garment_node(root, &scene, reference)?;
    let animation = match root
        .animations
        .iter()
        .position(|a| a.name.as_deref() == Some(reference.clip.as_str()))
    {
        Some(a) => a,
        None if root.animations.len() == 1 => 0,
        None => {
            return Err(format!(
                "no animation is named '{}' (the clip), and there are {}",
                reference.clip,
                root.animations.len()
            ))
        }
    };
    let keys = scene.times(animation).len();
    if keys != reference.frames.len() {
        return Err(format!(
            "animation {animation} has {keys} keys, the clip {} frames (another --fps?)",
            reference.frames.len()
        ));
    }
    let fps = reference.frames.fps as f64;
    Ok(compare(reference, &map, tolerance_mm, |f| {
        scene.positions(node, Some(animation), f as f64 / fps)
    }))
}

/// The node playing the reference's garment and, per file vertex, the reference vertex it
/// plays: a mesh with the bake's vertex count (named `garment` when several match), else one whose
/// `sourceVertex` extras (written by our bakes when they split vertices at UV seams) map every
/// vertex into the reference, e.g. a roll-out's glTF against its point cache.
fn garment_node(
    root: &gltf::json::Root,
    scene: &super::scene::Scene,
    reference: &Reference,
) -> Result<(usize, Vec<u32>), String> {
    let want = reference.baked_vertex.len();
    let count = |n: usize| scene.positions(n, None, 0.0).len();
    let meshes = || (0..root.nodes.len()).filter(|&n| root.nodes[n].mesh.is_some());
    let exact: Vec<usize> = meshes().filter(|&n| count(n) == want).collect();
    let named = |many: &[usize]| {
        *many
            .iter()
            .find(|&&n| root.nodes[n].name.as_deref() == Some("garment"))
            .unwrap_or(&many[0])
    };
    if !exact.is_empty() {
        return Ok((named(&exact), reference.baked_vertex.clone()));
    }
    let points = reference.frames.first().map_or(0, Vec::len);
    let mapped: Vec<(usize, Vec<u32>)> = meshes()
        .filter_map(|n| {
            let map = source_vertex(root, n)?;
            (map.len() == count(n) && map.iter().all(|&v| (v as usize) < points))
                .then_some((n, map))
        })
        .collect();
    match mapped.as_slice() {
        [] => Err(format!(
            "no mesh has the model's {want} baked garment vertices (a bake of another model?)"
        )),
        [one] => Ok(one.clone()),
        many => {
            let nodes: Vec<usize> = many.iter().map(|m| m.0).collect();
            let pick = named(&nodes);
            Ok(many
                .iter()
                .find(|m| m.0 == pick)
                .cloned()
                .expect("picked from these"))
        }
    }
}

/// The `sourceVertex` extras of node `n`'s mesh, if it has them.
fn source_vertex(root: &gltf::json::Root, n: usize) -> Option<Vec<u32>> {
    let mesh = root.get(root.nodes[n].mesh?)?;
    let extras: serde_json::Value = serde_json::from_str(mesh.extras.as_ref()?.get()).ok()?;
    serde_json::from_value(extras.get("sourceVertex")?.clone()).ok()
}
