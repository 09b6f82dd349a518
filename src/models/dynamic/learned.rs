//! The learnt latent dynamics (issue 37, not in the paper): a small MLP beside the linear
//! integrator, `Z_t = W [Z^ball_t, Z^stay_t, Z_{t−1}, 1, u_t] + D(x_t)` with
//! `x_t = [Z^ball_t − Z_{t−1}, Z^stay_t − Z_{t−1}, Z_{t−1}, u_t]` (inertia and the body's pull as
//! changes of the latent, the latent itself, the body drive). `W` stays the base the roll-out
//! falls back to: `D`'s last layer starts at zero, so an untrained `D` is exactly the linear
//! model, and `train::unroll` fits `D` through the model's own roll-outs (what the linear fit
//! on simulated histories cannot see: how its own state carries a swing on).
//!
//! Why an MLP on the latent rather than the paper's convolutional `ΔE`: the latent integrator
//! already sees inertia and the body through `Z^ball`, `Z^stay` and `u_t`; what it lacks is a
//! response that is not linear in them (a hem that swings further the faster the hips turn, a
//! skirt that settles differently after a hop than after a walk). An MLP on ~300 numbers costs
//! microseconds per frame and trains through 32-frame roll-outs on a CPU in minutes.

use serde::{Deserialize, Serialize};
use tch::nn::{self, Module};
use tch::{Kind, Tensor};

/// `D`: normalised inputs, hidden layers with SiLU, a linear output that starts at zero.
pub struct LearnedDynamics {
    /// Per input column, the training inputs' mean and standard deviation (set before
    /// training, stored with the model, never trained).
    shift: Tensor,
    scale: Tensor,
    hidden: Vec<nn::Linear>,
    output: nn::Linear,
}

/// Name of `D`'s variables under the motion encoder (`motion.dynamics.*` in the model file).
pub const PATH: &str = "dynamics";

impl LearnedDynamics {
    /// `D` for inputs of `width` columns and latents of `latent`, hidden `widths`.
    pub fn new(path: &nn::Path, width: i64, widths: &[usize], latent: i64) -> LearnedDynamics {
        let shift = path.zeros_no_train("shift", &[width]);
        let scale = path.ones_no_train("scale", &[width]);
        let mut hidden = Vec::new();
        let mut fan_in = width;
        for (k, &w) in widths.iter().enumerate() {
            hidden.push(nn::linear(
                path / format!("h{k}"),
                fan_in,
                w as i64,
                Default::default(),
            ));
            fan_in = w as i64;
        }
        let zero = nn::LinearConfig {
            ws_init: nn::Init::Const(0.0),
            bs_init: Some(nn::Init::Const(0.0)),
            bias: true,
        };
        let output = nn::linear(path / "out", fan_in, latent, zero);
        LearnedDynamics {
            shift,
            scale,
            hidden,
            output,
        }
    }

    /// `x_t` `[B, 3L + D + H·D]` from the linear path's inputs and the `H` past drives.
    pub fn inputs(inertia: &Tensor, previous: &Tensor, drive: &Tensor, past: &Tensor) -> Tensor {
        let l = previous.size()[1];
        Tensor::cat(
            &[
                inertia.narrow(1, 0, l) - previous,
                inertia.narrow(1, l, l) - previous,
                previous.shallow_clone(),
                drive.shallow_clone(),
                past.shallow_clone(),
            ],
            1,
        )
    }

    /// `D(x)` `[B, L]`: the change `D` makes to the linear path's latent.
    pub fn forward(&self, x: &Tensor) -> Tensor {
        let mut h = (x - &self.shift) / &self.scale;
        for layer in &self.hidden {
            h = layer.forward(&h).silu();
        }
        self.output.forward(&h)
    }

    /// Sets the input normalisation to the mean and spread of training inputs `x [F, 3L + D]`
    /// (a column that never varies keeps scale 1).
    pub fn normalise_to(&self, x: &Tensor) {
        tch::no_grad(|| {
            let mean = x.mean_dim(0, false, Kind::Float);
            let std = x.std_dim(0, false, false);
            let std = std.where_self(&std.gt(1e-6), &std.ones_like());
            let mut shift = self.shift.shallow_clone();
            let mut scale = self.scale.shallow_clone();
            shift.copy_(&mean);
            scale.copy_(&std);
        });
    }

