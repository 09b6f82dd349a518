//! Options several commands share, so each means the same everywhere: the clips a command reads,
//! where the tensors run, and machine-readable output.

use crate::models::file::ModelFile;
use crate::train::pbns::{set_training_threads, InputFiles, Inputs, RefreshMode, Settings};
use anyhow::{bail, Result};
use std::path::{Path, PathBuf};

/// How a number flag is checked while the command line is parsed: NaN and infinities are never
/// a setting, and rates, scales and learning rates must also be above 0.
#[derive(Clone, Copy)]
pub struct FiniteNumber<T> {
    above_zero: bool,
    kind: std::marker::PhantomData<T>,
}

/// A finite number above 0 (rates, tolerances, scales, learning rates, radii).
pub const fn positive<T>() -> FiniteNumber<T> {
    FiniteNumber {
        above_zero: true,
        kind: std::marker::PhantomData,
    }
}

/// A finite number of 0 or more (seconds, weights, ridges, margins, shares where 0 means "off").
pub const fn non_negative<T>() -> FiniteNumber<T> {
    FiniteNumber {
        above_zero: false,
        kind: std::marker::PhantomData,
    }
}

impl<T> clap::builder::TypedValueParser for FiniteNumber<T>
where
    T: std::str::FromStr + Into<f64> + Copy + Clone + Send + Sync + 'static,
{
    type Value = T;

    fn parse_ref(
        &self,
        cmd: &clap::Command,
        arg: Option<&clap::Arg>,
        value: &std::ffi::OsStr,
    ) -> std::result::Result<T, clap::Error> {
        let text = value.to_string_lossy();
        let parsed = text.trim().parse::<T>().ok().filter(|v| {
            let x: f64 = (*v).into();
            x.is_finite() && (x > 0.0 || (!self.above_zero && x == 0.0))
        });
        parsed.ok_or_else(|| {
            // The flag and the value first, as every other bad-input line names what was given.
            let flag = arg
                .and_then(|a| a.get_long())
                .map_or_else(|| "value".to_string(), |l| format!("--{l}"));
            let want = if self.above_zero {
                "a finite number above 0"
            } else {
                "a finite number, 0 or more"
            };
            clap::Error::raw(
                clap::error::ErrorKind::ValueValidation,
                format!("{flag} {text}: give {want}\n"),
            )
            .with_cmd(cmd)
        })
    }
}

/// The motion-capture clips a command reads, and how.
#[derive(clap::Args)]
#[command(next_help_heading = "Inputs")]
pub struct ClipArgs {
    /// BVH clip(s); repeat --motion for several.
    #[arg(long = "motion", required = true)]
    pub motions: Vec<PathBuf>,
    /// Joint-name map(s) (TOML); each applies to the clips whose joints it covers (the two CMU
    /// namings are recognised without one).
    #[arg(long = "map")]
    pub maps: Vec<PathBuf>,
    /// Keep every n-th frame so clips play at this rate (must divide the source rate).
    #[arg(long, value_parser = positive::<f32>())]
    pub fps: Option<f32>,
    /// The clips' up axis (y, z, -y, x ...); detected from the motion when left out (the axis the
    /// head stays above the feet along). Z-up clips are turned a quarter turn about X.
    #[arg(long, value_parser = parse_up)]
    pub up: Option<crate::rig::capture::UpAxis>,
    /// The clips' length unit (m, cm, mm, in, ft, cmu); detected from the leg length when left
    /// out. Only reported lengths use it: motion is scaled to the body by leg length.
    #[arg(long, value_parser = parse_units)]
    pub units: Option<crate::rig::capture::Units>,
}

pub fn parse_up(text: &str) -> Result<crate::rig::capture::UpAxis, String> {
    crate::rig::capture::UpAxis::parse(text)
        .ok_or_else(|| format!("'{text}': give x, y, z, -x, -y or -z"))
}

pub fn parse_units(text: &str) -> Result<crate::rig::capture::Units, String> {
    crate::rig::capture::Units::parse(text)
        .ok_or_else(|| format!("'{text}': give m, cm, mm, in, ft or cmu"))
}

impl ClipArgs {
    /// The clips as the pipeline's steps take them.
    pub fn clips(&self) -> crate::pipeline::Clips {
        crate::pipeline::Clips::new(&self.motions, &self.maps, self.fps, self.up, self.units)
    }

    /// The maps and axes every clip of the command is read with.
    pub fn reader(&self) -> Result<crate::motion::ClipReader> {
        self.clips().reader()
    }

    /// The one clip of a command that reads exactly one, retargeted onto `skeleton` at --fps.
    pub fn load_single(
        &self,
        skeleton: &crate::rig::Skeleton,
    ) -> Result<(&Path, crate::rig::retarget::Retargeted)> {
        self.load_single_at(skeleton, self.fps)
    }

