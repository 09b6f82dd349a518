//! USD files, checked by usd-core through python_bridge: its UsdValidation validators and our
//! UsdSkel binding rules (python_bridge/src/usd_validator.py). A garbled file is an error here.

use super::Problems;
use anyhow::Result;
use std::path::Path;

#[cfg(feature = "usd")]
pub fn check_usd(path: &Path, p: &mut Problems) -> Result<()> {
    for (severity, at, message) in python_bridge::validate_usd(path)? {
        match severity.as_str() {
            "error" => p.error(at, message),
            _ => p.warning(at, message),
        }
    }
    Ok(())
}

#[cfg(not(feature = "usd"))]
pub fn check_usd(path: &Path, _: &mut Problems) -> Result<()> {
    anyhow::bail!(
        "{}: this garmentbake was built without USD support (cargo feature `usd`)",
        path.display()
    )
}
