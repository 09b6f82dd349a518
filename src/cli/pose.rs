//! `garmentbake pose`: the body with a retargeted joint animation per clip, as glTF or USD.

use crate::bake::{animation_asset, skeleton_asset, skinned_mesh_asset, BODY_COLOR};
use crate::io::gltf_body::read_body;
use crate::motion::{load_clip, read_maps};
use anyhow::{Context, Result};
use std::path::PathBuf;

/// Pose the body with motion-capture clips and write an animated, skinned glTF or USD.
///
/// Each clip is retargeted onto the body's skeleton: joint names through a map (the two CMU
/// namings are recognised without --map), T-pose → A-pose rest difference, root translation
/// scaled by hip height, feet put on the floor. One animation per clip, at the clip's rate (USD: a
/// SkelAnimation per clip, switched by the variant set `clip`).
#[derive(clap::Args)]
pub struct Args {
    /// Skinned body (glTF/glb): the mesh, its skin and skeleton.
    #[arg(long)]
    body: PathBuf,
    #[command(flatten)]
    clips: super::ClipArgs,
    /// Output .glb (binary) or .gltf (+ .bin); .usda, .usdc or .usdz (UsdSkel, through usd-core).
    #[arg(long)]
    out: PathBuf,
    /// Print a JSON report instead of text.
    #[arg(long)]
    json: bool,
}

pub fn run(args: Args) -> Result<i32> {
    let body = read_body(&args.body)?;
    let maps = read_maps(&args.clips.maps)?;
    let mut asset = exporters::BakedAsset {
        skeleton: skeleton_asset(&body.skeleton),
        meshes: vec![skinned_mesh_asset(
            &body.name,
            &body.mesh,
            Some(&body.normals),
            &body.skin,
            BODY_COLOR,
        )],
        ..Default::default()
    };
    asset
        .provenance
        .push(("body".into(), args.body.display().to_string()));
    let mut report = Vec::new();
    let bar = super::progress(
        args.clips.motions.len() as u64,
        "retarget",
        args.json || args.clips.motions.len() < 2,
    );
    for path in &args.clips.motions {
        bar.inc(1);
        let clip = load_clip(path, &maps, &body.skeleton, args.clips.fps)?;
        let a = &clip.animation;
        if !args.json {
            println!(
                "{}: {} frames at {} fps ({:.2} s), map {}, {:.4} m per unit, floor offset {:+.3} m",
                path.display(), a.frame_count(), a.fps, a.duration(), clip.map_name, clip.scale, clip.floor_offset
            );
        }
        report.push(serde_json::json!({
            "clip": path.display().to_string(), "frames": a.frame_count(), "fps": a.fps,
            "map": clip.map_name, "scale": clip.scale, "floor_offset_m": clip.floor_offset,
        }));
        asset.animations.push(animation_asset(a));
        asset
            .provenance
            .push((format!("clip:{}", a.name), path.display().to_string()));
    }
    bar.finish_and_clear();
    exporters::write(&asset, &args.out)
        .with_context(|| format!("writing {}", args.out.display()))?;
    if args.json {
        println!(
            "{}",
            serde_json::json!({ "out": args.out.display().to_string(), "clips": report })
        );
    } else {
        println!("wrote {}", args.out.display());
    }
    Ok(0)
}
