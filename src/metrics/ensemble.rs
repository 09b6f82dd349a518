//! A played garment against an ensemble of simulations of one clip (runs that differ only by a
//! perturbed lead-in), in mean squares, so that the simulator's own chaos and a model's own
//! error separate.
//!
//! With the runs as independent draws around an expected garment μ (spread σ: E|X − μ|² = σ²),
//! a cache M has E|M − X|² = |M − μ|² + σ². So σ² is half the mean squared distance between two
//! runs (E|X − Y|² = 2σ²), and a cache's own error is `b = √(mean_i MSE(M, X_i) − σ²)`: a
//! re-run of the simulator scores b ≈ σ, the blurred mean garment μ scores 0 (it is not a garment
//! any run shows; the hem's amplitude in `hem` tells it apart). Mean *distances* (reference_error.rs)
//! do not add this way, and a run against the mean of two others is not comparable with a model
//! against one run (E|X − mean₂|² = 1.5σ²): every figure here is of one cache against one run.

use crate::geometry::Frames;
use serde::Serialize;
use std::ops::Range;

/// A figure over the first 50 predicted frames and over the whole clip (frame 0, the start, left
/// out as in reference_error.rs).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Spans {
    pub first_50: f64,
    pub clip: f64,
}

impl Spans {
    /// From per-frame values (frame 0 the start): their mean over each span, then `f` of it.
    fn of(per_frame: &[f64], f: impl Fn(f64) -> f64) -> Spans {
        let n = per_frame.len();
        Spans {
            first_50: f(mean_over(per_frame, 1.min(n)..51.min(n))),
            clip: f(mean_over(per_frame, 1.min(n)..n)),
        }
    }

    fn map(self, f: impl Fn(f64) -> f64) -> Spans {
        Spans {
            first_50: f(self.first_50),
            clip: f(self.clip),
        }
    }
}

/// Mean squared vertex distance (m²) between two frames of one garment.
pub fn frame_ms(a: &[[f32; 3]], b: &[[f32; 3]]) -> f64 {
    let sum: f64 = a
        .iter()
        .zip(b)
        .map(|(p, q)| (0..3).map(|k| f64::from(p[k] - q[k]).powi(2)).sum::<f64>())
        .sum();
    sum / a.len().max(1) as f64
}

/// [`frame_ms`] of every frame (the shorter's length).
pub fn per_frame_ms(a: &[Vec<[f32; 3]>], b: &[Vec<[f32; 3]>]) -> Vec<f64> {
    a.iter().zip(b).map(|(x, y)| frame_ms(x, y)).collect()
}

fn mean_over(v: &[f64], span: Range<usize>) -> f64 {
    let s = &v[span.start.min(v.len())..span.end.min(v.len())];
    s.iter().sum::<f64>() / s.len().max(1) as f64
}

/// √(m²) in millimetres.
fn mm(ms: f64) -> f64 {
    1e3 * ms.max(0.0).sqrt()
}

/// The pairs (i, j), i < j, of `n` runs.
fn pairs(n: usize) -> impl Iterator<Item = (usize, usize)> {
    (0..n).flat_map(move |i| (i + 1..n).map(move |j| (i, j)))
}

/// Two or more simulations of one clip, with their per-frame spread and mean garment.
pub struct Ensemble<'a> {
    runs: &'a [Frames],
    /// σ²(t): half the mean pairwise squared distance of frame t (m²).
    spread: Vec<f64>,
    mean: Vec<Vec<[f32; 3]>>,
}

/// How far apart the simulations are.
#[derive(Clone, Debug, Serialize)]
pub struct Spread {
    pub runs: usize,
    /// σ (mm): each run's RMS distance from the expected garment, √(½ mean pairwise MSE).
    pub sigma_mm: Spans,
    /// Two runs' RMS distance (√2 σ): what a re-run of the simulator scores against a run.
    pub pairwise_rms_mm: Spans,
    /// Each run against the mean garment of the others (√(1 + 1/(n−1)) σ: not comparable with a
    /// model against one run; kept to show why the old floor was too low).
    pub from_the_others_rms_mm: Spans,
}

