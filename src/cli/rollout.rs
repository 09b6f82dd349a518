//! `garmentbake rollout`: a dynamic model played over clips frame by frame, written as a point
//! cache (PC2, MDD, USD) or a compressed glTF, with its errors against reference simulations
//! (library: src/pipeline/rollout/).

use super::args::{
    output_set, short_help, CollisionFixArgs, ComputeArgs, OutputArgs, Writes, NO_IDS,
};
use super::args::{POINT_CACHE, SHORT_HELP_NOTE};
use super::Execute;
use crate::bake::compress::Targets;
use crate::pipeline::rollout::{run, Request};
use crate::pipeline::Feedback;
use anyhow::Result;
use exporters::FileKind;
use std::path::PathBuf;

pub use crate::pipeline::rollout::report::Report;

/// The flags (ids) `-h` leaves out besides the Advanced ones (`--help` shows them).
pub(super) const SHORT_HIDES: [&str; 3] = ["float_targets", "out_units", "out_up"];

/// Play a dynamic garment model (`train-dynamic --stage dynamic`) over motion clips.
///
/// Each frame's garment is predicted from the previous frames' garment and the body's motion,
/// then becomes the next frame's history. Clips are resampled to the rate the model was trained
/// at (recorded in the output). Several --motion clips play one after another as one roll-out:
/// each later clip starts where the previous one ended, its first frames blended from the last
/// pose (--fade). Per frame, the decoded garment's edges are pulled back within 2 % of their
/// rest lengths (the strain limit), and a garment that crosses the body is pushed out, the edges
/// around the pushed vertices kept, and a vertex still inside the body lifted out (the collision
/// fix; --collision-solver paper: the paper's Adam fit of a UV displacement map).
/// --no-collision-fix --strain-iterations 0 shows the network alone.
///
/// Writes the garment per frame as a point cache (.pc2, Blender's Mesh Cache reads it; .usda/
/// .usdc/.usd: time-sampled points). --reference SIM.pc2 (a `simulate` cache of the same clip)
/// measures the roll-out against it: after one step, over the first 50 frames, over the clip.
/// Several --reference simulations of the clip (e.g. `simulate --blend 1.1`, a lead-in 0.1 s
/// longer) also measure how far apart they are: a loose garment is chaotic, and a roll-out as
/// far from them as they are from each other is as close as a re-run of the simulator.
#[derive(clap::Args)]
#[command(after_help = SHORT_HELP_NOTE)]
#[command(mut_args(short_help(SHORT_HIDES, NO_IDS)))]
pub struct Args {
    /// Dynamic model with its motion stage (.safetensors).
    #[arg(long, help_heading = "Inputs")]
    pub model: PathBuf,
    /// The clips, played one after another at the model's rate.
    #[command(flatten)]
    pub clips: super::args::MotionArgs,
    /// Where the roll-out starts: `rest` or a point cache whose first frame is the start.
    ///
    /// `rest`: the rest garment on the first pose, at rest (pushed out of the body by the
    /// collision fix, like every frame); a point cache: its first frame is the starting garment
    /// as it is (e.g. the clip's simulation).
    #[arg(long, default_value = "rest", help_heading = "Inputs")]
    pub init: String,
    /// Play only the first N frames (of the clips in a row).
    #[arg(long, help_heading = "Inputs")]
    pub frames: Option<usize>,
    /// Frames over which a later clip blends in from the previous clip's last pose.
    #[arg(long, default_value_t = 15, help_heading = "Advanced")]
    pub fade: usize,
    /// Output: a point cache (.pc2, .mdd, .usda/.usdc, .abc, .vat.exr/.vat.png) or a glTF (.glb).
    ///
    /// .pc2, .mdd, .usda/.usdc, .abc: time-sampled points; .vat.exr / .vat.png: vertex animation
    /// textures with their normals, JSON and glb; .glb/.gltf: a compressed glTF, the garment
    /// skinned to the body's skeleton plus blend shapes from the singular directions of its
    /// un-skinned residual over the roll-out, their weights animated (plays in any glTF viewer).
    #[arg(long, help_heading = "Outputs")]
    pub out: PathBuf,
    /// glTF output: keep the fewest blend shapes whose replay stays within this distance (mm) of
    /// every rolled-out vertex (and --validate's limit).
    #[arg(long, default_value_t = 1.0, value_parser = super::args::positive::<f32>(), help_heading = "Outputs")]
    pub tolerance_mm: f32,
    /// glTF output: keep this many blend shapes instead of a tolerance.
    ///
    /// The strongest ones (8 is what every glTF client must support); the replay error they cost
    /// is printed.
    #[arg(long, conflicts_with = "tolerance_mm", help_heading = "Outputs")]
    pub max_targets: Option<usize>,
    /// glTF output: store the blend shapes as 32-bit floats instead of 16-bit integers. By
    /// default they are quantized (KHR_mesh_quantization: half the bytes, the rounding counted
    /// in --tolerance-mm), which three.js and Blender read (both checked) as do most engines'
    /// glTF loaders; this flag is for readers without that extension.
    #[arg(long, help_heading = "Outputs")]
    pub float_targets: bool,
    /// Also write the posed body per frame as a point cache.
    #[arg(long, help_heading = "Outputs")]
    pub body_out: Option<PathBuf>,
    /// USD or Alembic --out: put the posed body in the same stage / archive, beside the garment.
    ///
    /// `/NAME/garment`, `/NAME/body`, one timeline, so the shot opens in usdview or a DCC with
    /// the body it was rolled out on.
    #[arg(long, help_heading = "Outputs")]
    pub with_body: bool,
    /// A simulated cache of the same (single) clip to measure the roll-out against (repeat).
    ///
    /// The roll-out (and plain LBS beside it) is measured against it. Repeat for several
    /// simulations of the clip: the roll-out against each and against their mean, and the
    /// simulations against each other (their own spread); the first is the one --restart-every
    /// and --view use.
    #[arg(long = "reference", value_name = "SIM.pc2", help_heading = "Inputs")]
    pub references: Vec<PathBuf>,
    /// With --reference: also roll the model out afresh every N frames of the clip, each time
    /// from the reference's own state there (its last three frames: the garment starts moving
    /// as simulated), for N frames, and report the mean error of these restarts. A long
    /// roll-out of a loose garment leaves any one simulation by chaos alone (two simulations of
    /// a clip whose lead-ins differ by 0.1 s can end centimetres apart); the restarts measure the
    /// model's dynamics over N frames at every part of the clip instead (the paper's
    /// "rollout-50", taken all along the clip).
    #[arg(
        long,
        value_name = "N",
        requires = "references",
        help_heading = "Advanced"
    )]
    pub restart_every: Option<usize>,
    /// Also write plain linear blend skinning of the rest garment per frame (the baseline).
    ///
    /// The fixed skin of the glTF output (proximity weights, no dynamics) as a point cache, the
    /// baseline to compare with (e.g. `preview --side-by-side`).
    #[arg(long, value_name = "LBS.pc2", help_heading = "Outputs")]
    pub lbs_out: Option<PathBuf>,
    /// Also write a page that plays the roll-out on the body in a browser (see `view`).
    ///
    /// With --reference, the simulation beside it and error colours against it.
    #[arg(long, value_name = "PAGE.html", help_heading = "Outputs")]
    pub view: Option<PathBuf>,
    /// Check what was written as `garmentbake validate` does; exit 1 when it fails.
    ///
    /// Its structure, and that it plays the roll-out just computed within --tolerance-mm at every
    /// frame (a glTF evaluated as the spec says, a point cache read back).
    #[arg(long, help_heading = "Outputs")]
    pub validate: bool,
    /// Skip the per-frame collision fix.
    #[arg(long, help_heading = "Advanced")]
    pub no_collision_fix: bool,
    #[command(flatten)]
    pub collision: CollisionFixArgs,
    #[command(flatten)]
    pub space: super::args::CacheSpaceArgs,
    #[command(flatten)]
    pub compute: ComputeArgs,
    #[command(flatten)]
    pub output: OutputArgs,
}