    /// [`ClipArgs::load_single`] at the rate `fps` (a model's own rate: see
    /// [`crate::models::swing::clip_rate`]).
    pub fn load_single_at(
        &self,
        skeleton: &crate::rig::Skeleton,
        fps: Option<f32>,
    ) -> Result<(&Path, crate::rig::retarget::Retargeted)> {
        let motion = self.single()?;
        Ok((
            motion,
            crate::motion::load_clip(motion, &self.reader()?, skeleton, fps)?,
        ))
    }

    /// The one clip of a command that reads exactly one.
    pub fn single(&self) -> Result<&Path> {
        crate::pipeline::single_motion(&self.motions)
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
    /// keeps the edges around them (plain arrays, ~1 ms a frame); `paper` is the paper's Adam
    /// fit of a UV displacement map through libtorch (~100 ms a frame).
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

/// The documented training defaults, shared with the library (`Settings::DEFAULT`).
pub const TRAIN_DEFAULTS: Settings = Settings::DEFAULT;

/// Inputs and settings shared by `train` and `bench train`.
#[derive(clap::Args)]
pub struct TrainInputs {
    /// Skinned body (glTF/glb); metres, Y-up.
    #[arg(long, help_heading = "Inputs")]
    pub body: PathBuf,
    /// Garment mesh in the body's rest pose: OBJ, or USD with one Mesh prim (.usd/.usda/.usdc/.usdz,
    /// converted to metres, Y-up); sidecar NAME.toml: pinned vertices.
    #[arg(long, help_heading = "Inputs")]
    pub garment: PathBuf,
    /// The training clips (BVH): the poses come from them.
    #[command(flatten)]
    pub clips: ClipArgs,
    #[command(flatten)]
    pub fabric: FabricArgs,
    /// Seed: same seed and inputs → byte-identical model.
    #[arg(long, default_value_t = TRAIN_DEFAULTS.seed, help_heading = "Training")]
    pub seed: u64,
    #[command(flatten)]
    pub compute: ComputeArgs,
    /// Poses per optimisation step.
    #[arg(long, default_value_t = TRAIN_DEFAULTS.batch, help_heading = "Training")]
    pub batch: usize,
    /// Initial Adam learning rate (cosine decay to a tenth).
    #[arg(long, default_value_t = TRAIN_DEFAULTS.learning_rate, value_parser = positive::<f64>(), help_heading = "Training")]
    pub lr: f64,
    /// MLP width = number of PSD blend shapes.
    #[arg(long, default_value_t = TRAIN_DEFAULTS.width, help_heading = "Training")]
    pub width: usize,
    /// Skin influences per vertex (4 or 8), fixed at initialisation.
    #[arg(long, default_value_t = TRAIN_DEFAULTS.influences, help_heading = "Training")]
    pub influences: usize,
    /// Keep the proximity blend weights instead of optimising them.
    #[arg(long, help_heading = "Training")]
    pub fixed_weights: bool,
    /// Pose balancing threshold (radians, per rotation component of the garment's joints).
    #[arg(long, default_value_t = TRAIN_DEFAULTS.pose_threshold, value_parser = non_negative::<f32>(), help_heading = "Training")]
    pub pose_threshold: f32,
    /// At most this many balanced clip poses (train + validation). Many clips balance to
    /// thousands; beyond the budget the poses are thinned farthest first (each kept pose the one
    /// farthest from those already kept), which keeps rare poses and drops repeats of common ones.
    #[arg(long, default_value_t = TRAIN_DEFAULTS.pose_budget, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(2..), help_heading = "Training")]
    pub pose_budget: usize,
    /// Extra training poses per balanced one, each taking every limb chain (legs, spine, neck and
    /// head, arms) from a different real frame: covers pose combinations the clips lack.
    #[arg(long, default_value_t = TRAIN_DEFAULTS.recombine, help_heading = "Training")]
    pub recombine: usize,
    /// Pose coverage: generated training poses per balanced real one (0 turns it off). Half
    /// recombine limb chains of real frames (bent up to 30 % further), half draw about half of the
    /// garment's joints (hips, knees, spine, ...) uniformly across the rotation range the clips
    /// show, widened by 30 % of it on each side: wide stances, knee raises and deep bends the
    /// clips do not combine. The real poses stay in, so common poses keep their accuracy.
    #[arg(
        long,
        default_value_t = TRAIN_DEFAULTS.coverage,
        value_name = "PER_REAL_POSE",
        value_parser = non_negative::<f32>(),
        help_heading = "Training"
    )]
    pub coverage: f32,
    /// Epochs between refreshes of the nearest-body-vertex candidates.
    #[arg(long, default_value_t = TRAIN_DEFAULTS.refresh_every, help_heading = "Advanced")]
    pub refresh_every: usize,
    /// How candidates are refreshed: trees (CPU k-d trees on a worker thread), device (brute
    /// force with cdist + topk on the training device), auto (device on CUDA, else trees).
    #[arg(long, value_enum, default_value = "auto", help_heading = "Advanced")]
    pub refresh: RefreshArg,
    /// Candidate body vertices kept per garment vertex.
    #[arg(long, default_value_t = TRAIN_DEFAULTS.candidates, help_heading = "Advanced")]
    pub candidates: usize,
    /// Learning rate of the blend-weight logits relative to --lr.
    #[arg(long, default_value_t = TRAIN_DEFAULTS.weights_lr_scale, value_parser = non_negative::<f64>(), help_heading = "Training")]
    pub weights_lr_scale: f64,
    /// Initial blend weights: copy the body's within this distance (metres) of it at rest and
    /// interpolate them smoothly over the garment beyond (a skirt's hanging part).
    #[arg(long, default_value_t = TRAIN_DEFAULTS.inpaint_beyond.unwrap(), value_parser = non_negative::<f32>(), help_heading = "Training")]
    pub inpaint_beyond: f32,
    /// Copy the body's weights by proximity everywhere (no inpainting).
    #[arg(long, help_heading = "Training")]
    pub no_inpaint: bool,
    /// Epochs between validation passes (exact metrics on the held-out poses).
    #[arg(long, default_value_t = TRAIN_DEFAULTS.validate_every, help_heading = "Advanced")]
    pub validate_every: usize,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum RefreshArg {
    Auto,
    Trees,
    Device,
}

impl TrainInputs {
    /// Reads everything and builds the settings; warnings (garment fit) come back as lines.
    pub fn load(&self, epochs: usize, strict: bool) -> Result<(Inputs, Settings, Vec<String>)> {
        set_training_threads(self.compute.threads);
        let files = InputFiles {
            body: &self.body,
            garment: &self.garment,
            motions: &self.clips.motions,
            maps: &self.clips.maps,
            fps: self.clips.fps,
            fabric: &self.fabric.fabric,
        };
        if !(self.coverage.is_finite() && self.coverage >= 0.0) {
            bail!(
                "--coverage must be 0 or more generated poses per real one, not {}",
                self.coverage
            );
        }
        let (inputs, warnings) = Inputs::read(&files, strict)?;
        let settings = Settings {
            epochs,
            batch: self.batch,
            learning_rate: self.lr,
            width: self.width,
            influences: self.influences,
            train_weights: !self.fixed_weights,
            seed: self.seed,
            pose_threshold: self.pose_threshold,
            pose_budget: self.pose_budget,
            recombine: self.recombine,
            coverage: self.coverage,
            refresh_every: self.refresh_every,
            refresh: match self.refresh {
                RefreshArg::Auto => RefreshMode::Auto,
                RefreshArg::Trees => RefreshMode::Trees,
                RefreshArg::Device => RefreshMode::Device,
            },
            candidates: self.candidates.max(1),
            weights_lr_scale: self.weights_lr_scale,
            validate_every: self.validate_every,
            inpaint_beyond: (!self.no_inpaint).then_some(self.inpaint_beyond),
            device: crate::compute::parse_device(&self.compute.device)?,
            ..Settings::DEFAULT
        };
        Ok((inputs, settings, warnings))
    }
}

/// What an output flag writes, for [`output_set`].
#[derive(Clone, Copy)]
pub enum Writes {
    Kinds(&'static [exporters::FileKind]),
    /// A page (`--view PAGE.html`).
    Page,
    /// A file of one of these extensions (a picture, a joint map).
    Named(&'static [&'static str]),
    /// A file of any name (a log).
    Any,
}

impl Writes {
    fn extensions(self) -> Vec<&'static str> {
        match self {
            Writes::Kinds(kinds) => exporters::FileKind::written_extensions(kinds),
            Writes::Page => vec!["html", "htm"],
            Writes::Named(extensions) => extensions.to_vec(),
            Writes::Any => vec![],
        }
    }
}

