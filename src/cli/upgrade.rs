//! `garmentbake upgrade`: a model file written by an earlier garmentbake, in the current format.

use super::args::{output_set, OutputArgs, MODEL};
use super::Execute;
use crate::models::file::{self, Upgraded};
use anyhow::Result;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Rewrite a model file (or checkpoint) in the current model format.
///
/// Every command reads model files from the oldest supported format on (converting the
/// description as it loads), so upgrading is never required to use a model; it makes the file
/// itself current, for tools that read its description and before support for its version
/// ends. The tensors are copied byte for byte; a file from before format v3 keeps saying it does
/// not know which build trained it. A file already current is left alone.
#[derive(clap::Args)]
pub struct Args {
    /// The model file (.safetensors).
    pub model: PathBuf,
    /// Write the upgraded file here instead of replacing MODEL (atomically either way).
    #[arg(long, help_heading = "Outputs")]
    pub out: Option<PathBuf>,
    #[command(flatten)]
    pub output: OutputArgs,
}

#[derive(Serialize, Deserialize)]
pub struct Report {
    pub model: PathBuf,
    pub out: PathBuf,
    #[serde(flatten)]
    pub upgraded: Upgraded,
}

impl Execute for Args {
    type Report = Report;

    fn execute(&self, _say: &dyn Fn(&str)) -> Result<Report> {
        // Replacing MODEL needs no check: its folder is there, its name is what it is.
        let outputs = output_set(&[("--out", self.out.as_deref(), MODEL)])?;
        let (out, upgraded) = match &self.out {
            Some(out) => {
                let upgraded = outputs.write(out, |p| file::upgrade(&self.model, p))?;
                outputs.commit()?;
                (out.clone(), upgraded)
            }
            None => (self.model.clone(), file::upgrade(&self.model, &self.model)?),
        };
        Ok(Report {
            model: self.model.clone(),
            out,
            upgraded,
        })
    }

    fn print(r: &Report) {
        let u = &r.upgraded;
        if u.rewritten {
            println!(
                "{}: model format v{} → v{} ({} tensors unchanged), wrote {} ({} bytes)",
                r.model.display(),
                u.from_version,
                u.to_version,
                u.tensors,
                r.out.display(),
                u.bytes
            );
        } else {
            println!(
                "{}: already model format v{}; nothing written",
                r.model.display(),
                u.to_version
            );
        }
    }
}
