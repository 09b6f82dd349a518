//! Running jobs: one job as a child `garmentbake` process (its own log, killable, a crash stays
//! in it), skipped when its outputs already carry its key; and the local runner, which keeps up
//! to N jobs going in dependency order and skips the dependents of a failed job.

use super::ledger::{out_of_space, Ledger};
use super::plan::{Job, Plan};
use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Status {
    /// Ran and succeeded; its outputs now carry its key.
    Ran,
    /// Not run: its outputs already carried its key.
    UpToDate,
    /// Ran and failed (after its retries).
    Failed,
    /// Not run: a job it depends on failed or was skipped.
    Skipped,
}

impl Status {
    /// The status in a summary line: a failure stands out.
    pub fn word(self) -> &'static str {
        match self {
            Status::Ran => "ran",
            Status::UpToDate => "up to date",
            Status::Failed => "FAILED",
            Status::Skipped => "skipped",
        }
    }

    pub fn ok(self) -> bool {
        matches!(self, Status::Ran | Status::UpToDate)
    }
}

/// What became of one job.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Outcome {
    pub id: String,
    pub status: Status,
    /// Wall time of the runs of its command (0 when not run).
    pub seconds: f64,
    pub attempts: usize,
    pub outputs: Vec<PathBuf>,
    /// Key figures from the command's report (replay error, inside %, ...).
    pub metrics: BTreeMap<String, f64>,
    /// Why it failed or was skipped: the command's `error:` line names the file. On a job that
    /// ran: its report could not be read into the command's report type (a bug to report).
    pub error: Option<String>,
    pub log: PathBuf,
}

impl Outcome {
    fn of(job: &Job, status: Status) -> Outcome {
        Outcome {
            id: job.id.clone(),
            status,
            seconds: 0.0,
            attempts: 0,
            outputs: job.outputs.clone(),
            metrics: BTreeMap::new(),
            error: None,
            log: job.log.clone(),
        }
    }

    /// The job's line in a summary: status, time, key figures, outputs (relative to `out`), and
    /// the error on a line of its own.
    pub fn line(&self, out: &Path) -> String {
        let figures: Vec<String> = self
            .metrics
            .iter()
            .map(|(k, v)| format!("{k} {v:.3}"))
            .collect();
        let files: Vec<String> = self
            .outputs
            .iter()
            .map(|p| p.strip_prefix(out).unwrap_or(p).display().to_string())
            .collect();
        let mut s = format!(
            "{:<44} {:<10} {:>7.1} s  {:<34} {}",
            self.id,
            self.status.word(),
            self.seconds,
            figures.join(", "),
            files.join(" ")
        );
        if let Some(e) = &self.error {
            s.push_str(&format!("\n    {e}"));
        }
        s
    }

    /// A job not run because `upstream` did not succeed.
    pub fn skipped(job: &Job, upstream: &str) -> Outcome {
        Outcome {
            error: Some(format!("not run: {upstream} did not succeed")),
            ..Outcome::of(job, Status::Skipped)
        }
    }
}

/// `FILE.key` beside an output: the key of the job that wrote it.
pub fn key_path(path: &Path) -> PathBuf {
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(".key");
    path.with_file_name(name)
}

/// Reads a job's `--json` report into its key figures, given the job's kind: through the
/// commands' own report types, which live above this layer (the CLI passes `cli::figures`).
pub type Figures = dyn Fn(&str, &[u8]) -> Result<BTreeMap<String, f64>> + Sync;

/// Every output (and the report) is there and carries the job's key.
pub fn up_to_date(job: &Job) -> bool {
    job.outputs
        .iter()
        .chain([&job.report])
        .all(|p| p.is_file() && std::fs::read_to_string(key_path(p)).is_ok_and(|k| k == job.key))
}

