//! Rolling a dynamic model out over a pose sequence: each frame's prediction is the next
//! frame's history. Per frame, the decoded garment's edges are pulled back towards their rest
//! lengths (strain limiting: the linear decode stretches and shrinks them by ~16 % where cloth
//! keeps them within ~2 %), then, when the garment crosses the body (the paper's collision loss
//! `Σ ReLU(−o)`, `o = (g − b)·n` against the nearest posed body vertex, above a threshold), the
//! crossing vertices are pushed out and the edges around them kept ([`contact`]; the paper's
//! Adam fit of a UV displacement map is [`paper_fix`], an option). The resolved garment is fed
//! forward (paper Sec. 5.1).

pub mod contact;
pub mod paper_fix;
pub mod surface;
pub mod timing;

use crate::body::Body;
use crate::geometry::{Frames, StrainLimit};
use crate::models::dynamic::motion::History;
use crate::models::dynamic::{BodyAnchors, BodyFrames, Dynamic, MeshEdges, MeshLaplacian, Space};
use crate::models::file::ModelFile;
use crate::rig::JointTransform;
use anyhow::{bail, Result};
use paper_fix::{Decoded, ShapeTerms};
use serde::{Deserialize, Serialize};
use std::time::Instant;
use surface::{Planes, PosedSurface};
use tch::Tensor;

pub use paper_fix::LAMBDA_COLLISION;

/// Weight of the paper fix's edge-length term (not in the paper): without it the fix
/// stretches the garment it pushes out (a vertex squeezed between two limbs is pushed out of one
/// into the other) and the stretched garment is fed forward. Chosen on 131_02 (docs/dynamic.md).
pub const LAMBDA_EDGES: f64 = 10.0;

/// How far an edge may stretch or shrink before the strain limit pulls it back (fraction of
/// its rest length). Simulations of the skirt have mean strains of 1.5–3 %.
pub const STRAIN_BAND: f32 = 0.02;
/// Gauss–Seidel sweeps of the strain limit per frame.
pub const STRAIN_ITERATIONS: usize = 20;

/// How the collision fix resolves a frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Solver {
    /// Push the crossing vertices out, keep the edges around them (plain arrays, ~5 ms).
    #[default]
    Projection,
    /// The paper's Adam fit of a UV displacement map through libtorch (~100 ms).
    Paper,
}

impl Solver {
    /// Passes of the projection, Adam iterations of the paper's fit.
    pub fn default_iterations(self) -> usize {
        match self {
            Solver::Projection => 8,
            Solver::Paper => 20,
        }
    }
}

#[derive(Clone, Debug)]
pub struct Settings {
    /// Resolve collisions per frame (the paper's test-time optimisation).
    pub collision_fix: bool,
    pub solver: Solver,
    /// Distance outside the body a vertex must keep (metres): `o` is measured against it.
    pub margin: f32,
    /// Fix only when `Σ ReLU(margin − o)` exceeds this (metres, summed over vertices).
    pub threshold: f64,
    /// Projection passes or Adam iterations ([`Solver::default_iterations`]).
    pub iterations: usize,
    pub learning_rate: f64,
    /// The paper fix's edge-length term `Σ_e ||G̃_e| − |G_e||` (0: the paper's objective).
    pub edge_weight: f64,
    /// Texels per side of the paper fix's residual map `Θ`.
    pub map: i64,
    /// Strain limit sweeps after each decode (0: off) and its band (see [`STRAIN_BAND`]).
    pub strain_iterations: usize,
    pub strain_band: f32,
    /// Per latent dimension, the range the roll-out is held in (the model's training range).
    pub latent_range: Option<(Vec<f32>, Vec<f32>)>,
    /// Measure the collision loss when the fix is off (posing the body and indexing it costs
    /// a third of a frame; training roll-outs skip it).
    pub measure_collisions: bool,
}

