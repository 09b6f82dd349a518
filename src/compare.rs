//! Caches of one clip (a dynamic roll-out, PBNS, plain LBS, another simulation) against an
//! ensemble of perturbed simulations of it, measured so that dynamics show: RMS errors beside
//! the simulations' spread σ and each cache's own error b (metrics::ensemble), error against
//! horizon from restarts, e(k), beside the simulations' own divergence, the hem's swing beyond a
//! quasi-static baseline (metrics::hem), and whether it could be cloth (strain, inside the body,
//! jitter). Whole-clip L2 against one run of a chaotic simulation is won by a blurred average;
//! here the blur shows as b below σ with a hem amplitude ratio below 1.

use crate::body::Body;
use crate::geometry::{Frames, TriMesh};
use crate::metrics::ensemble::{Divergence, Ensemble, Score, Spread};
use crate::metrics::hem::{self, Lag, SpectrumSummary, Trace};
use crate::metrics::plausibility::{self, Plausibility};
use crate::models::file::ModelFile;
use crate::preview::plot::{line_chart, stack, Chart, Line, LINE_COLORS};
use crate::rig::JointTransform;
use crate::rollout::{for_model, Init};
use crate::simulate::stats::{self, ClipSetup};
use anyhow::{bail, Result};
use nalgebra::Matrix4;
use serde::Serialize;
use std::path::PathBuf;

/// The name the runs' mean garment is scored under (`Settings::with_mean`).
pub const RUNS_MEAN: &str = "runs-mean";

/// One cache compared: its frames (the clip's, frame 0 its start) and, for a dynamic model, the
/// model that played it, which e(k) restarts from each simulation's state.
pub struct Cache {
    pub name: String,
    pub frames: Frames,
    pub model: Option<ModelFile>,
}

/// What is compared.
pub struct Inputs<'a> {
    pub body: &'a Body,
    pub garment: &'a TriMesh,
    /// The clip's poses on the body's skeleton, one per frame.
    pub poses: &'a [Vec<JointTransform>],
    pub fps: f32,
    /// Two or more simulations of the clip (three or more for a ceiling worth the name).
    pub simulations: &'a [Frames],
    pub caches: &'a [Cache],
    /// The quasi-static cache the hem's swing is measured beyond (PBNS), by index.
    pub baseline: Option<usize>,
}

/// How it is compared.
#[derive(Clone, Debug)]
pub struct Settings {
    /// e(k) for k = 1 … horizon.
    pub horizon: usize,
    /// Restarts at frames 0, every, 2·every, … (whole horizons only).
    pub restart_every: usize,
    /// The lag is looked for within ± this (s).
    pub max_lag_s: f32,
    /// How a restarted dynamic model plays (the collision fix as `rollout`'s).
    pub rollout: crate::rollout::Settings,
    /// Also score the runs' vertex-wise mean garment, named [`RUNS_MEAN`]: the blur that wins
    /// whole-clip distance, for scale.
    pub with_mean: bool,
    /// Where to draw e(k) and the hem traces (PNG).
    pub horizon_png: Option<PathBuf>,
    pub hem_png: Option<PathBuf>,
    /// Hide the terminal bar (a command's `--json`): `progress::bar`'s `hide_bar`; silence is
    /// the global `--quiet` (`progress::set_quiet`), not a setting of the step.
    pub hide_bar: bool,
}

/// The hem's swing of one garment sequence.
#[derive(Clone, Debug, Serialize)]
pub struct Swing {
    /// RMS of the residual (mm).
    pub amplitude_mm: f64,
    /// Lag of the hem's centroid behind the pelvis' velocity.
    pub lag: Option<Lag>,
    pub spectrum: SpectrumSummary,
}

/// A cache's hem against the simulations'.
#[derive(Clone, Debug, Serialize)]
pub struct HemScore {
    pub swing: Swing,
    /// Correlation with the simulations' mean residual (the figure).
    pub correlation_with_mean: Option<f64>,
    /// Mean correlation with each simulation: one garment against one run, comparable with
    /// the simulations' mutual correlation (the ceiling).
    pub correlation_with_each: Option<f64>,
    /// Amplitude over the simulations' (mean over runs): 1 for a garment that swings as they
    /// do, below 1 for a blur, 0 for the baseline.
    pub amplitude_ratio: f64,
    /// Lag of the hem's centroid behind the runs' mean (positive: late), beside each run's
    /// behind the others' ([`HemEnsemble::behind_the_others`]): when the swings come.
    pub behind_the_runs: Option<Lag>,
    /// The same per part of the swing ([`hem::parts`]): which motion the garment misses.
    pub parts: Vec<PartScore>,
}

