//! `garmentbake simulate`: cloth-simulated ground truth of a garment on a clip (Blender).

use super::args::{ClipArgs, FabricArgs, OutputArgs};
use super::Execute;
use crate::garment::Garment;
use crate::io::gltf_body::read_body;
use crate::io::point_cache::write_cache;
use crate::simulate::{self, cache, stats, Scene, Settings};
use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Simulate a garment on a motion clip with Blender's cloth solver (headless, a subprocess) and
/// write the garment's vertices per frame as a point cache: the ground truth dynamic models
/// train on.
///
/// The body is posed by garmentbake's own retargeting and skinning (the body every model sees)
/// and given to Blender as an animated collision mesh; pinned vertices (the garment's NAME.toml,
/// or the fabric's `pinned`) follow the body. Before frame 0 the garment settles on the body at
/// rest (--settle seconds), then the body blends into the clip's first pose (--blend seconds);
/// those frames are simulated, not written. Solver settings come from the fabric's [simulate]
/// table. Blender's cloth runs in its own frame time, which is converted: the clip plays in real
/// seconds at its rate.
///
/// Results are cached under --cache (default runs/sim), keyed by the hash of everything Blender
/// is given: the same request again is read back at once. Figures per frame (vertices inside the
/// body by winding number, edge strain, fastest vertex, pinned drift) are computed by
/// garmentbake, not Blender; --json prints them all.
#[derive(clap::Args)]
pub struct Args {
    /// Skinned body (glTF/glb); metres, Y-up.
    #[arg(long, help_heading = "Inputs")]
    pub body: PathBuf,
    /// Garment mesh in the body's rest pose (OBJ or USD) with its NAME.toml sidecar (pins).
    #[arg(long, help_heading = "Inputs")]
    pub garment: PathBuf,
    /// The clip (one --motion).
    #[command(flatten)]
    pub clips: ClipArgs,
    #[command(flatten)]
    pub fabric: FabricArgs,
    /// Garment point cache, one sample per clip frame: .pc2 (start frame 0), .usda/.usdc/.usdz or
    /// .abc (Alembic).
    #[arg(long, help_heading = "Outputs")]
    pub out: PathBuf,
    /// Also write the posed body as a point cache (same formats).
    #[arg(long, help_heading = "Outputs")]
    pub body_out: Option<PathBuf>,
    /// Simulate only the clip's first N frames.
    #[arg(long, help_heading = "Inputs")]
    pub frames: Option<usize>,
    /// Seconds the garment settles on the resting body before the lead-in blend.
    #[arg(long, default_value_t = simulate::SETTLE_S, value_parser = super::args::non_negative::<f32>(), help_heading = "Advanced")]
    pub settle: f32,
    /// Seconds of blending from the rest pose into the clip's first pose.
    #[arg(long, default_value_t = simulate::BLEND_S, value_parser = super::args::non_negative::<f32>(), help_heading = "Advanced")]
    pub blend: f32,
    /// Run N of a perturbed ensemble (for `compare`): the rest hold before the blend lasts
    /// N × 0.1 s longer, so runs 0, 1, 2 … are independent draws of a chaotic garment on the
    /// same clip. 0 is the plain simulation; each N has its own cache entry.
    #[arg(long, default_value_t = 0, help_heading = "Advanced")]
    pub perturb: u32,
    /// Stop with an error when a vertex moves faster than this (m/s): the solver exploded.
    #[arg(long, default_value_t = simulate::SPEED_LIMIT, value_parser = super::args::positive::<f32>(), help_heading = "Advanced")]
    pub speed_limit: f32,
    /// Cache folder for simulations.
    #[arg(long, default_value = cache::DEFAULT_DIR, help_heading = "Advanced")]
    pub cache: PathBuf,
    /// Neither read nor write the cache.
    #[arg(long, help_heading = "Advanced")]
    pub no_cache: bool,
    /// Blender executable (default: $GARMENTBAKE_BLENDER, else `blender` on PATH).
    #[arg(long, help_heading = "Advanced")]
    pub blender: Option<PathBuf>,
    /// Blender's threads (0: all cores). Results are the same for any count (checked by a test).
    #[arg(long, default_value_t = 0, help_heading = "Advanced")]
    pub threads: usize,
    #[command(flatten)]
    pub output: OutputArgs,
}

#[derive(Serialize, Deserialize)]
pub struct Report {
    pub motion: PathBuf,
    pub garment: PathBuf,
    pub fabric: String,
    pub fps: f32,
    pub frames: usize,
    pub garment_vertices: usize,
    pub pinned: usize,
    pub lead_in_frames: usize,
    /// The run of a perturbed ensemble (`--perturb`).
    pub perturb: u32,
    pub blender_version: String,
    /// Solver seconds per simulated frame (lead-in included), from when it was simulated.
    pub seconds_per_frame: f64,
    pub cached: bool,
    pub cache_key: String,
    pub summary: stats::Summary,
    pub per_frame: Vec<stats::FrameStats>,
    pub out: PathBuf,
    pub body_out: Option<PathBuf>,
}

