//! Rolling a dynamic model out over a pose sequence: each frame's prediction is the next
//! frame's history. Per frame, when the garment crosses the body (the paper's collision loss
//! `Σ ReLU(−o)`, `o = (g − b)·n` against the nearest posed body vertex, above a threshold), a
//! residual displacement map `Θ` in UV space (bilinear per vertex, in the vertices' rest frames)
//! is optimised with Adam for `|G̃ − G|₁ + |ΔG̃ − ΔG|₁ + λ3·L_collision` (λ3 = 100) and the
//! resolved garment is fed forward (paper Sec. 5.1). One term beyond the paper keeps the edge
//! lengths the garment had before the fix ([`LAMBDA_EDGES`]).

use crate::body::{nearest_offsets, Body};
use crate::geometry::PointIndex;
use crate::models::dynamic::motion::History;
use crate::models::dynamic::{BodyFrames, Dynamic, MeshEdges, MeshLaplacian, Seeds, Space};
use crate::models::file::ModelFile;
use crate::rig::JointTransform;
use anyhow::{bail, Result};
use serde::Serialize;
use std::time::Instant;
use tch::nn::{self, OptimizerConfig};
use tch::{Kind, Tensor};

/// λ3 of the collision objective.
pub const LAMBDA_COLLISION: f64 = 100.0;
/// Weight of the collision fix's edge-length term (not in the paper): without it the fix
/// stretches the garment it pushes out (a vertex squeezed between two limbs is pushed out of one
/// into the other) and the stretched garment is fed forward. Chosen on 131_02 (docs/dynamic.md).
pub const LAMBDA_EDGES: f64 = 10.0;

#[derive(Clone, Debug)]
pub struct Settings {
    /// Resolve collisions per frame (the paper's test-time optimisation).
    pub collision_fix: bool,
    /// Distance outside the body a vertex must keep (metres): `o` is measured against it.
    pub margin: f32,
    /// Optimise only when `Σ ReLU(margin − o)` exceeds this (metres, summed over vertices).
    pub threshold: f64,
    pub iterations: usize,
    pub learning_rate: f64,
    /// Weight of the edge-length term `Σ_e ||G̃_e| − |G_e||` (0: the paper's objective).
    pub edge_weight: f64,
    /// Texels per side of the residual map `Θ`.
    pub map: i64,
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
            margin: 0.002,
            threshold: 0.001,
            iterations: 20,
            learning_rate: 0.002,
            edge_weight: LAMBDA_EDGES,
            map: 32,
            latent_range: None,
            measure_collisions: true,
        }
    }
}

/// Where the roll-out starts.
pub enum Init {
    /// The rest garment carried to the first pose by the seeds, at rest (zero velocity).
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
    /// Collision check and, when it fires, the optimisation.
    pub collision_ms: f64,
    pub collision_iterations: usize,
}

pub struct Rollout {
    /// The garment at every frame (frame 0 is the start).
    pub frames: Vec<Vec<[f32; 3]>>,
    pub timings: Vec<FrameTiming>,
    /// Collision loss `Σ ReLU(margin − o)` (metres) per frame before and after the fix.
    pub collision_before: Vec<f64>,
    pub collision_after: Vec<f64>,
}

/// The posed body of one frame for the collision term: points, normals, nearest-point index.
struct PosedSurface {
    points: Vec<[f32; 3]>,
    normals: Vec<[f32; 3]>,
    index: PointIndex,
}

