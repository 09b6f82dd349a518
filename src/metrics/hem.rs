//! The hem's swing: what a garment's dynamics add to where the body puts it.
//!
//! The hem (a boundary loop of the garment, the lowest at rest) is expressed in the waist frame
//! (the root joint's skinning transform undone: a garment riding the pelvis rigidly stands still
//! there), minus a quasi-static baseline's hem (PBNS: the garment the pose alone predicts), and
//! each vertex's mean over the clip is removed. What is left is the motion beyond the pose, the
//! part a blurred average of chaotic runs loses. Compared here: correlation with the
//! simulations (Pearson over every hem coordinate and frame), amplitude (RMS), the lag behind the
//! pelvis' velocity, and the power spectrum.

use crate::geometry::{Topology, TriMesh};
use nalgebra::{Matrix4, Vector3};
use serde::Serialize;

/// Per frame, per hem vertex, a point or a displacement (metres, f64).
pub type Trace = Vec<Vec<[f64; 3]>>;

/// The hem: of the garment's boundary loops, the one lowest at rest (mean height, Y-up). A
/// skirt's has the waist loop above it, a top's the neck and the sleeves. `None` for a closed
/// mesh.
pub fn hem_loop(mesh: &TriMesh) -> Option<Vec<u32>> {
    let height = |l: &Vec<u32>| {
        l.iter()
            .map(|&v| f64::from(mesh.positions[v as usize][1]))
            .sum::<f64>()
            / l.len().max(1) as f64
    };
    Topology::new(mesh)
        .boundary_loops()
        .into_iter()
        .filter(|l| l.len() >= 3)
        .min_by(|a, b| height(a).total_cmp(&height(b)))
}

/// The hem vertices of every frame in the waist frame: `waist[t]` maps the rest waist to the
/// posed one (the root joint's skinning matrix), so its inverse takes the hem back.
pub fn in_waist_frame(frames: &[Vec<[f32; 3]>], hem: &[u32], waist: &[Matrix4<f32>]) -> Trace {
    frames
        .iter()
        .zip(waist)
        .map(|(x, w)| {
            let inv = w
                .cast::<f64>()
                .try_inverse()
                .unwrap_or_else(Matrix4::identity);
            hem.iter()
                .map(|&v| {
                    let p = x[v as usize].map(f64::from);
                    let q = inv.transform_point(&nalgebra::Point3::new(p[0], p[1], p[2]));
                    [q.x, q.y, q.z]
                })
                .collect()
        })
        .collect()
}

/// `hem` minus `baseline` (when given), each vertex's mean over the frames removed.
pub fn residual(hem: &Trace, baseline: Option<&Trace>) -> Trace {
    let frames = baseline.map_or(hem.len(), |b| b.len().min(hem.len()));
    let mut r: Trace = (0..frames)
        .map(|t| {
            hem[t]
                .iter()
                .enumerate()
                .map(|(v, p)| match baseline {
                    Some(b) => std::array::from_fn(|k| p[k] - b[t][v][k]),
                    None => *p,
                })
                .collect()
        })
        .collect();
    let vertices = r.first().map_or(0, Vec::len);
    for v in 0..vertices {
        let mean: [f64; 3] =
            std::array::from_fn(|k| r.iter().map(|f| f[v][k]).sum::<f64>() / frames.max(1) as f64);
        for f in r.iter_mut() {
            (0..3).for_each(|k| f[v][k] -= mean[k]);
        }
    }
    r
}

/// The vertex-wise mean of several traces (the shortest's frames).
pub fn mean_trace(traces: &[&Trace]) -> Trace {
    let frames = traces.iter().map(|t| t.len()).min().unwrap_or(0);
    let n = traces.len().max(1) as f64;
    (0..frames)
        .map(|t| {
            (0..traces[0][t].len())
                .map(|v| {
                    std::array::from_fn(|k| traces.iter().map(|r| r[t][v][k]).sum::<f64>() / n)
                })
                .collect()
        })
        .collect()
}

fn flat(t: &Trace) -> impl Iterator<Item = f64> + '_ {
    t.iter().flatten().flatten().copied()
}

/// Pearson correlation over every coordinate of every vertex and frame (`None` when either is
/// constant: a baseline's own residual is zero).
pub fn correlation(a: &Trace, b: &Trace) -> Option<f64> {
    let n = a.len().min(b.len());
    pearson(
        &flat(&a[..n].to_vec()).collect::<Vec<_>>(),
        &flat(&b[..n].to_vec()).collect::<Vec<_>>(),
    )
}

