//! How far frames are from a reference's, vertex by vertex over a clip, in mm: the one error
//! type of the generative space's reconstructions (`train-dynamic`), a baked file replayed
//! against its network (`validate`, `bake`) and a roll-out compressed into blend shapes.
//! (`reference_error::ReferenceError` is the other question: a garment played from a start,
//! its error by span of frames after it.)

use serde::{Deserialize, Serialize};

/// Per-vertex distance of frames to their reference over a clip, in millimetres.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Deviation {
    pub frames: usize,
    pub mean_mm: f64,
    /// The 99th percentile of the distances; none where only each frame's mean and largest
    /// distance were kept (a bake's replay: 3.5 M distances per clip of the skirt).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub p99_mm: Option<f64>,
    pub max_mm: f64,
    /// The frame of the largest distance (a NaN counts as the largest).
    pub worst_frame: usize,
}

impl Deviation {
    /// From every distance (mm), frame by frame (frames of equal vertex counts), in f32 or f64.
    pub fn of<T: Copy + Into<f64>, D: AsRef<[T]>>(per_frame: &[D]) -> Deviation {
        let summaries: Vec<(f64, f64)> = per_frame
            .iter()
            .map(|d| {
                let d = d.as_ref();
                let largest = d.get(worst_index(d)).map_or(0.0, |&x| x.into());
                let sum: f64 = d.iter().map(|&x| x.into()).sum();
                (largest, sum / d.len().max(1) as f64)
            })
            .collect();
        let mut all: Vec<f32> = per_frame
            .iter()
            .flat_map(|d| d.as_ref().iter().map(|&x| x.into() as f32))
            .collect();
        Deviation {
            p99_mm: Some(super::percentile_unsorted(&mut all, 0.99)),
            ..Deviation::of_largest_and_mean(&summaries)
        }
    }

    /// From each frame's largest and mean distance (mm), frames of equal vertex counts.
    pub fn of_largest_and_mean(per_frame: &[(f64, f64)]) -> Deviation {
        let (mut worst_frame, mut max) = (0, 0.0);
        for (f, &(m, _)) in per_frame.iter().enumerate() {
            if worse(m, max) {
                (worst_frame, max) = (f, m);
            }
        }
        Deviation {
            frames: per_frame.len(),
            mean_mm: per_frame.iter().map(|e| e.1).sum::<f64>() / per_frame.len().max(1) as f64,
            p99_mm: None,
            max_mm: max,
            worst_frame,
        }
    }
}

/// Whether distance `x` is worse than `than`: larger, or a NaN (the worst) where `than` is not.
fn worse(x: f64, than: f64) -> bool {
    x > than || x.is_nan() && !than.is_nan()
}

/// Where the largest of `d` is (the first of equals), a NaN counting as the largest; 0 for none.
pub fn worst_index<T: Copy + Into<f64>>(d: &[T]) -> usize {
    let mut at = 0;
    for (i, &x) in d.iter().enumerate().skip(1) {
        if worse(x.into(), d[at].into()) {
            at = i;
        }
    }
    at
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_deviation_summarises_every_distance() {
        // Two frames of 100 vertices: the second has one vertex 50 mm off.
        let a = vec![1.0; 100];
        let mut b = vec![2.0; 100];
        b[7] = 50.0;
        let d = Deviation::of(&[a, b]);
        assert_eq!((d.frames, d.worst_frame), (2, 1));
        assert_eq!(d.max_mm, 50.0);
        assert!((d.mean_mm - (100.0 + 198.0 + 50.0) / 200.0).abs() < 1e-12);
        // 200 distances: the 198th smallest is a 2.
        assert_eq!(d.p99_mm, Some(2.0));
        let nan = Deviation::of(&[vec![1.0], vec![f64::NAN], vec![3.0]]);
        assert_eq!(nan.worst_frame, 1);
        assert!(nan.max_mm.is_nan());
        assert_eq!(worst_index(&[1.0f32, 5.0, f32::NAN, 5.0]), 2);
        assert_eq!(worst_index(&[1.0f32, 5.0, 2.0, 5.0]), 1);
        // f32 distances give the f64 figures.
        assert_eq!(
            Deviation::of(&[vec![1.0f32; 100], vec![2.0f32; 100]]).p99_mm,
            Some(2.0)
        );
    }
}
