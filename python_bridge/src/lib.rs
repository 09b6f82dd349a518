//! The only place that talks to Python: embeds the interpreter (pyo3) and drives Pixar's
//! `usd-core` (`pxr`) from the project venv. Callers pass and receive plain Rust data.

use pyo3::prelude::*;
use pyo3::types::PyModule;
use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    #[error("Python module 'pxr' (usd-core) is not importable ({0}); run `bash scripts/setup.sh` to create .venv with usd-core, or set GARMENTBAKE_VENV to a venv that has it")]
    MissingPxr(String),
    #[error("Python error: {0}")]
    Python(String),
}

impl From<PyErr> for BridgeError {
    fn from(e: PyErr) -> Self {
        BridgeError::Python(e.to_string())
    }
}

/// The venv whose site-packages hold usd-core: `$GARMENTBAKE_VENV`, else the one this binary was
/// built against (the project's `.venv`).
pub fn venv_dir() -> Option<PathBuf> {
    if let Some(v) = std::env::var_os("GARMENTBAKE_VENV") {
        return Some(PathBuf::from(v));
    }
    // PYO3_PYTHON = <venv>/bin/python at build time (see .cargo/config.toml).
    let python = PathBuf::from(option_env!("PYO3_PYTHON")?);
    Some(python.parent()?.parent()?.to_path_buf())
}

/// Makes the venv's site-packages importable in the embedded interpreter (which starts from the
/// base installation's prefix, not the venv's).
fn add_venv(py: Python<'_>) -> PyResult<()> {
    let Some(venv) = venv_dir() else {
        return Ok(());
    };
    let site = py.import("site")?;
    let sys = py.import("sys")?;
    let version: (u8, u8) = sys
        .getattr("version_info")?
        .extract::<(u8, u8, u8, String, u8)>()
        .map(|v| (v.0, v.1))?;
    let dir = venv.join(format!(
        "lib/python{}.{}/site-packages",
        version.0, version.1
    ));
    site.call_method1("addsitedir", (dir.to_string_lossy().into_owned(),))?;
    Ok(())
}

/// Imports `pxr.<module>` with the venv on the path; a missing usd-core gets an actionable error.
pub fn import_pxr<'py>(py: Python<'py>, module: &str) -> Result<Bound<'py, PyModule>, BridgeError> {
    add_venv(py)?;
    py.import(format!("pxr.{module}").as_str())
        .map_err(|e| BridgeError::MissingPxr(e.to_string()))
}

/// The usd-core version, e.g. "0.26.11": proves the bridge works end to end.
pub fn usd_version() -> Result<String, BridgeError> {
    Python::attach(|py| {
        let usd = import_pxr(py, "Usd")?;
        let (a, b, c): (u32, u32, u32) = usd.call_method0("GetVersion")?.extract()?;
        Ok(format!("{a}.{b}.{c}"))
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn usd_core_is_reachable_from_the_venv() {
        let v = super::usd_version().expect("usd-core importable");
        assert!(v.starts_with("0.26."), "{v}");
    }
}