/// Pearson correlation of two equally long series.
pub fn pearson(a: &[f64], b: &[f64]) -> Option<f64> {
    let n = a.len().min(b.len());
    if n < 2 {
        return None;
    }
    let (ma, mb) = (
        a[..n].iter().sum::<f64>() / n as f64,
        b[..n].iter().sum::<f64>() / n as f64,
    );
    let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
    for (x, y) in a[..n].iter().zip(&b[..n]) {
        ab += (x - ma) * (y - mb);
        aa += (x - ma).powi(2);
        bb += (y - mb).powi(2);
    }
    let d = (aa * bb).sqrt();
    (d > 1e-300).then(|| ab / d)
}

/// RMS length of the residual's displacement vectors (mm).
pub fn amplitude_mm(r: &Trace) -> f64 {
    let count = r.iter().map(Vec::len).sum::<usize>().max(1) as f64;
    1e3 * (flat(r).map(|x| x * x).sum::<f64>() / count).sqrt()
}

/// The hem's mean residual per frame (the loop's centroid).
pub fn centroid(r: &Trace) -> Vec<[f64; 3]> {
    r.iter()
        .map(|f| {
            std::array::from_fn(|k| f.iter().map(|p| p[k]).sum::<f64>() / f.len().max(1) as f64)
        })
        .collect()
}

/// Names of the parts [`parts`] splits a residual into, in its order.
pub const PARTS: [&str; 4] = ["lateral", "vertical", "forward", "shape"];

/// A residual split into parts: its centroid's motion along the waist frame's x (lateral), y
/// (vertical) and z (forward) axes, each as a trace whose every vertex carries that one
/// coordinate, and the shape left when the centroid is taken out (flare, folds, a twist). A
/// skirt swinging as a whole is in the first three, one rippling in the last. The parts are
/// orthogonal (the shape sums to zero over the hem), so their mean squares add up to the
/// residual's and each part's correlations and amplitudes read like the whole's. `c` is the
/// residual's [`centroid`] (callers have it already).
pub fn parts(r: &Trace, c: &[[f64; 3]]) -> [Trace; 4] {
    let axis = |k: usize| -> Trace {
        r.iter()
            .zip(c)
            .map(|(f, m)| {
                let mut p = [0.0; 3];
                p[k] = m[k];
                vec![p; f.len()]
            })
            .collect()
    };
    let shape = r
        .iter()
        .zip(c)
        .map(|(f, m)| {
            f.iter()
                .map(|p| std::array::from_fn(|k| p[k] - m[k]))
                .collect()
        })
        .collect();
    [axis(0), axis(1), axis(2), shape]
}

/// The pelvis' (root joint's) velocity per frame in its own frame (m/s, central differences,
/// one-sided at the ends): the body's motion as the garment riding it feels it.
pub fn pelvis_velocity(waist: &[Matrix4<f32>], fps: f32) -> Vec<[f64; 3]> {
    let n = waist.len();
    let origin = |t: usize| waist[t].cast::<f64>().fixed_view::<3, 1>(0, 3).into_owned();
    (0..n)
        .map(|t| {
            let (a, b) = (t.saturating_sub(1), (t + 1).min(n.saturating_sub(1)));
            if a == b {
                return [0.0; 3];
            }
            let step: Vector3<f64> = (origin(b) - origin(a)) * f64::from(fps) / (b - a) as f64;
            let r = waist[t].cast::<f64>().fixed_view::<3, 3>(0, 0).into_owned();
            // The rotation part of a skinning matrix with unit scale: R^T v is v in its frame.
            let v = r.transpose() * step;
            [v.x, v.y, v.z]
        })
        .collect()
}

/// The time shift at which a response follows a drive most closely.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Lag {
    /// Frames the response trails the drive by (negative: it leads).
    pub frames: i64,
    pub seconds: f64,
    /// The normalised cross-correlation there (its sign: with or against the drive).
    pub correlation: f64,
}

/// The lag τ in −`max` … `max` frames (at most half the frames) maximising |c(τ)|, `c(τ)` the
/// correlation of `response(t + τ)` with `drive(t)` over the frames where both exist, on the
/// horizontal axes (x, z: the swing; the vertical is the hem's bounce), means removed. `None`
/// for a still drive or response.
pub fn lag(response: &[[f64; 3]], drive: &[[f64; 3]], max: usize, fps: f32) -> Option<Lag> {
    let axes = |s: &[[f64; 3]]| -> Vec<Vec<f64>> {
        [0usize, 2]
            .iter()
            .map(|&k| s.iter().map(|p| p[k]).collect())
            .collect()
    };
    lag_of_channels(&axes(response), &axes(drive), max, fps)
}

