//! Options several commands share, so each means the same everywhere: the clips a command reads,
//! where the tensors run, and machine-readable output.

mod parse;
mod short_help;
mod training;

pub use crate::pipeline::outputs::{output_set, Writes, ASSET, MODEL, PNG, POINT_CACHE};
pub use parse::{non_negative, parse_units, parse_up, positive, FiniteNumber};
pub use short_help::{short_help, NO_IDS, SHORT_HELP_NOTE};
pub use training::{RefreshArg, TrainInputs, TRAIN_DEFAULTS, TRAIN_SHORT_HIDES};

use anyhow::{bail, Result};
use std::path::PathBuf;

/// How clips are read: which joints map to the body's, and the clips' up axis and unit.
#[derive(clap::Args)]
#[command(next_help_heading = "Inputs")]
pub struct ClipReading {
    /// Joint-name map(s) (TOML); each applies to the clips whose joints it covers (the two CMU
    /// namings are recognised without one).
    #[arg(long = "map")]
    pub maps: Vec<PathBuf>,
    /// The clips' up axis (y, z, -y, x ...); detected from the motion when left out (the axis the
    /// head stays above the feet along). Z-up clips are turned a quarter turn about X.
    #[arg(long, value_parser = parse_up)]
    pub up: Option<crate::rig::capture::UpAxis>,
    /// The clips' length unit (m, cm, mm, in, ft, cmu); detected from the leg length when left
    /// out. Only reported lengths use it: motion is scaled to the body by leg length.
    #[arg(long, value_parser = parse_units)]
    pub units: Option<crate::rig::capture::Units>,
}

impl ClipReading {
    /// `motions` read this way, played at `fps` (their own rate if none).
    pub fn clips(&self, motions: &[PathBuf], fps: Option<f32>) -> crate::pipeline::Clips {
        crate::pipeline::Clips::new(motions, &self.maps, fps, self.up, self.units)
    }
}

/// The motion-capture clips a command reads, and how, at their own rate or one the command sets
/// (a dynamic model plays at its training rate).
#[derive(clap::Args)]
#[command(next_help_heading = "Inputs")]
pub struct MotionArgs {
    /// BVH clip(s); repeat --motion for several.
    #[arg(long = "motion", required = true)]
    pub motions: Vec<PathBuf>,
    #[command(flatten)]
    pub reading: ClipReading,
}

impl MotionArgs {
    /// The clips as the pipeline's steps take them, played at `fps` (their own rate if none).
    pub fn clips(&self, fps: Option<f32>) -> crate::pipeline::Clips {
        self.reading.clips(&self.motions, fps)
    }
}

/// [`MotionArgs`] with `--fps`: clips a command plays at a rate the user picks.
#[derive(clap::Args)]
#[command(next_help_heading = "Inputs")]
pub struct ClipArgs {
    #[command(flatten)]
    pub motion: MotionArgs,
    /// Keep every n-th frame so clips play at this rate (must divide the source rate).
    #[arg(long, value_parser = positive::<f32>())]
    pub fps: Option<f32>,
}

impl ClipArgs {
    /// The clips as the pipeline's steps take them.
    pub fn clips(&self) -> crate::pipeline::Clips {
        self.motion.clips(self.fps)
    }
}

/// Where the tensors run.
#[derive(clap::Args)]
#[command(next_help_heading = "Advanced")]
pub struct ComputeArgs {
    /// cpu, cuda or cuda:N.
    #[arg(long, default_value = "cpu")]
    pub device: String,
    /// CPU threads (torch and the nearest-neighbour queries).
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
}

impl ComputeArgs {
    /// Where the pipeline's steps run their tensors (applied by the step).
    pub fn compute(&self) -> crate::compute::Compute {
        crate::compute::Compute::new(&self.device, self.threads)
    }

    /// [`ComputeArgs::compute`] applied now: the thread pools set, the device parsed.
    pub fn apply(&self) -> Result<tch::Device> {
        self.compute().apply()
    }
}

/// `--json`: print the command's report as one JSON object on stdout instead of text.
#[derive(clap::Args)]
#[command(next_help_heading = "Outputs")]
pub struct OutputArgs {
    /// Print the report as JSON on stdout instead of text (no progress bars, no warnings).
    #[arg(long)]
    pub json: bool,
}

