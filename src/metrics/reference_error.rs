//! A played garment (a roll-out, plain LBS) against simulated reference caches of the same clip:
//! mean vertex distance after one step, over the first 50 frames and over the whole clip.
//! Against several simulations of one clip (e.g. lead-ins 0.1 s apart) also how far apart the
//! simulations are: a loose garment is chaotic, so the simulator itself defines it only to that
//! spread, and a model as far from them as they are from each other is as good as a re-run.

use crate::geometry::Frames;
use serde::{Deserialize, Serialize};

/// The error of played frames against a reference: mean vertex L2 distance, over spans of the
/// played frames (frame 0 the start).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReferenceError {
    pub one_step_mm: f64,
    pub first_50_mm: f64,
    pub clip_mm: f64,
    pub max_mm: f64,
    pub worst_frame: usize,
}

impl ReferenceError {
    /// `frames` against `reference`, frame by frame (the shorter's length).
    pub fn between(frames: &[Vec<[f32; 3]>], reference: &[Vec<[f32; 3]>]) -> ReferenceError {
        ReferenceError::of(&distances_mm(frames, reference))
    }

    /// From each frame's mean and largest distance (frame 0 the start, not a prediction).
    pub fn of(per_frame: &[(f64, f64)]) -> ReferenceError {
        let mean = |s: &[(f64, f64)]| s.iter().map(|x| x.0).sum::<f64>() / s.len().max(1) as f64;
        let predicted = &per_frame[1.min(per_frame.len())..];
        let (worst_frame, max) =
            per_frame
                .iter()
                .enumerate()
                .fold((0, 0.0), |b, (f, x)| if x.1 > b.1 { (f, x.1) } else { b });
        ReferenceError {
            one_step_mm: mean(&predicted[..1.min(predicted.len())]),
            first_50_mm: mean(&predicted[..50.min(predicted.len())]),
            clip_mm: mean(predicted),
            max_mm: max,
            worst_frame,
        }
    }

    /// The means of several comparisons; the largest distance of all (and its frame).
    pub fn mean(all: &[ReferenceError]) -> ReferenceError {
        let n = all.len().max(1) as f64;
        let mean = |f: fn(&ReferenceError) -> f64| all.iter().map(f).sum::<f64>() / n;
        let worst = all.iter().max_by(|a, b| a.max_mm.total_cmp(&b.max_mm));
        ReferenceError {
            one_step_mm: mean(|v| v.one_step_mm),
            first_50_mm: mean(|v| v.first_50_mm),
            clip_mm: mean(|v| v.clip_mm),
            max_mm: worst.map_or(0.0, |w| w.max_mm),
            worst_frame: worst.map_or(0, |w| w.worst_frame),
        }
    }
}

/// Mean and largest vertex distance (mm) of each frame to the reference's.
pub fn distances_mm(frames: &[Vec<[f32; 3]>], reference: &[Vec<[f32; 3]>]) -> Vec<(f64, f64)> {
    frames
        .iter()
        .zip(reference)
        .map(|(a, b)| {
            let d = super::vertex_distances_mm(a, b);
            (
                d.iter().sum::<f64>() / d.len().max(1) as f64,
                d.iter().copied().fold(0.0, f64::max),
            )
        })
        .collect()
}

/// Two or more simulations of one clip, their vertex-wise mean garment computed once for every
/// sequence compared with them.
pub struct Simulations<'a> {
    caches: &'a [Frames],
    mean: Vec<Vec<[f32; 3]>>,
}

/// Played frames against several simulations of one clip.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Ensemble {
    /// Against each simulation, in the order given.
    pub each: Vec<ReferenceError>,
    /// Those averaged: how far the played garment is from a simulation.
    pub mean_of_each: ReferenceError,
    /// Against the simulations' vertex-wise mean garment (key `versus_mean` in reports).
    #[serde(rename = "versus_mean")]
    pub against_mean: ReferenceError,
}

