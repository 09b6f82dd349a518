//! Ray as the engine beyond one machine: the plan goes to a small Python driver
//! (python_bridge/ray_batch.py, embedded here) that submits one Ray task per job, its
//! dependencies as task references; each task runs `garmentbake batch job` on a node.

use super::run::Outcome;
use anyhow::{bail, Context, Result};
use std::path::Path;
use std::process::Command;

const DRIVER: &str = include_str!("../../python_bridge/ray_batch.py");

/// The Python that has `ray`: $GARMENTBAKE_PYTHON, else the project venv this binary was built
/// against (scripts/setup.sh installs ray there), else python3.
fn python() -> String {
    std::env::var("GARMENTBAKE_PYTHON")
        .ok()
        .or(option_env!("PYO3_PYTHON").map(String::from))
        .filter(|p| !p.is_empty())
        .unwrap_or_else(|| "python3".into())
}

/// Runs the plan saved at `plan` on the Ray cluster at `address` with the binary `exe`.
pub fn run(address: &str, plan: &Path, exe: &Path, retries: usize) -> Result<Vec<Outcome>> {
    let dir = plan.parent().unwrap_or(Path::new("."));
    let driver = dir.join("ray_batch.py");
    exporters::atomic::write_atomic(&driver, DRIVER.as_bytes())?;
    let python = python();
    let out = Command::new(&python)
        .arg(&driver)
        .args(["--address", address, "--retries", &retries.to_string()])
        .arg("--plan")
        .arg(plan)
        .arg("--exe")
        .arg(exe)
        .stdin(std::process::Stdio::null())
        .stderr(std::process::Stdio::inherit())
        .output()
        .with_context(|| {
            format!("cannot run {python} (set GARMENTBAKE_PYTHON to a Python with ray)")
        })?;
    if !out.status.success() {
        bail!(
            "the Ray driver {} failed ({}) on the cluster at {address}",
            driver.display(),
            out.status
        );
    }
    serde_json::from_slice(&out.stdout)
        .with_context(|| format!("the Ray driver {} printed no outcomes", driver.display()))
}
