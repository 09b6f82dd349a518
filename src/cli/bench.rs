//! `garmentbake bench train`: throughput of the training step and where its time goes.
//! `garmentbake bench rollout`: a dynamic model's roll-out against Blender's cloth solver on the
//! same frames, in the same run. `bench swing`: the swing trainer's setup and epochs.

use super::args::{short_help, CollisionFixArgs, ComputeArgs, FabricArgs, OutputArgs, NO_IDS};
use super::args::{TrainInputs, SHORT_HELP_NOTE, TRAIN_SHORT_HIDES};
use super::Execute;
use crate::bake::compress::Targets;
use crate::pipeline::bench_rollout::{self, RolloutTimes};
use crate::pipeline::Feedback;
use crate::train::pbns::{RefreshMode, StepBench, Trainer};
use anyhow::Result;
use serde::Serialize;
use std::path::PathBuf;

/// Measure speed. `train`: poses/s, garment-vertex-poses/s and the split between forward,
/// losses, nearest neighbour (candidate lookup + amortised k-d tree refreshes) and backward.
/// `rollout`: ms per frame of a dynamic model's roll-out (network phases, collision fix) beside
/// Blender's cloth simulation of the same frames, and the ratio. `bake`: a PBNS bake by phase
/// beside Blender's glTF export. `swing`: `train-swing`'s setup and epochs, and the recipe's time.
#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    what: What,
}

#[derive(clap::Subcommand)]
enum What {
    /// Time training steps on real inputs (same options as `train`).
    Train(TrainBench),
    /// Time a roll-out and the simulation of the same frames.
    Rollout(RolloutBench),
    /// Time a PBNS bake by phase beside Blender's glTF export of the same asset.
    Bake(BakeBench),
    /// Time `train-swing` on real inputs: setup, epochs, the recipe's projected time.
    Swing(SwingBench),
}

#[derive(clap::Args)]
struct SwingBench {
    /// The quasi-static PBNS the swing trains on (.safetensors).
    #[arg(long, help_heading = "Inputs")]
    from: PathBuf,
    #[command(flatten)]
    clips: super::args::ClipArgs,
    /// Epochs timed.
    #[arg(long, default_value_t = 2, help_heading = "Training")]
    epochs: usize,
    /// Swing blend shapes (as `train-swing --shapes`).
    #[arg(long, default_value_t = crate::train::swing::Settings::recipe().shapes, help_heading = "Training")]
    shapes: usize,
    /// Swing bones (as `train-swing --bones`).
    #[arg(long, default_value_t = 0, help_heading = "Training")]
    bones: usize,
    #[command(flatten)]
    compute: ComputeArgs,
    #[command(flatten)]
    output: OutputArgs,
}

#[derive(clap::Args)]
struct BakeBench {
    /// Trained PBNS model (.safetensors).
    #[arg(long, help_heading = "Inputs")]
    model: PathBuf,
    #[command(flatten)]
    clips: super::args::ClipArgs,
    /// Blend shapes to keep (as `bake --max-targets`).
    #[arg(long, default_value_t = 64, help_heading = "Outputs")]
    max_targets: usize,
    /// Skip Blender's export.
    #[arg(long, help_heading = "Advanced")]
    no_blender: bool,
    #[command(flatten)]
    compute: ComputeArgs,
    #[command(flatten)]
    output: OutputArgs,
}

#[derive(clap::Args)]
struct RolloutBench {
    /// Dynamic model with its motion stage.
    #[arg(long, help_heading = "Inputs")]
    model: PathBuf,
    /// The body to simulate on (glTF), the one the model was trained with.
    #[arg(long, help_heading = "Inputs")]
    body: PathBuf,
    /// The garment to simulate (OBJ/USD with its sidecar), the model's.
    #[arg(long, help_heading = "Inputs")]
    garment: PathBuf,
    /// The clip (one --motion), played at the model's rate.
    #[command(flatten)]
    clips: super::args::MotionArgs,
    #[command(flatten)]
    fabric: FabricArgs,
    /// Frames of the clip, from its start.
    #[arg(long, default_value_t = 60, help_heading = "Inputs")]
    frames: usize,
    #[command(flatten)]
    collision: CollisionFixArgs,
    #[command(flatten)]
    compute: ComputeArgs,
    #[command(flatten)]
    output: OutputArgs,
}

