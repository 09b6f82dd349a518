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
    #[error("alembic3d (Python module 'alembic3d', PyAlembic) is not importable from the venv {venv} ({reason}); run `bash scripts/setup.sh` to install it in .venv, or set GARMENTBAKE_VENV to a venv that has it")]
    MissingAlembic { venv: String, reason: String },
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

/// The USD authoring code (`usd_writer.py`) and reading code (`usd_reader.py`), each compiled once
/// per process.
static USD_WRITER: PyOnceLock<Py<PyModule>> = PyOnceLock::new();
static USD_READER: PyOnceLock<Py<PyModule>> = PyOnceLock::new();
static USD_VALIDATOR: PyOnceLock<Py<PyModule>> = PyOnceLock::new();
static USD_REPLAY: PyOnceLock<Py<PyModule>> = PyOnceLock::new();

fn embedded<'py>(
    py: Python<'py>,
    cell: &'static PyOnceLock<Py<PyModule>>,
    code: &str,
    file: &std::ffi::CStr,
    name: &std::ffi::CStr,
) -> Result<&'py Bound<'py, PyModule>, BridgeError> {
    // pxr first, so a missing usd-core is reported as such rather than as an ImportError inside
    // the embedded module.
    import_pxr(py, "Usd")?;
    let module = cell.get_or_try_init(py, || -> PyResult<_> {
        let code = CString::new(code).expect("no NUL in embedded Python");
        Ok(PyModule::from_code(py, &code, file, name)?.unbind())
    })?;
    Ok(module.bind(py))
}

