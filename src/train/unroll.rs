//! Fitting the learnt latent dynamics `D` (`models::dynamic::learned`) through the model's own
//! roll-outs. Each step plays windows of K frames: a window starts from a simulated state (its
//! two previous frames projected into the space, with noise on the latent so the model learns to
//! recover from states it was not shown), then every frame is the model's own prediction fed
//! back (linear path + `D`, the space frozen, latents held in the training range as `rollout`
//! holds them; no collision fix). Loss: the decoded garment's mean squared distance to the
//! simulated frame (mm²) plus that of its per-frame step (the velocity, weighted), averaged
//! over the window. K grows from the first to the last horizon over the epochs: short windows
//! teach the step, long ones the swing and its settling (and the fit sees its own drift).
//!
//! Why through roll-outs and not on simulated histories (teacher forcing): the linear path is
//! already the best one-step fit on simulated histories; what it gets wrong is how its own
//! errors carry on, which only its own histories show (Venkatraman et al. 2015; the roll-out
//! rounds of `train::motion` refit `W` the same way, in closed form).

use super::adam::Adam;
use super::dynamic::{deviation, FrameData};
use super::motion::history_indices;
use crate::geometry::strain_limit::StrainLimit;
use crate::metrics::deviation::Deviation;
use crate::models::dynamic::learned::{
    DynamicsEpoch, DynamicsFit, DynamicsSettings, LearnedDynamics,
};
use crate::models::dynamic::motion::{drives, past_drives, MotionEncoder};
use crate::models::dynamic::space::Posed;
use crate::models::dynamic::Dynamic;
use crate::models::dynamic::Space;
use crate::models::file::{KindInfo, ModelFile};
use crate::models::Model;
use anyhow::{bail, Result};
use std::time::Instant;
use tch::{Kind, Tensor};

/// The window length of epoch `e` (0-based) of `epochs`: linear from the first horizon to the
/// last.
pub fn horizon_at(e: usize, epochs: usize, (first, last): (usize, usize)) -> usize {
    if epochs <= 1 {
        return last;
    }
    let f = e as f64 / (epochs - 1) as f64;
    (first as f64 + f * (last as f64 - first as f64)).round() as usize
}

