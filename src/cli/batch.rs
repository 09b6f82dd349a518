//! `garmentbake batch plan|run|job`: one manifest for many garments × clips, run incrementally
//! here or on a Ray cluster.

use super::args::OutputArgs;
use super::Execute;
use crate::batch::ledger::Ledger;
use crate::batch::manifest;
use crate::batch::plan::{plan, Plan};
use crate::batch::run::{out_of_space_failure, run_job, run_local, Outcome, Status};
use anyhow::{bail, Context, Result};
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Run the pipeline for many garments × clips from one manifest (batch.toml), incrementally.
///
/// The manifest (docs/batch.md, samples/batch.toml) names the body, the clips (paths or globs,
/// joint map, fps) and per garment its fabric, seed, a static (PBNS) and/or dynamic recipe and
/// the outputs wanted (glTF / USD bakes, point caches, validation). `plan` expands it into a graph
/// of jobs (simulate → train / train-dynamic → eval / bake / rollout → validate), each one
/// `garmentbake` command line with a key: the hash of its input files' bytes, its arguments and
/// the tool version (and its upstream jobs' keys). `run` runs it: a job whose outputs already
/// carry its key (FILE.key beside each) is not run again, so after an edit only what depends on
/// the changed file runs, and a killed run picks up where it stopped.
#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    what: What,
}

#[derive(clap::Subcommand)]
enum What {
    /// Print the job graph (with --json: the engine-neutral plan, schema in docs/batch.md).
    Plan(PlanArgs),
    /// Run the plan: here with --jobs at a time, or on a Ray cluster with --ray.
    Run(RunArgs),
    /// Run one job of a saved plan (what a Ray task or a farm job calls).
    Job(JobArgs),
}

#[derive(clap::Args)]
struct PlanArgs {
    /// The manifest (TOML).
    manifest: PathBuf,
    /// Output folder (default: the manifest's `out`).
    #[arg(long)]
    out: Option<PathBuf>,
    #[command(flatten)]
    output: OutputArgs,
}

#[derive(clap::Args)]
struct RunArgs {
    #[command(flatten)]
    plan: PlanArgs,
    /// Jobs run at the same time (each uses the manifest's `threads`).
    #[arg(long, default_value_t = 1)]
    jobs: usize,
    /// Runs again a job that crashed or was killed (not one that reported bad input or a failed
    /// check) up to this many times.
    #[arg(long, default_value_t = 0)]
    retries: usize,
    /// Run on the Ray cluster at this address (HOST:PORT of `ray start --head`) instead of here;
    /// the binary, inputs and output folder must be on a path every node sees.
    #[arg(long, value_name = "ADDRESS")]
    ray: Option<String>,
}

#[derive(clap::Args)]
struct JobArgs {
    /// A plan saved by `batch plan --json` or `batch run` (OUT/plan.json).
    #[arg(long)]
    plan: PathBuf,
    /// The job's id.
    #[arg(long)]
    id: String,
    #[arg(long, default_value_t = 0)]
    retries: usize,
}

impl Args {
    pub fn json(&self) -> bool {
        match &self.what {
            What::Plan(p) => p.output.json,
            What::Run(r) => r.plan.output.json,
            What::Job(_) => true,
        }
    }
}

