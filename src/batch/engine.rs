//! A whole `batch run`: the plan saved beside its outputs, run on an engine (here, or the Ray
//! cluster), its outcomes counted into one report; and a run that stops for lack of space takes
//! back everything it wrote but the finished jobs' files.

use super::ledger::Ledger;
use super::plan::Plan;
use super::run::{out_of_space_failure, run_local, Figures, Outcome, Status};
use anyhow::{bail, Result};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Where the jobs run.
pub enum Engine<'a> {
    /// Here, this many jobs at a time.
    Local { jobs: usize },
    /// On the Ray cluster at this address (HOST:PORT of `ray start --head`).
    Ray { address: &'a str },
}

/// What `batch run` did.
#[derive(Serialize)]
pub struct RunReport {
    pub schema: &'static str,
    /// local or ray.
    pub engine: String,
    pub manifest: PathBuf,
    pub out: PathBuf,
    pub plan: PathBuf,
    pub wall_seconds: f64,
    pub ran: usize,
    pub up_to_date: usize,
    pub failed: usize,
    pub skipped: usize,
    pub jobs: Vec<Outcome>,
}

/// Runs `run` with a ledger of what it writes. A run that fails, or that stopped because a job
/// ran out of space, is one error, and the ledger takes back what it wrote.
pub fn all_or_nothing(run: impl FnOnce(&Ledger) -> Result<RunReport>) -> Result<RunReport> {
    let ledger = Ledger::default();
    let report = run(&ledger).and_then(|r| match out_of_space_failure(&r.jobs) {
        Some(o) => bail!(
            "{}: {}; the run stopped and took back what it wrote",
            o.id,
            o.error.as_deref().unwrap_or_default()
        ),
        None => Ok(r),
    });
    if report.is_err() {
        ledger.roll_back();
    }
    report
}

/// Saves `plan` as OUT/plan.json and runs it with the binary `exe` on `engine`; `done` hears of
/// each job as it ends (local runs).
pub fn run_plan(
    plan: &Plan,
    exe: &Path,
    engine: &Engine,
    retries: usize,
    figures: &Figures,
    ledger: &Ledger,
    done: &dyn Fn(&Outcome),
) -> Result<RunReport> {
    let saved = plan.out.join("plan.json");
    ledger.write(&saved, serde_json::to_string_pretty(plan)?.as_bytes())?;
    let start = Instant::now();
    let jobs = match engine {
        Engine::Ray { address } => super::ray::run(address, &saved, exe, retries)?,
        Engine::Local { jobs } => run_local(plan, exe, *jobs, retries, figures, ledger, done),
    };
    let count = |s: Status| jobs.iter().filter(|o| o.status == s).count();
    Ok(RunReport {
        schema: "garmentbake-batch-report/1",
        engine: match engine {
            Engine::Ray { .. } => "ray",
            Engine::Local { .. } => "local",
        }
        .into(),
        manifest: plan.manifest.clone(),
        out: plan.out.clone(),
        plan: saved,
        wall_seconds: start.elapsed().as_secs_f64(),
        ran: count(Status::Ran),
        up_to_date: count(Status::UpToDate),
        failed: count(Status::Failed),
        skipped: count(Status::Skipped),
        jobs,
    })
}
