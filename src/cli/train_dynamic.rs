//! `garmentbake train-dynamic`: the motion-guided dynamic model, trained on simulated clips.

use super::args::{ClipArgs, ComputeArgs, OutputArgs};
use super::Execute;
use crate::fabric::Fabric;
use crate::garment::Garment;
use crate::io::gltf_body::read_body;
use crate::io::point_cache::read_pc2;
use crate::models::dynamic::SpaceShape;
use crate::models::file::DynamicEpoch;
use crate::motion::{load_clip, read_maps};
use crate::rig::Skeleton;
use crate::train::dynamic::{FrameData, Reconstruction, Sequence, Settings, SpaceTrainer};
use crate::train::{fit, FitOptions, Fitted, Training};
use anyhow::{bail, Result};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Train the dynamic garment model on cloth simulations (`garmentbake simulate`).
///
/// Stage `space` (this build): the generative space of garment deformations. Each simulated
/// frame is measured relative to body seed points, laid out in the garment's UV map, encoded to
/// a 64-number latent and decoded to per-vertex displacements in each vertex's rest frame, then
/// skinned by the seeds with distance weights whose kernel radius is learnt per body part. Loss:
/// reconstruction (positions and Laplacians, L1), edge lengths of garments decoded from random
/// latents, the exact signed distance to the rest body (hinge) and a latent regulariser. The
/// garment needs UVs. The dynamic encoder and roll-out are the next stage, not built yet.
///
/// Give each --motion its --sim cache (same order, same --fps as simulated). Judge the space with
/// --eval-motion/--eval-sim on a clip it never saw. A checkpoint is written next to --out every
/// epoch; --resume continues from it.
#[derive(clap::Args)]
pub struct Args {
    /// Skinned body (glTF/glb) the simulations used.
    #[arg(long)]
    pub body: PathBuf,
    /// Garment mesh (OBJ with UVs) the simulations used.
    #[arg(long)]
    pub garment: PathBuf,
    #[command(flatten)]
    pub clips: ClipArgs,
    /// The simulated garment of each --motion (.pc2 from `garmentbake simulate`), in order.
    #[arg(long = "sim", required = true)]
    pub sims: Vec<PathBuf>,
    /// Stage to train.
    #[arg(long, value_enum, default_value = "space")]
    pub stage: StageArg,
    /// Network size: cpu (64² map, 128 seeds, ≤ 256 channels) or paper (128², 581, 1024: a GPU).
    #[arg(long, default_value = "cpu")]
    pub preset: String,
    /// Latent size (the preset's 64 when not given): the linear path starts as this many
    /// principal components of the training frames.
    #[arg(long)]
    pub latent: Option<usize>,
    /// Fabric the simulations used (recorded in the model).
    #[arg(long, default_value = "cotton")]
    pub config: String,
    #[arg(long, default_value_t = 30)]
    pub epochs: usize,
    /// Frames per optimisation step.
    #[arg(long, default_value_t = 4)]
    pub batch: usize,
    /// Initial Adam learning rate (cosine decay to a tenth).
    #[arg(long, default_value_t = 3e-4)]
    pub lr: f64,
    /// Seed: same seed and inputs → the same model.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// A clip held out from training and its simulation: reconstruction error reported on it.
    #[arg(long, requires = "eval_sim")]
    pub eval_motion: Option<PathBuf>,
    #[arg(long, requires = "eval_motion")]
    pub eval_sim: Option<PathBuf>,
    /// Output model (.safetensors).
    #[arg(long)]
    pub out: PathBuf,
    /// Continue from OUT's checkpoint up to --epochs.
    #[arg(long)]
    pub resume: bool,
    /// Append one JSON object per epoch to this file.
    #[arg(long)]
    pub log: Option<PathBuf>,
    #[command(flatten)]
    pub compute: ComputeArgs,
    #[command(flatten)]
    pub output: OutputArgs,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum StageArg {
    Space,
    Dynamic,
}

#[derive(Serialize)]
pub struct Report {
    #[serde(flatten)]
    pub fitted: Fitted,
    pub frames: usize,
    /// Training frames processed per second of wall time.
    pub frames_per_second: f64,
    pub train: Reconstruction,
    pub eval: Option<(String, Reconstruction)>,
    /// Learnt kernel radius per body part (mm).
    pub radius_mm: Vec<(String, f64)>,
    pub last: Option<DynamicEpoch>,
}

/// Clips and their simulations, checked against each other.
fn sequences(
    motions: &[PathBuf],
    sims: &[PathBuf],
    args: &ClipArgs,
    skeleton: &Skeleton,
    vertices: usize,
) -> Result<Vec<Sequence>> {
    if motions.len() != sims.len() {
        bail!(
            "{} --motion clips but {} --sim caches: give each clip its simulation",
            motions.len(),
            sims.len()
        );
    }
    let maps = read_maps(&args.maps)?;
    motions
        .iter()
        .zip(sims)
        .map(|(m, s)| {
            let clip = load_clip(m, &maps, skeleton, args.fps)?.animation;
            let garment = read_pc2(s, vertices)?;
            if garment.len() > clip.frame_count() {
                bail!(
                    "{}: {} frames, but {} has {} at {} fps (simulated at another --fps?)",
                    s.display(),
                    garment.len(),
                    m.display(),
                    clip.frame_count(),
                    clip.fps
                );
            }
            Ok(Sequence {
                name: file_name(m),
                clip,
                garment,
            })
        })
        .collect()
}

fn file_name(p: &Path) -> String {
    p.file_name()
        .map_or(String::new(), |n| n.to_string_lossy().into_owned())
}

impl Execute for Args {
    type Report = Report;

