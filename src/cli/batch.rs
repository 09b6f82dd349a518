//! `garmentbake batch plan|run|job`: one manifest for many garments × clips, run incrementally
//! here or on a Ray cluster.

use super::args::OutputArgs;
use super::{figures, Execute};
use crate::batch::engine::{all_or_nothing, run_plan, Engine, RunReport};
use crate::batch::ledger::Ledger;
use crate::batch::plan::{from_manifest, saved_job, Plan};
use crate::batch::run::{run_job, Outcome, Status};
use anyhow::{Context, Result};
use serde::Serialize;
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
    #[arg(long, help_heading = "Outputs")]
    out: Option<PathBuf>,
    #[command(flatten)]
    output: OutputArgs,
}

#[derive(clap::Args)]
struct RunArgs {
    #[command(flatten)]
    plan: PlanArgs,
    /// Jobs run at the same time (each uses the manifest's `threads`).
    #[arg(long, default_value_t = 1, help_heading = "Running")]
    jobs: usize,
    /// Runs again a job that crashed or was killed (not one that reported bad input or a failed
    /// check) up to this many times.
    #[arg(long, default_value_t = 0, help_heading = "Running")]
    retries: usize,
    /// Run on the Ray cluster at this address (HOST:PORT of `ray start --head`) instead of here;
    /// the binary, inputs and output folder must be on a path every node sees.
    #[arg(long, value_name = "ADDRESS", help_heading = "Running")]
    ray: Option<String>,
}

#[derive(clap::Args)]
struct JobArgs {
    /// A plan saved by `batch plan --json` or `batch run` (OUT/plan.json).
    #[arg(long, help_heading = "Inputs")]
    plan: PathBuf,
    /// The job's id.
    #[arg(long, help_heading = "Inputs")]
    id: String,
    /// Runs the job again if it crashed or was killed (not if it reported bad input or a failed
    /// check), up to this many times (as `batch run --retries`).
    #[arg(long, default_value_t = 0, help_heading = "Advanced")]
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

fn exe() -> Result<PathBuf> {
    std::env::current_exe().context("cannot find the garmentbake binary")
}

impl RunArgs {
    /// A run that stops for lack of space (its own write or a job's) is one error, and leaves
    /// nothing it wrote but the finished jobs' files.
    fn run(&self, say: &dyn Fn(&str)) -> Result<RunReport> {
        all_or_nothing(|ledger| {
            let plan = from_manifest(&self.plan.manifest, self.plan.out.as_deref(), ledger)?;
            let json = self.plan.output.json;
            let Some(address) = &self.ray else {
                let bar = crate::progress::bar(plan.jobs.len() as u64, "batch", json);
                let done = |o: &Outcome| {
                    bar.inc(1);
                    if !json {
                        bar.println(o.line(&plan.out));
                    }
                };
                let local = Engine::Local { jobs: self.jobs };
                let report = run_plan(
                    &plan,
                    &exe()?,
                    &local,
                    self.retries,
                    &figures,
                    ledger,
                    &done,
                );
                bar.finish_and_clear();
                return report;
            };
            say(&format!(
                "{} jobs on the Ray cluster at {address}",
                plan.jobs.len()
            ));
            let ray = Engine::Ray { address };
            run_plan(
                &plan,
                &exe()?,
                &ray,
                self.retries,
                &figures,
                ledger,
                &|_| {},
            )
        })
    }
}

impl Execute for Args {
    type Report = Report;

    fn execute(&self, say: &dyn Fn(&str)) -> Result<Report> {
        match &self.what {
            What::Plan(p) => {
                let start = Instant::now();
                let plan = from_manifest(&p.manifest, p.out.as_deref(), &Ledger::default())?;
                Ok(Report::Plan {
                    plan,
                    seconds: start.elapsed().as_secs_f64(),
                })
            }
            What::Run(r) => Ok(Report::Run(r.run(say)?)),
            What::Job(j) => {
                let job = saved_job(&j.plan, &j.id)?;
                let ledger = Ledger::default(); // a job of a farm's run: kept as it ends
                Ok(Report::Job(run_job(
                    &job,
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
            Report::Job(o) => println!("{}", o.line(Path::new("/"))),
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

fn print_plan(plan: &Plan, seconds: f64) {
    for j in &plan.jobs {
        let fresh = if crate::batch::run::up_to_date(j) {
            "up to date"
        } else {
            "to run"
        };
        println!("{:<44} {:<10} after: {}", j.id, fresh, j.deps.join(", "));
    }
    let kinds: Vec<String> = plan
        .kinds()
        .iter()
        .map(|(k, n)| format!("{n} {k}"))
        .collect();
    println!(
        "{} jobs ({}) planned in {:.3} s; outputs in {}",
        plan.jobs.len(),
        kinds.join(", "),
        seconds,
        plan.out.display()
    );
}

fn print_run(r: &RunReport) {
    println!(
        "{:<44} {:<10} {:>9}  {:<34} outputs",
        "job", "status", "seconds", "figures"
    );
    for o in &r.jobs {
        println!("{}", o.line(&r.out));
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
