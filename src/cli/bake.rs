//! `garmentbake bake`: a trained PBNS model + clips → glTF / USD with blend shapes, skin and
//! one animation (joints + blend-shape weights) per clip.

use super::args::{ClipArgs, ComputeArgs, OutputArgs};
use super::Execute;
use crate::bake::pbns::{bake, BakeOptions, BakeReport, Targets};
use crate::eval::ClipCoverage;

use crate::motion::load_clip;
use crate::validate::Validation;
use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Bake a trained PBNS model into a file any engine plays without a neural runtime.
///
/// The PSD basis becomes morph targets (applied before skinning, as in the model), the trained
/// blend weights the skin, and per clip the MLP output becomes a blend-shape weight animation
/// next to the joint animation. The basis is compressed (SVD of the offsets the clips use):
/// --max-targets fixes the count, --tolerance-mm picks the fewest within a replay error; with
/// neither, the full basis is written. The replay error against the network is printed in mm.
///
/// Per clip, the pose coverage is printed as `eval` prints it (each frame's pose distance to the
/// nearest training pose, the frames beyond the trained range, the farthest frames): the frames
/// to look at before shipping the file.
#[derive(clap::Args)]
pub struct Args {
    /// Trained model (.safetensors from `garmentbake train`).
    #[arg(long, help_heading = "Inputs")]
    pub model: PathBuf,
    #[command(flatten)]
    pub clips: ClipArgs,
    /// Output: .glb / .gltf (glTF 2.0) or .usda / .usdc / .usdz (UsdSkel).
    #[arg(long, help_heading = "Outputs")]
    pub out: PathBuf,
    /// Number of blend shapes to keep (8 is what every glTF client must support).
    #[arg(long, conflicts_with = "tolerance_mm", help_heading = "Outputs")]
    pub max_targets: Option<usize>,
    /// Keep the fewest blend shapes whose max offset error over the clips is within this (mm).
    #[arg(long, value_parser = super::args::positive::<f32>(), help_heading = "Outputs")]
    pub tolerance_mm: Option<f32>,
    /// Joint influences per vertex in the file (default: the model's own, which loses nothing).
    #[arg(long, help_heading = "Outputs")]
    pub influences: Option<usize>,
    /// Add the body mesh on the same skeleton.
    #[arg(long, help_heading = "Outputs")]
    pub with_body: bool,
    /// Check what was written as `garmentbake validate` does: its structure, and its replay
    /// (glTF: as the spec evaluates it; USD: through UsdSkel) against the network on every clip
    /// within --tolerance-mm (default 1 mm); exit 1 when it fails.
    #[arg(long, help_heading = "Outputs")]
    pub validate: bool,
    /// Also write a page that plays the bake in a browser (as `garmentbake view FILE.glb --out`).
    #[arg(long, value_name = "PAGE.html", help_heading = "Outputs")]
    pub view: Option<PathBuf>,
    #[command(flatten)]
    pub compute: ComputeArgs,
    #[command(flatten)]
    pub output: OutputArgs,
}

/// One clip's pose coverage, as `eval` reports it.
#[derive(Serialize, Deserialize)]
pub struct ClipCoverageLine {
    pub clip: String,
    #[serde(flatten)]
    pub coverage: ClipCoverage,
    /// The 8 frames farthest from the training poses (farthest first).
    pub farthest: Vec<usize>,
}

impl ClipCoverageLine {
    /// Every clip's coverage, when the model stores its training poses.
    fn of_clips(
        model: &crate::models::file::ModelFile,
        clips: &[crate::rig::SkelAnimation],
    ) -> Result<Vec<ClipCoverageLine>> {
        let (Some(c), joints) = (&model.coverage, &model.pbns()?.feature_joints) else {
            return Ok(Vec::new());
        };
        Ok(clips
            .iter()
            .map(|clip| {
                let (coverage, farthest) = ClipCoverage::of_clip(c, joints, clip);
                ClipCoverageLine {
                    clip: clip.name.clone(),
                    farthest,
                    coverage,
                }
            })
            .collect())
    }
}

/// What was written and what the bake cost.
#[derive(Serialize, Deserialize)]
pub struct Report {
    pub out: PathBuf,
    pub bytes: u64,
    pub report: BakeReport,
    /// Per clip, how far its frames lie from the training poses (empty for models trained before
    /// the coverage report).
    pub coverage: Vec<ClipCoverageLine>,
    /// With --validate: one check per clip.
    pub validation: Option<Vec<Validation>>,
    /// With --view: the page and its size in bytes.
    pub view: Option<(PathBuf, u64)>,
}

