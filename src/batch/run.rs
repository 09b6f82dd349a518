//! Running jobs: one job as a child `garmentbake` process (its own log, killable, a crash stays
//! in it), skipped when its outputs already carry its key; and the local runner, which keeps up
//! to N jobs going in dependency order and skips the dependents of a failed job.

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
    /// Why it failed or was skipped: the command's `error:` line names the file.
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

/// Every output (and the report) is there and carries the job's key.
pub fn up_to_date(job: &Job) -> bool {
    job.outputs
        .iter()
        .chain([&job.report])
        .all(|p| p.is_file() && std::fs::read_to_string(key_path(p)).is_ok_and(|k| k == job.key))
}

/// Runs `job` with the binary `exe` unless it is up to date, retrying up to `retries` times a
/// run that ended for a reason other than bad input (exit 2) or a failed check (exit 1): a
/// crash, a kill, a lost machine.
pub fn run_job(job: &Job, exe: &Path, retries: usize) -> Outcome {
    if up_to_date(job) {
        let mut done = Outcome::of(job, Status::UpToDate);
        done.metrics = std::fs::read(&job.report)
            .ok()
            .and_then(|b| serde_json::from_slice(&b).ok())
            .map(|r| metrics(&job.kind, &r))
            .unwrap_or_default();
        return done;
    }
    let mut outcome = Outcome::of(job, Status::Failed);
    let start = Instant::now();
    match attempts(job, exe, retries, &mut outcome) {
        Ok(()) => outcome.status = Status::Ran,
        Err(e) => outcome.error = Some(format!("{e:#}").replace('\n', " ")),
    }
    outcome.seconds = start.elapsed().as_secs_f64();
    outcome
}

fn attempts(job: &Job, exe: &Path, retries: usize, outcome: &mut Outcome) -> Result<()> {
    // A stale key must not vouch for what this run is about to replace.
    for p in job.outputs.iter().chain([&job.report]) {
        let _ = std::fs::remove_file(key_path(p));
        if let Some(dir) = p.parent() {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("cannot create {}", dir.display()))?;
        }
    }
    let logs = job.log.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(logs).with_context(|| format!("cannot create {}", logs.display()))?;
    let mut log = std::fs::File::create(&job.log)
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
        let report: Option<serde_json::Value> = serde_json::from_slice(&run.stdout).ok();
        if let Some(r) = &report {
            outcome.metrics = metrics(&job.kind, r);
            exporters::atomic::write_atomic(&job.report, &run.stdout)?;
        }
        match run.status.code() {
            Some(0) if report.is_some() => break,
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
        exporters::atomic::write_atomic(&key_path(p), job.key.as_bytes())?;
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

/// The figures a person scans the summary for, per kind of job.
pub fn metrics(kind: &str, r: &serde_json::Value) -> BTreeMap<String, f64> {
    let picks: &[(&str, &str, f64)] = match kind {
        "train" => &[
            ("edge_mm", "/last/train/edge_mm", 1.0),
            ("collided_pct", "/last/train/collided_pct", 1.0),
        ],
        "eval" => &[
            ("edge_mm", "/metrics/model/edge_mm", 1.0),
            ("inside_pct", "/inside/model/inside_pct", 1.0),
        ],
        "bake" => &[
            ("replay_mm", "/report/clips/0/max_error_m", 1e3),
            ("targets", "/report/targets", 1.0),
        ],
        "validate" => &[("replay_mm", "/replay/max_mm", 1.0)],
        "simulate" => &[("s_per_frame", "/seconds_per_frame", 1.0)],
        "train-dynamic" => &[("train_mm", "/train/mean_mm", 1.0)],
        "rollout" => &[
            ("inside_pct", "/summary/inside_pct", 1.0),
            ("vs_sim_mm", "/reference/clip_mm", 1.0),
        ],
        _ => &[],
    };
    picks
        .iter()
        .filter_map(|(name, ptr, scale)| {
            r.pointer(ptr)?
                .as_f64()
                .map(|v| (name.to_string(), v * scale))
        })
        .collect()
}

/// Runs the plan here with up to `jobs` at a time; `done` hears of each job as it ends.
/// Returns one outcome per job, in plan order.
pub fn run_local(
    plan: &Plan,
    exe: &Path,
    jobs: usize,
    retries: usize,
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
    std::thread::scope(|scope| {
        let mut running = 0;
        let mut finished = 0;
        while finished < n {
            while running < jobs.max(1) {
                let Some(i) = ready.pop_front() else { break };
                running += 1;
                let (tx, job) = (tx.clone(), &plan.jobs[i]);
                scope.spawn(move || {
                    let _ = tx.send((i, run_job(job, exe, retries)));
                });
            }
            let (i, o) = rx.recv().expect("a job thread reports");
            running -= 1;
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
        .map(|o| o.expect("every job ends"))
        .collect()
}
