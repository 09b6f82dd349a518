//! Loading motion clips onto a skeleton: read the BVH, resolve its joint names, retarget.

use crate::io::bvh::Bvh;
use crate::io::joint_map::{self, JointMap};
use crate::rig::retarget::{retarget, Retargeted};
use crate::rig::{JointTransform, Skeleton};
use anyhow::{bail, Result};
use std::path::Path;

/// Reads `--map` files (each applies to the clips whose joint names it covers).
pub fn read_maps(paths: &[impl AsRef<Path>]) -> Result<Vec<JointMap>> {
    Ok(paths
        .iter()
        .map(|p| JointMap::read(p.as_ref()))
        .collect::<Result<_, _>>()?)
}

/// A clip retargeted onto `skeleton`, optionally resampled to `fps` (an integer divisor of the
/// source rate: frames are kept, never interpolated).
pub fn load_clip(
    path: &Path,
    maps: &[JointMap],
    skeleton: &Skeleton,
    fps: Option<f32>,
) -> Result<Retargeted> {
    let bvh = Bvh::read(path)?;
    if bvh.frame_count() < 2 {
        bail!(
            "{}: needs at least 2 frames, has {}",
            path.display(),
            bvh.frame_count()
        );
    }
    let names: Vec<&str> = bvh.joints.iter().map(|j| j.name.as_str()).collect();
    let rig: Vec<&str> = skeleton.joint_names.iter().map(String::as_str).collect();
    let name = path
        .file_stem()
        .map_or("clip".into(), |s| s.to_string_lossy().into_owned());
    let resolved = joint_map::resolve(&path.display().to_string(), &names, &rig, maps)?;
    let mut clip = retarget(&bvh.capture(), &resolved, skeleton, &name);
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
