//! `garmentbake bake`: a trained PBNS model + clips → glTF / USD with blend shapes, skin and
//! one animation (joints + blend-shape weights) per clip.

use super::train::{parse_device, set_threads};
use crate::bake::pbns::{bake, BakeOptions, Targets};
use crate::models::file;
use crate::motion::{load_clip, read_maps};
use anyhow::{bail, Context, Result};
use std::path::PathBuf;

/// Bake a trained PBNS model into a file any engine plays without a neural runtime.
///
/// The PSD basis becomes morph targets (applied before skinning, as in the model), the trained
/// blend weights the skin, and per clip the MLP output becomes a blend-shape weight animation
/// next to the joint animation. The basis is compressed (SVD of the offsets the clips use):
/// --max-targets fixes the count, --tolerance-mm picks the fewest within a replay error; with
/// neither, the full basis is written. The replay error against the network is printed in mm.
#[derive(clap::Args)]
pub struct Args {
    /// Trained model (.safetensors from `garmentbake train`).
    #[arg(long)]
    model: PathBuf,
    #[command(flatten)]
    clips: super::ClipArgs,
    /// Output: .glb / .gltf (glTF 2.0) or .usda / .usdc / .usdz (UsdSkel).
    #[arg(long)]
    out: PathBuf,
    /// Number of blend shapes to keep (8 is what every glTF client must support).
    #[arg(long, conflicts_with = "tolerance_mm")]
    max_targets: Option<usize>,
    /// Keep the fewest blend shapes whose max offset error over the clips is within this (mm).
    #[arg(long)]
    tolerance_mm: Option<f32>,
    /// Joint influences per vertex in the file (default: the model's own, which loses nothing).
    #[arg(long)]
    influences: Option<usize>,
    /// Add the body mesh on the same skeleton.
    #[arg(long)]
    with_body: bool,
    /// Print a JSON report instead of text.
    #[arg(long)]
    json: bool,
    /// cpu, cuda or cuda:N.
    #[arg(long, default_value = "cpu")]
    device: String,
}

pub fn run(args: Args) -> Result<i32> {
    set_threads(2, 2);
    let device = parse_device(&args.device)?;
    let model = file::load(&args.model, device)?;
    let maps = read_maps(&args.clips.maps)?;
    let clips = args
        .clips
        .motions
        .iter()
        .map(|p| load_clip(p, &maps, model.skeleton(), args.clips.fps).map(|c| c.animation))
        .collect::<Result<Vec<_>>>()?;
    let targets = match (args.max_targets, args.tolerance_mm) {
        (Some(0), _) => bail!("--max-targets must be at least 1"),
        (Some(k), _) => Targets::Count(k),
        (None, Some(t)) if t > 0.0 => Targets::Tolerance(t * 1e-3),
        (None, Some(t)) => bail!("--tolerance-mm must be positive, got {t}"),
        (None, None) => Targets::Full,
    };
    let opts = BakeOptions {
        targets,
        influences: args.influences,
        with_body: args.with_body,
    };
    let (asset, report) = bake(&model, &clips, &opts, device)?;
    exporters::write(&asset, &args.out)
        .with_context(|| format!("writing {}", args.out.display()))?;
    let size = std::fs::metadata(&args.out).map(|m| m.len()).unwrap_or(0);
    if args.json {
        let v = serde_json::json!({ "out": args.out.display().to_string(), "bytes": size, "report": report });
        println!("{v}");
        return Ok(0);
    }
    println!(
        "{} blend shapes (offsets used by the clips have rank {}), {} influences per vertex",
        report.targets, report.used_rank, report.influences
    );
    for c in &report.clips {
        if let Some(p) = c.pruning_error_m {
            println!("{}: pruning the skin to {} influences alone would cost {:.3} mm; corrective blend shapes compensate", c.clip, report.influences, p * 1e3);
        }
        println!(
            "{}: {} frames, replay error vs network: max {:.3} mm, mean {:.4} mm",
            c.clip,
            c.frames,
            c.max_error_m * 1e3,
            c.mean_error_m * 1e3
        );
    }
    println!("wrote {} ({:.1} MB)", args.out.display(), size as f64 / 1e6);
    Ok(0)
}
