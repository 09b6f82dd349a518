//! `garmentbake bench train`: throughput of the training step and where its time goes.
//! `garmentbake bench rollout`: a dynamic model's roll-out against Blender's cloth solver on the
//! same frames, in the same run.

use super::args::{CollisionFixArgs, ComputeArgs, FabricArgs, OutputArgs, TrainInputs};
use super::Execute;
use crate::bake::compress::Targets;
use crate::garment::Garment;
use crate::io::gltf_body::read_body;
use crate::motion::{load_clip, read_maps};
use crate::rollout::timing::Timing;
use crate::rollout::{for_model, Init};
use crate::simulate::{self, Scene};
use crate::train::pbns::{RefreshMode, StepBench, Trainer};
use anyhow::bail;
use anyhow::Result;
use serde::Serialize;
use std::path::PathBuf;

/// Measure speed. `train`: poses/s, garment-vertex-poses/s and the split between forward,
/// losses, nearest neighbour (candidate lookup + amortised k-d tree refreshes) and backward.
/// `rollout`: ms per frame of a dynamic model's roll-out (network phases, collision fix) beside
/// Blender's cloth simulation of the same frames, and the ratio.
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
}

#[derive(clap::Args)]
struct BakeBench {
    /// Trained PBNS model (.safetensors).
    #[arg(long)]
    model: PathBuf,
    #[command(flatten)]
    clips: super::args::ClipArgs,
    /// Blend shapes to keep (as `bake --max-targets`).
    #[arg(long, default_value_t = 64)]
    max_targets: usize,
    /// Skip Blender's export.
    #[arg(long)]
    no_blender: bool,
    #[command(flatten)]
    compute: ComputeArgs,
    #[command(flatten)]
    output: OutputArgs,
}

