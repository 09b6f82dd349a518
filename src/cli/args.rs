//! Options several commands share, so each means the same everywhere: the clips a command reads,
//! where the tensors run, and machine-readable output.

use crate::models::file::ModelFile;
use anyhow::{bail, Result};
use std::path::{Path, PathBuf};

/// The motion-capture clips a command reads, and how.
#[derive(clap::Args)]
pub struct ClipArgs {
    /// BVH clip(s); repeat --motion for several.
    #[arg(long = "motion", required = true)]
    pub motions: Vec<PathBuf>,
    /// Joint-name map(s) (TOML); each applies to the clips whose joints it covers (the two CMU
    /// namings are recognised without one).
    #[arg(long = "map")]
    pub maps: Vec<PathBuf>,
    /// Keep every n-th frame so clips play at this rate (must divide the source rate).
    #[arg(long)]
    pub fps: Option<f32>,
}

impl ClipArgs {
    /// The one clip of a command that reads exactly one.
    pub fn single(&self) -> Result<&Path> {
        match self.motions.as_slice() {
            [one] => Ok(one),
            many => bail!(
                "this command reads one --motion, got {}; run it once per clip",
                many.len()
            ),
        }
    }
}

/// Where the tensors run.
#[derive(clap::Args)]
pub struct ComputeArgs {
    /// cpu, cuda or cuda:N.
    #[arg(long, default_value = "cpu")]
    pub device: String,
    /// CPU threads (torch and the nearest-neighbour queries).
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
}

impl ComputeArgs {
    /// Sets the thread pools and parses the device.
    pub fn apply(&self) -> Result<tch::Device> {
        crate::compute::set_threads(self.threads, self.threads);
        crate::compute::parse_device(&self.device)
    }

    /// [`ComputeArgs::apply`], then loads a model file onto the device.
    pub fn load_model(&self, path: &Path) -> Result<(ModelFile, tch::Device)> {
        let device = self.apply()?;
        Ok((crate::models::file::load(path, device)?, device))
    }
}

/// `--json`: print the command's report as one JSON object on stdout instead of text.
#[derive(clap::Args)]
pub struct OutputArgs {
    /// Print the report as JSON on stdout instead of text (no progress bars, no warnings).
    #[arg(long)]
    pub json: bool,
}
