//! `garmentbake eval`: a trained model over a clip → point cache + PBNS metrics.

use super::args::{ClipArgs, ComputeArgs, OutputArgs};
use super::Execute;
use crate::pipeline::eval::{run, Request};
use anyhow::Result;
use std::path::PathBuf;

pub use crate::pipeline::eval::Report;

/// Evaluate a trained model on a motion clip: write the garment's world-space vertices for every
/// frame as a point cache (PC2: Blender's Mesh Cache modifier on the garment OBJ, which has the
/// same vertex order; USD: a Mesh with time-sampled points) and print the PBNS metrics next to
/// plain linear blend skinning with the proximity weights (the same garment without the network).
///
/// Metrics: edge error (mean |e − e_T|, mm), bending (mean 1 − cos between neighbouring face
/// normals), collided vertices (% with d·n < 0 against the nearest body vertex; "of which body
/// overlap": those whose nearest body vertex is itself inside another part of the skinned body,
/// e.g. a chin sunk into the chest, where no garment can be outside both) and gravity energy.
///
/// Coverage (models trained with this version): each frame's pose distance to the nearest
/// training pose (radians: the largest rotation-vector difference over the garment's joints,
/// the measure pose balancing uses), the frames beyond the trained range and the metrics split
/// within / beyond it, so the frames to check before shipping are named. The range's threshold
/// is stored by `train`: the distance within which 95 % of the training clips' frames lie from
/// the training poses taken from other parts of the clips (each clip cut in 5 blocks). `--clamp-weights` keeps the network's blend-shape weights within the range
/// they took over the training poses (clamped correctives, as engine ML deformers do).
#[derive(clap::Args)]
pub struct Args {
    /// Trained model (.safetensors from `garmentbake train`).
    #[arg(long, help_heading = "Inputs")]
    pub model: PathBuf,
    /// The clip (one --motion), retargeted onto the model's skeleton.
    #[command(flatten)]
    pub clips: ClipArgs,
    /// Body to collide with (default: the one stored in the model); must have the same skeleton.
    #[arg(long, help_heading = "Inputs")]
    pub body: Option<PathBuf>,
    /// Output point cache of the garment, one sample per frame: .pc2 (start frame 0), .mdd
    /// (Lightwave's, frame times f / fps), .usda/.usdc/.usdz (a Mesh with time-sampled points
    /// and extent), .abc (Alembic PolyMesh, through the Python bridge) or .vat.exr / .vat.png
    /// (vertex animation textures, with their normals, JSON and glb beside).
    #[arg(long, help_heading = "Outputs")]
    pub out: PathBuf,
    /// Also write the posed body as a point cache (same formats).
    #[arg(long, help_heading = "Outputs")]
    pub body_out: Option<PathBuf>,
    /// Also write a page that plays the garment cache on the body in a browser (see `view`).
    #[arg(long, value_name = "PAGE.html", help_heading = "Outputs")]
    pub view: Option<PathBuf>,
    /// Keep each blend-shape weight within the range it took over the training poses.
    #[arg(long, help_heading = "Advanced")]
    pub clamp_weights: bool,
    #[command(flatten)]
    pub space: super::args::CacheSpaceArgs,
    #[command(flatten)]
    pub compute: ComputeArgs,
    #[command(flatten)]
    pub output: OutputArgs,
}

impl Execute for Args {
    type Report = Report;

    fn execute(&self, _say: &dyn Fn(&str)) -> Result<Report> {
        use super::args::{output_set, Writes, POINT_CACHE};
        let outputs = output_set(&[
            ("--out", Some(&self.out), POINT_CACHE),
            ("--body-out", self.body_out.as_deref(), POINT_CACHE),
            ("--view", self.view.as_deref(), Writes::Page),
        ])?;
        let request = Request {
            model: self.model.clone(),
            clips: self.clips.clips(),
            body: self.body.clone(),
            out: self.out.clone(),
            body_out: self.body_out.clone(),
            view: self.view.clone(),
            clamp_weights: self.clamp_weights,
            space: self.space.space(),
            compute: self.compute.compute(),
        };
        run(&request, outputs)
    }

    fn print(r: &Report) {
        print!("{r}");
    }
}