/// Gives `dynamic`'s motion encoder learnt dynamics and fits them on `data` (the training
/// clips, simulated, at `fps`) through roll-outs; `range` holds the latents as `rollout` does.
/// `progress(epoch, record)` after every epoch.
pub fn fit_dynamics(
    dynamic: &mut Dynamic,
    data: &FrameData,
    fps: f64,
    range: (&Tensor, &Tensor),
    limit: &StrainLimit,
    s: &DynamicsSettings,
    progress: &mut dyn FnMut(&DynamicsEpoch),
) -> Result<DynamicsFit> {
    let clock = Instant::now();
    let starts = window_starts(data, s.horizon.1.max(s.horizon.0));
    if starts.is_empty() {
        bail!(
            "no training clip is long enough for a {}-frame window (and 3 frames of history) of the learnt dynamics: give shorter --unroll-frames, or --dynamics-epochs 0 for the linear integrator alone",
            s.horizon.1
        );
    }
    if s.windows == 0 || s.steps == 0 {
        bail!("the dynamics fit needs at least one window and one step per epoch");
    }
    tch::manual_seed(s.seed as i64);
    if !dynamic.linear_only() {
        bail!("the learnt dynamics are fitted beside the linear integrator: train the space and the motion stage with --epochs 0");
    }
    let Some(encoder) = dynamic.motion.as_mut() else {
        bail!("the model has no motion stage to give dynamics to");
    };
    encoder.add_dynamics(&s.widths, s.drive_history);
    let teacher = TeacherFrames::new(dynamic, data, fps);
    let encoder = dynamic.motion.as_ref().expect("set above");
    encoder
        .dynamics
        .as_ref()
        .expect("added above")
        .normalise_to(&teacher_inputs(&teacher));
    let played = Played {
        dynamic,
        data,
        posed: &teacher.posed,
        drives: &teacher.drives,
        range,
        limit: (s.strain_iterations > 0).then_some((limit, s.strain_band, s.strain_iterations)),
    };
    let check = (32, s.horizon.1);
    let base_rms_mm = measure(&played, &starts, check.0, check.1);
    let learned = played
        .dynamic
        .motion
        .as_ref()
        .and_then(|m| m.dynamics.as_ref())
        .expect("added above");
    let params = learned.trainable();
    let named: Vec<(String, &Tensor)> = params
        .iter()
        .enumerate()
        .map(|(i, t)| (i.to_string(), t))
        .collect();
    let mut adam = Adam::new(&named);
    let latent = played.dynamic.space.shape.latent as i64;
    let device = data.garment.device();
    let mut history = Vec::new();
    for epoch in 0..s.epochs {
        let k = horizon_at(epoch, s.epochs, s.horizon);
        let lr = super::cosine_rate(s.learning_rate, epoch, s.epochs);
        let (mut pos_sum, mut vel_sum) = (0.0, 0.0);
        for _ in 0..s.steps {
            let pick = Tensor::randint(
                starts.len() as i64,
                [s.windows as i64],
                (Kind::Int64, device),
            );
            let t0: Vec<WindowStart> = Vec::<i64>::try_from(&pick)?
                .iter()
                .map(|&i| starts[i as usize])
                .collect();
            let b = s.windows as i64;
            let shift = Tensor::randn([b, latent], (Kind::Float, device)) * s.noise;
            let apart = Tensor::randn([b, latent], (Kind::Float, device)) * (s.noise / 3.0);
            let (pos, vel) = unroll_loss(&played, &t0, k, Some((&(&shift + apart), &shift)));
            let loss = (&pos + &vel * s.velocity_weight) * 1e6;
            let value = loss.double_value(&[]);
            if !value.is_finite() {
                bail!(
                    "the dynamics fit's loss became {value} at epoch {}",
                    epoch + 1
                );
            }
            loss.backward();
            adam.update(&params, &vec![lr; params.len()]);
            pos_sum += pos.double_value(&[]);
            vel_sum += vel.double_value(&[]);
        }
        let n = s.steps as f64;
        let record = DynamicsEpoch {
            epoch: epoch + 1,
            horizon: k,
            rms_mm: (pos_sum / n).sqrt() * 1e3,
            velocity_mm_s: (vel_sum / n).sqrt() * 1e3 * fps,
        };
        progress(&record);
        history.push(record);
    }
    let fitted_rms_mm = measure(&played, &starts, check.0, check.1);
    Ok(DynamicsFit {
        settings: s.clone(),
        history,
        check_windows: check.0,
        base_rms_mm,
        fitted_rms_mm,
        seconds: clock.elapsed().as_secs_f64(),
    })
}

/// [`fit_dynamics`] on a model file with its motion stage (its rate and latent range from its
/// description), the fit recorded in the description so the file reloads with `D`.
pub fn fit_model_dynamics(
    file: &mut ModelFile,
    data: &FrameData,
    s: &DynamicsSettings,
    progress: &mut dyn FnMut(&DynamicsEpoch),
) -> Result<DynamicsFit> {
    let info = file.info.dynamic()?;
    let fps = info.fps as f64;
    let Some(motion) = &info.motion else {
        bail!("the model has no motion stage to give dynamics to (train --stage dynamic)");
    };
    let device = data.garment.device();
    let t = |v: &[f32]| Tensor::from_slice(v).unsqueeze(0).to_device(device);
    let (lo, hi) = (t(&motion.latent_min), t(&motion.latent_max));
    let limit = StrainLimit::new(
        &file.garment.positions,
        &file.garment.triangles,
        &file.info.garment.pinned,
    );
    let Model::Dynamic(dynamic) = &mut file.model else {
        bail!("this is a PBNS model; the learnt dynamics belong to a dynamic model");
    };
    let fit = fit_dynamics(dynamic, data, fps, (&lo, &hi), &limit, s, progress)?;
    if let KindInfo::Dynamic(d) = &mut file.info.model {
        if let Some(m) = d.motion.as_mut() {
            m.shape.dynamics = s.widths.clone();
            m.shape.dynamics_history = s.drive_history;
            m.dynamics = Some(fit.clone());
        }
    }
    Ok(fit)
}

