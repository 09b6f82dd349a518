//! Settling towards the pose (not in the paper): the latent integrator's prediction is blended
//! with the garment the body's pose alone predicts,
//! `Z_t = keep · W x_t + (1 − keep) · P [1, u_t]`,
//! with `P` a ridge regression from the body drive `u_t` to the simulated frames' latents. A
//! history the integrator carries (a known start, a swing under way) fades by `keep` per frame,
//! so a drifted roll-out is pulled back to what the pose says within a fraction of a second and
//! cannot run away, while the first frames after a simulated start still follow it. The blend
//! is folded into the integrator's linear path, so a settled model plays like any other.

use tch::{Kind, Tensor};

/// Relative ridges the pose regression chooses from, by leave-one-clip-out error.
pub const POSE_RIDGES: [f64; 5] = [1e-3, 1e-2, 1e-1, 1.0, 10.0];

/// The ridge a pose regression was fitted with, and how much of the latents' spread around the
/// training clips' mean it explains on clips left out of the fit (%; 0: no better than the
/// mean garment, negative: worse).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeldOut {
    pub ridge: f64,
    pub explained_pct: f64,
}

/// The garment from the pose alone: latents as a linear function of `[1, u_t]`.
pub struct PoseRegression {
    /// `P` `[L, 1 + D]`.
    pub weights: Tensor,
}

impl PoseRegression {
    /// Fits `target [F, L] ≈ [1, drive] Pᵀ` (`drive [F, D]`); each drive column's penalty is
    /// `ridge` times its mean square (a floor keeps a joint that never turns solvable), none on
    /// the constant.
    pub fn fit(drive: &Tensor, target: &Tensor, ridge: f64) -> PoseRegression {
        tch::no_grad(|| {
            let x = with_constant(drive).to_kind(Kind::Double);
            let gram = x.tr().matmul(&x);
            let diagonal = gram.diagonal(0, 0, 1);
            let floor = diagonal.mean(Kind::Double) * 1e-6;
            let penalty = diagonal.maximum(&floor) * ridge;
            let _ = penalty.get(0).fill_(0.0);
            let rhs = x.tr().matmul(&target.to_kind(Kind::Double));
            let p = Tensor::linalg_solve(&(gram + penalty.diag(0)), &rhs, true);
            PoseRegression {
                weights: p.tr().to_kind(Kind::Float),
            }
        })
    }

    /// Fits with the ridge of `ridges` whose fits on all clips but one predict the clip left out
    /// best (mean square latent error over every clip's frames); `clip [F]` numbers each row's
    /// clip. One clip: its halves stand in for clips. A pose regression must hold for clips it
    /// was not fitted on, and which ridge does depends on the garment and the clips (on 131_02
    /// the skirt's best was 0.01, the top's 1: docs/lab/2026-12-05-dynamic-history.md), so it is
    /// chosen per model, not fixed (one ridge given: that one). [`HeldOut`] says how much of the
    /// left-out clips' latents the chosen ridge explains.
    pub fn fit_across_clips(
        drive: &Tensor,
        target: &Tensor,
        clip: &[usize],
        ridges: &[f64],
    ) -> (PoseRegression, HeldOut) {
        let folds = folds(clip);
        let rows = |m: &Tensor, t: &Tensor| t.index(&[Some(m)]);
        // Sum of squared misses over the left-out clips, of a fit or of the training mean.
        let miss = |ridge: Option<f64>| -> f64 {
            folds
                .iter()
                .map(|fold| {
                    let train = fold.logical_not();
                    let guess = match ridge {
                        Some(r) => {
                            PoseRegression::fit(&rows(&train, drive), &rows(&train, target), r)
                                .latent(&rows(fold, drive))
                        }
                        None => rows(&train, target).mean_dim(0, true, Kind::Float),
                    };
                    (guess - rows(fold, target))
                        .square()
                        .sum(Kind::Double)
                        .double_value(&[])
                })
                .sum()
        };
        let errors: Vec<f64> = ridges.iter().map(|&r| miss(Some(r))).collect();
        let best = (0..ridges.len())
            .min_by(|&a, &b| errors[a].total_cmp(&errors[b]))
            .expect("at least one ridge");
        let held = HeldOut {
            ridge: ridges[best],
            explained_pct: 100.0 * (1.0 - errors[best] / miss(None).max(1e-300)),
        };
        (PoseRegression::fit(drive, target, held.ridge), held)
    }