/// The per-frame strain limit and collision fix of a dynamic roll-out (`rollout`, `compare`, and
/// `train-dynamic`'s rounds, whose fix is on with --rollout-fix): the decoded garment's edges
/// pulled back towards their rest lengths, and a garment that crosses the body pushed out.
#[derive(clap::Args)]
#[command(next_help_heading = "Advanced")]
pub struct CollisionFixArgs {
    /// How the collision fix resolves a frame: `projection` pushes the crossing vertices out and
    /// keeps the edges around them (plain arrays, ~5 ms a frame); `paper` is the paper's Adam
    /// fit of a UV displacement map through libtorch (~100 ms a frame). Either way, vertices
    /// still inside the body after it (by winding number: where the nearest body vertex is on
    /// another limb) are put just outside the closest point of the body (~9 ms a frame).
    #[arg(long, value_enum, default_value_t = crate::rollout::Solver::Projection)]
    pub collision_solver: crate::rollout::Solver,
    /// Passes of the projection fix, or Adam iterations of the paper's (default 8 and 20).
    #[arg(long)]
    pub collision_iterations: Option<usize>,
    /// Clearance the collision fix keeps from the body (mm).
    #[arg(long, default_value_t = 2.0, value_parser = non_negative::<f32>())]
    pub collision_margin_mm: f32,
    /// Weight of the paper fix's edge-length term, which keeps the pushed-out garment from
    /// stretching; 0 gives the paper's objective (position + Laplacian + collision only).
    #[arg(long, default_value_t = crate::rollout::LAMBDA_EDGES, value_parser = non_negative::<f64>())]
    pub collision_edge_weight: f64,
    /// Strain limit: sweeps per frame that pull the decoded garment's edges back within
    /// --strain-band-pct of their rest lengths, before the collision fix (0: off, the decode as
    /// it is).
    #[arg(long, default_value_t = crate::rollout::STRAIN_ITERATIONS)]
    pub strain_iterations: usize,
    /// How far (% of rest length) an edge may stretch or shrink before the strain limit (and the
    /// projection fix) pull it back.
    #[arg(long, default_value_t = 100.0 * crate::rollout::STRAIN_BAND, value_parser = non_negative::<f32>())]
    pub strain_band_pct: f32,
}

impl CollisionFixArgs {
    /// The ids of its flags (for [`short_help`]'s `hidden`, where the fix is not the point).
    pub fn ids() -> Vec<String> {
        let cmd = <Self as clap::Args>::augment_args(clap::Command::new("fix"));
        cmd.get_arguments()
            .map(|a| a.get_id().to_string())
            .collect()
    }

    /// Roll-out settings with the fix on (`fix`) or off, checked.
    pub fn settings(&self, fix: bool) -> Result<crate::rollout::Settings> {
        let w = self.collision_edge_weight;
        if !(w >= 0.0 && w.is_finite()) {
            bail!("--collision-edge-weight {w}: give a weight of 0 or more (0: the paper's objective)");
        }
        let solver = self.collision_solver;
        Ok(crate::rollout::Settings {
            collision_fix: fix,
            solver,
            iterations: self
                .collision_iterations
                .unwrap_or(solver.default_iterations()),
            margin: self.collision_margin_mm * 1e-3,
            edge_weight: w,
            strain_iterations: self.strain_iterations,
            strain_band: self.strain_band_pct * 1e-2,
            ..crate::rollout::Settings::default()
        })
    }
}

/// The fabric of a garment: its physical parameters, and with `simulate` Blender's cloth
/// settings (the fabric file's [simulate] table).
#[derive(clap::Args)]
pub struct FabricArgs {
    /// Fabric: a FABRIC.toml or a preset name (cotton, silk, denim, jersey); `--config` is its
    /// old name (batch plans still pass it).
    #[arg(
        long = "fabric",
        alias = "config",
        value_name = "FABRIC",
        default_value = "cotton",
        help_heading = "Inputs"
    )]
    pub fabric: String,
}

impl FabricArgs {
    pub fn load(&self) -> Result<crate::fabric::Fabric> {
        crate::fabric::Fabric::load(&self.fabric)
    }
}

/// `--out-units` / `--out-up`: the units and up axis the point caches are written in (garmentbake
/// works in metres, Y-up; Unreal wants `--out-units cm --out-up z`, Maya `--out-units cm`).
/// Recorded where the format has a place: USD `metersPerUnit` / `upAxis`, Alembic's user
/// properties, a VAT's sidecar; PC2 and MDD have none. (`--units` / `--up` name a clip's own.)
#[derive(clap::Args)]
#[command(next_help_heading = "Outputs")]
pub struct CacheSpaceArgs {
    /// Units of the written caches: m (metres) or cm (x100).
    #[arg(long, value_enum, default_value = "m")]
    pub out_units: UnitsArg,
    /// Up axis of the written caches: y, or z (x, y, z) -> (x, -z, y), a right-handed turn.
    #[arg(long, value_enum, default_value = "y")]
    pub out_up: UpArg,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum UnitsArg {
    M,
    Cm,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum UpArg {
    Y,
    Z,
}

impl CacheSpaceArgs {
    pub fn space(&self) -> exporters::CacheSpace {
        exporters::CacheSpace {
            centimetres: matches!(self.out_units, UnitsArg::Cm),
            z_up: matches!(self.out_up, UpArg::Z),
        }
    }
}
