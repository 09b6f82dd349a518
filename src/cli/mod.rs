//! The command line: a file per subcommand; here `Execute`, dispatch, `main`, batch's `figures`.

pub mod args;
pub mod bake;
pub mod batch;
pub mod bench;
pub mod compare;
pub mod eval;
pub mod inspect;
pub mod interpolate;
pub mod map;
pub mod pose;
pub mod preview;
pub mod rollout;
pub mod simulate;
pub mod train;
pub mod train_dynamic;
pub mod train_swing;
pub mod upgrade;
pub mod validate;
pub mod view;

use anyhow::Result;
use clap::{Parser, Subcommand};
use serde::Serialize;

/// A command: `execute` does the work and returns a report (serde), `print` shows it; `--json` prints
/// the report instead. `batch` runs each job as a child process (src/batch/run.rs), reading `--json`.
pub trait Execute {
    type Report: Serialize;
    /// Runs the command; `say` gets progress notes for a person (a no-op with `--json`).
    fn execute(&self, say: &dyn Fn(&str)) -> Result<Self::Report>;
    fn print(report: &Self::Report);
    /// The exit code a successful run reports (1 for checks that failed).
    fn exit_code(_report: &Self::Report) -> i32 {
        0
    }
}

/// Executes `command`, then prints its report as text, or as JSON with `json` (`--json`).
fn run<C: Execute>(command: &C, json: bool) -> Result<i32> {
    let say = |line: &str| {
        if !json {
            println!("{line}");
        }
    };
    let report = command.execute(&say)?;
    if json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        C::print(&report);
    }
    Ok(C::exit_code(&report))
}

#[derive(Parser)]
#[command(
    name = "garmentbake",
    version,
    about = "Train neural garment deformers and bake them into glTF, USD and point caches.",
    long_about = "Train neural garment deformers and bake them into standard files that any engine or DCC \
plays back without a neural runtime.\n\nConventions: metres, Y-up, right-handed (glTF / USD). Inputs are \
converted at the edges: BVH units are scaled to the body by hip height, MakeHuman decimetres to metres.",
    after_help = "Typical session:\n  garmentbake inspect samples/body.glb\n  garmentbake pose --body samples/body.glb --motion samples/motions/131_01.bvh --out walk.glb\n  garmentbake preview --body samples/body.glb --motion samples/motions/131_01.bvh --frame-count 6 --out walk.png"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// No progress on stderr: neither the terminal bar nor, off a terminal (a farm log), the
    /// plain line per tenth of the work or per 30 s.
    #[arg(long, global = true)]
    quiet: bool,
}

#[derive(Subcommand)]
enum Command {
    Inspect(inspect::Args),
    Pose(pose::Args),
    Preview(preview::Args),
    Train(train::Args),
    Eval(eval::Args),
    Bake(bake::Args),
    Simulate(simulate::Args),
    TrainDynamic(Box<train_dynamic::Args>),
    TrainSwing(Box<train_swing::Args>),
    Rollout(rollout::Args),
    Compare(compare::Args),
    Interpolate(interpolate::Args),
    Map(map::Args),
    Bench(bench::Args),
    Batch(batch::Args),
    Validate(validate::Args),
    View(view::Args),
    Upgrade(upgrade::Args),
}

/// The whole command line as clap sees it (every command and flag), for tests that go through
/// all of them.
pub fn command() -> clap::Command {
    <Cli as clap::CommandFactory>::command()
}

/// Runs the CLI; errors are one line on stderr and exit code 2 (1 is left for failed checks).
pub fn main() -> i32 {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => return usage_error(e),
    };
    crate::progress::set_quiet(cli.quiet);
    let result = match cli.command {
        Command::Inspect(a) => run(&a, a.json),
        Command::Pose(a) => run(&a, a.output.json),
        Command::Preview(a) => run(&a, a.output.json),
        Command::Train(a) => run(&a, a.output.json),
        Command::Eval(a) => run(&a, a.output.json),
        Command::Bake(a) => run(&a, a.output.json),
        Command::Simulate(a) => run(&a, a.output.json),
        Command::TrainDynamic(a) => run(a.as_ref(), a.output.json),
        Command::TrainSwing(a) => run(a.as_ref(), a.output.json),
        Command::Rollout(a) => run(&a, a.output.json),
        Command::Compare(a) => run(&a, a.output.json),
        Command::Interpolate(a) => run(&a, a.output.json),
        Command::Map(a) => run(&a, a.json()),
        Command::Bench(a) => run(&a, a.json()),
        Command::Batch(a) => run(&a, a.json()),
        Command::Validate(a) => run(&a, a.output.json),
        Command::View(a) => run(&a, a.output.json),
        Command::Upgrade(a) => run(&a, a.output.json),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {}", one_line(&e));
            2
        }
    }
}

/// A command line clap refused: help and --version print as usual; a bad flag or value is one
/// `error:` line (clap's first paragraph, without the usage and tips that follow), exit code 2.
fn usage_error(e: clap::Error) -> i32 {
    use clap::error::ErrorKind;
    if matches!(
        e.kind(),
        ErrorKind::DisplayHelp
            | ErrorKind::DisplayVersion
            | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
    ) {
        e.exit();
    }
    let text = e.render().to_string();
    let first: Vec<&str> = text
        .lines()
        .map(str::trim)
        .take_while(|l| !l.is_empty())
        .collect();
    let line = first.join(" ");
    let line = line.strip_prefix("error: ").unwrap_or(&line);
    eprintln!("error: {line}");
    2
}

/// The error chain on one line, outermost first, without repeating a cause already quoted.
fn one_line(e: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if out.contains(&text) {
            continue;
        }
        if !out.is_empty() {
            out.push_str(": ");
        }
        out.push_str(&text);
    }
    out.replace('\n', " ")
}

/// The figures a person scans `batch`'s summary for, per kind of job, read from the job's `--json`
/// report through the command's own report type: a renamed field breaks this at compile time
/// instead of dropping a figure from every summary.
pub fn figures(kind: &str, report: &[u8]) -> Result<std::collections::BTreeMap<String, f64>> {
    fn read<R: serde::de::DeserializeOwned>(report: &[u8]) -> Result<R> {
        Ok(serde_json::from_slice(report)?)
    }
    let f: Vec<(&str, Option<f64>)> = match kind {
        "train" => {
            let r: train::Report = read(report)?;
            let last = r.last.map(|e| e.train);
            vec![
                ("edge_mm", last.map(|m| m.edge_mm)),
                ("collided_pct", last.map(|m| m.collided_pct)),
            ]
        }
        "eval" => {
            let r: eval::Report = read(report)?;
            vec![
                ("edge_mm", Some(r.metrics.model.edge_mm)),
                ("inside_pct", Some(r.inside.model.inside_pct)),
            ]
        }
        "bake" => {
            let r: bake::Report = read(report)?;
            let first = r.report.clips.first();
            vec![
                ("replay_mm", first.map(|c| c.error.max_mm)),
                ("targets", Some(r.report.targets as f64)),
            ]
        }
        "validate" => {
            let r: validate::Report = read(report)?;
            vec![("replay_mm", r.replay.map(|e| e.error.max_mm))]
        }
        "simulate" => {
            let r: simulate::Report = read(report)?;
            vec![("s_per_frame", Some(r.seconds_per_frame))]
        }
        "train-dynamic" => {
            let r: train_dynamic::Report = read(report)?;
            vec![("train_mm", Some(r.train.mean_mm))]
        }
        "rollout" => {
            let r: rollout::Report = read(report)?;
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