/// Runs `job` with the binary `exe` unless it is up to date, retrying up to `retries` times a
/// run that ended for a reason other than bad input (exit 2) or a failed check (exit 1): a
/// crash, a kill, a lost machine. What it writes (folders, log, report, keys) goes in `ledger`;
/// a job that succeeds keeps its files there.
pub fn run_job(
    job: &Job,
    exe: &Path,
    retries: usize,
    figures: &Figures,
    ledger: &Ledger,
) -> Outcome {
    if up_to_date(job) {
        let mut done = Outcome::of(job, Status::UpToDate);
        let report = std::fs::read(&job.report)
            .with_context(|| format!("cannot read {}", job.report.display()));
        read_figures(&mut done, job, report.and_then(|r| figures(&job.kind, &r)));
        return done;
    }
    let mut outcome = Outcome::of(job, Status::Failed);
    let start = Instant::now();
    match attempts(job, exe, retries, figures, ledger, &mut outcome) {
        Ok(()) => {
            outcome.status = Status::Ran;
            let files = job.outputs.iter().chain([&job.report]);
            let keys: Vec<PathBuf> = files.clone().map(|p| key_path(p)).collect();
            ledger.keep(files.chain(&keys).chain([&job.log]));
        }
        Err(e) => outcome.error = Some(one_line(&e)),
    }
    outcome.seconds = start.elapsed().as_secs_f64();
    outcome
}

fn one_line(e: &anyhow::Error) -> String {
    format!("{e:#}").replace('\n', " ")
}

/// The figures of `job`'s report, or why there are none: a report that does not read as its
/// command's is said, not skipped (the job's outputs still stand).
fn read_figures(outcome: &mut Outcome, job: &Job, figures: Result<BTreeMap<String, f64>>) {
    match figures {
        Ok(f) => {
            outcome.metrics = f;
            outcome.error = None;
        }
        Err(e) => {
            outcome.metrics.clear();
            outcome.error = Some(format!(
                "{}: not a `{}` report: {}",
                job.report.display(),
                job.kind,
                one_line(&e)
            ));
        }
    }
}