/// [`lag`] of one axis of a centroid series behind another's: when an axis part of the swing
/// ([`parts`]: every vertex carries the centroid's coordinate) comes against the runs'.
pub fn axis_lag(
    response: &[[f64; 3]],
    drive: &[[f64; 3]],
    axis: usize,
    max: usize,
    fps: f32,
) -> Option<Lag> {
    let channel = |s: &[[f64; 3]]| vec![s.iter().map(|p| p[axis]).collect::<Vec<f64>>()];
    lag_of_channels(&channel(response), &channel(drive), max, fps)
}

/// [`lag`] of a whole trace behind another, every vertex coordinate a channel: when the shape
/// part of the swing ([`parts`]) comes against the runs'.
pub fn trace_lag(response: &Trace, drive: &Trace, max: usize, fps: f32) -> Option<Lag> {
    let channels = |t: &Trace| -> Vec<Vec<f64>> {
        let width = t.first().map_or(0, |f| f.len());
        (0..width * 3)
            .map(|c| t.iter().map(|f| f[c / 3][c % 3]).collect())
            .collect()
    };
    lag_of_channels(&channels(response), &channels(drive), max, fps)
}

/// The lag over channels (each a series over frames) pooled into one correlation.
fn lag_of_channels(response: &[Vec<f64>], drive: &[Vec<f64>], max: usize, fps: f32) -> Option<Lag> {
    let n = response
        .iter()
        .chain(drive)
        .map(Vec::len)
        .min()
        .unwrap_or(0);
    if n < 4 || response.len() != drive.len() {
        return None;
    }
    let centred = |s: &Vec<f64>| {
        let m = s[..n].iter().sum::<f64>() / n as f64;
        s[..n].iter().map(|x| x - m).collect::<Vec<_>>()
    };
    let r: Vec<Vec<f64>> = response.iter().map(centred).collect();
    let d: Vec<Vec<f64>> = drive.iter().map(centred).collect();
    let max = max.min(n / 2) as i64;
    let at = |tau: i64| {
        // Drive frames t whose response frame t + τ exists.
        let ts = (0.max(-tau) as usize)..((n as i64).min(n as i64 - tau) as usize);
        let (mut rd, mut rr, mut dd) = (0.0, 0.0, 0.0);
        for (ra, da) in r.iter().zip(&d) {
            for t in ts.clone() {
                let x = ra[(t as i64 + tau) as usize];
                rd += x * da[t];
                rr += x * x;
                dd += da[t] * da[t];
            }
        }
        let norm = (rr * dd).sqrt();
        (norm > 1e-300).then(|| rd / norm)
    };
    (-max..=max)
        .filter_map(|tau| at(tau).map(|c| (tau, c)))
        .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
        .map(|(tau, c)| Lag {
            frames: tau,
            seconds: tau as f64 / f64::from(fps),
            correlation: c,
        })
}

/// One bin of a power spectrum.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Bin {
    pub hz: f64,
    /// Mean power per coordinate series (mm²; the bins sum to about a series' variance),
    /// Hann-windowed periodogram, one-sided.
    pub power_mm2: f64,
}

/// The residual's power spectrum: every coordinate of every hem vertex a series, Hann-windowed,
/// its periodogram averaged over the series; bins 0 … fps/2.
pub fn power_spectrum(r: &Trace, fps: f32) -> Vec<Bin> {
    let n = r.len();
    if n < 2 {
        return Vec::new();
    }
    let window: Vec<f64> = (0..n)
        .map(|t| 0.5 - 0.5 * (std::f64::consts::TAU * t as f64 / (n - 1) as f64).cos())
        .collect();
    let w2 = window.iter().map(|w| w * w).sum::<f64>();
    let bins = n / 2 + 1;
    let (cos, sin): (Vec<f64>, Vec<f64>) = (0..n)
        .map(|j| {
            let a = std::f64::consts::TAU * j as f64 / n as f64;
            (a.cos(), a.sin())
        })
        .unzip();
    let series = r.first().map_or(0, Vec::len) * 3;
    let mut power = vec![0.0; bins];
    for s in 0..series {
        let x: Vec<f64> = (0..n)
            .map(|t| 1e3 * r[t][s / 3][s % 3] * window[t])
            .collect();
        for (k, p) in power.iter_mut().enumerate() {
            let (mut re, mut im) = (0.0, 0.0);
            for (t, v) in x.iter().enumerate() {
                let j = (k * t) % n;
                re += v * cos[j];
                im -= v * sin[j];
            }
            let one_sided = if k == 0 || 2 * k == n { 1.0 } else { 2.0 };
            *p += one_sided * (re * re + im * im) / w2;
        }
    }
    power
        .iter()
        .enumerate()
        .map(|(k, p)| Bin {
            hz: k as f64 * f64::from(fps) / n as f64,
            power_mm2: p / series.max(1) as f64 / n as f64,
        })
        .collect()
}

