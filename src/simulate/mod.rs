//! Ground truth for dynamic garments: Blender's cloth solver on the body our retargeting and LBS
//! pose (the body every model sees), driven headless as a subprocess.
//!
//! The clip is preceded by a lead-in that is simulated but not returned: the body holds its rest
//! pose (the garment settles under gravity), then blends into the clip's first pose. Pinned
//! vertices follow the garment's own LBS (proximity weights from the body), so a waist band
//! rides the hips exactly.

pub mod blender;
pub mod cache;
pub mod lead_in;
pub mod stats;

use crate::body::Body;
use crate::fabric::Fabric;
use crate::garment::Garment;
use crate::geometry::{Frames, PointIndex};
use crate::rig::{weights, JointTransform, SkelAnimation, Skin};
use anyhow::{bail, Result};
use std::path::PathBuf;

/// What is simulated.
pub struct Scene<'a> {
    pub body: &'a Body,
    pub garment: &'a Garment,
    pub fabric: &'a Fabric,
    pub clip: &'a SkelAnimation,
}

/// How it is simulated.
#[derive(Clone, Debug)]
pub struct Settings {
    /// Seconds the garment settles on the body at rest, then seconds of blending into frame 0.
    pub settle_s: f32,
    pub blend_s: f32,
    /// Run N of a perturbed ensemble of the clip: the rest hold lasts N × `PERTURB_S` longer
    /// (at least one frame per step), so runs differ only by where the chaotic garment is when
    /// the clip starts. 0: the plain simulation. The hold's length is in the job Blender gets,
    /// so each run has its own cache key.
    pub perturb: u32,
    /// Simulate only the clip's first frames (tests, previews).
    pub frames: Option<usize>,
    /// A vertex faster than this (m/s) means the solver exploded.
    pub speed_limit: f32,
    pub blender: PathBuf,
    /// Blender's thread count (`-t`; 0: all cores).
    pub threads: usize,
}

/// Lead-in lengths in seconds, and the explosion bound: mocap limbs stay below ~10 m/s, an
/// exploding solver throws vertices at hundreds.
pub const SETTLE_S: f32 = 0.5;
pub const BLEND_S: f32 = 1.0;
pub const SPEED_LIMIT: f32 = 30.0;
/// Each perturbation step lengthens the rest hold by this (s): runs 0.1 s apart were 2–3 mm
/// apart at frame 0 and 30–37 mm over 131_02, independent draws of the skirt's chaos
/// (docs/lab/2026-12-05-dynamic-history.md, "How far apart two simulations of 131_02 are").
pub const PERTURB_S: f32 = 0.1;

/// The poses and meshes handed to the solver: lead-in and clip, body and pin targets.
pub struct Prepared {
    pub poses: Vec<Vec<JointTransform>>,
    pub lead_in: usize,
    pub body_frames: Frames,
    pub garment_targets: Frames,
}

impl Prepared {
    /// The clip's rate, which every frame sequence here carries.
    pub fn fps(&self) -> f32 {
        self.body_frames.fps
    }
}

/// Poses the body and the garment's LBS over lead-in + clip.
pub fn prepare(scene: &Scene, settings: &Settings) -> Result<Prepared> {
    let clip = scene.clip;
    let count = settings
        .frames
        .unwrap_or(usize::MAX)
        .min(clip.frame_count());
    if count == 0 {
        bail!("nothing to simulate: the clip has no frames");
    }
    let skeleton = &scene.body.skeleton;
    let frames_for = |s: f32| (s * clip.fps).round() as usize;
    let perturb = frames_for(PERTURB_S).max(1) * settings.perturb as usize;
    let mut poses = lead_in::poses(
        skeleton,
        &clip.local_pose(0),
        frames_for(settings.settle_s) + perturb,
        frames_for(settings.blend_s),
    );
    let lead_in = poses.len();
    poses.extend((0..count).map(|f| clip.local_pose(f)));
    let skin = garment_lbs(scene.body, scene.garment)?;
    let skinned = |s: &Skin, rest: &[[f32; 3]]| -> Frames {
        let points = poses
            .iter()
            .map(|p| s.skin_points(rest, &skeleton.skinning_matrices(p)))
            .collect();
        Frames::new(points, clip.fps)
    };
    Ok(Prepared {
        body_frames: skinned(&scene.body.skin, &scene.body.mesh().positions),
        garment_targets: skinned(&skin, &scene.garment.mesh.positions),
        poses,
        lead_in,
    })
}

