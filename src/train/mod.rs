//! Training: the machinery every model kind shares (the epoch loop with its progress bar and JSON
//! log, checkpoints, the NaN guard, Adam) and each kind's trainer (`pbns`; the dynamic model's
//! generative space in `dynamic` and its motion stage in `motion`).

pub mod adam;
pub mod dynamic;
pub mod fused;
pub mod losses;
pub mod motion;
pub mod nearest;
pub mod pbns;
pub mod poses;
pub mod swing;
pub mod unroll;

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What the shared loop needs of one model kind's trainer.
pub trait Training {
    /// One epoch's record: a line of the JSON log, the progress bar's message.
    type Record: Serialize;
    fn epochs_done(&self) -> usize;
    fn run_epoch(&mut self) -> Result<Self::Record, Blowup>;
    /// Writes the model; with `checkpoint`, the optimiser state too (for resume).
    fn save(&mut self, path: &Path, checkpoint: bool) -> Result<()>;
    /// Continues from a checkpoint written by `save` for the same inputs and settings.
    fn resume(&mut self, checkpoint: &Path) -> Result<()>;
    /// A short line for the progress bar.
    fn describe(record: &Self::Record) -> String;
    /// Seconds spent so far inside `run_epoch` on validation and candidate upkeep (the rest is
    /// optimisation steps); a trainer without such phases keeps the default.
    fn phases(&self) -> TrainerPhases {
        TrainerPhases::default()
    }
    /// Why training should stop now (early stopping), checked after every epoch.
    fn stop_reason(&self) -> Option<String> {
        None
    }
}

/// Cumulative seconds a trainer spent on work beside its optimisation steps.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TrainerPhases {
    pub validation: f64,
    pub refresh: f64,
}

/// The loss became NaN or infinite.
#[derive(Debug, thiserror::Error)]
#[error("the loss became {value} at epoch {epoch}, step {step}: the {term} term blew up")]
pub struct Blowup {
    pub epoch: usize,
    pub step: usize,
    pub term: &'static str,
    pub value: f64,
}

impl Blowup {
    /// The first non-finite term of `terms` (name, value), as a blow-up at `epoch`/`step`.
    pub fn check(terms: &[(&'static str, f64)], epoch: usize, step: usize) -> Result<(), Blowup> {
        match terms.iter().find(|(_, v)| !v.is_finite()) {
            Some(&(term, value)) => Err(Blowup {
                epoch,
                step,
                term,
                value,
            }),
            None => Ok(()),
        }
    }
}

/// How the loop runs.
pub struct FitOptions<'a> {
    pub epochs: usize,
    pub out: &'a Path,
    /// Hide the terminal bar (a command's `--json`: machine output); progress still reaches a
    /// farm log (`progress::bar`). Silence is the global `--quiet` (`progress::set_quiet`).
    pub hide_bar: bool,
    /// Append one JSON object per epoch to this file (JSON lines).
    pub log: Option<&'a Path>,
}

/// A checkpoint after this many epochs or this much wall time since the last one, whichever
/// comes first; `--checkpoint-every 50`, `300s`, `5m` or `50,5m`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct CheckpointEvery {
    pub epochs: Option<usize>,
    pub seconds: Option<f64>,
}

impl CheckpointEvery {
    /// After every epoch.
    pub const EPOCH: CheckpointEvery = CheckpointEvery {
        epochs: Some(1),
        seconds: None,
    };

    fn due(&self, epochs_since: usize, seconds_since: f64) -> bool {
        self.epochs.is_some_and(|e| epochs_since >= e)
            || self.seconds.is_some_and(|s| seconds_since >= s)
    }
}

impl std::str::FromStr for CheckpointEvery {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let mut every = CheckpointEvery {
            epochs: None,
            seconds: None,
        };
        for part in s.split(',').map(str::trim) {
            let (number, unit) = match part.strip_suffix('s') {
                Some(n) => (n, 1.0),
                None => match part.strip_suffix('m') {
                    Some(n) => (n, 60.0),
                    None => (part, 0.0),
                },
            };
            let bad = || {
                format!(
                    "'{part}': expected epochs (50), seconds (300s) or minutes (5m), e.g. 50,5m"
                )
            };
            if unit == 0.0 {
                let e: usize = number.parse().map_err(|_| bad())?;
                if e == 0 {
                    return Err(bad());
                }
                every.epochs = Some(e);
            } else {
                let v: f64 = number.parse().map_err(|_| bad())?;
                if !(v.is_finite() && v > 0.0) {
                    return Err(bad());
                }
                every.seconds = Some(v * unit);
            }
        }
        Ok(every)
    }
}

