//! `garmentbake interpolate`: garments decoded along a straight line between two frames' latents.

use super::args::{output_set, ComputeArgs, OutputArgs, POINT_CACHE};
use super::Execute;
use crate::interpolate::between;
use crate::io::point_cache::read_pc2;
use crate::io::point_cache::write_cache_in;
use crate::metrics::vertex_distances_mm;
use crate::simulate::stats::{self, ClipSetup, FrameStats};
use anyhow::{bail, Context, Result};
use serde::Serialize;
use std::path::PathBuf;

/// Walk a trained generative space (`train-dynamic`) from one simulated frame to another.
///
/// Encodes the simulated garment at clip frames A and B, then decodes the straight line between
/// the two latents, one step per clip frame from A to B, each skinned on that frame's body: the
/// ends are the space's reconstructions of A and B, the frames between show whether the space
/// is smooth (plausible garments, no blow-up, nothing through the body) or only memorised its
/// training frames. Prints per frame the distance to the simulation of that frame, the vertices
/// inside the body and the edge strain. Writes the walk as a point cache whose first sample is
/// clip frame A (recorded in the cache: PC2's start frame, MDD's times, USD's time codes,
/// Alembic's start time); draw it with `garmentbake preview --cache OUT`.
#[derive(clap::Args)]
pub struct Args {
    /// Dynamic model (.safetensors); the space stage is enough.
    #[arg(long, help_heading = "Inputs")]
    pub model: PathBuf,
    /// The simulated clip (one --motion), resampled to the model's rate.
    #[command(flatten)]
    pub clips: super::args::MotionArgs,
    /// The clip's simulation (.pc2 from `garmentbake simulate`, at the model's rate; its first
    /// frames are enough).
    #[arg(long, help_heading = "Inputs")]
    pub sim: PathBuf,
    /// The two clip frames, A,B (A < B), e.g. 40,70.
    #[arg(long, value_delimiter = ',', required = true, help_heading = "Inputs")]
    pub between: Vec<usize>,
    /// Output point cache (.pc2, .mdd, .usda/.usdc/.usd, .abc, .vat.exr/.vat.png), samples for
    /// frames A..=B.
    #[arg(long, help_heading = "Outputs")]
    pub out: PathBuf,
    #[command(flatten)]
    pub space: super::args::CacheSpaceArgs,
    #[command(flatten)]
    pub compute: ComputeArgs,
    #[command(flatten)]
    pub output: OutputArgs,
}

#[derive(Serialize)]
pub struct Report {
    pub motion: PathBuf,
    pub fps: f32,
    pub from_frame: usize,
    pub to_frame: usize,
    /// |z_B − z_A| (the latents are scaled to unit variance over the training frames).
    pub latent_distance: f64,
    pub frames: Vec<Step>,
    pub max_strain_pct: f64,
    pub mean_inside_pct: f64,
    pub out: PathBuf,
}

/// One decoded frame of the walk.
#[derive(Serialize)]
pub struct Step {
    pub frame: usize,
    /// Position on the line: 0 at A, 1 at B.
    pub t: f64,
    /// Vertex L2 to the simulation's garment of the same clip frame (mean, max).
    pub vs_sim_mean_mm: f64,
    pub vs_sim_max_mm: f64,
    pub inside_pct: f64,
    pub strain_pct: f64,
}

impl Execute for Args {
    type Report = Report;

    fn execute(&self, _say: &dyn Fn(&str)) -> Result<Report> {
        let [a, b] = self.between[..] else {
            bail!("--between takes two frames, A,B");
        };
        let outputs = output_set(&[("--out", Some(&self.out), POINT_CACHE)])?;
        let (file, _device) = crate::pipeline::load_model(&self.compute.compute(), &self.model)?;
        let fps = file.info.dynamic()?.fps;
        let clips = self.clips.clips(None);
        let (motion, clip) = clips.load_single_at(&file.body, Some(fps))?;
        let clip = clip.animation;
        let sim = read_pc2(&self.sim, file.garment.vertex_count(), fps)?;
        // A simulation of the clip's first frames (`simulate --frames N`) is enough.
        let poses: Vec<_> = (0..clip.frame_count().min(sim.len()))
            .map(|f| clip.local_pose(f))
            .collect();
        if sim.len() > clip.frame_count() {
            bail!(
                "{}: {} frames, the clip has {} at {fps} fps (simulated at another rate?)",
                self.sim.display(),
                sim.len(),
                clip.frame_count()
            );
        }
        let path =
            between(&file, &poses, &sim, (a, b)).with_context(|| format!("--between {a},{b}"))?;
        outputs.write(&self.out, |p| {
            write_cache_in(p, &file.garment, &path.frames, self.space.space())
        })?;
        outputs.commit()?;
        let (per_frame, summary) = stats::of(
            &ClipSetup::unpinned(&file.body, &file.garment, fps),
            &path.frames,
            &poses[a..=b],
            &[],
            None,
        );
        let steps = per_frame
            .iter()
            .zip(path.frames.iter())
            .map(|(s, x)| step(s, a, b, x, &sim[a + s.frame]))
            .collect();
        let latent_distance = path
            .z_a
            .iter()
            .zip(&path.z_b)
            .map(|(p, q)| f64::from(p - q).powi(2))
            .sum::<f64>()
            .sqrt();
        Ok(Report {
            motion: motion.to_path_buf(),
            fps,
            from_frame: a,
            to_frame: b,
            latent_distance,
            frames: steps,
            max_strain_pct: summary.max_strain_pct,
            mean_inside_pct: summary.inside.inside_pct,
            out: self.out.clone(),
        })
    }

    fn print(r: &Report) {
        println!(
            "latent walk from frame {} to {} of {} ({} fps), |z_B − z_A| = {:.2}",
            r.from_frame,
            r.to_frame,
            r.motion.display(),
            r.fps,
            r.latent_distance
        );
        println!("frame     t   vs simulation mm (mean, max)  inside %  strain %");
        for s in &r.frames {
            println!(
                "{:>5}  {:.2}  {:>10.2} {:>10.1}          {:>7.3}  {:>7.2}",
                s.frame, s.t, s.vs_sim_mean_mm, s.vs_sim_max_mm, s.inside_pct, s.strain_pct
            );
        }
        println!(
            "worst edge strain {:.2} %, {:.3} % of vertices inside the body on average; wrote {}",
            r.max_strain_pct,
            r.mean_inside_pct,
            r.out.display()
        );
    }
}

fn step(s: &FrameStats, a: usize, b: usize, x: &[[f32; 3]], sim: &[[f32; 3]]) -> Step {
    let d = vertex_distances_mm(x, sim);
    Step {
        frame: a + s.frame,
        t: s.frame as f64 / (b - a) as f64,
        vs_sim_mean_mm: d.iter().sum::<f64>() / d.len().max(1) as f64,
        vs_sim_max_mm: d.iter().copied().fold(0.0, f64::max),
        inside_pct: s.inside_pct,
        strain_pct: s.strain_pct,
    }
}
