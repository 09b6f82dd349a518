//! Whether a played garment could be cloth, whatever its distance from a simulation: how far its
//! edges stretch (mean and 99th percentile over every edge of every frame) and how much it
//! jitters (the RMS second difference of its vertices per frame: a blur is smooth, noise and
//! popping are not). Vertices inside the body are counted by `simulate::stats` (winding number).

use crate::geometry::edges::unique_edges;
use serde::Serialize;

#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Plausibility {
    /// |e − e_T| / e_T over every edge and frame (%).
    pub strain_mean_pct: f64,
    pub strain_p99_pct: f64,
    /// √(mean |x(t+1) − 2x(t) + x(t−1)|²) over vertices and frames (mm per frame²).
    pub jitter_mm: f64,
}

/// The figures of `frames` of a garment whose rest shape is (`rest`, `triangles`).
pub fn of(rest: &[[f32; 3]], triangles: &[[u32; 3]], frames: &[Vec<[f32; 3]>]) -> Plausibility {
    let edges: Vec<([u32; 2], f32)> = unique_edges(triangles)
        .into_iter()
        .map(|e| (e, length(rest, e)))
        .filter(|(_, r)| *r > 0.0)
        .collect();
    let mut strains: Vec<f32> = frames
        .iter()
        .flat_map(|x| {
            edges
                .iter()
                .map(move |&(e, r)| (length(x, e) - r).abs() / r)
        })
        .collect();
    let mean = strains.iter().map(|&s| f64::from(s)).sum::<f64>() / strains.len().max(1) as f64;
    strains.sort_by(f32::total_cmp);
    Plausibility {
        strain_mean_pct: 100.0 * mean,
        strain_p99_pct: 100.0 * super::percentile(&strains, 0.99),
        jitter_mm: jitter_mm(frames),
    }
}

/// RMS second difference (mm): 0 for a garment at rest or moving at constant velocity.
pub fn jitter_mm(frames: &[Vec<[f32; 3]>]) -> f64 {
    let (mut sum, mut count) = (0.0, 0usize);
    for w in frames.windows(3) {
        for ((a, b), c) in w[0].iter().zip(&w[1]).zip(&w[2]) {
            sum += (0..3)
                .map(|k| (f64::from(c[k]) - 2.0 * f64::from(b[k]) + f64::from(a[k])).powi(2))
                .sum::<f64>();
            count += 1;
        }
    }
    1e3 * (sum / count.max(1) as f64).sqrt()
}

fn length(p: &[[f32; 3]], [a, b]: [u32; 2]) -> f32 {
    let (a, b) = (p[a as usize], p[b as usize]);
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strain_and_jitter_of_known_motions() {
        let rest = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let tri = vec![[0, 1, 2]];
        // Constant velocity: no jitter; the rest shape: no strain.
        let glide: Vec<Vec<[f32; 3]>> = (0..5)
            .map(|t| {
                rest.iter()
                    .map(|p| [p[0] + 0.01 * t as f32, p[1], p[2]])
                    .collect()
            })
            .collect();
        let p = of(&rest, &tri, &glide);
        assert!(p.jitter_mm < 1e-3 && p.strain_mean_pct < 1e-4, "{p:?}");
        // Every point stepping 1 mm up and back in turn: second differences of ±2 mm.
        let shake: Vec<Vec<[f32; 3]>> = (0..6)
            .map(|t| {
                let d = if t % 2 == 0 { 0.0 } else { 1e-3 };
                rest.iter().map(|p| [p[0], p[1] + d, p[2]]).collect()
            })
            .collect();
        assert!(
            (jitter_mm(&shake) - 2.0).abs() < 1e-3,
            "{}",
            jitter_mm(&shake)
        );
        // Scaled by 1.1: every edge 10 % long.
        let big = vec![rest.iter().map(|p| p.map(|c| 1.1 * c)).collect::<Vec<_>>()];
        let s = of(&rest, &tri, &big);
        assert!((s.strain_mean_pct - 10.0).abs() < 1e-3 && (s.strain_p99_pct - 10.0).abs() < 1e-3);
    }
}
