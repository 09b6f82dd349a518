//! `garmentbake pose`: the body with a retargeted joint animation per clip, as glTF or USD.

use super::args::{output_set, ClipArgs, OutputArgs, ASSET};
use super::Execute;
use crate::bake::{animation_asset, skeleton_asset, skinned_mesh_asset, BODY_COLOR};
use crate::io::gltf_body::read_body;
use crate::motion::load_clip;
use crate::rig::retarget::ClipReading;
use anyhow::{Context, Result};
use serde::Serialize;
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
    #[arg(long, help_heading = "Inputs")]
    pub body: PathBuf,
    #[command(flatten)]
    pub clips: ClipArgs,
    /// Output .glb (binary) or .gltf (+ .bin); .usda, .usdc or .usdz (UsdSkel, through usd-core).
    #[arg(long, help_heading = "Outputs")]
    pub out: PathBuf,
    #[command(flatten)]
    pub output: OutputArgs,
}

/// The file written and how each clip was retargeted.
#[derive(Serialize)]
pub struct Report {
    pub out: PathBuf,
    pub clips: Vec<ClipReport>,
}

#[derive(Serialize)]
pub struct ClipReport {
    pub clip: PathBuf,
    pub frames: usize,
    pub fps: f32,
    pub duration_s: f32,
    pub map: String,
    /// Metres per clip unit.
    pub scale: f32,
    pub floor_offset_m: f32,
    /// Axes, units, rest pose and joint fates as read.
    pub reading: ClipReading,
}

impl Execute for Args {
    type Report = Report;

    fn execute(&self, say: &dyn Fn(&str)) -> Result<Report> {
        let outputs = output_set(&[("--out", Some(&self.out), ASSET)])?;
        let body = read_body(&self.body)?;
        let reader = self.clips.clips().reader()?;
        let mut asset = exporters::BakedAsset {
            skeleton: skeleton_asset(&body.skeleton),
            meshes: vec![skinned_mesh_asset(
                &body.name,
                body.mesh(),
                Some(&body.normals),
                &body.skin,
                BODY_COLOR,
            )],
            ..Default::default()
        };
        asset
            .provenance
            .push(("body".into(), self.body.display().to_string()));
        let mut clips = Vec::new();
        let motions = &self.clips.motion.motions;
        let bar = crate::progress::bar(
            motions.len() as u64,
            "retarget",
            self.output.json || motions.len() < 2,
        );
        for path in motions {
            bar.inc(1);
            let clip = load_clip(path, &reader, &body, self.clips.fps)?;
            let a = &clip.animation;
            let r = ClipReport {
                clip: path.clone(),
                frames: a.frame_count(),
                fps: a.fps,
                duration_s: a.duration(),
                map: clip.map_name.clone(),
                scale: clip.scale,
                floor_offset_m: clip.floor_offset,
                reading: clip.reading.clone(),
            };
            say(&format!(
                "{}: {} frames at {} fps ({:.2} s), {:.4} m per unit, floor offset {:+.3} m; {}",
                path.display(),
                r.frames,
                r.fps,
                r.duration_s,
                r.scale,
                r.floor_offset_m,
                r.reading.describe(&r.map)
            ));
            clips.push(r);
            asset.animations.push(animation_asset(a));
            asset
                .provenance
                .push((format!("clip:{}", a.name), path.display().to_string()));
        }
        bar.finish_and_clear();
        outputs.write(&self.out, |p| {
            exporters::write(&asset, p).with_context(|| format!("writing {}", p.display()))
        })?;
        outputs.commit()?;
        Ok(Report {
            out: self.out.clone(),
            clips,
        })
    }

    fn print(r: &Report) {
        println!("wrote {}", r.out.display());
    }
}
