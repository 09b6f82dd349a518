//! `bench swing`: the swing trainer (`train-swing`) timed on real inputs — the setup (clips,
//! basis, body correspondences) and whole epochs — and the recipe's training time projected
//! from them, beside `bench train`'s PBNS step.

use super::Clips;
use crate::compute::Compute;
use crate::train::swing::{Inputs, Settings, Trainer};
use crate::train::Training;
use anyhow::{bail, Result};
use serde::Serialize;
use std::fmt::{self, Display, Formatter};
use std::path::PathBuf;
use std::time::Instant;

/// What to time (the flags of `bench swing`, resolved).
pub struct Request {
    /// The quasi-static PBNS the swing trains on.
    pub from: PathBuf,
    pub clips: Clips,
    /// Epochs timed (each plays every clip in order, then its steps).
    pub epochs: usize,
    /// Swing blend shapes and bones, as `train-swing`.
    pub shapes: usize,
    pub bones: usize,
    pub compute: Compute,
}

/// Where a swing training's time goes.
#[derive(Serialize)]
pub struct SwingTimes {
    pub frames: usize,
    pub fps: f32,
    pub threads: usize,
    pub steps_per_epoch: usize,
    /// Reading the clips and model, the basis, the body correspondences.
    pub setup_s: f64,
    /// Mean over the timed epochs.
    pub epoch_s: f64,
    pub step_ms: f64,
    /// Training frames per second of wall time (an epoch's frames over its seconds).
    pub frames_per_s: f64,
    /// The documented recipe's epochs and its projected wall time (setup + epochs × epoch).
    pub recipe_epochs: usize,
    pub recipe_s: f64,
}

/// Builds the trainer as `train-swing` does and runs `request.epochs` epochs of it.
pub fn run(request: &Request) -> Result<SwingTimes> {
    if request.epochs == 0 {
        bail!("--epochs must be at least 1: nothing would be timed");
    }
    let started = Instant::now();
    let (model, device) = super::load_model(&request.compute, &request.from)?;
    let settings = Settings {
        shapes: request.shapes,
        bones: request.bones,
        fps: request.clips.fps.unwrap_or(Settings::recipe().fps),
        device,
        ..Settings::recipe()
    };
    let inputs = Inputs::read(
        model,
        &request.clips.motions,
        &request.clips.reader()?,
        settings.fps,
    )?;
    let mut trainer = Trainer::new(inputs, settings)?;
    let setup_s = started.elapsed().as_secs_f64();
    let timed = Instant::now();
    for _ in 0..request.epochs {
        trainer.run_epoch()?;
    }
    let epoch_s = timed.elapsed().as_secs_f64() / request.epochs as f64;
    let (frames, _) = trainer.frames();
    let steps = trainer.steps_per_epoch();
    let recipe_epochs = Settings::recipe().epochs;
    Ok(SwingTimes {
        frames,
        fps: trainer.settings.fps,
        threads: request.compute.threads,
        steps_per_epoch: steps,
        setup_s,
        epoch_s,
        step_ms: 1e3 * epoch_s / steps.max(1) as f64,
        frames_per_s: frames as f64 / epoch_s,
        recipe_epochs,
        recipe_s: setup_s + recipe_epochs as f64 * epoch_s,
    })
}

impl Display for SwingTimes {
    fn fmt(&self, f: &mut Formatter) -> fmt::Result {
        writeln!(
            f,
            "{} frames at {} fps, {} steps per epoch, {} threads",
            self.frames, self.fps, self.steps_per_epoch, self.threads
        )?;
        writeln!(
            f,
            "setup {:.1} s; an epoch {:.1} s ({:.0} ms per step, {:.0} frames/s)",
            self.setup_s, self.epoch_s, self.step_ms, self.frames_per_s
        )?;
        writeln!(
            f,
            "the recipe's {} epochs: about {:.0} s ({:.1} min)",
            self.recipe_epochs,
            self.recipe_s,
            self.recipe_s / 60.0
        )
    }
}
