//! What `rollout` reports: the roll-out's metrics (whole and per 100 frames), its errors against
//! reference simulations and restarts, what it wrote; and the report as text.

use crate::bake::sequence::SequenceReport;
use crate::metrics::reference_error::{Ensemble, ReferenceError};
use crate::rollout::timing::Timing;
use crate::simulate::stats::{FrameStats, Summary};
use crate::validate::Validation;
use serde::{Deserialize, Serialize};
use std::fmt::{self, Display, Formatter};
use std::path::PathBuf;

/// Several simulations of the clip (two or more --reference).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct References {
    pub paths: Vec<PathBuf>,
    /// Every pair of simulations against each other, averaged: the simulator's own spread.
    pub spread: ReferenceError,
    /// Each simulation against the mean garment of the others, averaged: how well re-running
    /// the simulator predicts a run it did not start from.
    pub from_the_others: ReferenceError,
    /// The roll-out, and plain LBS, against each simulation and against their mean.
    pub rollout: Ensemble,
    pub lbs: Ensemble,
}

/// Roll-outs restarted from the reference every `frames` frames, `frames` long.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Restarts {
    pub frames: usize,
    /// Each restart's first frame (of the clip) and its error against the reference.
    pub each: Vec<(usize, ReferenceError)>,
    /// Means over the restarts: after one step, and over each restart's frames.
    pub one_step_mm: f64,
    pub mean_mm: f64,
    /// The mean error `k` frames after a restart, k = 1 … `frames`: how fast the model leaves
    /// the simulated state.
    pub by_step_mm: Vec<f64>,
}

impl Restarts {
    /// From each restart's first frame, its error and its error per frame (frame 0 first).
    pub(super) fn of(frames: usize, each: Vec<(usize, ReferenceError, Vec<f64>)>) -> Restarts {
        let n = each.len().max(1) as f64;
        let by_step_mm = (1..=frames)
            .map(|k| each.iter().map(|e| e.2[k]).sum::<f64>() / n)
            .collect();
        Restarts {
            frames,
            one_step_mm: each.iter().map(|e| e.1.one_step_mm).sum::<f64>() / n,
            mean_mm: each.iter().map(|e| e.1.clip_mm).sum::<f64>() / n,
            by_step_mm,
            each: each.into_iter().map(|(start, v, _)| (start, v)).collect(),
        }
    }
}

/// Frames per row of the stability table ([`SpanMetrics`]).
pub const SPAN_FRAMES: usize = 100;

/// Metrics over one span of `SPAN_FRAMES` frames: a row of the stability table (the report's
/// `windows`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SpanMetrics {
    pub first_frame: usize,
    pub last_frame: usize,
    /// Mean share of garment vertices inside the body (winding number), %.
    pub inside_pct: f64,
    pub mean_strain_pct: f64,
    pub max_strain_pct: f64,
    /// Fastest vertex (m/s).
    pub max_speed: f64,
}

impl SpanMetrics {
    pub fn of(frames: &[FrameStats]) -> SpanMetrics {
        let n = frames.len().max(1) as f64;
        let max = |f: fn(&FrameStats) -> f64| frames.iter().map(f).fold(0.0, f64::max);
        SpanMetrics {
            first_frame: frames.first().map_or(0, |f| f.frame),
            last_frame: frames.last().map_or(0, |f| f.frame),
            inside_pct: frames.iter().map(|f| f.inside_pct).sum::<f64>() / n,
            mean_strain_pct: frames.iter().map(|f| f.strain_pct).sum::<f64>() / n,
            max_strain_pct: max(|f| f.strain_pct),
            max_speed: max(|f| f.max_speed),
        }
    }
}