fn attempts(
    job: &Job,
    exe: &Path,
    retries: usize,
    figures: &Figures,
    ledger: &Ledger,
    outcome: &mut Outcome,
) -> Result<()> {
    // A stale key must not vouch for what this run is about to replace.
    for p in job.outputs.iter().chain([&job.report]) {
        let _ = std::fs::remove_file(key_path(p));
        if let Some(dir) = p.parent() {
            ledger
                .create_dir_all(dir)
                .with_context(|| format!("cannot create {}", dir.display()))?;
        }
    }
    let logs = job.log.parent().unwrap_or(Path::new("."));
    ledger
        .create_dir_all(logs)
        .with_context(|| format!("cannot create {}", logs.display()))?;
    let mut log = ledger
        .create(&job.log)
        .with_context(|| format!("cannot write {}", job.log.display()))?;
    loop {
        outcome.attempts += 1;
        writeln!(
            log,
            "# attempt {}: {} {}",
            outcome.attempts,
            exe.display(),
            job.args.join(" ")
        )?;
        let child = Command::new(exe)
            .args(&job.args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(log.try_clone()?)
            .output()
            .with_context(|| format!("cannot run {}", exe.display()));
        let run = match child {
            Ok(run) => run,
            Err(e) if outcome.attempts <= retries => {
                writeln!(log, "# {e:#}")?;
                continue;
            }
            Err(e) => return Err(e),
        };
        // Any JSON is kept as the report, a failed check's too (its figures say by how much).
        let report = serde_json::from_slice::<serde::de::IgnoredAny>(&run.stdout).is_ok();
        if report {
            ledger.write(&job.report, &run.stdout)?;
            read_figures(outcome, job, figures(&job.kind, &run.stdout));
        }
        match run.status.code() {
            Some(0) if report => break,
            Some(0) => anyhow::bail!(
                "{} printed no JSON report (log: {})",
                job.id,
                job.log.display()
            ),
            Some(code @ (1 | 2)) => anyhow::bail!("{}", error_line(&job.log, code)),
            _ if outcome.attempts <= retries => {
                writeln!(log, "# {}: retrying", describe(&run.status))?;
            }
            _ => anyhow::bail!("{} (log: {})", describe(&run.status), job.log.display()),
        }
    }
    // Keys last, report's last of all: a job killed before this point runs again.
    for p in job.outputs.iter().chain([&job.report]) {
        ledger.write(&key_path(p), job.key.as_bytes())?;
    }
    Ok(())
}

fn describe(status: &std::process::ExitStatus) -> String {
    use std::os::unix::process::ExitStatusExt;
    match (status.code(), status.signal()) {
        (Some(c), _) => format!("exit code {c}"),
        (None, Some(s)) => format!("killed by signal {s}"),
        _ => status.to_string(),
    }
}

/// The command's own `error:` line (it names the file and the problem), else what exit 1 means.
fn error_line(log: &Path, code: i32) -> String {
    let text = std::fs::read_to_string(log).unwrap_or_default();
    match text.lines().rev().find(|l| l.starts_with("error: ")) {
        Some(line) => line.trim_start_matches("error: ").to_string(),
        None if code == 1 => "checks failed (exit 1; see the report)".into(),
        None => format!("exit code {code} (log: {})", log.display()),
    }
}

/// The job that stopped a run: it failed for lack of space (its own write or the runner's), so
/// the jobs after it would too. `batch run` then stops, takes back what it wrote
/// ([`Ledger::roll_back`]) and says so in one error line.
pub fn out_of_space_failure(outcomes: &[Outcome]) -> Option<&Outcome> {
    outcomes
        .iter()
        .find(|o| o.status == Status::Failed && o.error.as_deref().is_some_and(out_of_space))
}

/// Runs the plan here with up to `jobs` at a time; `done` hears of each job as it ends. A job
/// that fails for lack of space stops the run: no job starts after it (those left are skipped),
/// the running ones finish. Returns one outcome per job, in plan order.
pub fn run_local(
    plan: &Plan,
    exe: &Path,
    jobs: usize,
    retries: usize,
    figures: &Figures,
    ledger: &Ledger,
    done: &dyn Fn(&Outcome),
) -> Vec<Outcome> {
    let n = plan.jobs.len();
    let index: BTreeMap<&str, usize> = plan
        .jobs
        .iter()
        .enumerate()
        .map(|(i, j)| (j.id.as_str(), i))
        .collect();
    // Each job waits for `waiting[i]` dependencies; `blocked[i]` names one that did not succeed.
    let mut waiting: Vec<usize> = plan.jobs.iter().map(|j| j.deps.len()).collect();
    let mut dependents: Vec<Vec<usize>> = vec![vec![]; n];
    for (i, j) in plan.jobs.iter().enumerate() {
        for d in &j.deps {
            dependents[index[d.as_str()]].push(i);
        }
    }
    let mut blocked: Vec<Option<String>> = vec![None; n];
    let mut ready: std::collections::VecDeque<usize> =
        (0..n).filter(|&i| waiting[i] == 0).collect();
    let mut outcomes: Vec<Option<Outcome>> = vec![None; n];
    let (tx, rx) = std::sync::mpsc::channel::<(usize, Outcome)>();
    let mut stopped_by: Option<String> = None;
    std::thread::scope(|scope| {
        let mut running = 0;
        let mut finished = 0;
        while finished < n {
            while running < jobs.max(1) && stopped_by.is_none() {
                let Some(i) = ready.pop_front() else { break };
                running += 1;
                let (tx, job) = (tx.clone(), &plan.jobs[i]);
                scope.spawn(move || {
                    let _ = tx.send((i, run_job(job, exe, retries, figures, ledger)));
                });
            }
            if running == 0 {
                break; // stopped: nothing runs, nothing more starts
            }
            let (i, o) = rx.recv().expect("a job thread reports");
            running -= 1;
            if out_of_space_failure(std::slice::from_ref(&o)).is_some() {
                stopped_by.get_or_insert_with(|| o.id.clone());
            }
            // The finished job, then any dependents that are now skipped, in turn.
            let mut ended = vec![(i, o)];
            while let Some((i, o)) = ended.pop() {
                finished += 1;
                done(&o);
                for &k in &dependents[i] {
                    if !o.status.ok() && blocked[k].is_none() {
                        blocked[k] = Some(o.id.clone());
                    }
                    waiting[k] -= 1;
                    if waiting[k] == 0 {
                        match &blocked[k] {
                            Some(up) => ended.push((k, Outcome::skipped(&plan.jobs[k], up))),
                            None => ready.push_back(k),
                        }
                    }
                }
                outcomes[i] = Some(o);
            }
        }
    });
    outcomes
        .into_iter()
        .zip(&plan.jobs)
        .map(|(o, job)| match (o, &stopped_by) {
            (Some(o), _) => o,
            (None, Some(up)) => Outcome::skipped(job, up),
            (None, None) => Outcome::skipped(job, "the run"), // not reached: every job ends
        })
        .collect()
}
