//! `garmentbake bench train`: throughput of the training step and where its time goes.

use super::args::{OutputArgs, TrainInputs};
use super::Execute;
use crate::train::pbns::{RefreshMode, StepBench, Trainer};
use anyhow::Result;
use serde::Serialize;

/// Measure training speed: poses/s, garment-vertex-poses/s and the split between forward,
/// losses, nearest neighbour (candidate lookup + amortised k-d tree refreshes) and backward.
#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    what: What,
}

#[derive(clap::Subcommand)]
enum What {
    /// Time training steps on real inputs (same options as `train`).
    Train(TrainBench),
}

#[derive(clap::Args)]
struct TrainBench {
    #[command(flatten)]
    inputs: TrainInputs,
    /// Timed steps (0: one refresh cycle, `--refresh-every` epochs of steps).
    #[arg(long, default_value_t = 0)]
    steps: usize,
    /// Untimed steps first (allocator and cache warm-up).
    #[arg(long, default_value_t = 5)]
    warmup: usize,
    #[command(flatten)]
    output: OutputArgs,
}

/// The measurement and the thread count it ran with.
#[derive(Serialize)]
pub struct Report {
    #[serde(flatten)]
    pub bench: StepBench,
    pub threads: usize,
}

impl Args {
    pub fn json(&self) -> bool {
        let What::Train(b) = &self.what;
        b.output.json
    }
}

impl Execute for Args {
    type Report = Report;

    fn execute(&self, _say: &dyn Fn(&str)) -> Result<Report> {
        let What::Train(b) = &self.what;
        let (inputs, settings, _) = b.inputs.load(1, false)?;
        let mut trainer = Trainer::new(inputs, settings)?;
        Ok(Report {
            bench: trainer.bench(b.steps, b.warmup)?,
            threads: b.inputs.compute.threads,
        })
    }

    fn print(r: &Report) {
        let b = &r.bench;
        println!(
            "{} steps of {} poses, {} garment vertices, {} training poses, {} threads",
            b.steps, b.batch, b.garment_vertices, b.train_poses, r.threads
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
