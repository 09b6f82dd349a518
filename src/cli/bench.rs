//! `garmentbake bench train`: throughput of the training step and where its time goes.

use super::train::{split_json, split_line, InputArgs};
use crate::train::{PhaseTimes, Trainer};
use anyhow::Result;
use serde_json::json;
use std::time::Instant;

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
    inputs: InputArgs,
    /// Timed steps (0: one refresh cycle, `--refresh-every` epochs of steps).
    #[arg(long, default_value_t = 0)]
    steps: usize,
    /// Untimed steps first (allocator and cache warm-up).
    #[arg(long, default_value_t = 5)]
    warmup: usize,
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
}

pub fn run(args: Args) -> Result<i32> {
    let What::Train(b) = args.what;
    let (inputs, settings) = b.inputs.load(1, false, b.json)?;
    let mut trainer = Trainer::new(inputs, settings)?;
    let n = trainer.model().shape.vertices;
    let poses = trainer.poses.train.len() as i64;
    let batch = trainer.settings.batch as i64;
    let ids =
        |s: usize| -> Vec<i64> { (0..batch).map(|i| (s as i64 * batch + i) % poses).collect() };
    trainer.refresh();
    for s in 0..b.warmup {
        trainer.step(&ids(s), 1e-4)?;
    }
    // One refresh cycle as training runs it: snapshot + worker thread during the steps of
    // `refresh_every` epochs, then install (waiting for the worker if it is not done).
    let steps = match b.steps {
        0 => trainer.steps_per_epoch() * trainer.settings.refresh_every.max(1),
        s => s,
    };
    // On the device the refresh is synchronous (brute force), once per cycle.
    let dense = trainer.settings.dense_refresh;
    trainer.times = PhaseTimes::default();
    let t = Instant::now();
    if dense {
        trainer.refresh_dense();
    } else {
        trainer.start_refresh();
    }
    trainer.times.refresh += t.elapsed();
    for s in 0..steps {
        trainer.step(&ids(b.warmup + s), 1e-4)?;
    }
    let t = Instant::now();
    trainer.finish_refresh();
    trainer.times.refresh += t.elapsed();
    let timed = trainer.times;
    // What one refresh costs on its own (the worker's overlapped the steps above).
    let t = Instant::now();
    if dense {
        trainer.refresh_dense();
    } else {
        trainer.refresh();
    }
    let one_refresh = t.elapsed();
    trainer.times = timed;
    let t = trainer.times;
    let poses_per_s = t.poses as f64 / t.total().as_secs_f64();
    if b.json {
        println!(
            "{}",
            json!({ "garment_vertices": n, "batch": batch, "train_poses": poses, "threads": b.inputs.threads,
                    "poses_per_s": poses_per_s, "vertex_poses_per_s": poses_per_s * n as f64,
                    "refresh_seconds": one_refresh.as_secs_f64(), "refresh": if dense { "device" } else { "trees" }, "split": split_json(&t) })
        );
    } else {
        println!(
            "{} steps of {} poses, {} garment vertices, {} training poses, {} threads",
            steps, batch, n, poses, b.inputs.threads
        );
        println!(
            "{:.0} poses/s, {:.0}k garment-vertex-poses/s ({:.1} ms per step)",
            poses_per_s,
            poses_per_s * n as f64 / 1e3,
            1e3 * t.total().as_secs_f64() / steps as f64
        );
        println!(
            "candidate refresh ({}): {:.2} s for all {} poses, every {} epochs; body subset {} of {} vertices",
            if dense { "brute force on the device, between steps" } else { "k-d trees on a worker thread, overlapping the steps" },
            one_refresh.as_secs_f64(),
            poses,
            trainer.settings.refresh_every,
            trainer.correspondences().subset_len(),
            trainer.file.body.mesh.vertex_count()
        );
        println!("{}", split_line(&t));
    }
    Ok(0)
}