impl<'a> Simulations<'a> {
    /// `None` with fewer than two: one simulation has no spread and is its own mean.
    pub fn new(caches: &'a [Frames]) -> Option<Simulations<'a>> {
        (caches.len() >= 2).then(|| Simulations {
            caches,
            mean: mean_garment(&caches.iter().collect::<Vec<_>>()),
        })
    }

    /// `frames` against each simulation and against their mean garment.
    pub fn ensemble(&self, frames: &[Vec<[f32; 3]>]) -> Ensemble {
        let each: Vec<ReferenceError> = self
            .caches
            .iter()
            .map(|r| ReferenceError::between(frames, r))
            .collect();
        Ensemble {
            mean_of_each: ReferenceError::mean(&each),
            against_mean: ReferenceError::between(frames, &self.mean),
            each,
        }
    }

    /// Every pair of simulations against each other, averaged: the simulator's own spread.
    pub fn spread(&self) -> ReferenceError {
        let c = self.caches;
        let pairs: Vec<ReferenceError> = (0..c.len())
            .flat_map(|i| (i + 1..c.len()).map(move |j| (i, j)))
            .map(|(i, j)| ReferenceError::between(&c[i], &c[j]))
            .collect();
        ReferenceError::mean(&pairs)
    }

    /// Each simulation against the vertex-wise mean garment of the others, averaged: how near
    /// the simulator's own re-runs, pooled, come to one run they did not start from. A model
    /// scoring this against the simulations predicts as well as re-simulating would.
    pub fn from_the_others(&self) -> ReferenceError {
        let c = self.caches;
        let each: Vec<ReferenceError> = (0..c.len())
            .map(|i| {
                let others: Vec<_> = c
                    .iter()
                    .enumerate()
                    .filter(|(j, _)| *j != i)
                    .map(|x| x.1)
                    .collect();
                ReferenceError::between(&c[i], &mean_garment(&others))
            })
            .collect();
        ReferenceError::mean(&each)
    }
}

/// The vertex-wise mean of several caches of one garment (the shortest's frames).
fn mean_garment(caches: &[&Frames]) -> Vec<Vec<[f32; 3]>> {
    let frames = caches.iter().map(|c| c.len()).min().unwrap_or(0);
    let n = caches.len().max(1) as f32;
    (0..frames)
        .map(|f| {
            let mut sum = vec![[0.0f32; 3]; caches[0][f].len()];
            for cache in caches {
                for (s, p) in sum.iter_mut().zip(&cache[f]) {
                    (0..3).for_each(|k| s[k] += p[k] / n);
                }
            }
            sum
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cache(offsets_mm: &[f32]) -> Frames {
        let points = offsets_mm
            .iter()
            .map(|&d| vec![[d * 1e-3, 0.0, 0.0], [0.0, d * 1e-3, 1.0]])
            .collect();
        Frames::new(points, 30.0)
    }

    #[test]
    fn the_spans_skip_the_start_and_the_mean_of_two_is_half_way() {
        let a = cache(&[0.0; 60]);
        let mut offsets = vec![0.0; 60];
        offsets[0] = 100.0; // the start is not a prediction
        offsets[1] = 4.0;
        offsets[59] = 30.0;
        let b = cache(&offsets);
        let v = ReferenceError::between(&b, &a);
        assert!((v.one_step_mm - 4.0).abs() < 1e-3, "{v:?}");
        assert!((v.first_50_mm - 4.0 / 50.0).abs() < 1e-3, "{v:?}");
        assert!((v.clip_mm - 34.0 / 59.0).abs() < 1e-3, "{v:?}");
        assert_eq!(v.worst_frame, 0);
        // Against a and b: the played a is b's distance from b and 0 from itself; half of it
        // from their mean; the pair's spread is that distance.
        let pair = [a.clone(), b];
        let sims = Simulations::new(&pair).unwrap();
        let e = sims.ensemble(&a);
        assert_eq!(e.each[0].clip_mm, 0.0);
        assert!(
            (e.mean_of_each.clip_mm - v.clip_mm / 2.0).abs() < 1e-4,
            "{e:?}"
        );
        assert!(
            (e.against_mean.clip_mm - v.clip_mm / 2.0).abs() < 1e-4,
            "{e:?}"
        );
        assert!((sims.spread().clip_mm - v.clip_mm).abs() < 1e-4);
        // Two simulations: the others' mean is the other one, so this is the spread.
        assert!((sims.from_the_others().clip_mm - v.clip_mm).abs() < 1e-4);
        // Three on a line at 0, 1 and 3 (in units of b's distance): a is 2 from the mean of b
        // and c, b 0.5 from a's and c's, c 2.5 from a's and b's: 5/3 on average.
        let c = cache(&offsets.iter().map(|o| 3.0 * o).collect::<Vec<_>>());
        let three = [pair[0].clone(), pair[1].clone(), c];
        let others = Simulations::new(&three).unwrap().from_the_others();
        assert!(
            (others.clip_mm - v.clip_mm * 5.0 / 3.0).abs() < 1e-3,
            "{others:?} against {v:?}"
        );
        assert!(Simulations::new(&[a]).is_none());
    }
}
