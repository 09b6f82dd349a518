//! A yardstick for the dynamic model: the garment predicted from the body's pose alone, with no
//! garment history. A ridge regression from the body drive `u_t` (the motion stage's pose
//! features, optionally with earlier frames' too) to the frozen space's latent of each simulated
//! training frame, decoded on a held-out clip and compared with its simulation(s) in mm.
//!
//! It cannot drift (nothing is fed back), so over a long clip it shows how much of the roll-out's
//! error the pose alone already explains; the first 50 frames show what the dynamics add.
//!
//! `cargo run --release --example pose_regression -- MODEL.safetensors MOTIONS.txt EVAL.bvh
//! SIM.pc2 [MORE_SIMS.pc2 ...] [--lags 0,2,5]`
//! `MOTIONS.txt`: the training clips as `--motion A.bvh --sim A.pc2 ...` (what
//! `scripts/skirt_takes.sh` writes). Every simulation of the held-out clip is compared, and so
//! is their mean.

use anyhow::{bail, Context, Result};
use garmentbake::models::dynamic::motion::body_drive;
use garmentbake::models::dynamic::settle::PoseRegression;
use garmentbake::models::dynamic::{BodyAnchors, Dynamic, MotionShape};
use garmentbake::models::file::{self, ModelFile};
use garmentbake::train::dynamic::{deviation, FrameData, Sequence};
use garmentbake::train::motion::{drive_joints, history_indices};
use std::path::Path;
use tch::{Device, Kind, Tensor};

/// Relative ridge penalties tried (times each feature column's mean square).
const RIDGES: [f64; 4] = [1e-3, 1e-2, 1e-1, 1.0];
/// Frames the "first 50" figure covers (after frame 0, the simulation's own).
const FIRST: i64 = 50;

fn main() -> Result<()> {
    tch::set_num_threads(2);
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let lags = take_lags(&mut args)?;
    let [model, motions, eval_motion, sims @ ..] = args.as_slice() else {
        bail!("usage: pose_regression MODEL MOTIONS.txt EVAL.bvh SIM.pc2 [SIM.pc2 ...] [--lags 0,2,5]");
    };
    if sims.is_empty() {
        bail!("give at least one simulation of {eval_motion}");
    }
    let file = file::load(Path::new(model), Device::Cpu)?;
    let dynamic = file.dynamic()?;
    let info = file.info.dynamic()?;
    let anchors = BodyAnchors::from_vertices(&file.body, &info.anchors, &info.anchor_parts)?;
    let mut shape = MotionShape::for_space(&info.shape.encoder, 1);
    shape.drive_joints = drive_joints(&file);
    let data = |pairs: &[(String, String)]| -> Result<FrameData> {
        Ok(FrameData::new(
            &file.body,
            &anchors,
            &sequences(&file, pairs, info.fps)?,
            Device::Cpu,
        ))
    };
    let train = data(&training_pairs(motions)?)?;
    let evals: Vec<FrameData> = sims
        .iter()
        .map(|s| data(&[(eval_motion.clone(), s.clone())]))
        .collect::<Result<_>>()?;
    let features = |d: &FrameData| {
        lagged(
            d,
            &body_drive(
                &d.body.select(&history_indices(d, Device::Cpu)[0]),
                &d.body,
                &shape,
                info.fps as f64,
            ),
            &lags,
        )
    };
    let (x, target) = (features(&train), latents(dynamic, &train));
    println!(
        "{} training frames, {} pose features (lags {lags:?}); {} held-out frames",
        train.len(),
        x.size()[1],
        evals[0].len()
    );
    let report = Report::new(&evals);
    let columns: Vec<String> = (1..=sims.len())
        .map(|k| format!("sim {k}"))
        .chain((sims.len() > 1).then(|| "their mean".into()))
        .collect();
    println!(
        "{:52} mean vertex L2 in mm, whole clip (first 50 frames) vs {}",
        "",
        columns.join(", ")
    );
    report.line(
        "space alone (its latents of the first simulation)",
        &decode(dynamic, &evals[0], &latents(dynamic, &evals[0])),
    );
    let xe = features(&evals[0]);
    for ridge in RIDGES {
        let pose = PoseRegression::fit(&x, &target, ridge);
        report.line(
            &format!("pose regression, ridge {ridge}"),
            &decode(dynamic, &evals[0], &pose.latent(&xe)),
        );
    }
    Ok(())
}

