//! `garmentbake map suggest`: a draft joint map for a clip from a rig we do not know.

use super::args::{output_set, Writes};
use super::Execute;
use crate::io::map_suggest::Suggestion;
use anyhow::Result;
use serde::Serialize;
use std::path::PathBuf;

/// Joint maps: draft one for a new rig.
///
/// A joint map names which body-rig joint each clip joint that matters drives; joints it leaves out
/// are folded into the chain (a mapped joint lies below them) or dropped (face, fingers, toes,
/// twist leaves). See samples/motions/cc_base.map.toml for a commented one.
#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    pub action: Action,
}

#[derive(clap::Subcommand)]
pub enum Action {
    /// Draft a map from the clip's joint names and hierarchy (left / right, chain order) onto the
    /// sample body's rig; prints the rig joints it could not place. Check the draft with
    /// `garmentbake inspect CLIP.bvh --body BODY.glb --map MAP.toml`.
    Suggest(SuggestArgs),
}

#[derive(clap::Args)]
pub struct SuggestArgs {
    /// The clip (.bvh).
    pub clip: PathBuf,
    /// Write the draft here (.toml) instead of printing it.
    #[arg(long, help_heading = "Outputs")]
    pub out: Option<PathBuf>,
    /// Print the report as JSON.
    #[arg(long, help_heading = "Outputs")]
    pub json: bool,
}

impl Args {
    pub fn json(&self) -> bool {
        match &self.action {
            Action::Suggest(a) => a.json,
        }
    }
}

#[derive(Serialize)]
pub struct Report {
    pub clip: PathBuf,
    pub out: Option<PathBuf>,
    pub suggestion: Suggestion,
    /// The map as TOML.
    pub toml: String,
}

impl Execute for Args {
    type Report = Report;

    fn execute(&self, _say: &dyn Fn(&str)) -> Result<Report> {
        let Action::Suggest(a) = &self.action;
        let outputs = output_set(&[("--out", a.out.as_deref(), Writes::Named(&["toml"]))])?;
        let suggestion = crate::motion::suggest_map(&a.clip)?;
        let toml = suggestion.to_toml(&a.clip.display().to_string());
        if let Some(out) = &a.out {
            outputs.write(out, |p| exporters::atomic::write_atomic(p, toml.as_bytes()))?;
            outputs.commit()?;
        }
        Ok(Report {
            clip: a.clip.clone(),
            out: a.out.clone(),
            suggestion,
            toml,
        })
    }

    fn print(r: &Report) {
        match &r.out {
            Some(out) => println!(
                "wrote {} ({} joints mapped)",
                out.display(),
                r.suggestion.pairs.len()
            ),
            None => print!("{}", r.toml),
        }
        if !r.suggestion.unplaced.is_empty() {
            eprintln!(
                "not placed (they keep their rest pose): {}",
                r.suggestion.unplaced.join(", ")
            );
        }
    }
}
