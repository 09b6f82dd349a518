//! `garmentbake validate`: the pipeline gate — exit 0 only when a file is right.

use super::args::{output_set, ComputeArgs, OutputArgs, PNG};
use super::Execute;
use crate::pipeline::Clips;
use crate::validate::replay::{error_png, Reference, ReplayError};
use crate::validate::{check_file, checkable, Checked, Problem};
use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Check one file the way a pipeline's CI would, with our own readers (no Node, no Blender).
///
/// Structure. glTF / GLB: the container (GLB header and chunks), the JSON schema and its
/// references, buffer views inside their buffers, accessor layouts, strides and declared
/// min/max, the formats each attribute semantic allows, finite floats, unit normals, skin
/// weights (non-negative, summing to 1) and joints (unique, inside the skin), morph targets
/// consistent across primitives and with `weights`, animation samplers (strictly increasing
/// times, output counts), channel targets, an acyclic node tree, skins whose joints and inverse
/// bind matrices agree. Tolerances are the Khronos validator's.
///
/// USD (through usd-core): its UsdValidation validators, then the UsdSkel bindings (joint
/// indices inside the skeleton, element sizes, weight sums, blend shape / target counts, finite
/// time samples).
///
/// PC2 / MDD: the header, the size it announces (a cut-off file says so), finite points; MDD
/// frame times strictly increasing and evenly spaced (their spacing is the rate).
///
/// Replay, with --model and --motion: the file is evaluated as its spec says (glTF: morph
/// targets, then skinning, at every frame of the clip's animation, by our evaluator; USD: by
/// usd-core's UsdSkel blend shape and skinning queries; caches: read back, frame count and rate
/// checked against the clip) and compared with the PBNS model's own evaluation; max / mean / p99
/// error in mm, the worst frame and vertex; the file fails above --tolerance-mm. --png draws the
/// worst frame coloured by error. With --reference CACHE instead, the file is compared with that
/// cache (dynamic models: a roll-out; `rollout --validate` does it on what it writes).
///
/// Exit code: 0 the file passes, 1 it fails (every problem is listed, located by JSON
/// pointer), 2 it could not be read at all (missing file, unknown extension, bad options).
#[derive(clap::Args)]
pub struct Args {
    /// The file to check: .glb / .gltf, a point cache .pc2 / .mdd, or USD .usd / .usda / .usdc /
    /// .usdz.
    pub file: PathBuf,
    /// The model the file was made from (.safetensors): replay the file against it.
    #[arg(long, requires = "motion", help_heading = "Inputs")]
    pub model: Option<PathBuf>,
    /// The clip (BVH) the file plays, retargeted onto the model's skeleton as bake does.
    #[arg(long, requires = "model", help_heading = "Inputs")]
    pub motion: Option<PathBuf>,
    /// Joint-name map(s) (TOML) for the clip, as given to bake.
    #[arg(long = "map", help_heading = "Inputs")]
    pub maps: Vec<PathBuf>,
    /// The rate the file was baked at (--fps of bake); with --reference, the caches' rate.
    #[arg(long, value_parser = super::args::positive::<f32>(), help_heading = "Inputs")]
    pub fps: Option<f32>,
    /// A point cache (.pc2 / .mdd) the file must play frame for frame, vertex for vertex,
    /// instead of --model: a dynamic model's roll-out (its garment depends on where the roll-out
    /// started and on the collision fix, so it is compared with a cache, not re-run) or a
    /// simulation.
    #[arg(long, conflicts_with = "model", help_heading = "Inputs")]
    pub reference: Option<PathBuf>,
    /// Largest replay error allowed, in millimetres.
    #[arg(long, default_value_t = 1.0, value_parser = super::args::positive::<f64>(), help_heading = "Advanced")]
    pub tolerance_mm: f64,
    /// Write the worst frame, coloured by replay error (green: under a tenth of the tolerance,
    /// red: at or past it), as a PNG.
    #[arg(long, requires = "model", help_heading = "Outputs")]
    pub png: Option<PathBuf>,
    #[command(flatten)]
    pub compute: ComputeArgs,
    #[command(flatten)]
    pub output: OutputArgs,
}