/// A cache's hem against the simulations', in one part of the swing.
#[derive(Clone, Debug, Serialize)]
pub struct PartScore {
    /// lateral, vertical, forward (the centroid along the waist frame's axes) or shape.
    pub part: &'static str,
    pub correlation_with_each: Option<f64>,
    pub amplitude_ratio: f64,
    /// This part behind the runs' mean part (positive: late), every hem vertex's coordinates
    /// pooled: when it comes, beside how much of it.
    pub behind_the_runs: Option<Lag>,
}

/// The simulations' hem in one part of the swing: the ceiling and the target.
#[derive(Clone, Debug, Serialize)]
pub struct HemPart {
    pub part: &'static str,
    pub mutual_correlation: Option<f64>,
    /// RMS, mean over runs (mm).
    pub amplitude_mm: f64,
}

/// The simulations' own hem figures: the ceiling and the targets.
#[derive(Clone, Debug, Serialize)]
pub struct HemEnsemble {
    /// Hem vertices (the lowest boundary loop).
    pub vertices: usize,
    /// The cache the swing is measured beyond (`None`: the hem in the waist frame as it is).
    pub baseline: Option<String>,
    /// Mean correlation over pairs of runs: the ceiling of `correlation_with_each`.
    pub mutual_correlation: Option<f64>,
    /// Each run against the mean of the others, averaged (n − 1 runs in that mean, so a
    /// garment drawn like the runs scores a little higher against the mean of all n).
    pub correlation_with_the_others: Option<f64>,
    /// Each run's swing; the spectrum of their mean power.
    pub runs: Vec<Swing>,
    /// Each run's hem centroid behind the mean of the others (the timing a re-run has).
    pub behind_the_others: Vec<Option<Lag>>,
    pub amplitude_mm: f64,
    pub spectrum: Vec<hem::Bin>,
    /// The runs per part of the swing ([`hem::parts`]); their squares add up to the whole's.
    pub parts: Vec<HemPart>,
}