impl Args {
    /// `validate` on the file just written: per clip, its structure and its replay (glTF: our
    /// evaluation of the spec; USD: UsdSkel's) against the network.
    fn check_written(
        &self,
        model: &crate::models::file::ModelFile,
        clips: &[crate::rig::SkelAnimation],
        device: tch::Device,
    ) -> Result<Vec<Validation>> {
        use crate::validate::{check_file, replay::Reference};
        let tolerance = self.tolerance_mm.map_or(1.0, f64::from);
        let references: Vec<Option<Reference>> = clips
            .iter()
            .map(|c| Reference::of(model, c, device).map(Some))
            .collect::<Result<_>>()?;
        references
            .iter()
            .map(|r| {
                let checked = check_file(&self.out, r.as_ref(), tolerance)?;
                Ok(checked.validation(r.as_ref().map(|r| r.clip.clone())))
            })
            .collect()
    }
}

impl Execute for Args {
    type Report = Report;

    fn execute(&self, _say: &dyn Fn(&str)) -> Result<Report> {
        use exporters::FileKind::{Gltf, Usd};
        let outputs = super::args::output_set(&[
            (
                "--out",
                Some(&self.out),
                super::args::Writes::Kinds(&[Gltf, Usd]),
            ),
            ("--view", self.view.as_deref(), super::args::Writes::Page),
        ])?;
        let (model, device) = crate::pipeline::load_model(&self.compute.compute(), &self.model)?;
        let maps = self.clips.clips().reader()?;
        let fps = crate::models::swing::clip_rate(model.pbns()?, self.clips.fps)?;
        let clips = self
            .clips
            .motion
            .motions
            .iter()
            .map(|p| load_clip(p, &maps, &model.body, fps).map(|c| c.animation))
            .collect::<Result<Vec<_>>>()?;
        let targets = Targets::from_flags(self.max_targets, self.tolerance_mm, Targets::Full)?;
        let opts = BakeOptions {
            targets,
            influences: self.influences,
            with_body: self.with_body,
        };
        let (asset, report) = bake(&model, &clips, &opts, device)?;
        let coverage = ClipCoverageLine::of_clips(&model, &clips)?;
        let written = outputs.write(&self.out, |p| {
            exporters::write(&asset, p).with_context(|| format!("writing {}", p.display()))?;
            Ok::<_, anyhow::Error>(p.to_path_buf())
        })?;
        let view = match &self.view {
            Some(page) => {
                // A USD bake gets its page from the same asset as glTF.
                let glb = if is_glb(&self.out) {
                    std::fs::read(&written)
                        .with_context(|| format!("cannot read {}", self.out.display()))?
                } else {
                    exporters::gltf::to_glb(&asset)
                };
                let title = self.out.file_name().unwrap_or_default().to_string_lossy();
                let bytes =
                    outputs.write(page, |p| crate::pipeline::view::glb_page(p, &glb, &title))?;
                Some((page.clone(), bytes))
            }
            None => None,
        };
        outputs.commit()?;
        let validation = self
            .validate
            .then(|| self.check_written(&model, &clips, device))
            .transpose()?;
        Ok(Report {
            out: self.out.clone(),
            bytes: std::fs::metadata(&self.out).map(|m| m.len()).unwrap_or(0),
            report,
            coverage,
            validation,
            view,
        })
    }

    fn print(r: &Report) {
        let b = &r.report;
        println!(
            "{} blend shapes (offsets used by the clips have rank {}), {} influences per vertex",
            b.targets, b.used_rank, b.influences
        );
        for c in &b.clips {
            if let Some(p) = c.pruning_error_mm {
                println!("{}: pruning the skin to {} influences alone would cost {:.3} mm; corrective blend shapes compensate", c.clip, b.influences, p);
            }
            println!(
                "{}: {} frames, replay error vs network: max {:.3} mm, mean {:.4} mm",
                c.clip, c.error.frames, c.error.max_mm, c.error.mean_mm
            );
        }
        for c in &r.coverage {
            println!("{}: {}", c.clip, c.coverage.line(&c.farthest));
        }
        if r.coverage.is_empty() {
            println!("coverage: this model has no training poses stored (trained before the coverage report)");
        }
        println!("wrote {} ({:.1} MB)", r.out.display(), r.bytes as f64 / 1e6);
        if let Some((page, bytes)) = &r.view {
            println!("wrote {} ({:.1} MB)", page.display(), *bytes as f64 / 1e6);
        }
        for v in r.validation.iter().flatten() {
            v.print();
        }
    }

    fn exit_code(r: &Report) -> i32 {
        let failed = r.validation.iter().flatten().any(|v| !v.passed);
        i32::from(failed)
    }
}

fn is_glb(path: &std::path::Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("glb"))
}