#[derive(Serialize, Deserialize)]
pub struct Report {
    pub motions: Vec<PathBuf>,
    pub fps: f32,
    pub frames: usize,
    pub collision_fix: bool,
    /// The collision loss `Σ ReLU(margin − o)` (mm, summed over vertices), mean per frame, of the
    /// network's garment and of the garment written (after the fix).
    pub collision_loss_before_mm: f64,
    pub collision_loss_after_mm: f64,
    pub timing: Timing,
    /// Our metrics on the written frames (inside the body by winding number, strain, speed).
    pub summary: Summary,
    /// The same per 100 frames: whether a long roll-out drifts or blows up.
    #[serde(rename = "windows")]
    pub spans: Vec<SpanMetrics>,
    /// Against the (first) reference.
    pub reference: Option<ReferenceError>,
    /// With several references: against each, and their own spread.
    pub references: Option<References>,
    /// With --restart-every: the model restarted from the reference along the clip.
    pub restarts: Option<Restarts>,
    /// Plain LBS of the rest garment against the same reference.
    pub lbs_reference: Option<ReferenceError>,
    pub lbs_out: Option<PathBuf>,
    pub out: PathBuf,
    pub out_bytes: u64,
    /// For a glTF output: blend shapes kept and the replay error.
    pub baked: Option<SequenceReport>,
    pub body_out: Option<PathBuf>,
    /// With --view: the page and its size in bytes.
    pub view: Option<(PathBuf, u64)>,
    /// With --validate: the written file against the roll-out.
    pub validation: Option<Validation>,
}

impl Report {
    /// Whether a `--validate` check ran and failed.
    pub fn failed(&self) -> bool {
        self.validation.as_ref().is_some_and(|v| !v.passed)
    }
}

/// The report for a person, one line per figure (the `validate` lines printed after it, by
/// `Validation::print`).
impl Display for Report {
    fn fmt(&self, f: &mut Formatter) -> fmt::Result {
        let (r, t) = (self, &self.timing);
        writeln!(
            f,
            "rolled out {} frames at {} fps ({} clip(s)); collision fix {}",
            r.frames,
            r.fps,
            r.motions.len(),
            if r.collision_fix { "on" } else { "off" }
        )?;
        writeln!(
            f,
            "ms per frame: input maps {:.1}, encoder {:.1}, decode + skinning {:.1} (network {:.1}); strain limit {:.1}; collision {:.1} (fix ran on {} frames, {:.2} ms per iteration)",
            t.inputs_ms, t.encoder_ms, t.decode_ms, t.network_ms, t.strain_ms, t.collision_ms, t.fixed_frames, t.ms_per_collision_iteration
        )?;
        writeln!(
            f,
            "collision loss Σ ReLU(margin − o) per frame: {:.2} mm before the fix, {:.2} mm written",
            r.collision_loss_before_mm, r.collision_loss_after_mm
        )?;
        let s = &r.summary;
        writeln!(
            f,
            "inside the body (winding number): {:.3} % of vertices on average, worst frame {} ({} vertices); edge strain mean {:.2} %, worst {:.2} %; fastest vertex {:.2} m/s",
            s.inside.inside_pct, s.inside.worst_frame, s.inside.worst_frame_vertices, s.mean_strain_pct, s.max_strain_pct, s.max_speed
        )?;
        if r.spans.len() > 1 {
            writeln!(
                f,
                "frames      inside %  strain % (mean, worst)  fastest m/s"
            )?;
            for w in &r.spans {
                writeln!(
                    f,
                    "{:>4}-{:<4}  {:>8.3}  {:>7.2} {:>7.2}         {:>6.2}",
                    w.first_frame,
                    w.last_frame,
                    w.inside_pct,
                    w.mean_strain_pct,
                    w.max_strain_pct,
                    w.max_speed
                )?;
            }
        }
        if let Some(v) = &r.reference {
            writeln!(
                f,
                "vs reference (vertex L2): after 1 step {:.2} mm, first 50 frames {:.2} mm, whole clip {:.2} mm, max {:.1} mm (frame {})",
                v.one_step_mm, v.first_50_mm, v.clip_mm, v.max_mm, v.worst_frame
            )?;
        }
        if let Some(s) = &r.restarts {
            writeln!(
                f,
                "restarted from the reference every {} frames ({} restarts, {} frames each): after 1 step {:.2} mm, over the restarts {:.2} mm",
                s.frames,
                s.each.len(),
                s.frames,
                s.one_step_mm,
                s.mean_mm
            )?;
            let steps: Vec<String> = [1, 2, 5, 10, 25, 50, 100]
                .iter()
                .filter_map(|&k| Some(format!("{k}: {:.1}", s.by_step_mm.get(k - 1)?)))
                .collect();
            writeln!(
                f,
                "  mean error k frames after a restart (mm): {}",
                steps.join(", ")
            )?;
        }
        if let Some(v) = &r.lbs_reference {
            writeln!(
                f,
                "plain LBS vs reference: after 1 step {:.2} mm, first 50 frames {:.2} mm, whole clip {:.2} mm, max {:.1} mm (frame {})",
                v.one_step_mm, v.first_50_mm, v.clip_mm, v.max_mm, v.worst_frame
            )?;
        }
        if let Some(all) = &r.references {
            write!(f, "{all}")?;
        }
        if let Some(b) = &r.baked {
            if let Some(k) = b.max_targets {
                writeln!(
                    f,
                    "--max-targets {k} costs {:.3} mm: the glTF replays the roll-out within {:.3} mm at every frame (mean {:.4} mm)",
                    b.error.max_mm, b.error.max_mm, b.error.mean_mm
                )?;
            }
            writeln!(
                f,
                "glTF: {} blend shapes (residual rank {}), {}, weights 0 to {:.3}, within {:.3} mm of the roll-out (mean {:.4} mm)",
                b.targets,
                b.rank,
                if b.quantized {
                    "16-bit (KHR_mesh_quantization; --float-targets for 32-bit)"
                } else {
                    "32-bit floats"
                },
                b.max_weight,
                b.error.max_mm,
                b.error.mean_mm
            )?;
        }
        writeln!(
            f,
            "wrote {} ({} bytes, {:.0} per frame)",
            r.out.display(),
            r.out_bytes,
            r.out_bytes as f64 / r.frames.max(1) as f64
        )?;
        for b in r.body_out.iter().chain(&r.lbs_out) {
            writeln!(f, "wrote {}", b.display())?;
        }
        if let Some((page, bytes)) = &r.view {
            writeln!(
                f,
                "wrote {} ({:.1} MB)",
                page.display(),
                *bytes as f64 / 1e6
            )?;
        }
        Ok(())
    }
}