impl Args {
    fn settings(&self) -> Result<Settings> {
        for (name, v) in [("--settle", self.settle), ("--blend", self.blend)] {
            if !v.is_finite() || v < 0.0 {
                bail!("{name} {v}: must be a non-negative number of seconds");
            }
        }
        Ok(Settings {
            settle_s: self.settle,
            blend_s: self.blend,
            perturb: self.perturb,
            frames: self.frames,
            speed_limit: self.speed_limit,
            blender: self.blender.clone().unwrap_or_default(),
            threads: self.threads,
        })
    }
}

impl Execute for Args {
    type Report = Report;

    fn execute(&self, say: &dyn Fn(&str)) -> Result<Report> {
        let quiet = self.output.json;
        use super::args::{output_set, Writes, POINT_CACHE};
        use exporters::FileKind::{Alembic, Pc2, Usd};
        let outputs = output_set(&[
            (
                "--out",
                Some(&self.out),
                Writes::Kinds(&[Pc2, Usd, Alembic]),
            ),
            ("--body-out", self.body_out.as_deref(), POINT_CACHE),
        ])?;
        let body = read_body(&self.body)?;
        let garment = Garment::read(&self.garment)?;
        if let Some(p) = garment.fit_problems(&body)?.first() {
            bail!("{}: {p}", self.garment.display());
        }
        let fabric = self.fabric.load()?;
        let clips = self.clips.clips();
        let (motion, clip) = clips.load_single(&body)?;
        let mut settings = self.settings()?;
        settings.blender = simulate::blender::find(self.blender.as_deref())?;
        let scene = Scene {
            body: &body,
            garment: &garment,
            fabric: &fabric,
            clip: &clip.animation,
        };
        if simulate::blender::pinned(&scene).is_empty() {
            say(&format!(
                "warning: {} has no pinned vertices: nothing holds it to the body but collisions",
                self.garment.display()
            ));
        }
        let bar = crate::progress::bar(0, "simulate", quiet);
        let cache_dir = (!self.no_cache).then_some(self.cache.as_path());
        let outcome = simulate::run(&scene, &settings, cache_dir, &|done, total| {
            bar.set_length(total as u64);
            bar.set_position(done as u64);
        })?;
        bar.finish_and_clear();
        let fps = clip.animation.fps;
        outputs.write(&self.out, |p| {
            write_cache(p, &garment.mesh, &outcome.garment)
        })?;
        if let Some(path) = &self.body_out {
            outputs.write(path, |p| write_cache(p, body.mesh(), &outcome.body))?;
        }
        outputs.commit()?;
        let e = outcome.entry;
        Ok(Report {
            motion: motion.to_path_buf(),
            garment: self.garment.clone(),
            fabric: fabric.name.clone(),
            fps,
            frames: outcome.garment.len(),
            garment_vertices: garment.mesh.vertex_count(),
            pinned: simulate::blender::pinned(&scene).len(),
            lead_in_frames: e.lead_in,
            perturb: self.perturb,
            blender_version: e.blender_version,
            seconds_per_frame: e.seconds / e.simulated_frames.max(1) as f64,
            cached: outcome.cached,
            cache_key: outcome.key,
            summary: e.summary,
            per_frame: e.frames,
            out: self.out.clone(),
            body_out: self.body_out.clone(),
        })
    }

    fn print(r: &Report) {
        let s = &r.summary;
        println!(
            "{}: {} frames at {} fps, {} garment vertices ({} pinned), fabric {}, Blender {}",
            r.motion.display(),
            r.frames,
            r.fps,
            r.garment_vertices,
            r.pinned,
            r.fabric,
            r.blender_version
        );
        let how = if r.cached {
            "read from the cache"
        } else {
            "simulated"
        };
        println!(
            "{how}: {:.3} s/frame over {} lead-in + {} clip frames (key {}){}",
            r.seconds_per_frame,
            r.lead_in_frames,
            r.frames,
            &r.cache_key[..12],
            if r.perturb > 0 {
                format!(", perturbed run {}", r.perturb)
            } else {
                String::new()
            }
        );
        println!(
            "inside the body (winding number): {:.3} % of vertices on average, worst frame {} ({} vertices), depth p99 {:.1} mm, max {:.1} mm",
            s.inside.inside_pct, s.inside.worst_frame, s.inside.worst_frame_vertices, s.inside.depth_p99_mm, s.inside.depth_max_mm
        );
        println!(
            "edge strain |e − e_T| / e_T: mean {:.2} %, worst frame {:.2} %; fastest vertex {:.2} m/s (frame {}); pinned drift max {:.3} mm",
            s.mean_strain_pct, s.max_strain_pct, s.max_speed, s.max_speed_frame, s.pinned_error_max_mm
        );
        println!("wrote {}", r.out.display());
        if let Some(b) = &r.body_out {
            println!("wrote {}", b.display());
        }
    }
}