#[derive(clap::Args)]
#[command(after_help = SHORT_HELP_NOTE)]
#[command(mut_args(short_help(TRAIN_SHORT_HIDES, NO_IDS)))]
struct TrainBench {
    #[command(flatten)]
    inputs: TrainInputs,
    /// Timed steps (0: one refresh cycle, `--refresh-every` epochs of steps).
    #[arg(long, default_value_t = 0, help_heading = "Training")]
    steps: usize,
    /// Untimed steps first (allocator and cache warm-up).
    #[arg(long, default_value_t = 5, help_heading = "Training")]
    warmup: usize,
    #[command(flatten)]
    output: OutputArgs,
}

/// The measurement and the thread count it ran with.
#[derive(Serialize)]
#[serde(untagged)]
pub enum Report {
    Train {
        #[serde(flatten)]
        bench: StepBench,
        threads: usize,
    },
    Rollout(RolloutTimes),
    Bake(crate::pipeline::bench_bake::Report),
    Swing(crate::pipeline::bench_swing::SwingTimes),
}

impl Args {
    pub fn json(&self) -> bool {
        match &self.what {
            What::Train(b) => b.output.json,
            What::Rollout(b) => b.output.json,
            What::Bake(b) => b.output.json,
            What::Swing(b) => b.output.json,
        }
    }
}

impl RolloutBench {
    fn run(&self, say: &dyn Fn(&str)) -> Result<RolloutTimes> {
        let request = bench_rollout::Request {
            model: self.model.clone(),
            body: self.body.clone(),
            garment: self.garment.clone(),
            clips: self.clips.clips(None),
            fabric: self.fabric.fabric.clone(),
            frames: self.frames,
            plain: self.collision.settings(false)?,
            fixed: self.collision.settings(true)?,
            compute: self.compute.compute(),
        };
        let feedback = Feedback {
            say,
            hide_bars: self.output.json,
        };
        bench_rollout::run(&request, &feedback)
    }
}

impl Execute for Args {
    type Report = Report;

    fn execute(&self, say: &dyn Fn(&str)) -> Result<Report> {
        let b = match &self.what {
            What::Train(b) => b,
            What::Rollout(r) => return Ok(Report::Rollout(r.run(say)?)),
            What::Swing(s) => {
                let request = crate::pipeline::bench_swing::Request {
                    from: s.from.clone(),
                    clips: s.clips.clips(),
                    epochs: s.epochs,
                    shapes: s.shapes,
                    bones: s.bones,
                    compute: s.compute.compute(),
                };
                return Ok(Report::Swing(crate::pipeline::bench_swing::run(&request)?));
            }
            What::Bake(b) => {
                let request = crate::pipeline::bench_bake::Request {
                    model: b.model.clone(),
                    clips: b.clips.clips(),
                    targets: Targets::from_flags(Some(b.max_targets), None, Targets::Full)?,
                    blender: !b.no_blender,
                    device: b.compute.apply()?,
                };
                return Ok(Report::Bake(crate::pipeline::bench_bake::run(
                    &request, say,
                )?));
            }
        };
        let (inputs, settings, _) = b.inputs.load(1, false)?;
        let mut trainer = Trainer::new(inputs, settings)?;
        Ok(Report::Train {
            bench: trainer.bench(b.steps, b.warmup)?,
            threads: b.inputs.compute.threads,
        })
    }

    fn print(r: &Report) {
        let (b, threads) = match r {
            Report::Train { bench, threads } => (bench, *threads),
            Report::Rollout(t) => return print!("{t}"),
            Report::Bake(b) => return print!("{b}"),
            Report::Swing(s) => return print!("{s}"),
        };
        println!(
            "{} steps of {} poses, {} garment vertices, {} training poses, {} threads",
            b.steps, b.batch, b.garment_vertices, b.train_poses, threads
        );
        println!(
            "{:.0} poses/s, {:.0}k garment-vertex-poses/s ({:.1} ms per step)",
            b.poses_per_s,
            b.vertex_poses_per_s / 1e3,
            1e3 * b.split.seconds / b.steps.max(1) as f64
        );
        println!(
            "candidate refresh ({}): {:.2} s for all {} poses, every {} epochs; body subset {} of {} vertices",
            match b.refresh {
                RefreshMode::Device => "brute force on the device, between steps",
                _ => "k-d trees on a worker thread, overlapping the steps",
            },
            b.refresh_seconds,
            b.train_poses,
            b.refresh_every,
            b.body_subset,
            b.body_vertices
        );
        println!("{}", b.split);
    }
}