/// Where a training window starts: its first predicted frame and its clip's first frame (history before the clip
/// is the clip's first frame held still, as `history_indices` and a roll-out from rest have it).
#[derive(Clone, Copy, Debug)]
struct WindowStart {
    first: i64,
    clip: i64,
}

/// Every window of `k` frames that lies inside one clip after its first frame.
fn window_starts(data: &FrameData, k: usize) -> Vec<WindowStart> {
    let mut ends = data.clip_starts[1..].to_vec();
    ends.push(data.len());
    data.clip_starts
        .iter()
        .zip(&ends)
        .flat_map(|(&s, &e)| {
            (s + 1..=e.saturating_sub(k))
                .filter(move |t| t + k <= e)
                .map(move |t| WindowStart {
                    first: t as i64,
                    clip: s as i64,
                })
        })
        .collect()
}

/// Each training frame's clip's first frame.
fn clip_firsts(data: &FrameData) -> Vec<i64> {
    let mut first = vec![0i64; data.len()];
    for (k, &s) in data.clip_starts.iter().enumerate() {
        let end = data.clip_starts.get(k + 1).copied().unwrap_or(data.len());
        first[s..end].fill(s as i64);
    }
    first
}

/// The past drives `D` sees at frames `now` (`motion::past_drives` within their clips).
fn past_at(encoder: &MotionEncoder, drives: &Tensor, now: &[i64], clip_first: &[i64]) -> Tensor {
    let firsts: Vec<i64> = now.iter().map(|&t| clip_first[t as usize]).collect();
    past_drives(drives, now, &firsts, encoder.past_frames())
}

/// The training frames as the linear path sees them from their simulated histories (teacher
/// forcing): each frame's seeds blended once (`posed`) rather than once per encode, its history,
/// body drive and clip.
struct TeacherFrames<'a> {
    dynamic: &'a Dynamic,
    data: &'a FrameData,
    posed: PosedFrames,
    history: [Tensor; 3],
    /// Every frame's body drive against its previous frame (`motion::drives`).
    drives: Tensor,
    clip_first: Vec<i64>,
}

impl<'a> TeacherFrames<'a> {
    fn new(dynamic: &'a Dynamic, data: &'a FrameData, fps: f64) -> TeacherFrames<'a> {
        let encoder = dynamic.motion.as_ref().expect("a motion stage");
        let history = history_indices(data, data.garment.device());
        TeacherFrames {
            dynamic,
            data,
            posed: PosedFrames::new(&dynamic.space, data),
            drives: drives(&data.body, &history[0], &encoder.shape, fps),
            history,
            clip_first: clip_firsts(data),
        }
    }

    /// `(Z_{t−1}, [Z^ball_t, Z^stay_t], u_t, past drives)` at frames `idx`.
    fn inputs(&self, idx: &Tensor) -> (Tensor, Tensor, Tensor, Tensor) {
        tch::no_grad(|| {
            let encoder = self.dynamic.motion.as_ref().expect("a motion stage");
            let back = |k: usize| self.history[k].index_select(0, idx);
            let (b1, b2) = (back(0), back(1));
            let (previous, inertia) = self.dynamic.space.linear_step_latents(
                &self.data.garment.index_select(0, &b1),
                &self.data.garment.index_select(0, &b2),
                &self.posed.at(&b1),
                &self.posed.at(idx),
            );
            let now = Vec::<i64>::try_from(idx).unwrap_or_default();
            let past = past_at(encoder, &self.drives, &now, &self.clip_first);
            (previous, inertia, self.drives.index_select(0, idx), past)
        })
    }
}