    /// The trained tensors (the normalisation is not among them).
    pub fn trainable(&self) -> Vec<Tensor> {
        let mut t = Vec::new();
        for l in self.hidden.iter().chain([&self.output]) {
            t.push(l.ws.shallow_clone());
            if let Some(b) = &l.bs {
                t.push(b.shallow_clone());
            }
        }
        t
    }
}

/// How `D` is fitted (`train-dynamic --dynamics-epochs ...`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DynamicsSettings {
    /// Hidden layer widths of `D`.
    pub widths: Vec<usize>,
    pub epochs: usize,
    /// Optimiser steps per epoch.
    pub steps: usize,
    /// Windows per step.
    pub windows: usize,
    /// Window length (frames) at the first and at the last epoch.
    pub horizon: (usize, usize),
    pub learning_rate: f64,
    /// Spread of the noise on a window's starting latent, in units of the training latents'
    /// spread (the latent of a velocity gets a third of it).
    pub noise: f64,
    /// Weight of the velocity term beside the position term.
    pub velocity_weight: f64,
    pub seed: u64,
    /// The roll-out's strain limit, applied to each decoded frame before it is fed forward as
    /// `rollout` does (band, Gauss–Seidel sweeps; 0 sweeps: none): the fit then sees the states
    /// the model meets at play time.
    #[serde(default)]
    pub strain_band: f32,
    #[serde(default)]
    pub strain_iterations: usize,
    /// Past body drives `D` sees (frames; `MotionShape::dynamics_history`).
    #[serde(default)]
    pub drive_history: usize,
}

impl Default for DynamicsSettings {
    fn default() -> DynamicsSettings {
        DynamicsSettings {
            widths: vec![128, 128],
            epochs: 40,
            steps: 10,
            windows: 8,
            horizon: (8, 32),
            learning_rate: 1e-3,
            noise: 0.05,
            velocity_weight: 1.0,
            seed: 0,
            strain_band: 0.0,
            strain_iterations: 0,
            drive_history: 0,
        }
    }
}

/// One epoch of the fit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DynamicsEpoch {
    pub epoch: usize,
    /// Window length (frames).
    pub horizon: usize,
    /// RMS vertex distance to the simulation over the epoch's windows (mm).
    pub rms_mm: f64,
    /// RMS of the per-frame step's difference, as a speed (mm/s).
    pub velocity_mm_s: f64,
}

/// What the fit did, stored with the model (`inspect` shows it).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DynamicsFit {
    pub settings: DynamicsSettings,
    pub history: Vec<DynamicsEpoch>,
    /// RMS vertex distance (mm) of roll-outs of the last window length from this many fixed,
    /// evenly spaced training windows, with the linear integrator alone and with `D`.
    pub check_windows: usize,
    pub base_rms_mm: f64,
    pub fitted_rms_mm: f64,
    pub seconds: f64,
}

#[cfg(test)]
mod tests {
    use super::*;
    use tch::Device;

    #[test]
    fn untrained_dynamics_add_nothing_and_normalise_their_inputs() {
        let vs = nn::VarStore::new(Device::Cpu);
        let d = LearnedDynamics::new(&(vs.root() / PATH), 5, &[8, 8], 3);
        let x = Tensor::randn([20, 5], (Kind::Float, Device::Cpu)) * 3.0 + 2.0;
        assert_eq!(d.forward(&x).abs().max().double_value(&[]), 0.0);
        d.normalise_to(&x);
        let n = (&x - &d.shift) / &d.scale;
        let mean = n
            .mean_dim(0, false, Kind::Float)
            .abs()
            .max()
            .double_value(&[]);
        let std = n.std_dim(0, false, false);
        assert!(mean < 1e-5, "normalised mean {mean}");
        assert!((std - 1.0).abs().max().double_value(&[]) < 1e-4);
        // A weight and a bias per layer: two hidden, one output.
        assert_eq!(d.trainable().len(), 6);
        // A non-zero output layer changes the latent.
        let _ = tch::no_grad(|| d.output.bs.as_ref().unwrap().shallow_clone().fill_(0.5));
        assert_eq!(d.forward(&x).mean(Kind::Float).double_value(&[]), 0.5);
    }
}