fn usd_writer(py: Python<'_>) -> Result<&Bound<'_, PyModule>, BridgeError> {
    embedded(
        py,
        &USD_WRITER,
        include_str!("usd_writer.py"),
        c"usd_writer.py",
        c"garmentbake_usd_writer",
    )
}

static ABC_WRITER: PyOnceLock<Py<PyModule>> = PyOnceLock::new();

/// The Alembic authoring code (`abc_writer.py`), compiled once per process; a missing
/// `alembic3d` is reported as such rather than as an ImportError inside the module.
fn abc_writer(py: Python<'_>) -> Result<&Bound<'_, PyModule>, BridgeError> {
    add_venv(py)?;
    py.import("alembic3d")
        .map_err(|e| BridgeError::MissingAlembic {
            venv: venv_dir().map_or_else(|| "(none)".into(), |v| v.display().to_string()),
            reason: e.to_string(),
        })?;
    let module = ABC_WRITER.get_or_try_init(py, || -> PyResult<_> {
        let code = CString::new(include_str!("abc_writer.py")).expect("no NUL in embedded Python");
        Ok(PyModule::from_code(py, &code, c"abc_writer.py", c"garmentbake_abc_writer")?.unbind())
    })?;
    Ok(module.bind(py))
}

/// Whether `alembic3d` imports from the venv: checked before a command's work when it is to
/// write `.abc` (the missing module is then bad input, found before minutes of computation).
pub fn check_alembic() -> Result<(), BridgeError> {
    Python::attach(|py| abc_writer(py).map(|_| ()))
}

/// Calls `abc_writer.write_point_caches(spec, path)` (an Ogawa archive). The caller owns
/// atomicity (temporary name, rename).
pub fn write_alembic(spec: &Value<'_>, path: &Path) -> Result<(), BridgeError> {
    Python::attach(|py| {
        let writer = abc_writer(py)?;
        let spec = spec.to_py(py)?;
        writer.call_method1(
            "write_point_caches",
            (spec, path.to_string_lossy().into_owned()),
        )?;
        Ok(())
    })
}

/// A mesh prim read from a USD stage: world space, metres, Y-up, counter-clockwise faces.
#[derive(Clone, Debug, PartialEq)]
pub struct UsdMesh {
    /// The prim path, e.g. `/root/shirt`.
    pub path: String,
    pub points: Vec<[f32; 3]>,
    /// Vertices per face (polygons as authored, not triangulated).
    pub face_counts: Vec<u32>,
    pub face_indices: Vec<u32>,
}

/// Every mesh prim of the stage at `path` (any format usd-core opens: .usd, .usda, .usdc, .usdz).
pub fn read_usd_meshes(path: &Path) -> Result<Vec<UsdMesh>, BridgeError> {
    Python::attach(|py| {
        let reader = embedded(
            py,
            &USD_READER,
            include_str!("usd_reader.py"),
            c"usd_reader.py",
            c"garmentbake_usd_reader",
        )?;
        let meshes = reader.call_method1("read_meshes", (path.to_string_lossy().into_owned(),))?;
        let mut out = Vec::new();
        for m in meshes.try_iter()? {
            let m = m?;
            let flat: Vec<f32> = m.get_item("points")?.extract()?;
            out.push(UsdMesh {
                path: m.get_item("path")?.extract()?,
                points: flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
                face_counts: m.get_item("face_counts")?.extract()?,
                face_indices: m.get_item("face_indices")?.extract()?,
            });
        }
        Ok(out)
    })
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

/// One finding of [`validate_usd`]: severity (`error` / `warning`), where, what.
pub type UsdFinding = (String, String, String);

/// usd-core's UsdValidation validators on the stage at `path`, then the UsdSkel binding rules of
/// every skinned mesh (joint index range, element size, weight sums, blend shape / target
/// counts, finite time samples). A file usd-core cannot open is one error, not an `Err`.
pub fn validate_usd(path: &Path) -> Result<Vec<UsdFinding>, BridgeError> {
    Python::attach(|py| {
        let module = embedded(
            py,
            &USD_VALIDATOR,
            include_str!("usd_validator.py"),
            c"usd_validator.py",
            c"garmentbake_usd_validator",
        )?;
        let found = module.call_method1("validate", (path.to_string_lossy().into_owned(),))?;
        Ok(found.extract()?)
    })
}

/// A USD garment played by usd-core: [`replay_usd`]'s answer.
#[derive(Clone, Debug)]
pub struct UsdReplay {
    /// The mesh prim played, e.g. `/skirt/garment`.
    pub mesh: String,
    /// Skinned through UsdSkel (else its time-sampled `points`).
    pub skinned: bool,
    /// Time samples of the bound SkelAnimation's joints (skinned) or of `points`.
    pub samples: usize,
    /// `[frame][point]`, as usd-core computed them.
    pub frames: Vec<Vec<[f32; 3]>>,
}

/// The mesh of the stage at `path` holding one of `counts` points (`garment` when several do),
/// evaluated by usd-core at frames `0..frames` of the clip played at `fps` (the `clip` variant
/// named `clip`, or the only one): UsdSkel's BlendShapeQuery and SkinningQuery for a skinned
/// mesh, the time-sampled points otherwise (python_bridge/src/usd_replay.py). `Ok(Err(reason))`
/// when the file cannot be played that way.
pub fn replay_usd(
    path: &Path,
    counts: &[usize],
    clip: &str,
    fps: f64,
    frames: usize,
) -> Result<Result<UsdReplay, String>, BridgeError> {
    Python::attach(|py| {
        let module = embedded(
            py,
            &USD_REPLAY,
            include_str!("usd_replay.py"),
            c"usd_replay.py",
            c"garmentbake_usd_replay",
        )?;
        let path = path.to_string_lossy().into_owned();
        let got = module.call_method1("replay", (path, counts.to_vec(), clip, fps, frames))?;
        if let Ok(reason) = got.get_item("error") {
            return Ok(Err(reason.extract()?));
        }
        let points = got.get_item("points")?;
        let bytes = points.cast::<PyBytes>().map_err(PyErr::from)?.as_bytes();
        if frames == 0 || bytes.len() % (12 * frames) != 0 {
            return Ok(Err(format!(
                "usd-core gave {} bytes of points for {frames} frames",
                bytes.len()
            )));
        }
        let per_frame = bytes.len() / frames / 12;
        let point = |b: &[u8]| -> [f32; 3] {
            [0, 4, 8].map(|o| f32::from_le_bytes(b[o..o + 4].try_into().expect("4 bytes")))
        };
        Ok(Ok(UsdReplay {
            mesh: got.get_item("mesh")?.extract()?,
            skinned: got.get_item("skinned")?.extract()?,
            samples: got.get_item("samples")?.extract()?,
            frames: bytes
                .chunks_exact(12 * per_frame.max(1))
                .map(|f| f.chunks_exact(12).map(point).collect())
                .collect(),
        }))
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

    /// A Z-up stage in centimetres with a left-handed quad under a translated Xform: pxr itself
    /// parses the text; the reader must hand back metres, Y-up, world space, counter-clockwise.
    #[test]
    fn read_usd_meshes_converts_units_axis_transform_and_winding() {
        let dir = std::env::temp_dir().join(format!("bridge_read_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("quad.usda");
        std::fs::write(
            &path,
            r#"#usda 1.0
(
    upAxis = "Z"
    metersPerUnit = 0.01
)
def Xform "root" (
)
{
    double3 xformOp:translate = (0, 0, 100)
    uniform token[] xformOpOrder = ["xformOp:translate"]
    def Mesh "quad"
    {
        uniform token orientation = "leftHanded"
        point3f[] points = [(0, 0, 0), (10, 0, 0), (10, 20, 0), (0, 20, 0)]
        int[] faceVertexCounts = [4]
        int[] faceVertexIndices = [0, 1, 2, 3]
    }
}
"#,
        )
        .unwrap();
        let meshes = super::read_usd_meshes(&path).expect("read");
        assert_eq!(meshes.len(), 1);
        let m = &meshes[0];
        assert_eq!(m.path, "/root/quad");
        assert_eq!(m.face_counts, vec![4]);
        // Left-handed → the corners after the first are reversed.
        assert_eq!(m.face_indices, vec![0, 3, 2, 1]);
        // (x, y, z) cm Z-up, lifted 1 m → (x, z, -y) m Y-up.
        let expect = [
            [0.0, 1.0, 0.0],
            [0.1, 1.0, 0.0],
            [0.1, 1.0, -0.2],
            [0.0, 1.0, -0.2],
        ];
        for (p, e) in m.points.iter().zip(expect) {
            for k in 0..3 {
                assert!((p[k] - e[k]).abs() < 1e-6, "{p:?} vs {e:?}");
            }
        }
        std::fs::remove_dir_all(&dir).ok();
    }

    /// The shipped-data shirt (../shared/data, beside the repo in CI): centimetres → metres.
    #[test]
    fn reads_the_newton_shirt() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../shared/data/garments/unisex_shirt.usd");
        let meshes = super::read_usd_meshes(&path).expect("read");
        assert_eq!(meshes.len(), 1);
        assert_eq!(meshes[0].points.len(), 6436);
        assert_eq!(meshes[0].face_counts.len(), 12736);
        let top = meshes[0]
            .points
            .iter()
            .map(|p| p[1])
            .fold(f32::MIN, f32::max);
        assert!((top - 1.5259).abs() < 1e-3, "{top}");
    }
}