/// One cache's figures.
#[derive(Clone, Debug, Serialize)]
pub struct CacheReport {
    pub name: String,
    pub score: Score,
    /// e(k), k = 1 … horizon (mm RMS, pooled over runs and restarts).
    pub horizon_mm: Vec<f64>,
    /// Whether e(k) restarted the model from each run's state (else the cache's own frames).
    pub restarted: bool,
    pub hem: HemScore,
    pub spectrum: Vec<hem::Bin>,
    pub plausibility: Plausibility,
    /// Vertices inside the posed body (winding number), mean over frames (%).
    pub inside_pct: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct Report {
    pub frames: usize,
    pub fps: f32,
    pub spread: Spread,
    pub horizon: usize,
    pub starts: Vec<usize>,
    pub divergence: Divergence,
    pub hem: HemEnsemble,
    /// The simulations' own plausibility (mean over runs) and inside share.
    pub simulations: Plausibility,
    pub simulations_inside_pct: f64,
    pub caches: Vec<CacheReport>,
    pub horizon_png: Option<PathBuf>,
    pub hem_png: Option<PathBuf>,
}

/// Everything above; plots written when asked (atomically).
pub fn compare(inputs: &Inputs, settings: &Settings) -> Result<Report> {
    let frames = inputs.poses.len();
    let Some(ensemble) = Ensemble::new(inputs.simulations) else {
        bail!("compare needs two or more simulations of the clip (three or more for a ceiling)");
    };
    if ensemble.frames() != frames || inputs.caches.iter().any(|c| c.frames.len() != frames) {
        bail!("every simulation and cache must have the clip's {frames} frames");
    }
    if settings.horizon == 0 || settings.horizon >= frames {
        bail!(
            "horizon {}: give 1 to {} frames (the clip's frames − 1)",
            settings.horizon,
            frames - 1
        );
    }
    let starts = ensemble.starts(settings.horizon, settings.restart_every);
    let k = settings.horizon;
    let waist: Vec<Matrix4<f32>> = inputs
        .poses
        .iter()
        .map(|p| inputs.body.skeleton.skinning_matrices(p)[0])
        .collect();
    let Some(hem_loop) = hem::hem_loop(inputs.garment) else {
        bail!("the garment has no boundary loop: no hem to follow");
    };
    let hem_of = |f: &[Vec<[f32; 3]>]| hem::in_waist_frame(f, &hem_loop, &waist);
    let baseline = inputs.baseline.map(|b| hem_of(&inputs.caches[b].frames));
    let residual = |f: &[Vec<[f32; 3]>]| hem::residual(&hem_of(f), baseline.as_ref());
    let velocity = hem::pelvis_velocity(&waist, inputs.fps);
    let max_lag = (settings.max_lag_s * inputs.fps).round() as usize;
    // A trace's centroid serves its swing, its timing and the hem picture: found once.
    let swing = |r: &Trace, centroid: &[[f64; 3]]| Swing {
        amplitude_mm: hem::amplitude_mm(r),
        lag: hem::lag(centroid, &velocity, max_lag, inputs.fps),
        spectrum: hem::summarise(&hem::power_spectrum(r, inputs.fps)),
    };
    let runs: Vec<Trace> = inputs.simulations.iter().map(|s| residual(s)).collect();
    let run_centroids: Vec<Vec<[f64; 3]>> = runs.iter().map(hem::centroid).collect();
    let run_refs: Vec<&Trace> = runs.iter().collect();
    let runs_mean = hem::mean_trace(&run_refs);
    let runs_mean_centroid = hem::centroid(&runs_mean);
    let n = runs.len();
    let mean_of = |v: Vec<Option<f64>>| {
        let v: Vec<f64> = v.into_iter().flatten().collect();
        (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
    };
    let pairs: Vec<(usize, usize)> = (0..n)
        .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
        .collect();
    let mutual = mean_of(
        pairs
            .iter()
            .map(|&(i, j)| hem::correlation(&runs[i], &runs[j]))
            .collect(),
    );
    let run_parts: Vec<[Trace; 4]> = runs
        .iter()
        .zip(&run_centroids)
        .map(|(r, c)| hem::parts(r, c))
        .collect();
    let part_mutual = |p: usize| {
        mean_of(
            pairs
                .iter()
                .map(|&(i, j)| hem::correlation(&run_parts[i][p], &run_parts[j][p]))
                .collect(),
        )
    };
    let part_amplitude = |p: usize| {
        run_parts
            .iter()
            .map(|r| hem::amplitude_mm(&r[p]))
            .sum::<f64>()
            / n as f64
    };
    // The parts are linear in the residual: the runs' mean's parts are the mean of theirs.
    let runs_mean_parts = hem::parts(&runs_mean, &runs_mean_centroid);
    let parts_of_runs: Vec<HemPart> = hem::PARTS
        .iter()
        .enumerate()
        .map(|(p, &part)| HemPart {
            part,
            mutual_correlation: part_mutual(p),
            amplitude_mm: part_amplitude(p),
        })
        .collect();
    let others_mean = |i: usize| {
        let others: Vec<&Trace> = (0..n).filter(|&j| j != i).map(|j| &runs[j]).collect();
        hem::mean_trace(&others)
    };
    let with_others = mean_of(
        (0..n)
            .map(|i| hem::correlation(&runs[i], &others_mean(i)))
            .collect(),
    );
    let behind =
        |centroid: &[[f64; 3]], drive: &[[f64; 3]]| hem::lag(centroid, drive, max_lag, inputs.fps);
    let behind_the_others: Vec<Option<Lag>> = (0..n)
        .map(|i| behind(&run_centroids[i], &hem::centroid(&others_mean(i))))
        .collect();
    let run_spectra: Vec<Vec<hem::Bin>> = runs
        .iter()
        .map(|r| hem::power_spectrum(r, inputs.fps))
        .collect();
    let sims_spectrum: Vec<hem::Bin> = (0..run_spectra[0].len())
        .map(|b| hem::Bin {
            hz: run_spectra[0][b].hz,
            power_mm2: run_spectra.iter().map(|s| s[b].power_mm2).sum::<f64>() / n as f64,
        })
        .collect();
    let run_swings: Vec<Swing> = runs
        .iter()
        .zip(&run_centroids)
        .map(|(r, c)| swing(r, c))
        .collect();
    let sims_amplitude = run_swings.iter().map(|s| s.amplitude_mm).sum::<f64>() / n as f64;
    let setup = ClipSetup::unpinned(inputs.body, inputs.garment, inputs.fps);
    let inside = |f: &[Vec<[f32; 3]>]| {
        stats::of(&setup, f, inputs.poses, &[], None)
            .1
            .inside
            .inside_pct
    };
    let rest = &inputs.garment.positions;
    let tri = &inputs.garment.triangles;
    let sims_plaus: Vec<Plausibility> = inputs
        .simulations
        .iter()
        .map(|s| plausibility::of(rest, tri, s))
        .collect();
    let mean_plaus = |f: fn(&Plausibility) -> f64| sims_plaus.iter().map(f).sum::<f64>() / n as f64;
    let simulations = Plausibility {
        strain_mean_pct: mean_plaus(|p| p.strain_mean_pct),
        strain_p99_pct: mean_plaus(|p| p.strain_p99_pct),
        jitter_mm: mean_plaus(|p| p.jitter_mm),
    };
    let simulations_inside_pct =
        inputs.simulations.iter().map(|s| inside(s)).sum::<f64>() / n as f64;
    let mut caches = Vec::new();
    let mean = settings.with_mean.then(|| Cache {
        name: RUNS_MEAN.into(),
        frames: Frames::new(ensemble.mean().to_vec(), inputs.fps),
        model: None,
    });
    let all: Vec<&Cache> = inputs.caches.iter().chain(mean.as_ref()).collect();
    let mut cache_centroids = Vec::new();
    for &cache in &all {
        let horizon_mm = match &cache.model {
            Some(model) => restarted_horizon(
                model,
                &ensemble,
                inputs.poses,
                &starts,
                k,
                settings,
                &cache.name,
            )?,
            None => ensemble.horizon(&starts, k, |_, t0| {
                Ok::<_, anyhow::Error>(cache.frames[t0..=t0 + k].to_vec())
            })?,
        };
        let r = residual(&cache.frames);
        let centroid = hem::centroid(&r);
        let spectrum = hem::power_spectrum(&r, inputs.fps);
        let own_parts = hem::parts(&r, &centroid);
        let parts = parts_of_runs
            .iter()
            .enumerate()
            .map(|(p, runs)| PartScore {
                part: runs.part,
                correlation_with_each: mean_of(
                    run_parts
                        .iter()
                        .map(|s| hem::correlation(&own_parts[p], &s[p]))
                        .collect(),
                ),
                amplitude_ratio: hem::amplitude_mm(&own_parts[p]) / runs.amplitude_mm.max(1e-12),
                // An axis part is its centroid's coordinate at every vertex: time one series.
                behind_the_runs: if p < 3 {
                    hem::axis_lag(&centroid, &runs_mean_centroid, p, max_lag, inputs.fps)
                } else {
                    hem::trace_lag(&own_parts[p], &runs_mean_parts[p], max_lag, inputs.fps)
                },
            })
            .collect();
        let hem_score = HemScore {
            correlation_with_mean: hem::correlation(&r, &runs_mean),
            correlation_with_each: mean_of(runs.iter().map(|s| hem::correlation(&r, s)).collect()),
            amplitude_ratio: hem::amplitude_mm(&r) / sims_amplitude.max(1e-12),
            behind_the_runs: behind(&centroid, &runs_mean_centroid),
            swing: swing(&r, &centroid),
            parts,
        };
        cache_centroids.push(centroid);
        caches.push(CacheReport {
            name: cache.name.clone(),
            score: ensemble.score(&cache.frames),
            horizon_mm,
            restarted: cache.model.is_some(),
            hem: hem_score,
            spectrum,
            plausibility: plausibility::of(rest, tri, &cache.frames),
            inside_pct: inside(&cache.frames),
        });
    }
    let report = Report {
        frames,
        fps: inputs.fps,
        spread: ensemble.spread(),
        horizon: k,
        divergence: ensemble.divergence(&starts, k),
        starts,
        hem: HemEnsemble {
            vertices: hem_loop.len(),
            baseline: inputs.baseline.map(|b| inputs.caches[b].name.clone()),
            mutual_correlation: mutual,
            correlation_with_the_others: with_others,
            runs: run_swings,
            behind_the_others,
            amplitude_mm: sims_amplitude,
            spectrum: sims_spectrum,
            parts: parts_of_runs,
        },
        simulations,
        simulations_inside_pct,
        caches,
        horizon_png: settings.horizon_png.clone(),
        hem_png: settings.hem_png.clone(),
    };
    if let Some(path) = &settings.horizon_png {
        crate::preview::save_png(&horizon_chart(&report), path)
            .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    }
    if let Some(path) = &settings.hem_png {
        let mut traces: Vec<(String, Vec<f64>)> = run_centroids
            .iter()
            .enumerate()
            .map(|(i, c)| (format!("sim {i}"), forward(c)))
            .collect();
        traces.push(("sims mean".into(), forward(&runs_mean_centroid)));
        for (c, centroid) in all.iter().zip(&cache_centroids) {
            traces.push((c.name.clone(), forward(centroid)));
        }
        crate::preview::save_png(&hem_chart(&report, &traces, n), path)
            .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    }
    Ok(report)
}

/// e(k) of a dynamic model restarted from every run's state (its last three frames, so it
/// starts moving as simulated) at each start, `horizon` frames each.
fn restarted_horizon(
    model: &ModelFile,
    ensemble: &Ensemble,
    poses: &[Vec<JointTransform>],
    starts: &[usize],
    horizon: usize,
    settings: &Settings,
    name: &str,
) -> Result<Vec<f64>> {
    let total = (ensemble.runs().len() * starts.len() * horizon) as u64;
    let bar = crate::progress::bar(total, &format!("{name} e(k)"), settings.hide_bar);
    let mut done = 0u64;
    let curve = ensemble.horizon(starts, horizon, |i, t0| {
        let run = &ensemble.runs()[i];
        let init = Init::Moving(run[t0.saturating_sub(2)..=t0].to_vec());
        let played = for_model(
            model,
            poses,
            t0..t0 + horizon + 1,
            &init,
            settings.rollout.clone(),
            &mut |f| bar.set_position(done + f as u64),
        )?;
        done += horizon as u64;
        Ok::<_, anyhow::Error>(played.frames.into_points())
    });
    bar.finish_and_clear();
    curve
}

/// A hem residual's centroid along the waist frame's forward axis (+z at rest), mm.
fn forward(centroid: &[[f64; 3]]) -> Vec<f64> {
    centroid.iter().map(|p| 1e3 * p[2]).collect()
}

const SIM_GREY: [u8; 3] = [150, 150, 150];
const BLACK: [u8; 3] = [20, 20, 20];

fn horizon_chart(r: &Report) -> image::RgbImage {
    let ks = |v: &[f64]| -> Vec<(f64, f64)> {
        v.iter()
            .enumerate()
            .map(|(i, &y)| ((i + 1) as f64, y))
            .collect()
    };
    let mut lines = vec![
        Line {
            label: "sims from a common start (frame 0)".into(),
            points: ks(&r.divergence.from_the_start_mm),
            color: BLACK,
            width: 2,
        },
        Line {
            label: "two runs at the same frames (sqrt2 sigma)".into(),
            points: ks(&r.divergence.pairwise_mm),
            color: SIM_GREY,
            width: 2,
        },
        Line {
            label: "sigma (where the mean of the runs sits)".into(),
            points: ks(&r.divergence.sigma_mm),
            color: [200, 200, 200],
            width: 1,
        },
    ];
    for (c, color) in r.caches.iter().zip(LINE_COLORS.iter().cycle()) {
        lines.push(Line {
            label: format!(
                "{}{}",
                c.name,
                if c.restarted { " (restarted)" } else { "" }
            ),
            points: ks(&c.horizon_mm),
            color: *color,
            width: 2,
        });
    }
    line_chart(
        &Chart {
            title: format!("error k frames after a restart ({} starts)", r.starts.len()),
            x_label: "k (frames)".into(),
            y_label: "RMS mm".into(),
            lines,
            y_from_zero: true,
        },
        900,
        520,
    )
}

fn hem_chart(r: &Report, traces: &[(String, Vec<f64>)], runs: usize) -> image::RgbImage {
    let seconds = |v: &[f64]| -> Vec<(f64, f64)> {
        v.iter()
            .enumerate()
            .map(|(t, &y)| (t as f64 / f64::from(r.fps), y))
            .collect()
    };
    let mut colors = LINE_COLORS.iter().cycle();
    let lines = traces
        .iter()
        .enumerate()
        .map(|(i, (name, v))| Line {
            label: name.clone(),
            points: seconds(v),
            color: match i {
                i if i < runs => SIM_GREY,
                i if i == runs => BLACK,
                _ => *colors.next().unwrap_or(&BLACK),
            },
            width: if i < runs { 1 } else { 2 },
        })
        .collect();
    let base = r.hem.baseline.as_deref().unwrap_or("none");
    let traces = line_chart(
        &Chart {
            title: format!("hem forward swing in the waist frame beyond {base}"),
            x_label: "time (s)".into(),
            y_label: "mm".into(),
            lines,
            y_from_zero: false,
        },
        1100,
        420,
    );
    let mut colors = LINE_COLORS.iter().cycle();
    let power = |s: &[hem::Bin]| -> Vec<(f64, f64)> {
        s.iter()
            .skip(1)
            .filter(|b| b.hz <= 5.0)
            .map(|b| (b.hz, b.power_mm2))
            .collect()
    };
    let mut lines = vec![Line {
        label: "sims (mean power)".into(),
        points: power(&r.hem.spectrum),
        color: BLACK,
        width: 2,
    }];
    lines.extend(r.caches.iter().map(|c| Line {
        label: c.name.clone(),
        points: power(&c.spectrum),
        color: *colors.next().unwrap_or(&BLACK),
        width: 2,
    }));
    let spectrum = line_chart(
        &Chart {
            title: "hem residual power spectrum (to 5 Hz)".into(),
            x_label: "Hz".into(),
            y_label: "mm2".into(),
            lines,
            y_from_zero: true,
        },
        1100,
        360,
    );
    stack(&[traces, spectrum])
}

/// The report for a person: the simulations' spread, each cache's RMS and own error, e(k), the
/// hem, plausibility, and the plots written.
impl std::fmt::Display for Report {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        let r = self;
        let s = &r.spread;
        writeln!(
            f,
            "{} simulations, {} frames at {} fps: σ {:.1} mm over the clip ({:.1} over the first 50 frames); two runs {:.1} mm RMS apart; a run from the others' mean {:.1} mm",
            s.runs, r.frames, r.fps, s.sigma_mm.clip, s.sigma_mm.first_50, s.pairwise_rms_mm.clip, s.from_the_others_rms_mm.clip
        )?;
        writeln!(f, "RMS vertex error, mm (first 50 frames / whole clip); own = √(RMS² − σ²): a re-run scores σ, the runs' mean 0")?;
        writeln!(
            f,
            "  {:<12} {:>15} {:>15} {:>15}",
            "cache", "RMS", "own b", "vs mean garment"
        )?;
        let pair = |a: f64, b: f64| format!("{a:.1} / {b:.1}");
        for c in &r.caches {
            let sc = &c.score;
            writeln!(
                f,
                "  {:<12} {:>15} {:>15} {:>15}",
                c.name,
                pair(sc.rms_mm.first_50, sc.rms_mm.clip),
                pair(sc.own_mm.first_50, sc.own_mm.clip),
                pair(sc.against_mean_rms_mm.first_50, sc.against_mean_rms_mm.clip)
            )?;
        }
        let at = |v: &[f64]| {
            [1usize, 10, 25, 50]
                .iter()
                .filter(|&&k| k <= v.len())
                .map(|&k| format!("{:.1}", v[k - 1]))
                .collect::<Vec<_>>()
                .join(" / ")
        };
        writeln!(
            f,
            "error k = 1 / 10 / 25 / 50 frames after a restart (RMS mm, {} starts × {} runs):",
            r.starts.len(),
            s.runs
        )?;
        let d = &r.divergence;
        writeln!(
            f,
            "  simulations from a common start (frame 0, {:.1} mm apart): {}",
            d.start_mm,
            at(&d.from_the_start_mm)
        )?;
        writeln!(
            f,
            "  two runs at the same frames (√2 σ): {}; σ: {}",
            at(&d.pairwise_mm),
            at(&d.sigma_mm)
        )?;
        for c in &r.caches {
            writeln!(
                f,
                "  {}{}: {}",
                c.name,
                if c.restarted { " (restarted)" } else { "" },
                at(&c.horizon_mm)
            )?;
        }
        let h = &r.hem;
        let opt = |v: Option<f64>| v.map_or("—".to_string(), |x| format!("{x:.2}"));
        let lag = |l: &Option<crate::metrics::hem::Lag>| {
            l.map_or("—".to_string(), |l| {
                format!("{:+.2} s ({:+.2})", l.seconds, l.correlation)
            })
        };
        writeln!(
            f,
            "hem ({} vertices) in the waist frame beyond {}: the runs' swing {:.1} mm RMS, mutual correlation {} (each against the others' mean {}), lag behind the pelvis {}",
            h.vertices,
            h.baseline.as_deref().unwrap_or("nothing (no --baseline)"),
            h.amplitude_mm,
            opt(h.mutual_correlation),
            opt(h.correlation_with_the_others),
            h.runs.iter().map(|s| lag(&s.lag)).collect::<Vec<_>>().join(", ")
        )?;
        writeln!(
            f,
            "  each run's hem behind the others' mean: {}",
            h.behind_the_others
                .iter()
                .map(lag)
                .collect::<Vec<_>>()
                .join(", ")
        )?;
        let spectrum = |s: &crate::metrics::hem::SpectrumSummary| {
            format!(
                "peak {:.2} Hz, centroid {:.2} Hz, {:.0} % above 1 Hz",
                s.peak_hz, s.centroid_hz, s.above_1hz_pct
            )
        };
        if let Some(first) = h.runs.first() {
            writeln!(
                f,
                "  the runs' spectrum (run 0): {}",
                spectrum(&first.spectrum)
            )?;
        }
        for c in &r.caches {
            let m = &c.hem;
            writeln!(
                f,
                "  {:<12} correlation with the runs' mean {}, with each {}, amplitude ratio {:.2}, lag {}, behind the runs {}, {}",
                c.name,
                opt(m.correlation_with_mean),
                opt(m.correlation_with_each),
                m.amplitude_ratio,
                lag(&m.swing.lag),
                lag(&m.behind_the_runs),
                spectrum(&m.swing.spectrum)
            )?;
        }
        let part = |c: Option<f64>, amplitude: String| format!("{} ({amplitude})", opt(c));
        let late = |l: &Option<crate::metrics::hem::Lag>| {
            l.map_or("—".to_string(), |l| format!("{:+.2} s", l.seconds))
        };
        writeln!(
            f,
            "hem parts, correlation (amplitude): {}",
            h.parts
                .iter()
                .map(|p| p.part)
                .collect::<Vec<_>>()
                .join(" / ")
        )?;
        writeln!(
            f,
            "  {:<12} {} (mutual; mm RMS)",
            "runs",
            h.parts
                .iter()
                .map(|p| part(p.mutual_correlation, format!("{:.1}", p.amplitude_mm)))
                .collect::<Vec<_>>()
                .join(" / ")
        )?;
        for c in &r.caches {
            writeln!(
                f,
                "  {:<12} {} (with each run; × the runs', behind them)",
                c.name,
                c.hem
                    .parts
                    .iter()
                    .map(|p| part(
                        p.correlation_with_each,
                        format!("{:.2}, {}", p.amplitude_ratio, late(&p.behind_the_runs))
                    ))
                    .collect::<Vec<_>>()
                    .join(" / ")
            )?;
        }
        writeln!(
            f,
            "plausibility: strain mean / p99 %, inside the body %, jitter mm"
        )?;
        let p = &r.simulations;
        writeln!(
            f,
            "  {:<12} {:.2} / {:.2}, {:.3}, {:.2}",
            "simulations",
            p.strain_mean_pct,
            p.strain_p99_pct,
            r.simulations_inside_pct,
            p.jitter_mm
        )?;
        for c in &r.caches {
            let p = &c.plausibility;
            writeln!(
                f,
                "  {:<12} {:.2} / {:.2}, {:.3}, {:.2}",
                c.name, p.strain_mean_pct, p.strain_p99_pct, c.inside_pct, p.jitter_mm
            )?;
        }
        for path in [&r.horizon_png, &r.hem_png].into_iter().flatten() {
            writeln!(f, "wrote {}", path.display())?;
        }
        Ok(())
    }
}
