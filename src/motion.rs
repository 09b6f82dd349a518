//! Loading motion clips onto a body: read the BVH, resolve its joint names, retarget onto its
//! skeleton, its feet on the floor.

use crate::body::Body;
use crate::io::bvh::Bvh;
use crate::io::joint_map::{self, ClipJoints, JointMap};
use crate::rig::capture::ClipAxes;
use crate::rig::ground::Feet;
use crate::rig::retarget::{check_drive, retarget, JointFate, JointMapping, Retargeted};
use crate::rig::JointTransform;
use anyhow::{bail, Result};
use std::path::Path;

/// How clips are read: the `--map` files (each applies to the clips whose joints it names) and
/// what the user says of axes and units (`--up`, `--units`; detected when not given).
#[derive(Clone, Debug, Default)]
pub struct ClipReader {
    pub maps: Vec<JointMap>,
    pub axes: ClipAxes,
}

impl ClipReader {
    pub fn with_axes(mut self, axes: ClipAxes) -> ClipReader {
        self.axes = axes;
        self
    }
}

/// Reads `--map` files into a [`ClipReader`] that detects axes and units.
pub fn read_maps(paths: &[impl AsRef<Path>]) -> Result<ClipReader> {
    Ok(ClipReader {
        maps: paths
            .iter()
            .map(|p| JointMap::read(p.as_ref()))
            .collect::<Result<_, _>>()?,
        axes: ClipAxes::default(),
    })
}

/// What one clip joint became under the resolved map (`inspect --map`).
#[derive(Clone, Debug, serde::Serialize)]
pub struct JointFateLine {
    pub joint: String,
    /// `LeftUpLeg`, `folded into CC_Base_Hip`, `dropped` ...
    pub became: String,
}

/// The map a clip resolves to, what each of its joints became, and how it was read.
pub fn clip_joint_fates(
    path: &Path,
    reader: &ClipReader,
    body: &Body,
) -> Result<(Retargeted, Vec<JointFateLine>)> {
    let bvh = Bvh::read(path)?;
    let (clip, mapping) = retarget_bvh(path, &bvh, reader, body)?;
    let lines = mapping
        .fates
        .iter()
        .zip(&bvh.joints)
        .map(|(fate, j)| JointFateLine {
            joint: j.name.clone(),
            became: match fate {
                JointFate::Mapped { rig } => body.skeleton.joint_names[*rig].clone(),
                JointFate::Folded { into, explicit } => format!(
                    "folded into {}{}",
                    into.map_or("the root (turns the whole clip)", |k| bvh.joints[k]
                        .name
                        .as_str()),
                    if *explicit { " (fold)" } else { "" }
                ),
                JointFate::Dropped { explicit: true } => "dropped (skip)".to_string(),
                JointFate::Dropped { explicit: false } => "dropped".to_string(),
            },
        })
        .collect();
    Ok((clip, lines))
}

/// A draft joint map for a clip (`garmentbake map suggest`).
pub fn suggest_map(path: &Path) -> Result<crate::io::map_suggest::Suggestion> {
    let bvh = Bvh::read(path)?;
    let names: Vec<&str> = bvh.joints.iter().map(|j| j.name.as_str()).collect();
    let parents: Vec<Option<usize>> = bvh.joints.iter().map(|j| j.parent).collect();
    Ok(crate::io::map_suggest::suggest(
        &path.display().to_string(),
        &names,
        &parents,
    )?)
}

/// A clip retargeted onto `body`'s skeleton, optionally resampled to `fps` (an integer divisor of the
/// source rate: frames are kept, never interpolated).
pub fn load_clip(
    path: &Path,
    reader: &ClipReader,
    body: &Body,
    fps: Option<f32>,
) -> Result<Retargeted> {
    let bvh = Bvh::read(path)?;
    let (mut clip, _) = retarget_bvh(path, &bvh, reader, body)?;
    // Every command that reads a clip says how: a wrong up axis or unit is found here, not in
    // a garment through the floor.
    crate::progress::note(&format!(
        "reading: {}: {}",
        path.file_name().unwrap_or_default().to_string_lossy(),
        clip.reading.describe(&clip.map_name)
    ));
    if let Some(fps) = fps {
        let step = clip.animation.fps / fps;
        if fps <= 0.0 || (step - step.round()).abs() > 1e-3 || step < 1.0 {
            bail!(
                "{}: --fps {fps} must divide the clip rate {} (e.g. {})",
                path.display(),
                clip.animation.fps,
                clip.animation.fps / 4.0
            );
        }
        clip.animation = clip.animation.subsampled(0, step.round() as usize);
    }
    Ok(clip)
}

/// Resolves the clip's map, checks it drives the body, retargets.
fn retarget_bvh(
    path: &Path,
    bvh: &Bvh,
    reader: &ClipReader,
    body: &Body,
) -> Result<(Retargeted, JointMapping)> {
    let skeleton = &body.skeleton;
    if bvh.frame_count() < 2 {
        bail!(
            "{}: needs at least 2 frames, has {}",
            path.display(),
            bvh.frame_count()
        );
    }
    let names: Vec<&str> = bvh.joints.iter().map(|j| j.name.as_str()).collect();
    let parents: Vec<Option<usize>> = bvh.joints.iter().map(|j| j.parent).collect();
    let rig: Vec<&str> = skeleton.joint_names.iter().map(String::as_str).collect();
    let name = path
        .file_stem()
        .map_or("clip".into(), |s| s.to_string_lossy().into_owned());
    let joints = ClipJoints {
        names: &names,
        parents: &parents,
    };
    let resolved = joint_map::resolve(&path.display().to_string(), joints, &rig, &reader.maps)?;
    check_drive(&resolved, skeleton)
        .map_err(|e| anyhow::anyhow!("{}: map '{}': {e}", path.display(), resolved.map_name))?;
    let feet = Feet::of(skeleton, &body.mesh().positions, &body.skin);
    let clip = retarget(
        &bvh.capture(),
        &resolved,
        skeleton,
        &feet,
        &name,
        reader.axes,
    );
    Ok((clip, resolved))
}

/// Clips played one after another as one pose sequence: each clip after the first is moved
/// on the ground so that its root starts where the previous clip's root ended (no jump), and its
/// first `fade` frames blend from the previous clip's last pose (smoothstep; rotations slerped).
/// All clips must share one frame rate.
pub fn chain(clips: &[&crate::rig::SkelAnimation], fade: usize) -> Vec<Vec<JointTransform>> {
    let mut poses: Vec<Vec<JointTransform>> = Vec::new();
    for clip in clips {
        let mut frames: Vec<Vec<JointTransform>> = (0..clip.frame_count())
            .map(|f| clip.local_pose(f))
            .collect();
        if let (Some(last), Some(first)) = (poses.last().cloned(), frames.first().cloned()) {
            let mut shift = last[0].translation - first[0].translation;
            shift.y = 0.0;
            for pose in &mut frames {
                pose[0].translation += shift;
            }
            for (i, pose) in frames.iter_mut().take(fade).enumerate() {
                let x = (i + 1) as f32 / (fade + 1) as f32;
                let w = x * x * (3.0 - 2.0 * x);
                for (j, from) in pose.iter_mut().zip(&last) {
                    j.translation = from.translation.lerp(&j.translation, w);
                    j.rotation = from.rotation.slerp(&j.rotation, w);
                }
            }
        }
        poses.extend(frames);
    }
    poses
}
