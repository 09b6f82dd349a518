//! Progress off a terminal: a farm log (stderr to a pipe or file) gets a plain line per tenth
//! of the work (or per 30 s), so a Deadline- or Tractor-style parser sees the job is alive;
//! `--quiet` silences it. The bar itself only draws on a terminal.

use crate::common::*;
use std::process::Command;

/// `train` of the top for `epochs` epochs with stderr piped (not a terminal); its stderr.
fn train_stderr(epochs: &str, extra: &[&str]) -> String {
    let dir = out_dir(&format!("progress_{epochs}_{}", extra.len()));
    let out = run_ok(
        Command::new(env!("CARGO_BIN_EXE_garmentbake"))
            .args([
                "train",
                "--epochs",
                epochs,
                "--width",
                "8",
                "--threads",
                "1",
            ])
            .args(["--coverage", "0", "--json"])
            .arg("--body")
            .arg(sample("body.glb"))
            .arg("--garment")
            .arg(sample("garments/top.obj"))
            .arg("--motion")
            .arg(sample("motions/131_01.bvh"))
            .arg("--out")
            .arg(dir.join("top.safetensors"))
            // From the first tenth, so the count does not depend on how fast this machine is.
            .env("GARMENTBAKE_PROGRESS_AFTER_S", "0")
            .args(extra),
    );
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).expect("the report");
    assert_eq!(report["epochs"].as_u64(), Some(epochs.parse().unwrap()));
    String::from_utf8(out.stderr).unwrap()
}

#[test]
fn a_log_gets_a_line_per_tenth_of_a_training_and_quiet_gets_none() {
    // With no quiet first second, 20 epochs make a line at each 10 %: ten lines at any speed
    // (a slow machine could add a 30-second line, never remove one).
    let log = train_stderr("20", &[]);
    let lines: Vec<&str> = log
        .lines()
        .filter(|l| l.starts_with("progress: epochs "))
        .collect();
    assert!(lines.len() >= 10, "{log}");
    let percent = |l: &str| -> u64 {
        let word = l.split_whitespace().find(|w| w.ends_with('%')).unwrap();
        word.trim_end_matches('%').parse().unwrap()
    };
    assert!(
        lines.windows(2).all(|w| percent(w[0]) <= percent(w[1])),
        "{log}"
    );
    assert!(
        lines.last().unwrap().contains(" 20/20 100% "),
        "the end is reported: {log}"
    );
    // --json takes stdout for the report; stderr is the log's, so the lines stay. --quiet
    // removes them and nothing else.
    let quiet = train_stderr("20", &["--quiet"]);
    assert!(!quiet.contains("progress:"), "{quiet}");
}