/// A cache against the simulations.
#[derive(Clone, Debug, Serialize)]
pub struct Score {
    /// RMS against each run, in the order given.
    pub each_rms_mm: Vec<Spans>,
    /// √(mean_i MSE(cache, run_i)).
    pub rms_mm: Spans,
    /// `b = √(max(0, mean_i MSE − σ²))`: the cache's own error, its RMS distance from the
    /// expected garment. A run of the simulator scores about σ here.
    pub own_mm: Spans,
    /// RMS against the runs' mean garment (key `versus_mean_rms_mm` in reports).
    #[serde(rename = "versus_mean_rms_mm")]
    pub against_mean_rms_mm: Spans,
    /// b estimated from the mean garment instead, `√(MSE(cache, mean) − σ²/n)`: the same in
    /// expectation; the two differing says the runs are too few to trust b.
    pub own_from_mean_mm: Spans,
}

impl<'a> Ensemble<'a> {
    /// `None` with fewer than two runs (one run has no spread). Runs are cut to the shortest.
    pub fn new(runs: &'a [Frames]) -> Option<Ensemble<'a>> {
        if runs.len() < 2 {
            return None;
        }
        let frames = runs.iter().map(|r| r.len()).min().unwrap_or(0);
        let n_pairs = (runs.len() * (runs.len() - 1) / 2) as f64;
        let spread = (0..frames)
            .map(|t| {
                pairs(runs.len())
                    .map(|(i, j)| frame_ms(&runs[i][t], &runs[j][t]))
                    .sum::<f64>()
                    / n_pairs
                    / 2.0
            })
            .collect();
        Some(Ensemble {
            runs,
            spread,
            mean: mean_garment(&runs.iter().collect::<Vec<_>>(), frames),
        })
    }

    pub fn runs(&self) -> &[Frames] {
        self.runs
    }

    pub fn frames(&self) -> usize {
        self.spread.len()
    }

    /// The runs' vertex-wise mean garment.
    pub fn mean(&self) -> &[Vec<[f32; 3]>] {
        &self.mean
    }

    /// σ²(t) of every frame (m²).
    pub fn sigma2(&self) -> &[f64] {
        &self.spread
    }

    pub fn spread(&self) -> Spread {
        let n = self.runs.len();
        let others: Vec<f64> = (0..self.frames())
            .map(|t| {
                (0..n)
                    .map(|i| {
                        let rest: Vec<_> =
                            (0..n).filter(|&j| j != i).map(|j| &self.runs[j]).collect();
                        frame_ms(&self.runs[i][t], &mean_frame(&rest, t))
                    })
                    .sum::<f64>()
                    / n as f64
            })
            .collect();
        Spread {
            runs: n,
            sigma_mm: Spans::of(&self.spread, mm),
            pairwise_rms_mm: Spans::of(&self.spread, |s| mm(2.0 * s)),
            from_the_others_rms_mm: Spans::of(&others, mm),
        }
    }

    /// `frames` (a cache of the clip, frame 0 its start) against every run.
    pub fn score(&self, frames: &[Vec<[f32; 3]>]) -> Score {
        let t = self.frames().min(frames.len());
        let frames = &frames[..t];
        let each: Vec<Vec<f64>> = self.runs.iter().map(|r| per_frame_ms(frames, r)).collect();
        let n = self.runs.len() as f64;
        let mean_ms: Vec<f64> = (0..t)
            .map(|f| each.iter().map(|e| e[f]).sum::<f64>() / n)
            .collect();
        let sigma2 = Spans::of(&self.spread[..t], |s| s);
        let mean_of = Spans::of(&mean_ms, |s| s);
        let to_mean = Spans::of(&per_frame_ms(frames, &self.mean), |s| s);
        let own = |total: Spans, share: f64| Spans {
            first_50: mm(total.first_50 - share * sigma2.first_50),
            clip: mm(total.clip - share * sigma2.clip),
        };
        Score {
            each_rms_mm: each.iter().map(|e| Spans::of(e, mm)).collect(),
            rms_mm: mean_of.map(mm),
            own_mm: own(mean_of, 1.0),
            against_mean_rms_mm: to_mean.map(mm),
            own_from_mean_mm: own(to_mean, 1.0 / n),
        }
    }

    /// The restart frames of a horizon study: 0, `every`, 2·`every`, … while `horizon` frames
    /// still follow.
    pub fn starts(&self, horizon: usize, every: usize) -> Vec<usize> {
        (0..self.frames().saturating_sub(horizon))
            .step_by(every.max(1))
            .collect()
    }

    /// Error against horizon, e(k) for k = 1 … `horizon` (mm RMS): `segment(i, t0)` is what the
    /// cache plays from frame t0 (its frame 0) when started from run i there; it is measured
    /// against run i at t0 + k, the mean square pooled over runs and starts. A cache that cannot
    /// be restarted gives its own frames t0.. for every i (its curve is its error at those frames).
    pub fn horizon<E>(
        &self,
        starts: &[usize],
        horizon: usize,
        mut segment: impl FnMut(usize, usize) -> Result<Vec<Vec<[f32; 3]>>, E>,
    ) -> Result<Vec<f64>, E> {
        let mut sum = vec![0.0; horizon + 1];
        let mut count = vec![0usize; horizon + 1];
        for (i, run) in self.runs.iter().enumerate() {
            for &t0 in starts {
                let played = segment(i, t0)?;
                for (k, frame) in played.iter().enumerate().take(horizon + 1).skip(1) {
                    if let Some(truth) = run.get(t0 + k) {
                        sum[k] += frame_ms(frame, truth);
                        count[k] += 1;
                    }
                }
            }
        }
        Ok((1..=horizon)
            .map(|k| mm(sum[k] / count[k].max(1) as f64))
            .collect())
    }

    /// The simulations' own curves beside e(k), k = 1 … `horizon` (mm RMS).
    pub fn divergence(&self, starts: &[usize], horizon: usize) -> Divergence {
        let n_pairs = (self.runs.len() * (self.runs.len() - 1) / 2) as f64;
        let pairwise = |t: usize| {
            pairs(self.runs.len())
                .map(|(i, j)| frame_ms(&self.runs[i][t], &self.runs[j][t]))
                .sum::<f64>()
                / n_pairs
        };
        let at = |k: usize, f: &dyn Fn(usize) -> f64| {
            let ts: Vec<usize> = starts
                .iter()
                .map(|t0| t0 + k)
                .filter(|&t| t < self.frames())
                .collect();
            mm(ts.iter().map(|&t| f(t)).sum::<f64>() / ts.len().max(1) as f64)
        };
        let ks = 1..=horizon;
        Divergence {
            from_the_start_mm: ks
                .clone()
                .map(|k| {
                    if k < self.frames() {
                        mm(pairwise(k))
                    } else {
                        f64::NAN
                    }
                })
                .collect(),
            start_mm: mm(pairwise(0)),
            pairwise_mm: ks.clone().map(|k| at(k, &pairwise)).collect(),
            sigma_mm: ks.map(|k| at(k, &|t| self.spread[t])).collect(),
        }
    }
}

/// How the simulations themselves part, at the horizons of e(k).
#[derive(Clone, Debug, Serialize)]
pub struct Divergence {
    /// Two runs' RMS distance k frames into the clip: runs that start `start_mm` apart (the
    /// lead-in's perturbation), the simulator's own divergence from a common state. One start
    /// (frame 0) only: Blender cannot be restarted from a mid-clip state.
    pub from_the_start_mm: Vec<f64>,
    pub start_mm: f64,
    /// Two runs' RMS distance at the same frames as e(k)'s (t0 + k over the starts): where a
    /// real garment's e(k) levels off once it has forgotten its start (√2 σ).
    pub pairwise_mm: Vec<f64>,
    /// σ at those frames: where the runs' mean garment sits (not a garment).
    pub sigma_mm: Vec<f64>,
}

fn mean_frame(caches: &[&Frames], t: usize) -> Vec<[f32; 3]> {
    let n = caches.len().max(1) as f64;
    let mut sum = vec![[0.0f64; 3]; caches[0][t].len()];
    for c in caches {
        for (s, p) in sum.iter_mut().zip(&c[t]) {
            (0..3).for_each(|k| s[k] += f64::from(p[k]));
        }
    }
    sum.iter().map(|s| s.map(|x| (x / n) as f32)).collect()
}

fn mean_garment(caches: &[&Frames], frames: usize) -> Vec<Vec<[f32; 3]>> {
    (0..frames).map(|t| mean_frame(caches, t)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small deterministic generator (no crate needed): uniform, then Gaussian by Box–Muller.
    struct Noise(u64);
    impl Noise {
        fn uniform(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((self.0 >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        }
        fn gauss(&mut self) -> f64 {
            let (u, v) = (self.uniform(), self.uniform());
            (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
        }
    }

    /// `frames` × `vertices` of a moving truth, plus independent Gaussian noise of total
    /// variance `sigma²` per vertex (σ/√3 per axis).
    fn noisy(truth: &[Vec<[f32; 3]>], sigma: f64, seed: u64) -> Frames {
        let mut g = Noise(seed);
        let s = sigma / 3f64.sqrt();
        let points = truth
            .iter()
            .map(|f| {
                f.iter()
                    .map(|p| p.map(|c| c + (s * g.gauss()) as f32))
                    .collect()
            })
            .collect();
        Frames::new(points, 30.0)
    }

    fn truth(frames: usize, vertices: usize) -> Frames {
        let points = (0..frames)
            .map(|t| {
                (0..vertices)
                    .map(|v| {
                        let a = t as f32 * 0.1 + v as f32;
                        [a.sin() * 0.2, 0.9 - v as f32 * 1e-3, a.cos() * 0.2]
                    })
                    .collect()
            })
            .collect();
        Frames::new(points, 30.0)
    }

    #[test]
    fn sigma_and_the_models_own_error_are_recovered_from_noisy_runs() {
        // Runs: truth + independent noise of σ = 24 mm; a model: truth + its own noise of
        // 46 mm (the figures). b must come out 46, σ 24, a re-run's b ≈ σ.
        let t = truth(120, 400);
        let runs: Vec<_> = (0..3).map(|i| noisy(&t, 0.024, 10 + i)).collect();
        let e = Ensemble::new(&runs).unwrap();
        let s = e.spread();
        assert!((s.sigma_mm.clip - 24.0).abs() < 0.3, "{s:?}");
        assert!(
            (s.pairwise_rms_mm.clip - 24.0 * 2f64.sqrt()).abs() < 0.4,
            "{s:?}"
        );
        // Against the mean of two others: √1.5 σ, not √2 σ.
        assert!(
            (s.from_the_others_rms_mm.clip - 24.0 * 1.5f64.sqrt()).abs() < 0.4,
            "{s:?}"
        );
        let model = noisy(&t, 0.046, 99);
        let m = e.score(&model);
        // Measured: 46.0 / 46.0 mm (clip); the RMS to a run is √(46² + 24²) = 51.9.
        assert!((m.own_mm.clip - 46.0).abs() < 0.5, "{m:?}");
        assert!((m.own_from_mean_mm.clip - 46.0).abs() < 0.5, "{m:?}");
        assert!((m.rms_mm.clip - (46f64.powi(2) + 24f64.powi(2)).sqrt()).abs() < 0.5);
        // A fourth run of the simulator: its own error is σ; the truth (the blur) scores 0.
        let rerun = e.score(&noisy(&t, 0.024, 77));
        assert!((rerun.own_mm.clip - 24.0).abs() < 0.6, "{rerun:?}");
        let blur = e.score(&t);
        assert!(blur.own_mm.clip < 2.0, "{blur:?}");
        assert!(Ensemble::new(&runs[..1]).is_none());
    }

    #[test]
    fn horizon_curves_pool_runs_and_starts_and_the_divergence_starts_from_frame_0() {
        // Two runs equal at frame 0, apart by 1 mm × k at frame k (on one vertex of one).
        let t = truth(30, 1);
        let mut b = t.clone();
        for (k, f) in b.iter_mut().enumerate() {
            f[0][0] += 1e-3 * k as f32;
        }
        let runs = vec![t.clone(), b];
        let e = Ensemble::new(&runs).unwrap();
        let starts = e.starts(5, 10);
        assert_eq!(starts, vec![0, 10, 20]);
        let d = e.divergence(&starts, 5);
        assert!(d.start_mm < 1e-3);
        assert!((d.from_the_start_mm[2] - 3.0).abs() < 1e-3, "{d:?}");
        // At the starts' frames 10+k and 20+k: √(mean of (10+k)², (20+k)²) mm ... for k = 1.
        let want = ((11f64.powi(2) + 1f64.powi(2) + 21f64.powi(2)) / 3.0).sqrt();
        assert!((d.pairwise_mm[0] - want).abs() < 1e-2, "{d:?} {want}");
        assert!((d.sigma_mm[0] - want / 2f64.sqrt()).abs() < 1e-2);
        // A model restarted exactly on each run's state and then frozen: its error k frames on
        // is how far that run moved in k frames; pooled over both runs and the three starts.
        let frozen = e
            .horizon(&starts, 5, |i, t0| {
                Ok::<_, ()>(vec![runs[i][t0].clone(); 6])
            })
            .unwrap();
        let moved = |i: usize, t0: usize, k: usize| frame_ms(&runs[i][t0], &runs[i][t0 + k]);
        let k = 3;
        let want: f64 = (0..2)
            .flat_map(|i| starts.iter().map(move |&t0| (i, t0)))
            .map(|(i, t0)| moved(i, t0, k))
            .sum::<f64>()
            / 6.0;
        assert!(
            (frozen[k - 1] - 1e3 * want.sqrt()).abs() < 1e-6,
            "{frozen:?}"
        );
    }
}