impl Default for Settings {
    fn default() -> Settings {
        Settings {
            collision_fix: true,
            solver: Solver::Projection,
            margin: 0.002,
            threshold: 0.001,
            iterations: Solver::Projection.default_iterations(),
            learning_rate: 0.002,
            edge_weight: LAMBDA_EDGES,
            map: 32,
            strain_iterations: STRAIN_ITERATIONS,
            strain_band: STRAIN_BAND,
            latent_range: None,
            measure_collisions: true,
        }
    }
}

/// Where the roll-out starts.
pub enum Init {
    /// The rest garment carried to the first pose by the anchors, at rest (zero velocity).
    Rest,
    /// A garment's last frames, oldest first, the last one as frame 0 (the model reads up to
    /// three: velocity and acceleration come from them). One frame: that garment at rest (e.g.
    /// a simulation's first frame).
    Moving(Vec<Vec<[f32; 3]>>),
}

/// Frames of history the motion encoder reads (the garment, its velocity and acceleration).
const HISTORY: usize = 3;

/// Milliseconds per phase of one frame, split as the paper does.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct FrameTiming {
    pub inputs_ms: f64,
    pub encoder_ms: f64,
    pub decode_ms: f64,
    /// The strain limit after the decode.
    pub strain_ms: f64,
    /// Collision check and, when it fires, the fix.
    pub collision_ms: f64,
    pub collision_iterations: usize,
}

pub struct Rollout {
    /// The garment at every frame (frame 0 is the start, clip frame `first`).
    pub frames: Frames,
    pub timings: Vec<FrameTiming>,
    /// Collision loss `Σ ReLU(margin − o)` (metres) per frame before and after the fix.
    pub collision_before: Vec<f64>,
    pub collision_after: Vec<f64>,
}

fn to_points(t: &Tensor) -> Vec<[f32; 3]> {
    let flat: Vec<f32> = t.reshape([-1]).try_into().unwrap_or_default();
    flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
}

fn to_tensor(points: &[[f32; 3]], device: tch::Device) -> Tensor {
    let flat: Vec<f32> = points.iter().flatten().copied().collect();
    Tensor::from_slice(&flat)
        .reshape([1, -1, 3])
        .to_device(device)
}

/// The garment a roll-out plays: its triangles, and its rest shape and pinned vertices (what
/// the strain limit and the projection fix keep).
pub struct GarmentShape<'a> {
    pub rest: &'a [[f32; 3]],
    pub triangles: &'a [[u32; 3]],
    pub pinned: &'a [u32],
}