/// `--lags 0,2,5` (frames back; default 0: the current pose only), removed from `args`.
fn take_lags(args: &mut Vec<String>) -> Result<Vec<i64>> {
    let Some(at) = args.iter().position(|a| a == "--lags") else {
        return Ok(vec![0]);
    };
    let value = args
        .get(at + 1)
        .context("--lags needs a list, e.g. 0,2,5")?
        .clone();
    args.drain(at..at + 2);
    value
        .split(',')
        .map(|s| {
            s.parse::<i64>()
                .with_context(|| format!("--lags: {s} is not a frame count"))
        })
        .collect()
}

/// `--motion A --sim B` pairs of a motions file.
fn training_pairs(path: &str) -> Result<Vec<(String, String)>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {path}"))?;
    let words: Vec<&str> = text.split_whitespace().collect();
    words
        .chunks(4)
        .map(|w| match w {
            ["--motion", m, "--sim", s] => Ok((m.to_string(), s.to_string())),
            _ => bail!("{path}: expected `--motion A.bvh --sim A.pc2` pairs, got {w:?}"),
        })
        .collect()
}

fn sequences(file: &ModelFile, pairs: &[(String, String)], fps: f32) -> Result<Vec<Sequence>> {
    let (body, vertices) = (&file.body, file.garment.vertex_count());
    pairs
        .iter()
        .map(|(m, s)| {
            Sequence::load(
                Path::new(m),
                Path::new(s),
                &Default::default(),
                body,
                Some(fps),
                vertices,
            )
        })
        .collect()
}

/// The frozen space's latent of every frame `[F, L]`.
fn latents(model: &Dynamic, d: &FrameData) -> Tensor {
    garmentbake::models::predict_chunks(d.len(), |s, n| {
        let (g, b, m) = d.batch(&d.range(s, n));
        model.space.encode(&g, &b, &m)
    })
}

fn decode(model: &Dynamic, d: &FrameData, z: &Tensor) -> Tensor {
    tch::no_grad(|| {
        model
            .space
            .skin(&model.space.canonical(z), &d.body.transforms)
    })
}

/// `[1, u_{t−k} for k in lags]` per frame, held at each clip's first frame.
fn lagged(d: &FrameData, u: &Tensor, lags: &[i64]) -> Tensor {
    let mut ends = d.clip_starts[1..].to_vec();
    ends.push(d.len());
    let rows: Vec<Tensor> = d
        .clip_starts
        .iter()
        .zip(&ends)
        .map(|(&s, &e)| {
            let len = (e - s) as i64;
            let clip = u.narrow(0, s as i64, len);
            let cols: Vec<Tensor> = lags
                .iter()
                .map(|&k| {
                    let back: Vec<i64> = (0..len).map(|t| (t - k).max(0)).collect();
                    clip.index_select(0, &Tensor::from_slice(&back))
                })
                .collect();
            Tensor::cat(&cols, 1)
        })
        .collect();
    Tensor::cat(&rows, 0)
}

/// Mean vertex L2 against each simulation and their mean, over the whole clip and its first
/// 50 predicted frames (frame 0 left out: a roll-out starts from the simulation there).
struct Report {
    truths: Vec<Tensor>,
    frames: i64,
}

impl Report {
    fn new(evals: &[FrameData]) -> Report {
        let frames = evals.iter().map(|e| e.len() as i64).min().unwrap_or(0);
        let mut truths: Vec<Tensor> = evals
            .iter()
            .map(|e| e.garment.narrow(0, 0, frames))
            .collect();
        if truths.len() > 1 {
            truths.push(Tensor::stack(&truths, 0).mean_dim(0, false, Kind::Float));
        }
        Report { truths, frames }
    }

    fn line(&self, name: &str, pred: &Tensor) {
        let n = self.frames - 1;
        let pred = pred.narrow(0, 1, n);
        let cells: Vec<String> = self
            .truths
            .iter()
            .map(|t| {
                let t = t.narrow(0, 1, n);
                let whole = deviation(&pred, &t).mean_mm;
                let first = deviation(
                    &pred.narrow(0, 0, FIRST.min(n)),
                    &t.narrow(0, 0, FIRST.min(n)),
                )
                .mean_mm;
                format!("{whole:6.1} ({first:5.1})")
            })
            .collect();
        println!("{name:52} {}", cells.join("  "));
    }
}
