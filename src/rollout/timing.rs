//! Where a roll-out's time goes: the mean milliseconds per frame of each phase (inputs, encoder,
//! decode, strain limit, collision fix), as `rollout` reports them and `bench rollout` compares
//! them with Blender's.

use super::FrameTiming;
use serde::{Deserialize, Serialize};

/// Mean milliseconds per frame of each phase.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize)]
pub struct Timing {
    pub inputs_ms: f64,
    pub encoder_ms: f64,
    pub decode_ms: f64,
    /// The strain limit after the decode (absent from reports written before it).
    #[serde(default)]
    pub strain_ms: f64,
    pub collision_ms: f64,
    /// Without the strain limit and the collision phase.
    pub network_ms: f64,
    /// Frames on which the collision fix ran, and its mean time per iteration.
    pub fixed_frames: usize,
    pub ms_per_collision_iteration: f64,
}

impl Timing {
    /// The means over a roll-out's frames (`Rollout::timings`).
    pub fn of(frames: &[FrameTiming]) -> Timing {
        // Frame 0 is the start, not a prediction.
        let predicted = &frames[1.min(frames.len())..];
        let n = predicted.len().max(1) as f64;
        let mean = |f: fn(&FrameTiming) -> f64| predicted.iter().map(f).sum::<f64>() / n;
        let fixed: Vec<&FrameTiming> = predicted
            .iter()
            .filter(|t| t.collision_iterations > 0)
            .collect();
        let iterations: usize = fixed.iter().map(|t| t.collision_iterations).sum();
        Timing {
            inputs_ms: mean(|t| t.inputs_ms),
            encoder_ms: mean(|t| t.encoder_ms),
            decode_ms: mean(|t| t.decode_ms),
            strain_ms: mean(|t| t.strain_ms),
            collision_ms: mean(|t| t.collision_ms),
            network_ms: mean(|t| t.inputs_ms + t.encoder_ms + t.decode_ms),
            fixed_frames: fixed.len(),
            // `+ 0.0`: an empty f64 sum is −0.0.
            ms_per_collision_iteration: fixed.iter().map(|t| t.collision_ms).sum::<f64>()
                / iterations.max(1) as f64
                + 0.0,
        }
    }
}
