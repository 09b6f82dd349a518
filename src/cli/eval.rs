//! `garmentbake eval`: a trained model over a clip → PC2 point cache + PBNS metrics.

use super::train::{parse_device, set_threads};
use crate::eval::{body_edges_under, compare, lbs_frames, model_frames, ClothGeometry, Metrics};
use crate::io::gltf_body::read_body;
use crate::models::file::{self, check_skeleton};
use crate::motion::{load_clip, read_maps};
use anyhow::{Context, Result};
use serde_json::json;
use std::path::PathBuf;

/// Evaluate a trained model on a motion clip: write the garment's world-space vertices for every
/// frame as a PC2 point cache (Blender: Mesh Cache modifier on the garment OBJ, which has the
/// same vertex order) and print the PBNS metrics next to plain linear blend skinning with the
/// proximity weights (the same garment without the network).
///
/// Metrics: edge error (mean |e − e_T|, mm), bending (mean 1 − cos between neighbouring face
/// normals), collided vertices (% with d·n < 0 against the nearest body vertex; "of which body
/// overlap": those whose nearest body vertex is itself inside another part of the skinned body,
/// e.g. a chin sunk into the chest, where no garment can be outside both) and gravity energy.
#[derive(clap::Args)]
pub struct Args {
    /// Trained model (.safetensors from `garmentbake train`).
    #[arg(long)]
    model: PathBuf,
    /// BVH clip, retargeted onto the model's skeleton.
    #[arg(long)]
    motion: PathBuf,
    /// Joint-name map(s) for the clip (TOML).
    #[arg(long = "map")]
    maps: Vec<PathBuf>,
    /// Body to collide with (default: the one stored in the model); must have the same skeleton.
    #[arg(long)]
    body: Option<PathBuf>,
    /// Keep every n-th frame so the clip plays at this rate (must divide the source rate).
    #[arg(long)]
    fps: Option<f32>,
    /// Output point cache of the garment, one sample per frame: .pc2 (start frame 0), or
    /// .usda/.usdc/.usdz (a Mesh with time-sampled points and extent).
    #[arg(long)]
    out: PathBuf,
    /// Also write the posed body as a PC2.
    #[arg(long)]
    body_out: Option<PathBuf>,
    /// Write the metrics as JSON to this file.
    #[arg(long)]
    json: Option<PathBuf>,
    /// cpu, cuda or cuda:N.
    #[arg(long, default_value = "cpu")]
    device: String,
    /// CPU threads.
    #[arg(long, default_value_t = 2)]
    threads: usize,
}