/// `D`'s inputs on every frame's simulated history (its normalisation).
fn teacher_inputs(frames: &TeacherFrames) -> Tensor {
    crate::models::predict_chunks(frames.data.len(), |start, n| {
        let (previous, inertia, drive, past) = frames.inputs(&frames.data.range(start, n));
        LearnedDynamics::inputs(&inertia, &previous, &drive, &past)
    })
}

/// One-step predictions from the simulated histories of `frames` against the simulation, for a
/// model whose space and motion residual are linear ([`Dynamic::linear_only`]): the integrator
/// (and `D`, with the past drives a roll-out gives it) on each frame's simulated history,
/// decoded and skinned. `progress(done, total)` after each chunk.
pub fn one_step_linear(
    dynamic: &Dynamic,
    data: &FrameData,
    fps: f64,
    frames: &[i64],
    progress: &mut dyn FnMut(usize, usize),
) -> Deviation {
    let encoder = dynamic.motion.as_ref().expect("a motion stage");
    let device = data.garment.device();
    let teacher = TeacherFrames::new(dynamic, data, fps);
    let idx_all = Tensor::from_slice(frames).to_device(device);
    let pred = crate::models::predict_chunks(frames.len(), |s, n| {
        let idx = idx_all.narrow(0, s as i64, n as i64);
        let (previous, inertia, drive, past) = teacher.inputs(&idx);
        let z = encoder.integrate(&inertia, &previous, &drive, &past);
        progress(s + n, frames.len());
        teacher.posed.at(&idx).skin(&dynamic.space.canonical(&z))
    });
    deviation(&pred, &data.garment.index_select(0, &idx_all))
}

/// Every training frame's per-vertex seed transforms, blended once (the body never changes
/// between epochs).
pub struct PosedFrames(Posed);

impl PosedFrames {
    pub fn new(space: &Space, data: &FrameData) -> PosedFrames {
        let parts: Vec<Posed> = (0..data.len())
            .step_by(crate::models::PREDICT_CHUNK)
            .map(|start| {
                let n = crate::models::PREDICT_CHUNK.min(data.len() - start);
                space.posed(&data.body.transforms.narrow(0, start as i64, n as i64))
            })
            .collect();
        PosedFrames(Posed::cat(&parts))
    }

    fn at(&self, idx: &Tensor) -> Posed {
        self.0.select(idx)
    }
}

/// Mean squared position and step errors (m², per vertex and frame) of windows starting at
/// frames `t0` and playing `k` frames, from starts shifted by `noise` (latent units, `[B, L]`
/// pairs for frames t0−1 and t0−2).
fn unroll_loss(
    model: &Played,
    t0: &[WindowStart],
    k: usize,
    noise: Option<(&Tensor, &Tensor)>,
) -> (Tensor, Tensor) {
    let Played {
        dynamic,
        data,
        posed,
        drives,
        range: (lo, hi),
        limit,
    } = model;
    let space = &dynamic.space;
    let encoder = dynamic.motion.as_ref().expect("a motion stage");
    let device = data.garment.device();
    let at =
        |offset: i64| -> Vec<i64> { t0.iter().map(|w| (w.first + offset).max(w.clip)).collect() };
    let frames = |offset: i64| Tensor::from_slice(&at(offset)).to_device(device);
    let firsts: Vec<i64> = t0.iter().map(|w| w.clip).collect();
    // The start: the simulated frames t0−1 and t0−2 projected into the space, shifted.
    let start = |offset: i64, eps: Option<&Tensor>| {
        tch::no_grad(|| {
            let idx = frames(offset);
            let at = posed.at(&idx);
            let mut z = space.linear_latent_posed(&data.garment.index_select(0, &idx), &at);
            if let Some(e) = eps {
                z += e;
            }
            at.skin(&space.canonical(&z))
        })
    };
    let mut g1 = start(-1, noise.map(|n| n.0));
    let mut g2 = start(-2, noise.map(|n| n.1));
    let mut pos = Tensor::zeros([], (Kind::Float, device));
    let mut vel = Tensor::zeros([], (Kind::Float, device));
    let mut before_idx = frames(-1);
    let mut before = posed.at(&before_idx);
    for step in 0..k as i64 {
        let now_idx = frames(step);
        let now = posed.at(&now_idx);
        let (previous, inertia) = space.linear_step_latents(&g1, &g2, &before, &now);
        // The drive of frame t against t − 1 (the clip's first frame against itself).
        let drive = drives.index_select(0, &now_idx);
        let past = past_drives(drives, &at(step), &firsts, encoder.past_frames());
        let z = encoder
            .integrate(&inertia, &previous, &drive, &past)
            .clamp_tensor(Some(*lo), Some(*hi));
        let g = now.skin(&space.canonical(&z));
        let g = match limit {
            Some(l) => strain_limited(&g, l),
            None => g,
        };
        let truth = data.garment.index_select(0, &now_idx);
        let truth_before = data.garment.index_select(0, &before_idx);
        pos += (&g - &truth)
            .square()
            .sum_dim_intlist(2, false, Kind::Float)
            .mean(Kind::Float);
        vel += ((&g - &g1) - (&truth - truth_before))
            .square()
            .sum_dim_intlist(2, false, Kind::Float)
            .mean(Kind::Float);
        g2 = g1;
        g1 = g;
        before_idx = now_idx;
        before = now;
    }
    (pos / k as f64, vel / k as f64)
}