#[derive(clap::Args)]
struct RolloutBench {
    /// Dynamic model with its motion stage.
    #[arg(long)]
    model: PathBuf,
    /// The body to simulate on (glTF), the one the model was trained with.
    #[arg(long)]
    body: PathBuf,
    /// The garment to simulate (OBJ/USD with its sidecar), the model's.
    #[arg(long)]
    garment: PathBuf,
    /// The clip (one --motion), played at the model's rate.
    #[arg(long)]
    motion: PathBuf,
    /// Joint-name map(s) (TOML) for the clip.
    #[arg(long = "map")]
    maps: Vec<PathBuf>,
    #[command(flatten)]
    fabric: FabricArgs,
    /// Frames of the clip, from its start.
    #[arg(long, default_value_t = 60)]
    frames: usize,
    #[command(flatten)]
    collision: CollisionFixArgs,
    #[command(flatten)]
    compute: ComputeArgs,
    #[command(flatten)]
    output: OutputArgs,
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
#[serde(untagged)]
pub enum Report {
    Train {
        #[serde(flatten)]
        bench: StepBench,
        threads: usize,
    },
    Rollout(RolloutTimes),
    Bake(crate::pipeline::bench_bake::Report),
}

/// Roll-out and simulation of the same frames, per clip frame.
#[derive(Serialize)]
pub struct RolloutTimes {
    pub frames: usize,
    pub fps: f32,
    pub threads: usize,
    /// Network phases and collision check, without the fix.
    pub plain: Timing,
    pub plain_ms: f64,
    /// With the collision fix (the product's default).
    pub fixed: Timing,
    pub fixed_ms: f64,
    /// Blender's wall time per clip frame (its lead-in frames included in the total), and the
    /// solver's own seconds per simulated frame.
    pub simulate_ms: f64,
    pub solver_ms_per_simulated_frame: f64,
    pub lead_in_frames: usize,
    /// The solver's ms per simulated frame over the roll-out's ms per frame (lead-in aside),
    /// without and with the fix.
    pub speedup_plain: f64,
    pub speedup_fixed: f64,
}

impl Args {
    pub fn json(&self) -> bool {
        match &self.what {
            What::Train(b) => b.output.json,
            What::Rollout(b) => b.output.json,
            What::Bake(b) => b.output.json,
        }
    }
}

impl RolloutBench {
    fn run(&self, say: &dyn Fn(&str)) -> Result<RolloutTimes> {
        let (file, _device) = self.compute.load_model(&self.model)?;
        let fps = file.info.dynamic()?.fps;
        file.dynamic()?.motion()?;
        let body = read_body(&self.body)?;
        let garment = Garment::read(&self.garment)?;
        if garment.mesh.vertex_count() != file.garment.vertex_count() {
            bail!(
                "{}: {} vertices, the model's garment {}",
                self.garment.display(),
                garment.mesh.vertex_count(),
                file.garment.vertex_count()
            );
        }
        let maps = read_maps(&self.maps)?;
        let clip = load_clip(&self.motion, &maps, &body.skeleton, Some(fps))?.animation;
        let n = self.frames.max(2).min(clip.frame_count());
        let poses: Vec<_> = (0..n).map(|f| clip.local_pose(f)).collect();
        let quiet = self.output.json;
        let roll = |fix: bool| -> Result<Timing> {
            let bar = crate::progress::bar(poses.len() as u64, "roll-out", quiet);
            let settings = self.collision.settings(fix)?;
            let r = for_model(&file, &poses, &Init::Rest, settings, &mut |f| {
                bar.set_position(f as u64 + 1)
            })?;
            bar.finish_and_clear();
            Ok(Timing::of(&r.timings))
        };
        say(&format!("rolling out {} frames at {fps} fps", poses.len()));
        let plain = roll(false)?;
        let fixed = roll(true)?;
        say("simulating the same frames in Blender (no cache)");
        let fabric = self.fabric.load()?;
        let scene = Scene {
            body: &body,
            garment: &garment,
            fabric: &fabric,
            clip: &clip,
        };
        let settings = simulate::Settings {
            settle_s: simulate::SETTLE_S,
            blend_s: simulate::BLEND_S,
            perturb: 0,
            frames: Some(poses.len()),
            speed_limit: simulate::SPEED_LIMIT,
            blender: simulate::blender::find(None)?,
            threads: self.compute.threads,
        };
        let bar = crate::progress::bar(0, "simulate", quiet);
        let clock = std::time::Instant::now();
        let outcome = simulate::run(&scene, &settings, None, &|done, total| {
            bar.set_length(total as u64);
            bar.set_position(done as u64);
        })?;
        bar.finish_and_clear();
        let simulate_ms = 1e3 * clock.elapsed().as_secs_f64() / poses.len() as f64;
        let total = |t: &Timing| t.network_ms + t.strain_ms + t.collision_ms;
        let e = outcome.entry;
        let solver_ms = 1e3 * e.seconds / e.simulated_frames.max(1) as f64;
        Ok(RolloutTimes {
            frames: poses.len(),
            fps,
            threads: self.compute.threads,
            plain_ms: total(&plain),
            fixed_ms: total(&fixed),
            simulate_ms,
            solver_ms_per_simulated_frame: solver_ms,
            lead_in_frames: e.lead_in,
            speedup_plain: solver_ms / total(&plain).max(1e-9),
            speedup_fixed: solver_ms / total(&fixed).max(1e-9),
            plain,
            fixed,
        })
    }
}

impl Execute for Args {
    type Report = Report;

    fn execute(&self, say: &dyn Fn(&str)) -> Result<Report> {
        let b = match &self.what {
            What::Train(b) => b,
            What::Rollout(r) => return Ok(Report::Rollout(r.run(say)?)),
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
            Report::Rollout(t) => return print_rollout(t),
            Report::Bake(b) => return print!("{b}"),
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

fn print_rollout(t: &RolloutTimes) {
    println!(
        "{} frames at {} fps, {} threads",
        t.frames, t.fps, t.threads
    );
    let row = |name: &str, x: &Timing, total: f64| {
        println!(
            "{name}: {total:.1} ms per frame (input maps {:.1}, encoder {:.1}, decode + skinning {:.1}, strain limit {:.1}, collision {:.1}; fix on {} frames)",
            x.inputs_ms, x.encoder_ms, x.decode_ms, x.strain_ms, x.collision_ms, x.fixed_frames
        )
    };
    row("roll-out, no collision fix", &t.plain, t.plain_ms);
    row("roll-out, collision fix", &t.fixed, t.fixed_ms);
    println!(
        "simulate (Blender cloth): solver {:.1} ms per simulated frame; {:.1} ms per clip frame with its {} lead-in frames",
        t.solver_ms_per_simulated_frame, t.simulate_ms, t.lead_in_frames
    );
    println!(
        "roll-out is {:.1}x faster than simulate without the fix, {:.1}x with it",
        t.speedup_plain, t.speedup_fixed
    );
}
