//! A command's outputs, checked before any work: each flag's path against the extensions of what
//! it writes, and the whole set written all or none (`exporters::atomic::OutputSet`).

use anyhow::Result;
use std::path::Path;

/// What an output flag writes, for [`output_set`].
#[derive(Clone, Copy)]
pub enum Writes {
    Kinds(&'static [exporters::FileKind]),
    /// A page (`--view PAGE.html`).
    Page,
    /// A file of one of these extensions (a picture, a joint map).
    Named(&'static [&'static str]),
    /// A file of any name (a log).
    Any,
}

impl Writes {
    fn extensions(self) -> Vec<&'static str> {
        match self {
            Writes::Kinds(kinds) => exporters::FileKind::written_extensions(kinds),
            Writes::Page => vec!["html", "htm"],
            Writes::Named(extensions) => extensions.to_vec(),
            Writes::Any => vec![],
        }
    }
}

/// A point cache: .pc2, .mdd, .usda/.usdc/.usdz, .abc, .vat.exr or .vat.png.
pub const POINT_CACHE: Writes = Writes::Kinds(&exporters::POINT_CACHE_KINDS);

/// A picture (`--out S.png`, `--png`, `--plot-*`).
pub const PNG: Writes = Writes::Named(&["png"]);

/// A model file (.safetensors).
pub const MODEL: Writes = Writes::Kinds(&[exporters::FileKind::Model]);

/// A baked asset: glTF (.glb/.gltf) or USD (.usda/.usdc/.usdz).
pub const ASSET: Writes = Writes::Kinds(&[exporters::FileKind::Gltf, exporters::FileKind::Usd]);

/// A command's outputs, `(flag, path if given, what it writes)`, checked before its work and
/// written all or none (exporters::atomic::OutputSet).
pub fn output_set(
    outputs: &[(&str, Option<&Path>, Writes)],
) -> Result<exporters::atomic::OutputSet> {
    let extensions: Vec<Vec<&str>> = outputs.iter().map(|o| o.2.extensions()).collect();
    let planned: Vec<exporters::atomic::Planned> = outputs
        .iter()
        .zip(&extensions)
        .filter_map(|(&(flag, path, _), extensions)| {
            path.map(|path| exporters::atomic::Planned {
                flag,
                path,
                extensions,
            })
        })
        .collect();
    Ok(exporters::atomic::OutputSet::check(&planned)?)
}