/// What a window is played with.
struct Played<'a> {
    dynamic: &'a Dynamic,
    data: &'a FrameData,
    posed: &'a PosedFrames,
    /// Every training frame's body drive against its previous frame (`motion::drives`).
    drives: &'a Tensor,
    range: (&'a Tensor, &'a Tensor),
    /// The roll-out's strain limit, its band and sweeps.
    limit: Option<(&'a StrainLimit, f32, usize)>,
}

/// Garments `g [B, V, 3]` strain-limited as `rollout` feeds them forward; gradients pass
/// straight through (the limit is a projection on plain arrays, outside the graph).
fn strain_limited(g: &Tensor, (limit, band, iterations): &(&StrainLimit, f32, usize)) -> Tensor {
    let moved = tch::no_grad(|| {
        let size = g.size();
        let flat: Vec<f32> =
            Vec::<f32>::try_from(g.detach().to_device(tch::Device::Cpu).reshape([-1]))
                .unwrap_or_default();
        let per = (size[1] * 3) as usize;
        let mut out: Vec<f32> = Vec::with_capacity(flat.len());
        for garment in flat.chunks_exact(per) {
            let mut points: Vec<[f32; 3]> = garment
                .chunks_exact(3)
                .map(|c| [c[0], c[1], c[2]])
                .collect();
            limit.project(&mut points, *band, *iterations);
            out.extend(points.iter().flatten());
        }
        Tensor::from_slice(&out)
            .reshape(size.as_slice())
            .to_device(g.device())
            - g.detach()
    });
    g + moved
}

/// RMS vertex distance (mm) of roll-outs over fixed windows: `windows` evenly spaced starts,
/// `k` frames each, no noise (before and after the fit, on the same windows).
fn measure(model: &Played, starts: &[WindowStart], windows: usize, k: usize) -> f64 {
    let step = (starts.len() / windows.max(1)).max(1);
    let t0: Vec<WindowStart> = starts.iter().step_by(step).take(windows).copied().collect();
    let mut sum = 0.0;
    for chunk in t0.chunks(8) {
        let (pos, _) = tch::no_grad(|| unroll_loss(model, chunk, k, None));
        sum += pos.double_value(&[]) * chunk.len() as f64;
    }
    (sum / t0.len() as f64).sqrt() * 1e3
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn horizons_grow_from_first_to_last() {
        let h: Vec<usize> = (0..5).map(|e| horizon_at(e, 5, (8, 32))).collect();
        assert_eq!(h, vec![8, 14, 20, 26, 32]);
        assert_eq!(horizon_at(0, 1, (8, 32)), 32);
    }
}
