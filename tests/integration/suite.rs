//! The test suite's own rules, checked on its sources: no environment switch turns a test into
//! a pass, and every test target the docs and comments name in a test command (`--test NAME`)
//! exists.

use crate::common::root;
use std::path::{Path, PathBuf};

/// Every file under `dir` (recursively) whose name ends with one of `extensions`.
fn files(dir: &Path, extensions: &[&str], out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries {
        let path = entry.unwrap().path();
        if path.is_dir() {
            files(&path, extensions, out);
        } else if extensions
            .iter()
            .any(|e| path.extension().is_some_and(|x| x == *e))
        {
            out.push(path);
        }
    }
}

/// A test that returns early when a variable is set passes without testing (the old
/// `GARMENTBAKE_SKIP_BLENDER` made ten Blender tests pass with nothing checked): the integration
/// tests read no environment variable at run time. Compile-time `env!` (paths cargo sets) is
/// allowed; a missing reader (Blender, Node, usd-core) fails the test that needs it.
#[test]
fn no_test_is_switched_off_by_the_environment() {
    let mut sources = Vec::new();
    files(&root().join("tests/integration"), &["rs"], &mut sources);
    assert!(sources.len() > 10, "{sources:?}");
    let mut reads = Vec::new();
    for file in &sources {
        let text = std::fs::read_to_string(file).unwrap();
        for (n, line) in text.lines().enumerate() {
            let code = line.split("//").next().unwrap_or_default();
            // Spelled in two halves so this file does not find itself.
            if [concat!("env::", "var("), concat!("env::", "var_os(")]
                .iter()
                .any(|call| code.contains(call))
            {
                reads.push(format!("{}:{}: {}", file.display(), n + 1, line.trim()));
            }
        }
    }
    assert!(
        reads.is_empty(),
        "tests that read the environment (a switch that can skip them):\n{}",
        reads.join("\n")
    );
}

/// The test targets of the workspace's packages: `tests/NAME.rs` and `tests/NAME/main.rs`.
fn test_targets() -> Vec<String> {
    let mut names = Vec::new();
    for package in [".", "exporters", "python_bridge"] {
        let Ok(entries) = std::fs::read_dir(root().join(package).join("tests")) else {
            continue;
        };
        for entry in entries {
            let path = entry.unwrap().path();
            let stem = path.file_stem().unwrap().to_string_lossy().into_owned();
            if path.is_dir() && path.join("main.rs").exists()
                || path.extension().is_some_and(|e| e == "rs")
            {
                names.push(stem);
            }
        }
    }
    names
}

/// The ignored USD benchmarks' commands named a test target `usd` that does not exist (the USD
/// tests live in the one `integration` binary), so they could not be run as written. Every
/// `--test NAME` of a test command in the docs, README, scripts and sources names a real target.
#[test]
fn documented_test_commands_name_real_targets() {
    let targets = test_targets();
    assert!(targets.contains(&"integration".to_string()), "{targets:?}");
    let mut sources = vec![root().join("README.md")];
    for (dir, extensions) in [
        ("docs", &["md"][..]),
        ("scripts", &["sh"]),
        ("src", &["rs"]),
        ("tests", &["rs"]),
        ("exporters/src", &["rs"]),
        ("python_bridge/src", &["rs"]),
    ] {
        files(&root().join(dir), extensions, &mut sources);
    }
    let (mut commands, mut wrong) = (0, Vec::new());
    for file in &sources {
        let text = std::fs::read_to_string(file).unwrap();
        for (n, line) in text.lines().enumerate() {
            for (i, _) in line.match_indices("cargo test") {
                let rest = &line[i..];
                // The command ends at the end of its code span (or the line).
                let command = rest.split('`').next().unwrap_or(rest);
                let words: Vec<&str> = command.split_whitespace().collect();
                for pair in words.windows(2).filter(|w| w[0] == "--test") {
                    commands += 1;
                    if !targets.iter().any(|t| t == pair[1]) {
                        wrong.push(format!("{}:{}: {command}", file.display(), n + 1));
                    }
                }
            }
        }
    }
    assert!(commands >= 10, "only {commands} `--test` commands found");
    assert!(
        wrong.is_empty(),
        "commands naming no test target (targets: {targets:?}):\n{}",
        wrong.join("\n")
    );
}