/// Where the loop's wall time went (seconds).
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize)]
pub struct WallSplit {
    /// Optimisation steps (forward, losses, backward, the optimiser).
    pub steps: f64,
    /// Exact metrics on the validation poses.
    pub validation: f64,
    /// Candidate upkeep on the training thread (snapshots, installs, synchronous refreshes).
    pub refresh: f64,
    pub checkpoint: f64,
    pub logging: f64,
    /// The final model, the progress bar and the rest of the loop.
    pub other: f64,
}

impl WallSplit {
    pub fn total(&self) -> f64 {
        self.steps + self.validation + self.refresh + self.checkpoint + self.logging + self.other
    }
}

impl std::fmt::Display for WallSplit {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        let total = self.total().max(1e-12);
        let part = |name: &str, s: f64| format!("{name} {s:.1} s ({:.1} %)", 100.0 * s / total);
        write!(
            f,
            "wall {total:.1} s: {}, {}, {}, {}, {}, {}",
            part("steps", self.steps),
            part("validation", self.validation),
            part("candidate refresh", self.refresh),
            part("checkpoints", self.checkpoint),
            part("logging", self.logging),
            part("other", self.other)
        )
    }
}

/// What the loop did.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Fitted {
    pub out: PathBuf,
    pub checkpoint: PathBuf,
    pub epochs: usize,
    pub seconds: f64,
    /// Wall time spent writing checkpoints.
    pub checkpoint_seconds: f64,
    /// Checkpoints written, and the epoch of the last one.
    pub checkpoints: usize,
    pub checkpoint_epoch: usize,
    pub wall: WallSplit,
    /// Why training stopped before `epochs`, if it did.
    pub stopped_early: Option<String>,
}

/// `runs/skirt.safetensors` → `runs/skirt.ckpt.safetensors`.
pub fn checkpoint_path(out: &Path) -> PathBuf {
    let stem = out
        .file_stem()
        .map_or("model".into(), |s| s.to_string_lossy().into_owned());
    out.with_file_name(format!("{stem}.ckpt.safetensors"))
}

/// Trains up to `opts.epochs` with a checkpoint after every epoch (see [`fit_every`]).
pub fn fit<T: Training>(trainer: &mut T, opts: &FitOptions) -> Result<Fitted> {
    fit_every(trainer, opts, CheckpointEvery::EPOCH)
}