/// A point cache: .pc2, .mdd, .usda/.usdc/.usdz, .abc, .vat.exr or .vat.png.
pub const POINT_CACHE: Writes = Writes::Kinds(&exporters::POINT_CACHE_KINDS);

/// A picture (`--out S.png`, `--png`, `--plot-*`).
pub const PNG: Writes = Writes::Named(&["png"]);

/// A model file (.safetensors).
pub const MODEL: Writes = Writes::Kinds(&[exporters::FileKind::Model]);

/// A baked asset: glTF (.glb/.gltf) or USD (.usda/.usdc/.usdz).
pub const ASSET: Writes = Writes::Kinds(&[exporters::FileKind::Gltf, exporters::FileKind::Usd]);

/// A command's outputs, `(flag, path if given, what it writes)`, checked before its work and
/// written all or none (exporters::atomic::OutputSet).
pub fn output_set(
    outputs: &[(&str, Option<&Path>, Writes)],
) -> Result<exporters::atomic::OutputSet> {
    let extensions: Vec<Vec<&str>> = outputs.iter().map(|o| o.2.extensions()).collect();
    let planned: Vec<exporters::atomic::Planned> = outputs
        .iter()
        .zip(&extensions)
        .filter_map(|(&(flag, path, _), extensions)| {
            path.map(|path| exporters::atomic::Planned {
                flag,
                path,
                extensions,
            })
        })
        .collect();
    Ok(exporters::atomic::OutputSet::check(&planned)?)
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
