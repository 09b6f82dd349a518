//! `bench rollout`: a dynamic model's roll-out timed by phase, without and with the collision
//! fix, beside Blender's cloth simulation of the same frames, in the same run.

use super::Feedback;
use crate::compute::Compute;
use crate::garment::Garment;
use crate::io::gltf_body::read_body;
use crate::rollout::timing::Timing;
use crate::rollout::{for_model, Init, Settings};
use crate::simulate::{self, Scene};
use anyhow::{bail, Result};
use serde::Serialize;
use std::fmt::{self, Display, Formatter};
use std::path::PathBuf;

/// What to time (the flags of `bench rollout`, resolved).
pub struct Request {
    /// Dynamic model with its motion stage.
    pub model: PathBuf,
    /// The body and garment to simulate, the model's.
    pub body: PathBuf,
    pub garment: PathBuf,
    /// The one clip, played at the model's rate.
    pub clips: super::Clips,
    /// The fabric (a FABRIC.toml or a preset name), read when the simulation starts.
    pub fabric: String,
    /// Frames of the clip, from its start.
    pub frames: usize,
    /// The roll-out's strain limit and collision fix, off (`plain`) and on (`fixed`).
    pub plain: Settings,
    pub fixed: Settings,
    pub compute: Compute,
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

/// Rolls the model out over the clip's first frames twice (fix off, then on), then simulates
/// the same frames in Blender, each timed.
pub fn run(request: &Request, feedback: &Feedback) -> Result<RolloutTimes> {
    let r = request;
    let (file, _device) = super::load_model(&r.compute, &r.model)?;
    let fps = file.info.dynamic()?.fps;
    file.dynamic()?.motion()?;
    let body = read_body(&r.body)?;
    let garment = Garment::read(&r.garment)?;
    if garment.mesh.vertex_count() != file.garment.vertex_count() {
        bail!(
            "{}: {} vertices, the model's garment {}",
            r.garment.display(),
            garment.mesh.vertex_count(),
            file.garment.vertex_count()
        );
    }
    let clip = r.clips.load_single_at(&body, Some(fps))?.1.animation;
    let n = r.frames.max(2).min(clip.frame_count());
    let poses: Vec<_> = (0..n).map(|f| clip.local_pose(f)).collect();
    let (say, hide_bar) = (feedback.say, feedback.hide_bars);
    let roll = |settings: &Settings| -> Result<Timing> {
        let bar = crate::progress::bar(poses.len() as u64, "roll-out", hide_bar);
        let r = for_model(
            &file,
            &poses,
            0..poses.len(),
            &Init::Rest,
            settings.clone(),
            &mut |f| bar.set_position(f as u64 + 1),
        )?;
        bar.finish_and_clear();
        Ok(Timing::of(&r.timings))
    };
    say(&format!("rolling out {} frames at {fps} fps", poses.len()));
    let plain = roll(&r.plain)?;
    let fixed = roll(&r.fixed)?;
    say("simulating the same frames in Blender (no cache)");
    let fabric = crate::fabric::Fabric::load(&r.fabric)?;
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
        threads: r.compute.threads,
    };
    let bar = crate::progress::bar(0, "simulate", hide_bar);
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
        threads: r.compute.threads,
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

impl Display for RolloutTimes {
    fn fmt(&self, f: &mut Formatter) -> fmt::Result {
        let t = self;
        writeln!(
            f,
            "{} frames at {} fps, {} threads",
            t.frames, t.fps, t.threads
        )?;
        let row = |f: &mut Formatter, name: &str, x: &Timing, total: f64| {
            writeln!(
                f,
                "{name}: {total:.1} ms per frame (input maps {:.1}, encoder {:.1}, decode + skinning {:.1}, strain limit {:.1}, collision {:.1}; fix on {} frames)",
                x.inputs_ms, x.encoder_ms, x.decode_ms, x.strain_ms, x.collision_ms, x.fixed_frames
            )
        };
        row(f, "roll-out, no collision fix", &t.plain, t.plain_ms)?;
        row(f, "roll-out, collision fix", &t.fixed, t.fixed_ms)?;
        writeln!(
            f,
            "simulate (Blender cloth): solver {:.1} ms per simulated frame; {:.1} ms per clip frame with its {} lead-in frames",
            t.solver_ms_per_simulated_frame, t.simulate_ms, t.lead_in_frames
        )?;
        writeln!(
            f,
            "roll-out is {:.1}x faster than simulate without the fix, {:.1}x with it",
            t.speedup_plain, t.speedup_fixed
        )
    }
}