/// Trains up to `opts.epochs`: a checkpoint on `every` and after the last epoch, the final model
/// at `opts.out`. A blow-up stops with an error that says which checkpoint survives.
pub fn fit_every<T: Training>(
    trainer: &mut T,
    opts: &FitOptions,
    every: CheckpointEvery,
) -> Result<Fitted> {
    let started = Instant::now();
    if let Some(dir) = opts.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    let ckpt = checkpoint_path(opts.out);
    let mut log = opts.log.map(open_log).transpose()?;
    let bar = crate::progress::bar(
        opts.epochs.saturating_sub(trainer.epochs_done()) as u64,
        "epochs",
        opts.hide_bar,
    );
    let mut wall = WallSplit::default();
    // A resumed run starts from a checkpoint.
    let (mut checkpoints, mut checkpoint_epoch) = (0, trainer.epochs_done());
    let mut since_checkpoint = (trainer.epochs_done(), Instant::now());
    let mut stopped_early = None;
    while trainer.epochs_done() < opts.epochs {
        let before = trainer.phases();
        let epoch_start = Instant::now();
        let record = trainer.run_epoch().map_err(|b| {
            bar.abandon();
            blown_up(b, trainer.epochs_done(), checkpoint_epoch, &ckpt)
        })?;
        let epoch_s = epoch_start.elapsed().as_secs_f64();
        let after = trainer.phases();
        let split = EpochSplit {
            seconds: epoch_s,
            validation_seconds: after.validation - before.validation,
            refresh_seconds: after.refresh - before.refresh,
            checkpoint_seconds: 0.0,
        };
        wall.validation += split.validation_seconds;
        wall.refresh += split.refresh_seconds;
        wall.steps += epoch_s - split.validation_seconds - split.refresh_seconds;
        stopped_early = trainer.stop_reason();
        let last = trainer.epochs_done() >= opts.epochs || stopped_early.is_some();
        let due = every.due(
            trainer.epochs_done() - since_checkpoint.0,
            since_checkpoint.1.elapsed().as_secs_f64(),
        );
        let split = if due || last {
            let save_start = Instant::now();
            trainer.save(&ckpt, true)?;
            let save_s = save_start.elapsed().as_secs_f64();
            wall.checkpoint += save_s;
            checkpoints += 1;
            checkpoint_epoch = trainer.epochs_done();
            since_checkpoint = (checkpoint_epoch, Instant::now());
            EpochSplit {
                checkpoint_seconds: save_s,
                ..split
            }
        } else {
            split
        };
        let log_start = Instant::now();
        bar.set_message(T::describe(&record));
        bar.inc(1);
        if let Some((path, w)) = &mut log {
            let line = log_line(&record, &split)?;
            writeln!(w, "{line}").with_context(|| format!("writing {}", path.display()))?;
        }
        wall.logging += log_start.elapsed().as_secs_f64();
        if stopped_early.is_some() {
            break;
        }
    }
    bar.finish_and_clear();
    trainer.save(opts.out, false)?;
    let seconds = started.elapsed().as_secs_f64();
    wall.other = (seconds - wall.total()).max(0.0);
    Ok(Fitted {
        out: opts.out.to_path_buf(),
        checkpoint: ckpt,
        epochs: trainer.epochs_done(),
        seconds,
        checkpoint_seconds: wall.checkpoint,
        checkpoints,
        checkpoint_epoch,
        wall,
        stopped_early,
    })
}

/// One epoch's wall time and its parts beside the steps, as the JSON log records them.
#[derive(Clone, Copy, Debug, Serialize)]
struct EpochSplit {
    seconds: f64,
    validation_seconds: f64,
    refresh_seconds: f64,
    checkpoint_seconds: f64,
}

type Log = (PathBuf, std::io::LineWriter<std::fs::File>);

fn open_log(path: &Path) -> Result<Log> {
    let file = std::fs::File::create(path)
        .with_context(|| format!("cannot create log {}", path.display()))?;
    Ok((path.to_path_buf(), std::io::LineWriter::new(file)))
}

/// The record with the epoch's wall split added.
fn log_line(record: &impl Serialize, split: &EpochSplit) -> Result<String> {
    let mut v = serde_json::to_value(record)?;
    if let (Some(map), serde_json::Value::Object(times)) =
        (v.as_object_mut(), serde_json::to_value(split)?)
    {
        map.extend(times);
    }
    Ok(v.to_string())
}

fn blown_up(b: Blowup, epochs_done: usize, checkpoint_epoch: usize, ckpt: &Path) -> anyhow::Error {
    let kept = if epochs_done == 0 {
        "no epoch finished, so there is no checkpoint".to_string()
    } else if checkpoint_epoch > 0 {
        format!(
            "the checkpoint of epoch {checkpoint_epoch} is kept: {}",
            ckpt.display()
        )
    } else {
        format!("no checkpoint was written in the {epochs_done} epochs done (--checkpoint-every)")
    };
    anyhow::anyhow!("{b}; {kept} (lower --lr or the fabric's λ for that term, then --resume)")
}

/// Cosine decay from `rate` at the first epoch to a tenth of it at the last of `epochs`.
pub fn cosine_rate(rate: f64, epoch: usize, epochs: usize) -> f64 {
    let t = (epoch as f64 / (epochs.max(2) - 1) as f64).min(1.0);
    rate * (0.1 + 0.9 * 0.5 * (1.0 + (std::f64::consts::PI * t).cos()))
}