impl Execute for Args {
    type Report = Report;

    fn execute(&self, say: &dyn Fn(&str)) -> Result<Report> {
        let kinds = &[
            FileKind::Pc2,
            FileKind::Mdd,
            FileKind::Usd,
            FileKind::Alembic,
            FileKind::Vat,
            FileKind::Gltf,
        ];
        let outputs = output_set(&[
            ("--out", Some(&self.out), Writes::Kinds(kinds)),
            ("--lbs-out", self.lbs_out.as_deref(), POINT_CACHE),
            ("--body-out", self.body_out.as_deref(), POINT_CACHE),
            ("--view", self.view.as_deref(), Writes::Page),
        ])?;
        let tolerance = Some(self.tolerance_mm);
        let targets = Targets::from_flags(self.max_targets, tolerance, Targets::Full)?;
        let request = Request {
            model: self.model.clone(),
            compute: self.compute.compute(),
            clips: self.clips.clips(None),
            fade: self.fade,
            init: (self.init != "rest").then(|| PathBuf::from(&self.init)),
            frames: self.frames,
            settings: self.collision.settings(!self.no_collision_fix)?,
            out: self.out.clone(),
            targets,
            tolerance_mm: self.tolerance_mm,
            float_targets: self.float_targets,
            body_out: self.body_out.clone(),
            with_body: self.with_body,
            references: self.references.clone(),
            restart_every: self.restart_every,
            lbs_out: self.lbs_out.clone(),
            view: self.view.clone(),
            validate: self.validate,
            space: self.space.space(),
        };
        let feedback = Feedback {
            say,
            hide_bars: self.output.json,
        };
        run(&request, outputs, &feedback)
    }

    fn print(r: &Report) {
        print!("{r}");
        if let Some(v) = &r.validation {
            v.print();
        }
    }

    fn exit_code(r: &Report) -> i32 {
        i32::from(r.failed())
    }
}
