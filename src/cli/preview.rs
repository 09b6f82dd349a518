//! `garmentbake preview`: a PNG contact sheet of the posed body, garments at rest, or garments
//! played by point caches (side by side, or coloured by the distance to a reference).

use super::args::{output_set, OutputArgs, PNG};
use super::Execute;
use crate::pipeline::preview::Request;
use crate::preview::{save_png, View};
use anyhow::Result;
use serde::Serialize;
use std::path::PathBuf;

/// Render the body (grey) posed by a clip, front and side, to a PNG contact sheet.
///
/// Without --motion the body is drawn in its rest pose together with any --garment meshes
/// (coloured), which shows how garments sit on the body before training. With --model the
/// trained garment is drawn posed on the body (and, with --lbs, next to plain linear blend
/// skinning of the same garment, for comparison).
#[derive(clap::Args)]
pub struct Args {
    /// Skinned body (glTF/glb).
    #[arg(long, help_heading = "Inputs")]
    pub body: PathBuf,
    /// BVH clip to pose the body with (rest pose when omitted). Several play one after another
    /// as one sequence, each later clip blended in over --fade frames (as `rollout` chains
    /// them), so a chained roll-out's cache can be shown.
    #[arg(long = "motion", help_heading = "Inputs")]
    pub motions: Vec<PathBuf>,
    #[command(flatten)]
    pub reading: super::args::ClipReading,
    /// Frames over which a later --motion clip blends in from the previous clip's last pose.
    #[arg(long, default_value_t = 15, help_heading = "Advanced")]
    pub fade: usize,
    /// Garment mesh(es) drawn at rest, OBJ or USD (only without --motion).
    #[arg(long = "garment", help_heading = "Inputs")]
    pub garments: Vec<PathBuf>,
    /// With --motion: one point cache per --garment (.pc2, one sample per clip frame, e.g. from
    /// `simulate` or `eval`) that poses it.
    #[arg(long = "cache", help_heading = "Inputs")]
    pub caches: Vec<PathBuf>,
    /// The clip frame of each --cache's first sample (--error-vs keeps its own). By default the
    /// start frame the cache records (PC2's header: 0 from `simulate` or `eval`, A from `interpolate
    /// --between A,B`); give it for a cache of part of the clip that does not record it.
    #[arg(long, help_heading = "Advanced")]
    pub cache_start: Option<usize>,
    /// With several --cache: draw each cached garment in its own panel (labelled by its file
    /// name), side by side per frame, instead of all on one body: model / simulation / LBS.
    #[arg(long, help_heading = "Outputs")]
    pub side_by_side: bool,
    /// Colour each cached garment by its per-vertex distance to this cache of the same garment
    /// (e.g. the simulation): green under a tenth of --error-scale-mm, red at or past it.
    #[arg(long, value_name = "REF.pc2", help_heading = "Inputs")]
    pub error_vs: Option<PathBuf>,
    /// The distance (mm) drawn red by --error-vs.
    #[arg(long, default_value_t = 50.0, value_parser = super::args::positive::<f64>(), help_heading = "Outputs")]
    pub error_scale_mm: f64,
    /// Resample the clip to this rate (the rate the caches were written at).
    #[arg(long, value_parser = super::args::positive::<f32>(), help_heading = "Advanced")]
    pub fps: Option<f32>,
    /// Trained PBNS model (.safetensors): draw its garment posed by the clip.
    #[arg(long, help_heading = "Inputs")]
    pub model: Option<PathBuf>,
    /// With --model: add a panel of plain LBS (proximity weights, no PSD) next to each one.
    #[arg(long, help_heading = "Outputs")]
    pub lbs: bool,
    /// How many frames to show, evenly spaced over the clip (first and last included); each is
    /// drawn in every --views. (`--frames` is its old name: elsewhere it means the first N.)
    #[arg(long, alias = "frames", default_value_t = 6, help_heading = "Outputs")]
    pub frame_count: usize,
    /// Explicit frame numbers instead of --frame-count, e.g. 0,120,240.
    #[arg(long, value_delimiter = ',', help_heading = "Outputs")]
    pub frame_list: Vec<usize>,
    /// Views per frame: front, side, back, three-quarter.
    #[arg(long, value_delimiter = ',', default_values_t = [ViewArg::Front, ViewArg::Side])]
    #[arg(help_heading = "Outputs")]
    pub views: Vec<ViewArg>,
    /// Panel size in pixels.
    #[arg(long, default_value_t = 240, help_heading = "Outputs")]
    pub width: u32,
    #[arg(long, default_value_t = 360, help_heading = "Outputs")]
    pub height: u32,
    /// Output PNG.
    #[arg(long, help_heading = "Outputs")]
    pub out: PathBuf,
    #[command(flatten)]
    pub output: OutputArgs,
}

/// The picture written.
#[derive(Serialize)]
pub struct Report {
    pub out: PathBuf,
    pub panels: usize,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum ViewArg {
    Front,
    Side,
    Back,
    ThreeQuarter,
}

impl std::fmt::Display for ViewArg {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        use clap::ValueEnum;
        f.write_str(
            self.to_possible_value()
                .expect("no skipped values")
                .get_name(),
        )
    }
}

impl From<ViewArg> for View {
    fn from(v: ViewArg) -> View {
        match v {
            ViewArg::Front => View::Front,
            ViewArg::Side => View::Side,
            ViewArg::Back => View::Back,
            ViewArg::ThreeQuarter => View::ThreeQuarter,
        }
    }
}

impl Execute for Args {
    type Report = Report;

    fn execute(&self, _say: &dyn Fn(&str)) -> Result<Report> {
        let outputs = output_set(&[("--out", Some(&self.out), PNG)])?;
        let (sheet, panels) = crate::pipeline::preview::sheet(&self.request())?;
        outputs.write(&self.out, |p| save_png(&sheet, p))?;
        outputs.commit()?;
        Ok(Report {
            out: self.out.clone(),
            panels,
        })
    }

    fn print(r: &Report) {
        println!("wrote {} ({} panels)", r.out.display(), r.panels);
    }
}

impl Args {
    fn request(&self) -> Request {
        Request {
            body: self.body.clone(),
            clips: self.reading.clips(&self.motions, self.fps),
            fade: self.fade,
            garments: self.garments.clone(),
            caches: self.caches.clone(),
            cache_start: self.cache_start,
            side_by_side: self.side_by_side,
            error_vs: self.error_vs.clone(),
            error_scale_mm: self.error_scale_mm,
            model: self.model.clone(),
            lbs: self.lbs,
            frames: self.frame_count,
            frame_list: self.frame_list.clone(),
            views: self.views.iter().map(|&v| v.into()).collect(),
            width: self.width,
            height: self.height,
        }
    }
}