/// Rolls `model` out over `poses[first..]` (at `fps`, the model's rate): the poses before
/// `first` are the body's known past (a restart inside a clip), whose drives the learnt
/// dynamics read ([`Dynamic::past_drives`]); the garment starts at `first` from `init`.
/// `progress` is called after every frame, counted from `first`.
#[allow(clippy::too_many_arguments)]
pub fn roll_out(
    model: &Dynamic,
    body: &Body,
    anchors: &BodyAnchors,
    garment: &GarmentShape,
    poses: &[Vec<JointTransform>],
    first: usize,
    fps: f64,
    init: &Init,
    settings: &Settings,
    progress: &mut dyn FnMut(usize),
) -> Result<Rollout> {
    model.motion()?;
    let space = &model.space;
    let linear_only = model.linear_only();
    let device = space.consts.rest.device();
    if first >= poses.len() {
        bail!("nothing to roll out: the clip has no frames");
    }
    let bodies = BodyFrames::new(body, anchors, poses, device);
    let drives = model.clip_drives(&bodies, fps)?;
    let at = |f: usize| bodies.select(&Tensor::from_slice(&[f as i64]).to_device(device));
    let limit = StrainLimit::new(garment.rest, garment.triangles, garment.pinned);
    let mut first_fix = FrameFix::default();
    let start: Vec<Vec<[f32; 3]>> = match init {
        Init::Rest => {
            let mut rest = tch::no_grad(|| {
                to_points(&space.skin(&space.consts.rest.unsqueeze(0), &at(first).transforms))
            });
            // The rest garment skinned on a first pose far from rest can cross the body
            // (hundreds of vertices on a seated start): the first frame is fixed too.
            first_fix = fix_frame(&mut rest, body, &poses[first], &limit, settings, None)?;
            vec![rest]
        }
        Init::Moving(frames) => frames[frames.len().saturating_sub(HISTORY)..].to_vec(),
    };
    let Some(initial) = start.last().cloned() else {
        bail!("the roll-out's start has no garment");
    };
    let shape = (settings.solver == Solver::Paper).then(|| ShapeTerms {
        laplacian: MeshLaplacian::new(garment.triangles, initial.len(), device),
        edges: MeshEdges::new(garment.triangles, device),
    });
    let range = settings.latent_range.as_ref().map(|(lo, hi)| {
        let t = |v: &[f32]| Tensor::from_slice(v).unsqueeze(0).to_device(device);
        (t(lo), t(hi))
    });
    let mut out = Rollout {
        frames: Frames::new(vec![initial], fps as f32).starting_at(first),
        timings: vec![FrameTiming::default()],
        collision_before: vec![first_fix.before],
        collision_after: vec![first_fix.after],
    };
    let mut history: Vec<Tensor> = start.iter().map(|g| to_tensor(g, device)).collect();
    // Each frame's body is selected once and kept for the next frame's `before`; the linear
    // path blends its seed transforms once: to skin it, and a frame later to unskin its garment.
    let posed = |b: &BodyFrames| linear_only.then(|| space.posed(&b.transforms));
    let mut body_before = at(first);
    let mut posed_before = posed(&body_before);
    progress(0);
    for (t, pose) in poses.iter().enumerate().skip(first + 1) {
        let mut timing = FrameTiming::default();
        let clock = Instant::now();
        let back = |k: usize| history[history.len().saturating_sub(k)].shallow_clone();
        let now = at(t);
        let posed_now = posed(&now);
        let h = History {
            garment: [back(1), back(2), back(3)],
            before: body_before,
            now,
            fps,
        };
        let x = match (&posed_before, &posed_now) {
            (Some(before), Some(now)) => {
                model.linear_step_inputs(&h, (before, now), model.past_drives(&drives, t)?)?
            }
            _ => model.step_inputs(&h)?,
        };
        timing.inputs_ms = ms(clock);
        let clock = Instant::now();
        let z = model.next_latent(&x, range.as_ref())?;
        timing.encoder_ms = ms(clock);
        let clock = Instant::now();
        let canonical = tch::no_grad(|| space.canonical(&z));
        let skinned = tch::no_grad(|| match &posed_now {
            Some(now) => now.skin(&canonical),
            None => space.skin(&canonical, &h.now.transforms),
        });
        posed_before = posed_now;
        let mut points = to_points(&skinned);
        timing.decode_ms = ms(clock);
        let clock = Instant::now();
        limit.project(
            &mut points,
            settings.strain_band,
            settings.strain_iterations,
        );
        timing.strain_ms = ms(clock);
        let clock = Instant::now();
        let decoded = Decoded {
            canonical: &canonical,
            transforms: &h.now.transforms,
            skinned: &skinned,
        };
        let paper = shape.as_ref().map(|shape| PaperFit {
            space,
            shape,
            decoded,
        });
        let fix = fix_frame(&mut points, body, pose, &limit, settings, paper)?;
        timing.collision_ms = ms(clock);
        timing.collision_iterations = fix.iterations;
        if points.iter().flatten().any(|x| !x.is_finite()) {
            bail!("the roll-out produced a non-finite vertex at frame {t}");
        }
        history.push(to_tensor(&points, device));
        if history.len() > HISTORY {
            drop(history.remove(0));
        }
        out.frames.push(points);
        out.timings.push(timing);
        out.collision_before.push(fix.before);
        out.collision_after.push(fix.after);
        body_before = h.now;
        progress(t - first);
    }
    Ok(out)
}

/// The paper's collision fix needs the frame's decode (what it optimises `Θ` from).
struct PaperFit<'a> {
    space: &'a Space,
    shape: &'a ShapeTerms,
    decoded: Decoded<'a>,
}