/// Where a spectrum's power lies: its peak and centroid (Hz; the zero bin left out).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SpectrumSummary {
    pub peak_hz: f64,
    pub centroid_hz: f64,
    /// Share of the power above 1 Hz (%): quick swings and flutter.
    pub above_1hz_pct: f64,
}

pub fn summarise(spectrum: &[Bin]) -> SpectrumSummary {
    let bins = spectrum.get(1..).unwrap_or(&[]);
    let total: f64 = bins.iter().map(|b| b.power_mm2).sum();
    let peak = bins
        .iter()
        .filter(|b| b.power_mm2 > 0.0)
        .max_by(|a, b| a.power_mm2.total_cmp(&b.power_mm2));
    let share = |f: &dyn Fn(&Bin) -> bool| {
        100.0
            * bins
                .iter()
                .filter(|b| f(b))
                .map(|b| b.power_mm2)
                .sum::<f64>()
            / total.max(1e-300)
    };
    SpectrumSummary {
        peak_hz: peak.map_or(0.0, |b| b.hz),
        centroid_hz: bins.iter().map(|b| b.hz * b.power_mm2).sum::<f64>() / total.max(1e-300),
        above_1hz_pct: share(&|b| b.hz > 1.0),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::TriMesh;

    /// An open cylinder (a skirt without pleats): `rings` loops of `around` vertices, the first
    /// at the top.
    fn tube(rings: usize, around: usize) -> TriMesh {
        let mut p = Vec::new();
        for r in 0..rings {
            for a in 0..around {
                let t = std::f32::consts::TAU * a as f32 / around as f32;
                p.push([0.2 * t.cos(), 1.0 - 0.1 * r as f32, 0.2 * t.sin()]);
            }
        }
        let mut tri = Vec::new();
        for r in 0..rings - 1 {
            for a in 0..around {
                let (i, j) = (
                    (r * around + a) as u32,
                    (r * around + (a + 1) % around) as u32,
                );
                let (k, l) = (i + around as u32, j + around as u32);
                tri.push([i, k, j]);
                tri.push([j, k, l]);
            }
        }
        TriMesh::new(p, tri)
    }

    #[test]
    fn the_hem_is_the_lowest_loop_and_a_rigid_ride_leaves_no_residual() {
        let mesh = tube(4, 12);
        let hem = hem_loop(&mesh).unwrap();
        assert_eq!(hem.len(), 12);
        assert!(hem.iter().all(|&v| v >= 36), "{hem:?}");
        // The garment carried rigidly by the waist (turning and walking): in the waist frame
        // it stands still, so no residual.
        let waist: Vec<Matrix4<f32>> = (0..20)
            .map(|t| {
                let r = nalgebra::Rotation3::from_euler_angles(0.0, 0.1 * t as f32, 0.0);
                Matrix4::new_translation(&Vector3::new(0.05 * t as f32, 0.0, 0.0))
                    * r.to_homogeneous()
            })
            .collect();
        let frames: Vec<Vec<[f32; 3]>> = waist
            .iter()
            .map(|w| {
                mesh.positions
                    .iter()
                    .map(|p| {
                        let q = w.transform_point(&nalgebra::Point3::new(p[0], p[1], p[2]));
                        [q.x, q.y, q.z]
                    })
                    .collect()
            })
            .collect();
        let r = residual(&in_waist_frame(&frames, &hem, &waist), None);
        assert!(amplitude_mm(&r) < 1e-3, "{}", amplitude_mm(&r));
        // The pelvis walks 0.05 m per frame along world x; in its own (turning) frame that is
        // 1.5 m/s long.
        let v = pelvis_velocity(&waist, 30.0);
        let speed = (v[7][0].powi(2) + v[7][2].powi(2)).sqrt();
        assert!((speed - 1.5).abs() < 1e-3, "{v:?}");
        // A baseline equal to the garment leaves nothing either, and correlation is undefined.
        let hem_frames = in_waist_frame(&frames, &hem, &waist);
        let zero = residual(&hem_frames, Some(&hem_frames));
        assert_eq!(correlation(&zero, &zero), None);
    }

    fn swing(frames: usize, shift: i64, scale: f64) -> Trace {
        (0..frames as i64)
            .map(|t| {
                let s = ((t - shift) as f64 * 0.21).sin() + 0.5 * ((t - shift) as f64 * 0.05).cos();
                vec![[0.01 * scale * s, 0.0, -0.02 * scale * s]; 3]
            })
            .collect()
    }

    #[test]
    fn parts_split_a_swing_from_a_ripple_and_their_squares_add_up() {
        // Eight hem vertices on a circle: the whole hem swinging forward (z) and bouncing (y),
        // plus a ripple that moves vertices in and out with no net motion.
        let around = 8;
        let r: Trace = (0..100)
            .map(|t| {
                let (fwd, up, ripple) = (
                    0.03 * (t as f64 * 0.2).sin(),
                    0.01 * (t as f64 * 0.5).cos(),
                    0.02 * (t as f64 * 0.7).sin(),
                );
                (0..around)
                    .map(|a| {
                        let angle = std::f64::consts::TAU * a as f64 / around as f64;
                        let out = ripple * (2.0 * angle).cos();
                        [out * angle.cos(), up, fwd + out * angle.sin()]
                    })
                    .collect()
            })
            .collect();
        let [lateral, vertical, forward, shape] = parts(&r, &centroid(&r));
        assert!(amplitude_mm(&lateral) < 1e-9, "{}", amplitude_mm(&lateral));
        let fwd: Trace = (0..100)
            .map(|t| vec![[0.0, 0.0, 0.03 * (t as f64 * 0.2).sin()]; around])
            .collect();
        assert!((correlation(&forward, &fwd).unwrap() - 1.0).abs() < 1e-9);
        assert!((amplitude_mm(&forward) - amplitude_mm(&fwd)).abs() < 1e-9);
        assert!(amplitude_mm(&vertical) > 6.0, "{}", amplitude_mm(&vertical));
        // The ripple is all shape, uncorrelated with the swing.
        assert!(amplitude_mm(&shape) > 5.0, "{}", amplitude_mm(&shape));
        let square = |t: &Trace| amplitude_mm(t).powi(2);
        let sum = square(&lateral) + square(&vertical) + square(&forward) + square(&shape);
        assert!(
            (sum / square(&r) - 1.0).abs() < 1e-9,
            "{sum} against {}",
            square(&r)
        );
    }

    #[test]
    fn correlation_amplitude_lag_and_spectrum_of_known_signals() {
        let a = swing(200, 0, 1.0);
        let c = correlation(&a, &a).unwrap();
        assert!((c - 1.0).abs() < 1e-12);
        let half = swing(200, 0, 0.5);
        assert!((correlation(&a, &half).unwrap() - 1.0).abs() < 1e-12);
        assert!((amplitude_mm(&half) / amplitude_mm(&a) - 0.5).abs() < 1e-12);
        let negated: Trace = a
            .iter()
            .map(|f| f.iter().map(|p| p.map(|x| -x)).collect())
            .collect();
        assert!((correlation(&a, &negated).unwrap() + 1.0).abs() < 1e-12);
        // The response is the drive 7 frames late (and against it).
        let drive = centroid(&a);
        let late: Vec<[f64; 3]> = centroid(&swing(200, 7, -2.0));
        let l = lag(&late, &drive, 30, 30.0).unwrap();
        assert_eq!(l.frames, 7, "{l:?}");
        assert!(l.correlation < -0.9, "{l:?}");
        assert!((l.seconds - 7.0 / 30.0).abs() < 1e-12);
        // The same on whole traces, every vertex a channel: 4 frames early.
        let early = trace_lag(&swing(200, -4, 1.0), &a, 30, 30.0).unwrap();
        assert_eq!(early.frames, -4, "{early:?}");
        assert!(early.correlation > 0.9, "{early:?}");
        // 0.21 rad per frame at 30 fps: 1.003 Hz; the bin nearest it holds the peak.
        let pure: Trace = (0..300)
            .map(|t| vec![[0.01 * (t as f64 * 0.21).sin(), 0.0, 0.0]])
            .collect();
        let s = power_spectrum(&pure, 30.0);
        let sum = summarise(&s);
        assert!(
            (sum.peak_hz - 0.21 * 30.0 / std::f64::consts::TAU).abs() < 0.1,
            "{sum:?}"
        );
        // Parseval (Hann-normalised): the spectrum's power sums to about the variance in mm².
        let total: f64 = s.iter().map(|b| b.power_mm2).sum();
        let var = 1e6 * pure.iter().map(|f| f[0][0].powi(2)).sum::<f64>() / 300.0 / 3.0;
        assert!((total / var - 1.0).abs() < 0.1, "{total} vs {var}");
    }
}