/// The nearest body vertex's weights (4 influences): the pinned vertices move rigidly with the
/// skin vertex under them. Only pinned vertices read these targets after the first frame.
fn garment_lbs(body: &Body, garment: &Garment) -> Result<Skin> {
    let index = PointIndex::new(&body.mesh().positions)?;
    let (skin, _) = weights::garment_skin(
        &garment.mesh,
        &body.skin,
        body.skeleton.joint_count(),
        &index,
        1,
        4,
        None,
    );
    Ok(skin)
}

/// A finished simulation of the clip's frames (lead-in dropped).
pub struct Simulation {
    pub garment: Frames,
    pub blender_version: String,
    /// Solver wall time over lead-in + clip.
    pub seconds: f64,
    pub simulated_frames: usize,
}

/// A simulated clip with its figures.
pub struct Outcome {
    /// The garment at the clip's frames (lead-in dropped).
    pub garment: Frames,
    /// The posed body at the clip's frames.
    pub body: Frames,
    pub entry: cache::Entry,
    pub key: String,
    /// Read from the cache instead of simulated.
    pub cached: bool,
}

/// Simulates `scene` (or reads it from `cache_dir`), checks it and measures it.
/// `on_frame(done, total)` follows the solver.
pub fn run(
    scene: &Scene,
    settings: &Settings,
    cache_dir: Option<&std::path::Path>,
    on_frame: &dyn Fn(usize, usize),
) -> Result<Outcome> {
    let prepared = prepare(scene, settings)?;
    let files = blender::job_files(scene, &prepared, settings)?;
    let blender_version = blender::version(&settings.blender)?;
    let key = cache::key(crate::build_id::id(), &blender_version, &files);
    let n = scene.garment.mesh.vertex_count();
    let lead = prepared.lead_in;
    let clip_body = Frames::new(prepared.body_frames[lead..].to_vec(), prepared.fps());
    if let Some((garment, entry)) = cache_dir.and_then(|d| cache::load(d, &key, n, prepared.fps()))
    {
        return Ok(Outcome {
            garment,
            body: clip_body,
            entry,
            key,
            cached: true,
        });
    }
    let total = prepared.poses.len();
    let work = blender::WorkDir::new()?;
    blender::write_job(&work.0, &files)?;
    drop(files);
    let sim = blender::run(&work.0, settings, n, prepared.fps(), lead, &|k| {
        on_frame(k, total)
    })?;
    if sim.simulated_frames != total {
        bail!(
            "Blender simulated {} of {total} frames",
            sim.simulated_frames
        );
    }
    stats::check(&sim.garment, prepared.fps(), settings.speed_limit, lead)?;
    let setup = stats::ClipSetup {
        body: scene.body,
        rest: &scene.garment.mesh.positions,
        triangles: &scene.garment.mesh.triangles,
        pinned: blender::pinned(scene),
        fps: prepared.fps(),
    };
    let garment = Frames::new(sim.garment[lead..].to_vec(), prepared.fps());
    let (frames, summary) = stats::of(
        &setup,
        &garment,
        &prepared.poses[lead..],
        &prepared.garment_targets[lead..],
        lead.checked_sub(1).map(|p| &sim.garment[p][..]),
    );
    let entry = cache::Entry {
        blender_version: sim.blender_version,
        seconds: sim.seconds,
        simulated_frames: sim.simulated_frames,
        lead_in: lead,
        summary,
        frames,
    };
    if let Some(dir) = cache_dir {
        cache::store(dir, &key, &garment, &entry)?;
    }
    Ok(Outcome {
        garment,
        body: clip_body,
        entry,
        key,
        cached: false,
    })
}