#[derive(Serialize, Deserialize)]
pub struct Report {
    pub file: PathBuf,
    pub format: String,
    pub passed: bool,
    pub errors: Vec<Problem>,
    pub warnings: Vec<Problem>,
    /// The replay against the model, when asked and the structure allowed it.
    pub replay: Option<ReplayError>,
    pub png: Option<PathBuf>,
}

impl Args {
    /// The model's evaluation of the clip, when --model and --motion are given.
    fn reference(&self) -> Result<Option<Reference>> {
        if let Some(cache) = &self.reference {
            return Reference::from_cache(cache, self.fps).map(Some);
        }
        let (Some(path), Some(motion)) = (&self.model, &self.motion) else {
            return Ok(None);
        };
        let (model, device) = crate::pipeline::load_model(&self.compute.compute(), path)?;
        if model.pbns().is_err() {
            bail!(
                "{}: a dynamic model's garment depends on its roll-out (start, collision fix): validate the roll-out's cache with --reference ROLLOUT.pc2, or run `rollout --validate`",
                path.display()
            );
        }
        let clips = Clips::new(
            std::slice::from_ref(motion),
            &self.maps,
            self.fps,
            None,
            None,
        );
        let fps = crate::models::swing::clip_rate(model.pbns()?, self.fps)?;
        let (_, clip) = clips.load_single_at(&model.body, fps)?;
        Ok(Some(Reference::of(&model, &clip.animation, device)?))
    }
}

impl Execute for Args {
    type Report = Report;

    fn execute(&self, _say: &dyn Fn(&str)) -> Result<Report> {
        let outputs = output_set(&[("--png", self.png.as_deref(), PNG)])?;
        let path = &self.file;
        let kind = checkable(path)?;
        if !self.tolerance_mm.is_finite() || self.tolerance_mm <= 0.0 {
            bail!("--tolerance-mm must be positive, got {}", self.tolerance_mm);
        }
        let reference = self.reference()?;
        let Checked { problems, replay } = check_file(path, reference.as_ref(), self.tolerance_mm)?;
        let mut png = None;
        if let (Some(r), Some(reference)) = (&replay, &reference) {
            if let Some(path) = &self.png {
                outputs.write(path, |p| error_png(reference, r, p))?;
                outputs.commit()?;
                png = Some(path.clone());
            }
        }
        Ok(Report {
            file: path.clone(),
            format: format!("{kind:?}"),
            passed: problems.passed(),
            errors: problems.errors,
            warnings: problems.warnings,
            replay,
            png,
        })
    }

    fn print(r: &Report) {
        let verdict = if r.passed { "passes" } else { "FAILS" };
        println!(
            "{}: {} ({} errors, {} warnings)",
            r.file.display(),
            verdict,
            r.errors.len(),
            r.warnings.len()
        );
        if let Some(x) = &r.replay {
            println!(
                "replay on {} ({} frames, {} vertices): max {:.4} mm (frame {}, vertex {}), mean {:.4} mm, p99 {:.4} mm; tolerance {} mm",
                x.clip, x.error.frames, x.vertices, x.error.max_mm, x.error.worst_frame, x.worst_vertex, x.error.mean_mm, x.error.p99_mm.unwrap_or(f64::NAN), x.tolerance_mm
            );
        }
        for (severity, list) in [("error", &r.errors), ("warning", &r.warnings)] {
            for p in list {
                println!("  {severity} {}: {}", p.at, p.message);
            }
        }
        if let Some(png) = &r.png {
            println!("wrote {}", png.display());
        }
    }

    fn exit_code(r: &Report) -> i32 {
        if r.passed {
            0
        } else {
            1
        }
    }
}
