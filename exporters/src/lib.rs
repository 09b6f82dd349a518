//! Writers that turn a [`asset::BakedAsset`] into files.
//!
//! The baked asset is plain data (gltfpack style): everything a format needs, nothing about how it
//! was produced. It lives here rather than in the core crate because the core's CLI calls the
//! exporters, and Cargo forbids the cycle; data still flows one way: model → asset → exporter → file.

#[cfg(feature = "usd")]
pub mod abc;
pub mod asset;
pub mod atomic;
pub mod gltf;
pub mod mdd;
pub mod pc2;
#[cfg(feature = "usd")]
pub mod usd;
pub mod vat;
pub mod viewer;

pub use asset::{BakedAsset, CacheSpace, PointCache};
use std::path::Path;

#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    #[error(transparent)]
    Gltf(#[from] gltf::GltfError),
    #[error(transparent)]
    Pc2(#[from] pc2::Pc2Error),
    #[error(transparent)]
    Mdd(#[from] mdd::MddError),
    #[cfg(feature = "usd")]
    #[error(transparent)]
    Usd(#[from] usd::UsdError),
    #[cfg(feature = "usd")]
    #[error(transparent)]
    Abc(#[from] abc::AbcError),
    #[error(transparent)]
    Vat(#[from] vat::VatError),
    #[error("cannot write {path}: {what}")]
    Unsupported { path: String, what: String },
}

/// The kinds of file garmentbake reads or writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FileKind {
    Gltf,
    Usd,
    Pc2,
    Mdd,
    /// Alembic (`.abc`): point caches, written through the Python bridge like USD.
    Alembic,
    /// Vertex animation textures (`.vat.exr`, 16-bit `.vat.png`): a point cache as textures.
    Vat,
    Bvh,
    Obj,
    /// A garmentbake model (`.safetensors`).
    Model,
}

/// The one extension table: every extension, its kind, and whether garmentbake writes it
/// (usd-core reads plain `.usd`, we write the explicit `.usda`/`.usdc`/`.usdz`). An extension
/// may have two parts (`vat.exr`): a name matches the row its end names.
pub const EXTENSIONS: [(&str, FileKind, bool); 14] = [
    ("glb", FileKind::Gltf, true),
    ("gltf", FileKind::Gltf, true),
    ("usd", FileKind::Usd, false),
    ("usda", FileKind::Usd, true),
    ("usdc", FileKind::Usd, true),
    ("usdz", FileKind::Usd, true),
    ("pc2", FileKind::Pc2, true),
    ("mdd", FileKind::Mdd, true),
    ("abc", FileKind::Alembic, true),
    ("vat.exr", FileKind::Vat, true),
    ("vat.png", FileKind::Vat, true),
    ("bvh", FileKind::Bvh, false),
    ("obj", FileKind::Obj, true),
    ("safetensors", FileKind::Model, true),
];

impl FileKind {
    /// The kind a path's extension names (any case).
    pub fn of(path: &Path) -> Option<FileKind> {
        Self::row(path).map(|(_, k, _)| k)
    }

    /// The kind of an output path, when garmentbake writes that extension.
    pub fn written(path: &Path) -> Option<FileKind> {
        Self::row(path).filter(|r| r.2).map(|(_, k, _)| k)
    }

    fn row(path: &Path) -> Option<(&'static str, FileKind, bool)> {
        let name = path.file_name()?.to_string_lossy().to_ascii_lowercase();
        EXTENSIONS
            .iter()
            .copied()
            .find(|(e, _, _)| name.len() > e.len() + 1 && name.ends_with(&format!(".{e}")))
    }

    /// The extensions garmentbake writes for `kinds` (lower case, no dot), e.g. for the checks
    /// of an [`atomic::OutputSet`].
    pub fn written_extensions(kinds: &[FileKind]) -> Vec<&'static str> {
        EXTENSIONS
            .iter()
            .filter(|(_, k, w)| *w && kinds.contains(k))
            .map(|(e, _, _)| *e)
            .collect()
    }

    /// `.a, .b or .c`: the extensions of `kinds` (written ones only with `written`), for messages.
    pub fn extension_list(kinds: &[FileKind], written: bool) -> String {
        let exts: Vec<String> = EXTENSIONS
            .iter()
            .filter(|(_, k, w)| kinds.contains(k) && (*w || !written))
            .map(|(e, _, _)| format!(".{e}"))
            .collect();
        match exts.split_last() {
            Some((last, [])) => last.clone(),
            Some((last, rest)) => format!("{} or {last}", rest.join(", ")),
            None => String::new(),
        }
    }
}

/// Writes a skinned asset in the format its extension names.
pub fn write(asset: &BakedAsset, path: &Path) -> Result<(), ExportError> {
    match FileKind::written(path) {
        Some(FileKind::Gltf) => Ok(gltf::write(asset, path)?),
        Some(FileKind::Usd) => write_usd(asset, path),
        _ => Err(wrong_extension(path, "", &[FileKind::Gltf, FileKind::Usd])),
    }
}

/// The kinds a point cache can be written as (a VAT through [`vat::write`], which needs the
/// rest mesh and normals beside the frames).
pub const POINT_CACHE_KINDS: [FileKind; 5] = [
    FileKind::Pc2,
    FileKind::Mdd,
    FileKind::Usd,
    FileKind::Alembic,
    FileKind::Vat,
];

/// Writes a per-frame point cache in the format its extension names: PC2, MDD, USD (a Mesh
/// with time-sampled points) or Alembic (a PolyMesh with time-sampled positions).
pub fn write_point_cache(cache: &PointCache, path: &Path) -> Result<(), ExportError> {
    write_point_cache_in(cache, path, CacheSpace::NATIVE)
}

/// [`write_point_cache`] of points already turned into `space` (see [`CacheSpace::point`]),
/// recorded where the format has a place (USD, Alembic).
pub fn write_point_cache_in(
    cache: &PointCache,
    path: &Path,
    space: CacheSpace,
) -> Result<(), ExportError> {
    match FileKind::written(path) {
        Some(FileKind::Pc2) => Ok(pc2::write(path, cache)?),
        Some(FileKind::Mdd) => Ok(mdd::write(path, cache)?),
        Some(FileKind::Usd) => write_usd_caches(std::slice::from_ref(cache), path, space),
        Some(FileKind::Alembic) => write_abc_caches(std::slice::from_ref(cache), path, space),
        Some(FileKind::Vat) => Err(unsupported(
            path,
            "a VAT needs the rest mesh and normals beside the frames: write it with exporters::vat::write",
        )),
        _ => Err(wrong_extension(path, "point-cache ", &POINT_CACHE_KINDS)),
    }
}

/// Writes several point caches of one shot (e.g. a garment and the posed body it moves on) into
/// one USD stage or Alembic archive, one mesh each; PC2 and MDD hold a single mesh, so other
/// extensions are refused.
pub fn write_point_caches(caches: &[PointCache], path: &Path) -> Result<(), ExportError> {
    write_point_caches_in(caches, path, CacheSpace::NATIVE)
}

/// [`write_point_caches`] of points already turned into `space`, recorded in the file.
pub fn write_point_caches_in(
    caches: &[PointCache],
    path: &Path,
    space: CacheSpace,
) -> Result<(), ExportError> {
    match FileKind::written(path) {
        Some(FileKind::Usd) => write_usd_caches(caches, path, space),
        Some(FileKind::Alembic) => write_abc_caches(caches, path, space),
        _ => Err(wrong_extension(
            path,
            "several-mesh point-cache ",
            &[FileKind::Usd, FileKind::Alembic],
        )),
    }
}

/// "unknown {what}extension; use .a, .b or .c" for the written extensions of `kinds`.
fn wrong_extension(path: &Path, what: &str, kinds: &[FileKind]) -> ExportError {
    let list = FileKind::extension_list(kinds, true);
    unsupported(path, &format!("unknown {what}extension; use {list}"))
}

fn unsupported(path: &Path, what: &str) -> ExportError {
    ExportError::Unsupported {
        path: path.display().to_string(),
        what: what.into(),
    }
}

#[cfg(feature = "usd")]
fn write_usd(asset: &BakedAsset, path: &Path) -> Result<(), ExportError> {
    Ok(usd::write(asset, path)?)
}

#[cfg(feature = "usd")]
fn write_usd_caches(
    caches: &[PointCache],
    path: &Path,
    space: CacheSpace,
) -> Result<(), ExportError> {
    Ok(usd::write_point_caches_in(caches, path, space)?)
}

#[cfg(feature = "usd")]
fn write_abc_caches(
    caches: &[PointCache],
    path: &Path,
    space: CacheSpace,
) -> Result<(), ExportError> {
    Ok(abc::write_point_caches_in(caches, path, space)?)
}

#[cfg(not(feature = "usd"))]
fn write_abc_caches(_: &[PointCache], path: &Path, _: CacheSpace) -> Result<(), ExportError> {
    Err(unsupported(
        path,
        "this garmentbake was built without the Python bridge that writes Alembic (cargo feature `usd`); rebuild with default features",
    ))
}

#[cfg(not(feature = "usd"))]
const NO_USD: &str = "this garmentbake was built without USD support (cargo feature `usd`); rebuild with default features";

#[cfg(not(feature = "usd"))]
fn write_usd(_: &BakedAsset, path: &Path) -> Result<(), ExportError> {
    Err(unsupported(path, NO_USD))
}

#[cfg(not(feature = "usd"))]
fn write_usd_caches(_: &[PointCache], path: &Path, _: CacheSpace) -> Result<(), ExportError> {
    Err(unsupported(path, NO_USD))
}