impl PosedSurface {
    fn new(body: &Body, pose: &[JointTransform]) -> Result<PosedSurface> {
        let skinning = body.skeleton.skinning_matrices(pose);
        let points = body.skin.skin_points(&body.mesh.positions, &skinning);
        let normals = body.skin.skin_normals(&body.normals, &skinning);
        let index = PointIndex::new(&points)?;
        Ok(PosedSurface {
            points,
            normals,
            index,
        })
    }
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

/// Rolls `model` out over `poses` (at `fps`, the model's rate). `progress` is called after
/// every frame.
#[allow(clippy::too_many_arguments)]
pub fn roll_out(
    model: &Dynamic,
    body: &Body,
    seeds: &Seeds,
    triangles: &[[u32; 3]],
    poses: &[Vec<JointTransform>],
    fps: f64,
    init: &Init,
    settings: &Settings,
    progress: &mut dyn FnMut(usize),
) -> Result<Rollout> {
    model.motion()?;
    let space = &model.space;
    let linear_only = model.linear_only();
    let device = space.consts.rest.device();
    if poses.is_empty() {
        bail!("nothing to roll out: the clip has no frames");
    }
    let bodies = BodyFrames::new(body, seeds, poses, device);
    let at = |f: usize| bodies.select(&Tensor::from_slice(&[f as i64]).to_device(device));
    let start: Vec<Vec<[f32; 3]>> = match init {
        Init::Rest => vec![tch::no_grad(|| {
            to_points(&space.skin(&space.consts.rest.unsqueeze(0), &at(0).transforms))
        })],
        Init::Moving(frames) => frames[frames.len().saturating_sub(HISTORY)..].to_vec(),
    };
    let Some(first) = start.last().cloned() else {
        bail!("the roll-out's start has no garment");
    };
    let shape = ShapeTerms {
        laplacian: MeshLaplacian::new(triangles, first.len(), device),
        edges: MeshEdges::new(triangles, device),
    };
    let range = settings.latent_range.as_ref().map(|(lo, hi)| {
        let t = |v: &[f32]| Tensor::from_slice(v).unsqueeze(0).to_device(device);
        (t(lo), t(hi))
    });
    let mut out = Rollout {
        frames: vec![first],
        timings: vec![FrameTiming::default()],
        collision_before: vec![0.0],
        collision_after: vec![0.0],
    };
    let mut history: Vec<Tensor> = start.iter().map(|g| to_tensor(g, device)).collect();
    progress(0);
    for (t, pose) in poses.iter().enumerate().skip(1) {
        let mut timing = FrameTiming::default();
        let clock = Instant::now();
        let back = |k: usize| history[history.len().saturating_sub(k)].shallow_clone();
        let h = History {
            garment: [back(1), back(2), back(3)],
            before: at(t - 1),
            now: at(t),
            fps,
        };
        let x = model.step_inputs(&h, linear_only)?;
        timing.inputs_ms = ms(clock);
        let clock = Instant::now();
        let z = model.next_latent(&x, range.as_ref())?;
        timing.encoder_ms = ms(clock);
        let clock = Instant::now();
        let canonical = tch::no_grad(|| space.canonical(&z));
        let garment = tch::no_grad(|| space.skin(&canonical, &h.now.transforms));
        timing.decode_ms = ms(clock);
        let clock = Instant::now();
        let (resolved, before, after, iterations) =
            if settings.collision_fix || settings.measure_collisions {
                resolve_collisions(
                    model,
                    &canonical,
                    &garment,
                    &h.now.transforms,
                    &PosedSurface::new(body, pose)?,
                    &shape,
                    settings,
                )
            } else {
                (garment, 0.0, 0.0, 0)
            };
        timing.collision_ms = ms(clock);
        timing.collision_iterations = iterations;
        let points = to_points(&resolved);
        if points.iter().flatten().any(|x| !x.is_finite()) {
            bail!("the roll-out produced a non-finite vertex at frame {t}");
        }
        history.push(resolved);
        if history.len() > HISTORY {
            drop(history.remove(0));
        }
        out.frames.push(points);
        out.timings.push(timing);
        out.collision_before.push(before);
        out.collision_after.push(after);
        progress(t);
    }
    Ok(out)
}

/// [`roll_out`] of a model file's dynamic model over `poses` at the model's rate, with its seeds
/// and, unless `settings` says otherwise, its latents held in the training range.
pub fn for_model(
    file: &ModelFile,
    poses: &[Vec<JointTransform>],
    init: &Init,
    mut settings: Settings,
    progress: &mut dyn FnMut(usize),
) -> Result<Rollout> {
    let model = file.dynamic()?;
    let info = file.info.dynamic()?;
    if settings.latent_range.is_none() {
        settings.latent_range = info
            .motion
            .as_ref()
            .map(|m| (m.latent_min.clone(), m.latent_max.clone()));
    }
    let seeds = Seeds::from_vertices(&file.body, &info.seeds, &info.seed_parts)?;
    roll_out(
        model,
        &file.body,
        &seeds,
        &file.garment.triangles,
        poses,
        info.fps as f64,
        init,
        &settings,
        progress,
    )
}

fn ms(since: Instant) -> f64 {
    since.elapsed().as_secs_f64() * 1e3
}

/// Each vertex's nearest posed body vertex as tensors: positions and normals `[1, V, 3]`.
fn nearest_planes(garment: &Tensor, surface: &PosedSurface) -> (Tensor, Tensor) {
    let points = to_points(garment);
    let nearest = nearest_offsets(&points, &surface.points, &surface.normals, &surface.index);
    let pick = |of: &[[f32; 3]]| {
        let v: Vec<[f32; 3]> = nearest.iter().map(|&(b, _)| of[b as usize]).collect();
        to_tensor(&v, garment.device())
    };
    (pick(&surface.points), pick(&surface.normals))
}

/// `Σ ReLU(margin − o)` with `o = (g − b)·n`.
fn collision_loss(g: &Tensor, planes: &(Tensor, Tensor), margin: f32) -> Tensor {
    let o = ((g - &planes.0) * &planes.1).sum_dim_intlist(2, false, Kind::Float);
    (-(o - margin as f64)).relu().sum(Kind::Float)
}

/// The garment's operators the collision fix keeps its shape with.
struct ShapeTerms {
    laplacian: MeshLaplacian,
    edges: MeshEdges,
}

/// The paper's test-time fix: when the collision loss passes the threshold, optimise `Θ` for
/// `|G̃ − G|₁ + |ΔG̃ − ΔG|₁ + λ3·L_collision`, plus `λ_e·Σ_e ||G̃_e| − |G_e||` (edge lengths
/// kept). Returns the garment, the loss before and after, and the iterations run.
fn resolve_collisions(
    model: &Dynamic,
    canonical: &Tensor,
    garment: &Tensor,
    transforms: &Tensor,
    surface: &PosedSurface,
    shape: &ShapeTerms,
    s: &Settings,
) -> (Tensor, f64, f64, usize) {
    let planes = nearest_planes(garment, surface);
    let before = tch::no_grad(|| collision_loss(garment, &planes, s.margin).double_value(&[]));
    if !s.collision_fix || before <= s.threshold {
        return (garment.shallow_clone(), before, before, 0);
    }
    let space = &model.space;
    let vs = nn::VarStore::new(garment.device());
    let theta = vs.root().zeros("theta", &[1, 3, s.map, s.map]);
    let Ok(mut opt) = nn::Adam::default().build(&vs, s.learning_rate) else {
        return (garment.shallow_clone(), before, before, 0);
    };
    let target_laplacian = tch::no_grad(|| shape.laplacian.of(garment));
    // Weight 0 is the paper's objective: the edge term is then left out, not computed at zero.
    let target_lengths =
        (s.edge_weight > 0.0).then(|| tch::no_grad(|| shape.edges.lengths(garment)));
    // The pose is fixed over the iterations: blend the seeds' transforms once.
    let blended = tch::no_grad(|| space.blended(transforms));
    let resolved = |theta: &Tensor| {
        let offsets = space.at_vertices(theta);
        Space::skin_blended(&space.offset_canonical(canonical, &offsets), &blended)
    };
    for _ in 0..s.iterations {
        let g = resolved(&theta);
        let mut loss = (&g - garment).abs().sum(Kind::Float)
            + (shape.laplacian.of(&g) - &target_laplacian)
                .abs()
                .sum(Kind::Float);
        if let Some(lengths) = &target_lengths {
            loss += (shape.edges.lengths(&g) - lengths).abs().sum(Kind::Float) * s.edge_weight;
        }
        loss += collision_loss(&g, &planes, s.margin) * LAMBDA_COLLISION;
        opt.zero_grad();
        loss.backward();
        opt.step();
    }
    let g = tch::no_grad(|| resolved(&theta));
    let after = tch::no_grad(|| collision_loss(&g, &planes, s.margin).double_value(&[]));
    (g, before, after, s.iterations)
}