    /// The latents the pose alone predicts `[F, L]` for `drive [F, D]`.
    pub fn latent(&self, drive: &Tensor) -> Tensor {
        with_constant(drive).matmul(&self.weights.tr())
    }
}

/// Boolean row masks, one per fold: each clip, or the two halves of a single clip.
fn folds(clip: &[usize]) -> Vec<Tensor> {
    let n = clip.len();
    let mut ids: Vec<usize> = clip.to_vec();
    ids.dedup();
    let of = |k: &dyn Fn(usize) -> bool| -> Tensor {
        Tensor::from_slice(&(0..n).map(k).collect::<Vec<bool>>())
    };
    if ids.len() < 2 {
        return vec![of(&|i| i < n / 2), of(&|i| i >= n / 2)];
    }
    ids.iter().map(|&c| of(&|i| clip[i] == c)).collect()
}

fn with_constant(drive: &Tensor) -> Tensor {
    let ones = Tensor::ones([drive.size()[0], 1], (drive.kind(), drive.device()));
    Tensor::cat(&[ones, drive.shallow_clone()], 1)
}

/// The share of the history kept per frame for a settling time `seconds` (the time constant
/// of the fade: after it, `1/e` of a deviation from the pose's garment is left).
pub fn keep_per_frame(seconds: f64, fps: f64) -> f64 {
    if seconds <= 0.0 {
        return 0.0;
    }
    (-1.0 / (seconds * fps)).exp()
}

#[cfg(test)]
mod tests {
    use super::*;
    use tch::Device;

    #[test]
    fn the_pose_regression_recovers_a_linear_map_and_ignores_a_still_joint() {
        tch::manual_seed(3);
        let drive = Tensor::randn([200, 4], (Kind::Float, Device::Cpu));
        // A joint that never turns: a zero column must not make the fit singular.
        let _ = drive.narrow(1, 3, 1).fill_(0.0);
        let truth = Tensor::randn([5, 5], (Kind::Float, Device::Cpu));
        let target = with_constant(&drive).matmul(&truth.tr());
        let fitted = PoseRegression::fit(&drive, &target, 1e-6);
        let error = (fitted.latent(&drive) - &target)
            .abs()
            .max()
            .double_value(&[]);
        assert!(error < 1e-3, "largest error {error}");
        let still = fitted.weights.narrow(1, 4, 1).abs().max().double_value(&[]);
        assert!(still < 1e-6, "a still joint got weight {still}");
    }

    #[test]
    fn the_ridge_is_chosen_on_the_clip_left_out() {
        tch::manual_seed(5);
        // Two clips, each a few frames of many inputs plus noise: without a penalty the fit
        // interpolates one clip's noise and misses the other; the weakest ridge must lose.
        let drive = Tensor::randn([24, 20], (Kind::Float, Device::Cpu));
        let truth = Tensor::randn([3, 21], (Kind::Float, Device::Cpu)) * 0.1;
        let noise = Tensor::randn([24, 3], (Kind::Float, Device::Cpu));
        let target = with_constant(&drive).matmul(&truth.tr()) + noise;
        let clip: Vec<usize> = (0..24).map(|i| i / 12).collect();
        let (_, held) = PoseRegression::fit_across_clips(&drive, &target, &clip, &[1e-6, 10.0]);
        assert_eq!(held.ridge, 10.0);
        // Mostly noise: the fit explains little of the clip left out.
        assert!(held.explained_pct < 20.0, "{held:?}");
        // Noise-free and well determined, the exact map wins.
        let drive = drive.narrow(1, 0, 4);
        let target = with_constant(&drive).matmul(&truth.narrow(1, 0, 5).tr());
        let (_, held) = PoseRegression::fit_across_clips(&drive, &target, &clip, &[1e-6, 10.0]);
        assert_eq!(held.ridge, 1e-6);
        assert!(held.explained_pct > 99.9, "{held:?}");
        assert_eq!(folds(&[0; 6]).len(), 2, "one clip: its halves");
    }

    #[test]
    fn a_deviation_fades_to_one_over_e_after_the_settling_time() {
        let keep = keep_per_frame(0.3, 30.0);
        assert!((keep.powi(9) - (-1.0f64).exp()).abs() < 1e-12);
        assert_eq!(keep_per_frame(0.0, 30.0), 0.0);
    }
}