pub fn run(args: Args) -> Result<i32> {
    set_threads(args.threads, args.threads);
    let device = parse_device(&args.device)?;
    let model = file::load(&args.model, device)?;
    let body = match &args.body {
        Some(path) => {
            let b = read_body(path)?;
            check_skeleton(model.skeleton(), &b.skeleton, &path.display().to_string())?;
            b
        }
        None => model.body.clone(),
    };
    let clip = load_clip(
        &args.motion,
        &read_maps(&args.maps)?,
        &body.skeleton,
        args.fps,
    )?;
    let anim = &clip.animation;
    let poses: Vec<_> = (0..anim.frame_count())
        .map(|f| anim.local_pose(f))
        .collect();
    let garment = model_frames(&model.model, &body.skeleton, &poses, device);
    let lbs = lbs_frames(&model.lbs, &model.garment.positions, &body.skeleton, &poses);
    let geometry = ClothGeometry::new(&model.garment, model.info.fabric.density);
    let under = body_edges_under(&body, &model.garment.positions, UNDER);
    let comparison = compare(&geometry, &[&garment, &lbs], &body, &under, &poses);
    let m = &comparison.metrics;
    write_cache(&args.out, &model.garment, &garment, anim.fps)?;
    if let Some(path) = &args.body_out {
        let frames: Vec<Vec<[f32; 3]>> = poses
            .iter()
            .map(|p| {
                body.skin
                    .skin_points(&body.mesh.positions, &body.skeleton.skinning_matrices(p))
            })
            .collect();
        write_cache(path, &body.mesh, &frames, anim.fps)?;
    }
    println!(
        "{}: {} frames at {} fps, {} garment vertices",
        args.motion.display(),
        anim.frame_count(),
        anim.fps,
        model.model.shape.vertices
    );
    println!(
        "{:<12} {:>10} {:>10} {:>13} {:>22} {:>12}",
        "", "edge (mm)", "bend", "collided (%)", "of which body overlap", "gravity (J)"
    );
    for (name, x) in [("model", &m[0]), ("plain LBS", &m[1])] {
        println!("{}", row(name, x));
    }
    println!(
        "edge strain |e − e_T| / e_T: model {:.2} %, plain LBS {:.2} %; the skinned body under the garment {:.2} %",
        comparison.strain_pct[0], comparison.strain_pct[1], comparison.body_strain_pct
    );
    let overlap = OverlapSummary::of(&comparison.body_overlap);
    println!(
        "body vertices inside another part of the skinned body: median {} per frame, most {} (frame {})",
        overlap.median, overlap.most, overlap.worst_frame
    );
    println!("wrote {}", args.out.display());
    if let Some(path) = &args.json {
        let report = json!({
            "model": args.model.file_name().map(|n| n.to_string_lossy().into_owned()),
            "clip": anim.name, "frames": anim.frame_count(), "fps": anim.fps,
            "garment_vertices": model.model.shape.vertices,
            "metrics": { "model": m[0], "lbs": m[1] },
            "strain_pct": { "model": comparison.strain_pct[0], "lbs": comparison.strain_pct[1],
                "body_under_garment": comparison.body_strain_pct },
            "body_overlap_vertices": { "median": overlap.median, "most": overlap.most,
                "worst_frame": overlap.worst_frame },
            "pc2": args.out.display().to_string(),
        });
        exporters::atomic::write_atomic(path, serde_json::to_string_pretty(&report)?.as_bytes())?;
    }
    Ok(0)
}

/// Body skin within this distance of the garment at rest counts as under it (metres).
const UNDER: f32 = 0.02;

/// How much the skinned body overlaps itself over the clip (vertices inside another part).
struct OverlapSummary {
    median: usize,
    most: usize,
    worst_frame: usize,
}

impl OverlapSummary {
    fn of(per_frame: &[usize]) -> OverlapSummary {
        let (worst_frame, most) = per_frame
            .iter()
            .copied()
            .enumerate()
            .max_by_key(|&(f, n)| (n, std::cmp::Reverse(f)))
            .unwrap_or((0, 0));
        let mut sorted = per_frame.to_vec();
        sorted.sort_unstable();
        OverlapSummary {
            median: sorted.get(sorted.len() / 2).copied().unwrap_or(0),
            most,
            worst_frame,
        }
    }
}

fn row(name: &str, m: &Metrics) -> String {
    format!(
        "{name:<12} {:>10.3} {:>10.4} {:>13.2} {:>22.2} {:>12.4}",
        m.edge_mm, m.bend, m.collided_pct, m.collided_overlap_pct, m.gravity_j
    )
}

/// A per-frame point cache: PC2 by default, USD (time-sampled `points`) for .usda/.usdc/.usdz.
fn write_cache(
    path: &std::path::Path,
    mesh: &crate::geometry::TriMesh,
    frames: &[Vec<[f32; 3]>],
    fps: f32,
) -> Result<()> {
    let usd = exporters::Format::from_path(path) == Some(exporters::Format::Usd);
    if !usd {
        return exporters::pc2::write(path, frames, 0.0)
            .with_context(|| format!("writing {}", path.display()));
    }
    let cache = exporters::PointCache {
        name: path
            .file_stem()
            .map_or("cache".into(), |s| s.to_string_lossy().into_owned()),
        fps,
        triangles: mesh.triangles.clone(),
        uvs: None,
        point_count: mesh.vertex_count(),
        points: frames.iter().flatten().copied().collect(),
    };
    exporters::write_point_cache(&cache, path)
        .with_context(|| format!("writing {}", path.display()))
}