    fn execute(&self, say: &dyn Fn(&str)) -> Result<Report> {
        if matches!(self.stage, StageArg::Dynamic) {
            bail!("--stage dynamic (the dynamic encoder and roll-out) is not built yet; this build trains --stage space");
        }
        let device = self.compute.apply()?;
        let body = read_body(&self.body)?;
        let garment = Garment::read(&self.garment)?;
        // The UV layout first: a garment without one fails before any cache is read.
        crate::models::dynamic::UvRaster::new(
            &garment.mesh,
            8,
            &self.garment.display().to_string(),
        )?;
        let fabric = Fabric::load(&self.config)?;
        let n = garment.mesh.vertex_count();
        let train = sequences(
            &self.clips.motions,
            &self.sims,
            &self.clips,
            &body.skeleton,
            n,
        )?;
        let eval = match (&self.eval_motion, &self.eval_sim) {
            (Some(m), Some(s)) => sequences(
                std::slice::from_ref(m),
                std::slice::from_ref(s),
                &self.clips,
                &body.skeleton,
                n,
            )?
            .pop(),
            _ => None,
        };
        let mut shape = SpaceShape::preset(&self.preset)?;
        shape.latent = self.latent.unwrap_or(shape.latent);
        let mut settings = Settings::new(shape);
        settings.epochs = self.epochs;
        settings.batch = self.batch;
        settings.learning_rate = self.lr;
        settings.seed = self.seed;
        settings.device = device;
        let mut trainer = SpaceTrainer::new(body, garment, fabric, &train, settings)?;
        let frames = trainer.data.len();
        say(&format!(
            "{frames} training frames from {} clip(s)",
            train.len()
        ));
        if self.resume {
            trainer.resume(&crate::train::checkpoint_path(&self.out))?;
        }
        let done = trainer.epochs_done();
        let fitted = fit(
            &mut trainer,
            &FitOptions {
                epochs: self.epochs,
                out: &self.out,
                quiet: self.output.json,
                log: self.log.as_deref(),
            },
        )?;
        let space = trainer.space();
        let train_err = SpaceTrainer::measure(space, &trainer.data);
        let eval = eval
            .map(|s| {
                let info = trainer.info();
                let seeds = crate::models::dynamic::Seeds::from_vertices(
                    &trainer.file.body,
                    &info.seeds,
                    &info.seed_parts,
                )?;
                let data =
                    FrameData::new(&trainer.file.body, &seeds, std::slice::from_ref(&s), device);
                Ok::<_, anyhow::Error>((s.name.clone(), SpaceTrainer::measure(space, &data)))
            })
            .transpose()?;
        let info = trainer.info();
        Ok(Report {
            frames,
            frames_per_second: (frames * (fitted.epochs - done)) as f64 / fitted.seconds.max(1e-9),
            train: train_err,
            eval,
            radius_mm: info
                .parts
                .iter()
                .cloned()
                .zip(info.radii.iter().map(|r| r * 1e3))
                .collect(),
            last: info.history.last().cloned(),
            fitted,
        })
    }

    fn print(r: &Report) {
        println!(
            "trained {} epochs on {} frames in {:.0} s ({:.1} frames/s)",
            r.fitted.epochs, r.frames, r.fitted.seconds, r.frames_per_second
        );
        let row = |name: &str, x: &Reconstruction| {
            println!("{name:<24} {:>6} frames   mean {:>6.2} mm   p99 {:>6.2} mm   max {:>6.2} mm (worst frame {})", x.frames, x.mean_mm, x.p99_mm, x.max_mm, x.worst_frame);
        };
        println!("reconstruction (vertex L2):");
        row("training frames", &r.train);
        if let Some((name, e)) = &r.eval {
            row(&format!("{name} (held out)"), e);
        }
        let radii: Vec<String> = r
            .radius_mm
            .iter()
            .map(|(p, v)| format!("{p} {v:.1}"))
            .collect();
        println!("kernel radius per part (mm): {}", radii.join(", "));
        println!("wrote {}", r.fitted.out.display());
    }
}
