//! `garmentbake view`: a baked glTF (and point caches on its garment) in one self-contained HTML
//! page, written to disk or served on 127.0.0.1 (the page itself: `pipeline::view`).

use super::args::{output_set, OutputArgs, Writes};
use super::Execute;
use crate::pipeline::view::{
    file_name, is_vat, read_glb, read_vat, serve, vat_page, write_page, CacheReport, Scene,
};
use anyhow::{bail, Result};
use exporters::viewer::Page;
use serde::Serialize;
use std::path::PathBuf;

/// Look at a bake in the browser: clips, frames, body, point caches, error colours.
///
/// Writes ONE self-contained HTML page (three.js, the glb and the caches inlined: it opens
/// offline by double-click and can be attached to a review ticket), or serves it on 127.0.0.1.
/// The page has a clip selector (one entry per glTF animation), play / pause / scrub with the
/// frame number and time, body on/off, a turntable and the fixed views of `garmentbake preview`,
/// wireframe, and with --error-vs per-vertex colours (distance in mm) with a legend.
///
/// --with caches (e.g. from `eval`, `rollout`, `simulate`) play on the garment mesh beside or
/// over the bake, at the selected clip's frame rate (or --fps): give caches of that clip.
/// A link can open one frame: PAGE.html#clip=131_02&frame=40&view=front (see docs/view.md).
#[derive(clap::Args)]
#[command(group(clap::ArgGroup::new("target").required(true).args(["out", "serve"])))]
pub struct Args {
    /// Binary glTF (.glb), e.g. from `garmentbake bake`; its mesh named `garment` (else the first)
    /// is the one caches play on. Or vertex animation textures (NAME.vat.exr / .vat.png /
    /// .vat.json from `eval`, `rollout`, `interpolate`): their mesh played by the textures in a
    /// vertex shader, as an engine plays them.
    pub file: PathBuf,
    /// Point cache(s) (.pc2) of the garment to play beside or instead of the bake; repeat.
    #[arg(long = "with", help_heading = "Inputs")]
    pub with: Vec<PathBuf>,
    /// Colour every shown garment by its distance (mm) to this cache (.pc2), frame by frame:
    /// e.g. the network's `eval` output against a bake, a simulation against a roll-out.
    #[arg(long, help_heading = "Inputs")]
    pub error_vs: Option<PathBuf>,
    /// Distance at the red end of the error colours (mm).
    #[arg(long, default_value_t = 10.0, value_parser = super::args::positive::<f32>(), help_heading = "Advanced")]
    pub error_scale_mm: f32,
    /// Rate the caches play at (default: the selected clip's, or 30 without animations).
    #[arg(long, value_parser = super::args::positive::<f32>(), help_heading = "Advanced")]
    pub fps: Option<f32>,
    /// Write the page here (.html).
    #[arg(long, help_heading = "Outputs")]
    pub out: Option<PathBuf>,
    /// Serve the page on http://127.0.0.1:PORT/ until interrupted (Ctrl-C).
    #[arg(long, help_heading = "Outputs")]
    pub serve: bool,
    /// Port for --serve (0: any free port; the URL is printed).
    #[arg(
        long,
        default_value_t = 8017,
        requires = "serve",
        help_heading = "Outputs"
    )]
    pub port: u16,
    #[command(flatten)]
    pub output: OutputArgs,
}

/// The page written.
#[derive(Serialize)]
pub struct Report {
    pub out: Option<PathBuf>,
    /// Size of the page in bytes (everything inlined).
    pub bytes: u64,
    /// The glTF's animations, in the order of the page's clip selector.
    pub clips: Vec<String>,
    pub garment: String,
    pub garment_vertices: usize,
    pub caches: Vec<CacheReport>,
    pub error_vs: Option<CacheReport>,
    pub three_version: String,
}

impl Execute for Args {
    type Report = Report;

    fn execute(&self, say: &dyn Fn(&str)) -> Result<Report> {
        if self.error_scale_mm.is_nan() || self.error_scale_mm <= 0.0 {
            bail!(
                "--error-scale-mm must be positive, got {}",
                self.error_scale_mm
            );
        }
        if self.fps.is_some_and(|f| f.is_nan() || f <= 0.0) {
            bail!("--fps must be positive");
        }
        let outputs = output_set(&[("--out", self.out.as_deref(), Writes::Page)])?;
        let vat = is_vat(&self.file)
            .then(|| read_vat(&self.file))
            .transpose()?;
        if vat.is_some() && (!self.with.is_empty() || self.error_vs.is_some()) {
            bail!("--with and --error-vs play caches on a glb: a VAT page shows the VAT alone");
        }
        let glb = match &vat {
            Some(v) => v.glb.clone(),
            None => read_glb(&self.file)?,
        };
        let scene = Scene::of(&glb, &self.file)?;
        let caches = self
            .with
            .iter()
            .map(|p| scene.cache(p))
            .collect::<Result<Vec<_>>>()?;
        let reference = self
            .error_vs
            .as_deref()
            .map(|p| scene.cache(p))
            .transpose()?;
        let page = match &vat {
            Some(v) => Page {
                fps: self.fps.or(Some(v.sidecar.fps)),
                ..vat_page(v, file_name(&self.file))
            },
            None => Page {
                title: file_name(&self.file),
                glb: &glb,
                garment: Some(scene.garment.clone()),
                garment_is_bake: true,
                vertex_map: scene.vertex_map.clone(),
                fps: self.fps,
                tracks: caches.iter().map(|c| c.1.clone()).collect(),
                reference: reference.as_ref().map(|c| c.1.clone()),
                error_scale_mm: self.error_scale_mm,
                vat: None,
            },
        };
        let report = |out: Option<PathBuf>, bytes: u64| Report {
            out,
            bytes,
            clips: scene.clips.clone(),
            garment: scene.garment.clone(),
            garment_vertices: scene.vertices,
            caches: caches.iter().map(|c| c.0.clone()).collect(),
            error_vs: reference.as_ref().map(|c| c.0.clone()),
            three_version: exporters::viewer::three_version().unwrap_or_default(),
        };
        match &self.out {
            Some(out) => {
                let bytes = outputs.write(out, |p| write_page(p, &page))?;
                outputs.commit()?;
                Ok(report(Some(out.clone()), bytes))
            }
            None => {
                let html = exporters::viewer::html(&page)?;
                serve(&html, self.port, say)?;
                Ok(report(None, html.len() as u64))
            }
        }
    }

    fn print(r: &Report) {
        if let Some(out) = &r.out {
            println!(
                "wrote {} ({:.2} MB, three.js {} inlined)",
                out.display(),
                r.bytes as f64 / 1e6,
                r.three_version
            );
        }
        match r.clips.len() {
            0 => println!("no animations: the page shows the rest pose"),
            _ => println!("clips: {}", r.clips.join(", ")),
        }
        println!("garment: '{}', {} vertices", r.garment, r.garment_vertices);
        for c in &r.caches {
            println!(
                "with {}: {} frames of {} points",
                c.path.display(),
                c.frames,
                c.points
            );
        }
        if let Some(c) = &r.error_vs {
            println!(
                "error colours against {} ({} frames)",
                c.path.display(),
                c.frames
            );
        }
    }
}
