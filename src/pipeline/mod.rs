//! The steps behind the commands that gather inputs from several layers and hand back what a
//! command writes or prints: a command file declares its flags, converts them into a step's
//! inputs, calls it and prints the result; the work is here, callable without a command line.
//!
//! - `preview`: clips, caches and models posed into the shots of a contact sheet
//! - `eval`: a PBNS model over a clip, written as a point cache, measured beside plain LBS
//! - `view`: the browser page of a bake, or of caches on a model's garment
//! - `rollout`: a dynamic model played over clips, written and measured against simulations
//! - `compare`: caches of one clip against perturbed simulations of it
//! - `train_dynamic`: the dynamic model's two stages trained on simulated clips
//! - `outputs`: a command's outputs checked before any work, written all or none
//! - `bench_bake`: the PBNS bake timed by phase beside Blender's glTF export of the same asset
//! - `bench_rollout`: a dynamic model's roll-out timed beside Blender's cloth on the same frames

pub mod bench_bake;
pub mod bench_rollout;
pub mod bench_swing;
pub mod compare;
pub mod eval;
pub mod outputs;
pub mod preview;
pub mod rollout;
pub mod train_dynamic;
pub mod view;

use anyhow::{bail, Result};
use std::path::{Path, PathBuf};

/// The motion-capture clips a step reads, and how (the flags of `cli::args::ClipArgs`).
#[derive(Clone, Debug, Default)]
pub struct Clips {
    pub motions: Vec<PathBuf>,
    /// Joint-name maps (TOML); each applies to the clips whose joints it covers.
    pub maps: Vec<PathBuf>,
    /// Keep every n-th frame so clips play at this rate.
    pub fps: Option<f32>,
    /// The clips' up axis and length unit; detected when none.
    pub up: Option<crate::rig::capture::UpAxis>,
    pub units: Option<crate::rig::capture::Units>,
}

impl Clips {
    pub fn new(
        motions: &[PathBuf],
        maps: &[PathBuf],
        fps: Option<f32>,
        up: Option<crate::rig::capture::UpAxis>,
        units: Option<crate::rig::capture::Units>,
    ) -> Clips {
        let (motions, maps) = (motions.to_vec(), maps.to_vec());
        Clips {
            motions,
            maps,
            fps,
            up,
            units,
        }
    }

    /// The maps and axes every clip is read with.
    pub fn reader(&self) -> Result<crate::motion::ClipReader> {
        Ok(
            crate::motion::read_maps(&self.maps)?.with_axes(crate::rig::capture::ClipAxes {
                up: self.up,
                units: self.units,
            }),
        )
    }

    /// The one clip of a step that reads exactly one, retargeted onto `body` at `fps`.
    pub fn load_single(
        &self,
        body: &crate::body::Body,
    ) -> Result<(&Path, crate::rig::retarget::Retargeted)> {
        self.load_single_at(body, self.fps)
    }

    /// [`Clips::load_single`] at the rate `fps` (a model's own rate: see
    /// [`crate::models::swing::clip_rate`]).
    pub fn load_single_at(
        &self,
        body: &crate::body::Body,
        fps: Option<f32>,
    ) -> Result<(&Path, crate::rig::retarget::Retargeted)> {
        let motion = self.single()?;
        Ok((
            motion,
            crate::motion::load_clip(motion, &self.reader()?, body, fps)?,
        ))
    }

    /// The one clip of a step that reads exactly one.
    pub fn single(&self) -> Result<&Path> {
        single_motion(&self.motions)
    }
}

/// `compute` applied (threads, then the device), then the model file at `path` loaded onto it.
pub fn load_model(
    compute: &crate::compute::Compute,
    path: &Path,
) -> Result<(crate::models::file::ModelFile, tch::Device)> {
    let device = compute.apply()?;
    Ok((crate::models::file::load(path, device)?, device))
}

/// The one clip of `motions`, for a step that reads exactly one.
pub fn single_motion(motions: &[PathBuf]) -> Result<&Path> {
    match motions {
        [one] => Ok(one),
        many => bail!(
            "this command reads one --motion, got {}; run it once per clip",
            many.len()
        ),
    }
}

/// What a step tells a person while it runs: notes (`say`: a command prints them, `--json`
/// drops them) and progress bars (`hide_bars`: a command's `--json` hides the terminal bar;
/// `progress::bar` still logs plain lines off a terminal, and `--quiet` silences all).
pub struct Feedback<'a> {
    pub say: &'a dyn Fn(&str),
    pub hide_bars: bool,
}