/// What the collision fix found and did on one frame: the loss `Σ ReLU(margin − o)` before
/// and after, and the passes it took (0: not needed, or off).
#[derive(Clone, Copy, Debug, Default)]
struct FrameFix {
    before: f64,
    after: f64,
    iterations: usize,
}

/// One frame's collision measure and fix against the body at `pose`: when the loss exceeds the
/// threshold, the projection (or, given the frame's decode and the paper solver, the paper's
/// fit), then the lift of what the planes leave inside. A frame with no decode (a first frame
/// from rest) is projected whatever the solver, with the projection's passes unless it is the
/// solver. Neither measured nor fixed when both are off in `settings`.
fn fix_frame(
    points: &mut Vec<[f32; 3]>,
    body: &Body,
    pose: &[JointTransform],
    limit: &StrainLimit,
    settings: &Settings,
    paper: Option<PaperFit>,
) -> Result<FrameFix> {
    let mut fix = FrameFix::default();
    if !(settings.collision_fix || settings.measure_collisions) {
        return Ok(fix);
    }
    let surface = PosedSurface::new(body, pose)?;
    let planes = Planes::of(points, &surface);
    fix.before = planes.loss(points, settings.margin);
    fix.after = fix.before;
    if !settings.collision_fix || fix.before <= settings.threshold {
        return Ok(fix);
    }
    match paper {
        Some(fit) => {
            fix.iterations = settings.iterations;
            let g = to_tensor(points, fit.decoded.skinned.device());
            let fixed =
                paper_fix::resolve(fit.space, &fit.decoded, &g, &planes, fit.shape, settings);
            *points = to_points(&fixed);
        }
        None => {
            fix.iterations = match settings.solver {
                Solver::Projection => settings.iterations,
                Solver::Paper => Solver::Projection.default_iterations(),
            };
            contact::push_out(
                points,
                &planes,
                limit,
                settings.margin,
                settings.strain_band,
                fix.iterations,
            );
        }
    }
    // The planes miss where a vertex's nearest body vertex is on another limb.
    surface.lift_inside(points, &planes, settings.margin);
    fix.after = planes.loss(points, settings.margin);
    Ok(fix)
}

/// [`roll_out`] of a model file's dynamic model over the clip frames `played` of `poses` (the
/// whole clip's poses) at the model's rate, with its anchors and, unless `settings` says
/// otherwise, its latents held in the training range. A roll-out restarted inside the clip
/// (`played.start > 0`) keeps the frames before it that the learnt dynamics read as the body's
/// known past ([`Dynamic::past_drives`]): a restart sees the motion the clip had, not a body
/// held still.
pub fn for_model(
    file: &ModelFile,
    poses: &[Vec<JointTransform>],
    played: std::ops::Range<usize>,
    init: &Init,
    mut settings: Settings,
    progress: &mut dyn FnMut(usize),
) -> Result<Rollout> {
    let model = file.dynamic()?;
    let info = file.info.dynamic()?;
    if played.end > poses.len() {
        bail!(
            "frames {}..{} are past the clip's {} frames",
            played.start,
            played.end,
            poses.len()
        );
    }
    let lead = played.start.min(model.motion()?.past_frames());
    if settings.latent_range.is_none() {
        settings.latent_range = info
            .motion
            .as_ref()
            .map(|m| (m.latent_min.clone(), m.latent_max.clone()));
    }
    let anchors = BodyAnchors::from_vertices(&file.body, &info.anchors, &info.anchor_parts)?;
    let garment = GarmentShape {
        rest: &file.garment.positions,
        triangles: &file.garment.triangles,
        pinned: &file.info.garment.pinned,
    };
    roll_out(
        model,
        &file.body,
        &anchors,
        &garment,
        &poses[played.start - lead..played.end],
        lead,
        info.fps as f64,
        init,
        &settings,
        progress,
    )
}

fn ms(since: Instant) -> f64 {
    since.elapsed().as_secs_f64() * 1e3
}