#[derive(Serialize)]
#[serde(untagged)]
pub enum Report {
    Plan {
        #[serde(flatten)]
        plan: Plan,
        #[serde(skip)]
        seconds: f64,
    },
    Run(RunReport),
    Job(Outcome),
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

impl PlanArgs {
    /// The plan; the output folder is created if missing (noted in `ledger`).
    fn plan(&self, ledger: &Ledger) -> Result<Plan> {
        let resolved = manifest::read(&self.manifest)?;
        let out = match (&self.out, &resolved.manifest.out) {
            (Some(o), _) => o.clone(),
            (None, Some(o)) => o.clone(),
            (None, None) => bail!("{}: no `out` folder; give --out", self.manifest.display()),
        };
        ledger
            .create_dir_all(&out)
            .with_context(|| format!("cannot create {}", out.display()))?;
        let out = out
            .canonicalize()
            .with_context(|| format!("cannot read {}", out.display()))?;
        plan(&resolved, &out)
    }
}

fn exe() -> Result<PathBuf> {
    std::env::current_exe().context("cannot find the garmentbake binary")
}

impl RunArgs {
    /// A run that stops for lack of space (its own write or a job's) is one error, and leaves
    /// nothing it wrote but the finished jobs' files.
    fn run(&self, say: &dyn Fn(&str)) -> Result<RunReport> {
        let ledger = Ledger::default();
        let report =
            self.run_noting(&ledger, say)
                .and_then(|r| match out_of_space_failure(&r.jobs) {
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

    fn run_noting(&self, ledger: &Ledger, say: &dyn Fn(&str)) -> Result<RunReport> {
        let plan = self.plan.plan(ledger)?;
        let saved = plan.out.join("plan.json");
        ledger.write(&saved, serde_json::to_string_pretty(&plan)?.as_bytes())?;
        let exe = exe()?;
        let start = Instant::now();
        let jobs = match &self.ray {
            Some(address) => {
                say(&format!(
                    "{} jobs on the Ray cluster at {address}",
                    plan.jobs.len()
                ));
                crate::batch::ray::run(address, &saved, &exe, self.retries)?
            }
            None => {
                let bar =
                    crate::progress::bar(plan.jobs.len() as u64, "batch", self.plan.output.json);
                let done = |o: &Outcome| {
                    bar.inc(1);
                    if !self.plan.output.json {
                        bar.println(line(o, &plan.out));
                    }
                };
                let outcomes = run_local(
                    &plan,
                    &exe,
                    self.jobs,
                    self.retries,
                    &figures,
                    ledger,
                    &done,
                );
                bar.finish_and_clear();
                outcomes
            }
        };
        let count = |s: Status| jobs.iter().filter(|o| o.status == s).count();
        Ok(RunReport {
            schema: "garmentbake-batch-report/1",
            engine: if self.ray.is_some() { "ray" } else { "local" }.into(),
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
}

impl Execute for Args {
    type Report = Report;

    fn execute(&self, say: &dyn Fn(&str)) -> Result<Report> {
        match &self.what {
            What::Plan(p) => {
                let start = Instant::now();
                let plan = p.plan(&Ledger::default())?;
                Ok(Report::Plan {
                    plan,
                    seconds: start.elapsed().as_secs_f64(),
                })
            }
            What::Run(r) => Ok(Report::Run(r.run(say)?)),
            What::Job(j) => {
                let text = std::fs::read(&j.plan)
                    .with_context(|| format!("cannot read {}", j.plan.display()))?;
                let plan: Plan = serde_json::from_slice(&text)
                    .with_context(|| format!("{} is not a batch plan", j.plan.display()))?;
                let job = plan
                    .jobs
                    .iter()
                    .find(|x| x.id == j.id)
                    .with_context(|| format!("{}: no job '{}'", j.plan.display(), j.id))?;
                let ledger = Ledger::default(); // a job of a farm's run: kept as it ends
                Ok(Report::Job(run_job(
                    job,
                    &exe()?,
                    j.retries,
                    &figures,
                    &ledger,
                )))
            }
        }
    }

    fn print(r: &Report) {
        match r {
            Report::Plan { plan, seconds } => print_plan(plan, *seconds),
            Report::Run(run) => print_run(run),
            Report::Job(o) => println!("{}", line(o, Path::new("/"))),
        }
    }

    fn exit_code(r: &Report) -> i32 {
        match r {
            Report::Plan { .. } => 0,
            Report::Run(run) => i32::from(run.failed > 0),
            Report::Job(o) => i32::from(o.status == Status::Failed),
        }
    }
}

/// The figures a person scans the summary for, per kind of job, read from the job's `--json`
/// report through the command's own report type: a renamed field breaks this at compile time
/// instead of dropping a figure from every summary.
pub fn figures(kind: &str, report: &[u8]) -> Result<BTreeMap<String, f64>> {
    fn read<R: DeserializeOwned>(report: &[u8]) -> Result<R> {
        Ok(serde_json::from_slice(report)?)
    }
    let f: Vec<(&str, Option<f64>)> = match kind {
        "train" => {
            let r: super::train::Report = read(report)?;
            let last = r.last.map(|e| e.train);
            vec![
                ("edge_mm", last.map(|m| m.edge_mm)),
                ("collided_pct", last.map(|m| m.collided_pct)),
            ]
        }
        "eval" => {
            let r: super::eval::Report = read(report)?;
            vec![
                ("edge_mm", Some(r.metrics.model.edge_mm)),
                ("inside_pct", Some(r.inside.model.inside_pct)),
            ]
        }
        "bake" => {
            let r: super::bake::Report = read(report)?;
            let first = r.report.clips.first();
            vec![
                ("replay_mm", first.map(|c| 1e3 * c.max_error_m as f64)),
                ("targets", Some(r.report.targets as f64)),
            ]
        }
        "validate" => {
            let r: super::validate::Report = read(report)?;
            vec![("replay_mm", r.replay.map(|e| e.max_mm))]
        }
        "simulate" => {
            let r: super::simulate::Report = read(report)?;
            vec![("s_per_frame", Some(r.seconds_per_frame))]
        }
        "train-dynamic" => {
            let r: super::train_dynamic::Report = read(report)?;
            vec![("train_mm", Some(r.train.mean_mm))]
        }
        "rollout" => {
            let r: super::rollout::Report = read(report)?;
            vec![
                ("inside_pct", Some(r.summary.inside.inside_pct)),
                ("vs_sim_mm", r.reference.map(|v| v.clip_mm)),
            ]
        }
        _ => vec![],
    };
    Ok(f.into_iter()
        .filter_map(|(name, v)| Some((name.to_string(), v?)))
        .collect())
}

fn print_plan(plan: &Plan, seconds: f64) {
    for j in &plan.jobs {
        let fresh = if crate::batch::run::up_to_date(j) {
            "up to date"
        } else {
            "to run"
        };
        println!("{:<44} {:<10} after: {}", j.id, fresh, j.deps.join(", "));
    }
    let mut kinds: Vec<(&str, usize)> = vec![];
    for j in &plan.jobs {
        match kinds.iter_mut().find(|(k, _)| *k == j.kind) {
            Some((_, n)) => *n += 1,
            None => kinds.push((&j.kind, 1)),
        }
    }
    let kinds: Vec<String> = kinds.iter().map(|(k, n)| format!("{n} {k}")).collect();
    println!(
        "{} jobs ({}) planned in {:.3} s; outputs in {}",
        plan.jobs.len(),
        kinds.join(", "),
        seconds,
        plan.out.display()
    );
}

/// One job's line: status, time, key figures, error.
fn line(o: &Outcome, out: &Path) -> String {
    let status = match o.status {
        Status::Ran => "ran",
        Status::UpToDate => "up to date",
        Status::Failed => "FAILED",
        Status::Skipped => "skipped",
    };
    let figures: Vec<String> = o
        .metrics
        .iter()
        .map(|(k, v)| format!("{k} {v:.3}"))
        .collect();
    let files: Vec<String> = o
        .outputs
        .iter()
        .map(|p| p.strip_prefix(out).unwrap_or(p).display().to_string())
        .collect();
    let mut s = format!(
        "{:<44} {:<10} {:>7.1} s  {:<34} {}",
        o.id,
        status,
        o.seconds,
        figures.join(", "),
        files.join(" ")
    );
    if let Some(e) = &o.error {
        s.push_str(&format!("\n    {e}"));
    }
    s
}

fn print_run(r: &RunReport) {
    println!(
        "{:<44} {:<10} {:>9}  {:<34} outputs",
        "job", "status", "seconds", "figures"
    );
    for o in &r.jobs {
        println!("{}", line(o, &r.out));
    }
    println!(
        "{} jobs on {}: {} ran, {} up to date, {} failed, {} skipped in {:.1} s; logs in {}",
        r.jobs.len(),
        r.engine,
        r.ran,
        r.up_to_date,
        r.failed,
        r.skipped,
        r.wall_seconds,
        r.out.join("logs").display()
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A report that is not its command's is an error naming what is missing, not a summary
    /// line quietly short of a figure.
    #[test]
    fn a_report_not_of_its_command_is_an_error() {
        let stale = br#"{"summary": {"inside_pct": 3.0}, "reference": {"clip_mm": 50.0}}"#;
        let e = figures("rollout", stale).unwrap_err();
        assert!(format!("{e:#}").contains("missing field"), "{e:#}");
        assert!(figures("validate", b"[]").is_err());
        assert!(figures("a kind with no figures", b"{}").unwrap().is_empty());
    }
}
