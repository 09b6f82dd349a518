//! The only place that talks to Python: embeds the interpreter (pyo3) and drives Pixar's
//! `usd-core` (`pxr`) from the project venv. Callers pass and receive plain Rust data.

use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{PyBool, PyBytes, PyDict, PyList, PyMemoryView, PyModule, PyString};
use std::borrow::Cow;
use std::ffi::CString;
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    #[error("usd-core (Python module 'pxr') is not importable from the venv {venv} ({reason}); run `bash scripts/setup.sh` to create .venv with usd-core, or set GARMENTBAKE_VENV to a venv that has it")]
    MissingPxr { venv: String, reason: String },
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
        .map_err(|e| BridgeError::MissingPxr {
            venv: venv_dir().map_or_else(|| "(none)".into(), |v| v.display().to_string()),
            reason: e.to_string(),
        })
}

/// Plain data handed to the embedded writer: the Python side sees `None`, `bool`, `int`, `float`,
/// `str`, `list`, `dict`, and arrays as flat memoryviews cast to `'f'` / `'i'` / `'d'`, which
/// `Vt.*Array.FromBuffer` takes in one copy (no per-element Python calls: that is the speed).
#[derive(Clone, Debug)]
pub enum Value<'a> {
    None,
    Bool(bool),
    Int(i64),
    Float(f64),
    Str(Cow<'a, str>),
    F32(Cow<'a, [f32]>),
    I32(Cow<'a, [i32]>),
    F64(Cow<'a, [f64]>),
    List(Vec<Value<'a>>),
    Dict(Vec<(&'static str, Value<'a>)>),
}

impl<'a> From<&'a str> for Value<'a> {
    fn from(s: &'a str) -> Self {
        Value::Str(Cow::Borrowed(s))
    }
}

impl From<String> for Value<'_> {
    fn from(s: String) -> Self {
        Value::Str(Cow::Owned(s))
    }
}

impl<'a, T: Into<Value<'a>>> From<Option<T>> for Value<'a> {
    fn from(v: Option<T>) -> Self {
        v.map_or(Value::None, Into::into)
    }
}

/// A flat native-endian buffer → `memoryview(bytes).cast(code)`.
fn buffer<'py, const N: usize>(
    py: Python<'py>,
    items: impl ExactSizeIterator<Item = [u8; N]>,
    code: &str,
) -> PyResult<Bound<'py, PyAny>> {
    let bytes = PyBytes::new_with(py, items.len() * N, |buf| {
        for (dst, src) in buf.chunks_exact_mut(N).zip(items) {
            dst.copy_from_slice(&src);
        }
        Ok(())
    })?;
    PyMemoryView::from(bytes.as_any())?.call_method1("cast", (code,))
}

impl Value<'_> {
    fn to_py<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        Ok(match self {
            Value::None => py.None().into_bound(py),
            Value::Bool(b) => PyBool::new(py, *b).to_owned().into_any(),
            Value::Int(i) => i.into_pyobject(py)?.into_any(),
            Value::Float(f) => f.into_pyobject(py)?.into_any(),
            Value::Str(s) => PyString::new(py, s).into_any(),
            Value::F32(v) => buffer(py, v.iter().map(|x| x.to_ne_bytes()), "f")?,
            Value::I32(v) => buffer(py, v.iter().map(|x| x.to_ne_bytes()), "i")?,
            Value::F64(v) => buffer(py, v.iter().map(|x| x.to_ne_bytes()), "d")?,
            Value::List(items) => {
                let list = PyList::empty(py);
                for item in items {
                    list.append(item.to_py(py)?)?;
                }
                list.into_any()
            }
            Value::Dict(entries) => {
                let dict = PyDict::new(py);
                for (k, v) in entries {
                    dict.set_item(k, v.to_py(py)?)?;
                }
                dict.into_any()
            }
        })
    }
}

/// The USD authoring code (`usd_writer.py`), compiled once per process.
static USD_WRITER: PyOnceLock<Py<PyModule>> = PyOnceLock::new();

fn usd_writer(py: Python<'_>) -> Result<&Bound<'_, PyModule>, BridgeError> {
    // pxr first, so a missing usd-core is reported as such rather than as an ImportError inside
    // the writer module.
    import_pxr(py, "Usd")?;
    let module = USD_WRITER.get_or_try_init(py, || -> PyResult<_> {
        let code = CString::new(include_str!("usd_writer.py")).expect("no NUL in the writer");
        Ok(PyModule::from_code(py, &code, c"usd_writer.py", c"garmentbake_usd_writer")?.unbind())
    })?;
    Ok(module.bind(py))
}

/// Calls `usd_writer.<function>(spec, path)`: the writer authors the stage and exports it to `path`
/// (format from the extension). The caller owns atomicity (temporary name, rename).
pub fn write_usd(function: &str, spec: &Value<'_>, path: &Path) -> Result<(), BridgeError> {
    Python::attach(|py| {
        let writer = usd_writer(py)?;
        let spec = spec.to_py(py)?;
        writer.call_method1(function, (spec, path.to_string_lossy().into_owned()))?;
        Ok(())
    })
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