/// Several simulations: the roll-out and LBS against each, against their mean, and the
/// simulations against each other, each as "after 1 step / first 50 frames / whole clip".
impl Display for References {
    fn fmt(&self, f: &mut Formatter) -> fmt::Result {
        let all = self;
        let spans = |v: &ReferenceError| {
            format!(
                "{:.2} / {:.2} / {:.2} mm",
                v.one_step_mm, v.first_50_mm, v.clip_mm
            )
        };
        writeln!(
            f,
            "against {} simulations (vertex L2, after 1 step / first 50 frames / whole clip):",
            all.paths.len()
        )?;
        for ((path, m), l) in all.paths.iter().zip(&all.rollout.each).zip(&all.lbs.each) {
            writeln!(
                f,
                "  {}: roll-out {}, plain LBS {}",
                path.display(),
                spans(m),
                spans(l)
            )?;
        }
        writeln!(
            f,
            "  roll-out, mean over the simulations: {} (their mean garment: {})",
            spans(&all.rollout.mean_of_each),
            spans(&all.rollout.against_mean)
        )?;
        writeln!(
            f,
            "  plain LBS, mean over the simulations: {} (their mean garment: {})",
            spans(&all.lbs.mean_of_each),
            spans(&all.lbs.against_mean)
        )?;
        writeln!(
            f,
            "  the simulations from each other (mean over pairs): {} — the simulator defines the garment only to this",
            spans(&all.spread)
        )?;
        writeln!(
            f,
            "  each simulation from the mean garment of the others: {} — re-simulating predicts a run this well",
            spans(&all.from_the_others)
        )
    }
}
