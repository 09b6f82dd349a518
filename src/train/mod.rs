//! Training: the machinery every model kind shares (the epoch loop with its progress bar and JSON
//! log, checkpoints, the NaN guard, Adam) and each kind's trainer (`pbns`; the dynamic one next).

pub mod adam;
pub mod dynamic;
pub mod losses;
pub mod motion;
pub mod nearest;
pub mod pbns;
pub mod poses;

use anyhow::{Context, Result};
use serde::Serialize;
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
    /// Hide the progress bar (machine output).
    pub quiet: bool,
    /// Append one JSON object per epoch to this file (JSON lines).
    pub log: Option<&'a Path>,
}

/// What the loop did.
#[derive(Clone, Debug, Serialize)]
pub struct Fitted {
    pub out: PathBuf,
    pub checkpoint: PathBuf,
    pub epochs: usize,
    pub seconds: f64,
    /// Wall time spent writing checkpoints.
    pub checkpoint_seconds: f64,
}

/// `runs/skirt.safetensors` → `runs/skirt.ckpt.safetensors`.
pub fn checkpoint_path(out: &Path) -> PathBuf {
    let stem = out
        .file_stem()
        .map_or("model".into(), |s| s.to_string_lossy().into_owned());
    out.with_file_name(format!("{stem}.ckpt.safetensors"))
}

/// Trains up to `opts.epochs`: a checkpoint after every epoch, the final model at `opts.out`.
/// A blow-up stops with an error that says which checkpoint survives.
pub fn fit<T: Training>(trainer: &mut T, opts: &FitOptions) -> Result<Fitted> {
    let started = Instant::now();
    if let Some(dir) = opts.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    let ckpt = checkpoint_path(opts.out);
    let mut log = opts.log.map(open_log).transpose()?;
    let bar = crate::progress::bar(
        opts.epochs.saturating_sub(trainer.epochs_done()) as u64,
        "epochs",
        opts.quiet,
    );
    let mut checkpoint_seconds = 0.0;
    while trainer.epochs_done() < opts.epochs {
        let epoch_start = Instant::now();
        let record = trainer.run_epoch().map_err(|b| {
            bar.abandon();
            blown_up(b, trainer.epochs_done(), &ckpt)
        })?;
        let save_start = Instant::now();
        trainer.save(&ckpt, true)?;
        let save_s = save_start.elapsed().as_secs_f64();
        checkpoint_seconds += save_s;
        bar.set_message(T::describe(&record));
        bar.inc(1);
        if let Some((path, w)) = &mut log {
            let line = log_line(&record, epoch_start.elapsed().as_secs_f64(), save_s)?;
            writeln!(w, "{line}").with_context(|| format!("writing {}", path.display()))?;
        }
    }
    bar.finish_and_clear();
    trainer.save(opts.out, false)?;
    Ok(Fitted {
        out: opts.out.to_path_buf(),
        checkpoint: ckpt,
        epochs: trainer.epochs_done(),
        seconds: started.elapsed().as_secs_f64(),
        checkpoint_seconds,
    })
}

type Log = (PathBuf, std::io::LineWriter<std::fs::File>);

fn open_log(path: &Path) -> Result<Log> {
    let file = std::fs::File::create(path)
        .with_context(|| format!("cannot create log {}", path.display()))?;
    Ok((path.to_path_buf(), std::io::LineWriter::new(file)))
}

/// The record with the epoch's wall time and checkpoint time added.
fn log_line(record: &impl Serialize, seconds: f64, checkpoint: f64) -> Result<String> {
    let mut v = serde_json::to_value(record)?;
    if let Some(map) = v.as_object_mut() {
        map.insert("seconds".into(), seconds.into());
        map.insert("checkpoint_seconds".into(), checkpoint.into());
    }
    Ok(v.to_string())
}

fn blown_up(b: Blowup, epochs_done: usize, ckpt: &Path) -> anyhow::Error {
    let kept = if epochs_done > 0 {
        format!(
            "the checkpoint of epoch {epochs_done} is kept: {}",
            ckpt.display()
        )
    } else {
        "no epoch finished, so there is no checkpoint".to_string()
    };
    anyhow::anyhow!("{b}; {kept} (lower --lr or the fabric's λ for that term, then --resume)")
}
