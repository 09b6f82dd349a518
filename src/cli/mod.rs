//! The `garmentbake` command line: one subcommand per pipeline step.

mod bake;
mod bench;
mod eval;
mod inspect;
mod pose;
mod preview;
mod train;

use clap::{Parser, Subcommand};
use std::path::PathBuf;

/// The motion-capture clips a command reads, and how (shared by `pose` and `bake`).
#[derive(clap::Args)]
struct ClipArgs {
    /// BVH clip(s); repeat --motion for several, one animation each.
    #[arg(long = "motion", required = true)]
    motions: Vec<PathBuf>,
    /// Joint-name map(s) (TOML); each applies to the clips whose joints it covers.
    #[arg(long = "map")]
    maps: Vec<PathBuf>,
    /// Keep every n-th frame so clips play at this rate (must divide the source rate).
    #[arg(long)]
    fps: Option<f32>,
}

#[derive(Parser)]
#[command(
    name = "garmentbake",
    version,
    about = "Train neural garment deformers and bake them into glTF, USD and point caches.",
    long_about = "Train neural garment deformers and bake them into standard files that any engine or DCC \
plays back without a neural runtime.\n\nConventions: metres, Y-up, right-handed (glTF / USD). Inputs are \
converted at the edges: BVH units are scaled to the body by hip height, MakeHuman decimetres to metres.",
    after_help = "Typical session:\n  garmentbake inspect samples/body.glb\n  garmentbake pose --body samples/body.glb --motion samples/motions/131_01.bvh --out walk.glb\n  garmentbake preview --body samples/body.glb --motion samples/motions/131_01.bvh --frames 6 --out walk.png"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    Inspect(inspect::Args),
    Pose(pose::Args),
    Preview(preview::Args),
    Train(train::Args),
    Eval(eval::Args),
    Bake(bake::Args),
    Bench(bench::Args),
}

/// Runs the CLI; errors are one line on stderr and exit code 2 (1 is left for failed checks).
pub fn main() -> i32 {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Inspect(a) => inspect::run(a),
        Command::Pose(a) => pose::run(a),
        Command::Preview(a) => preview::run(a),
        Command::Train(a) => train::run(a),
        Command::Eval(a) => eval::run(a),
        Command::Bake(a) => bake::run(a),
        Command::Bench(a) => bench::run(a),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {}", one_line(&e));
            2
        }
    }
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

/// A progress bar on stderr for work longer than a second; hidden when stderr is not a terminal
/// or in `--json` mode so machine output stays clean.
pub(crate) fn progress(len: u64, what: &str, quiet: bool) -> indicatif::ProgressBar {
    if quiet {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(len);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{msg:>12} [{bar:30}] {pos}/{len} ({eta})")
            .expect("valid template")
            .progress_chars("=> "),
    );
    bar.set_message(what.to_string());
    bar
}
