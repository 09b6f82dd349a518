//! `validate`: is this file right? Structure read by our own code (glTF/GLB, PC2, MDD; no Node
//! or Blender at run time), and, given the model and clip, the file replayed as its format's
//! spec evaluates it against the model's own evaluation, in mm.

pub mod accessor;
pub mod cache;
pub mod container;
pub mod replay;
pub mod scene;
pub mod structure;
pub mod usd;

use anyhow::{bail, Context, Result};
use exporters::FileKind;
use replay::{compare, replay_gltf, Reference, ReplayError};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// One finding, located by a JSON pointer (glTF) or a byte/frame position (caches).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Problem {
    pub at: String,
    pub message: String,
}

/// Errors fail a file; warnings (a spec's SHOULD) are reported and do not.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Problems {
    pub errors: Vec<Problem>,
    pub warnings: Vec<Problem>,
}

/// At most this many findings of one severity are kept: a corrupt file says enough by then.
const KEEP: usize = 50;

impl Problems {
    pub fn error(&mut self, at: impl Into<String>, message: impl Into<String>) {
        if self.errors.len() < KEEP {
            self.errors.push(Problem {
                at: at.into(),
                message: message.into(),
            });
        }
    }

    pub fn warning(&mut self, at: impl Into<String>, message: impl Into<String>) {
        if self.warnings.len() < KEEP {
            self.warnings.push(Problem {
                at: at.into(),
                message: message.into(),
            });
        }
    }

    pub fn passed(&self) -> bool {
        self.errors.is_empty()
    }
}

/// A glTF file read and checked: the document (when it parsed) and its accessors' data (when
/// its references are sound), for the replay.
pub struct CheckedGltf {
    pub document: Option<container::Document>,
    pub accessors: Option<structure::Accessors>,
}

/// Checks the structure of a glTF/GLB held in `bytes` (read from `path`, which locates the
/// buffers of a `.gltf`).
pub fn check_gltf(path: &Path, bytes: &[u8], problems: &mut Problems) -> CheckedGltf {
    let is_glb = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("glb"));
    if is_glb && !bytes.starts_with(b"glTF") {
        problems.error(
            "/",
            "not a GLB: the file does not start with the magic 'glTF'",
        );
        return CheckedGltf {
            document: None,
            accessors: None,
        };
    }
    let document = container::parse(path, bytes, problems);
    let accessors = document
        .as_ref()
        .and_then(|d| structure::check(d, problems));
    CheckedGltf {
        document,
        accessors,
    }
}

/// The kinds of file `validate` checks.
pub const CHECKABLE: [FileKind; 4] = [FileKind::Gltf, FileKind::Pc2, FileKind::Mdd, FileKind::Usd];

/// The kind of `path` when it is one `validate` checks; else the error naming the extensions.
pub fn checkable(path: &Path) -> Result<FileKind> {
    match FileKind::of(path).filter(|k| CHECKABLE.contains(k)) {
        Some(kind) => Ok(kind),
        None => bail!(
            "{}: cannot validate this kind of file; use {}",
            path.display(),
            FileKind::extension_list(&CHECKABLE, true)
        ),
    }
}

/// What checking one file found.
pub struct Checked {
    pub problems: Problems,
    /// The replay against the model, when a reference was given and the structure allowed it.
    pub replay: Option<ReplayError>,
}

/// `validate` run by the command that just wrote the file (`bake --validate`, `rollout
/// --validate`): the verdict, the errors and the replay, per clip.
#[derive(Serialize, Deserialize)]
pub struct Validation {
    pub clip: Option<String>,
    pub passed: bool,
    pub errors: Vec<Problem>,
    pub replay: Option<ReplayError>,
}

impl Checked {
    pub fn validation(self, clip: Option<String>) -> Validation {
        Validation {
            clip,
            passed: self.problems.passed(),
            errors: self.problems.errors,
            replay: self.replay,
        }
    }
}

impl Validation {
    /// The verdict in one line, then one line per error.
    pub fn print(&self) {
        let clip = self.clip.as_deref().unwrap_or("structure");
        let verdict = if self.passed { "passes" } else { "FAILS" };
        match &self.replay {
            Some(x) => println!(
                "validate {clip}: {verdict}; replay max {:.4} mm, mean {:.4} mm, p99 {:.4} mm",
                x.error.max_mm,
                x.error.mean_mm,
                x.error.p99_mm.unwrap_or(f64::NAN)
            ),
            None => println!("validate {clip}: {verdict}"),
        }
        for e in &self.errors {
            println!("  error {}: {}", e.at, e.message);
        }
    }
}

/// Checks the file at `path`: its structure, then (with `reference`) its replay against the
/// model; a replay above `tolerance_mm` is an error. `Err` only when it cannot be read at all.
pub fn check_file(
    path: &Path,
    reference: Option<&Reference>,
    tolerance_mm: f64,
) -> Result<Checked> {
    let kind = checkable(path)?;
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mut p = Problems::default();
    let replay = match kind {
        FileKind::Gltf => gltf(path, &bytes, reference, tolerance_mm, &mut p),
        FileKind::Usd => {
            usd::check_usd(path, &mut p)?;
            match reference {
                Some(reference) if p.passed() => usd::replay_usd(path, reference, tolerance_mm)
                    .map_err(|reason| p.error("replay", reason))
                    .ok(),
                _ => None,
            }
        }
        _ => point_cache(kind, &bytes, reference, tolerance_mm, &mut p),
    };
    if let Some(r) = replay.as_ref().filter(|r| !r.passed) {
        p.error(
            "replay",
            format!(
                "max error {:.3} mm (frame {}, vertex {}) exceeds the tolerance of {} mm",
                r.error.max_mm, r.error.worst_frame, r.worst_vertex, r.tolerance_mm
            ),
        );
    }
    Ok(Checked {
        problems: p,
        replay,
    })
}

/// Structure of a glTF, then its replay against the model.
fn gltf(
    path: &Path,
    bytes: &[u8],
    reference: Option<&Reference>,
    tolerance_mm: f64,
    p: &mut Problems,
) -> Option<ReplayError> {
    let checked = check_gltf(path, bytes, p);
    let (Some(reference), Some(doc), Some(accessors), true) =
        (reference, &checked.document, &checked.accessors, p.passed())
    else {
        return None;
    };
    replay_gltf(doc, accessors, reference, tolerance_mm)
        .map_err(|reason| p.error("replay", reason))
        .ok()
}

/// Structure of a PC2 / MDD, then its frames against the model's (same vertex order, as `eval`
/// writes them).
fn point_cache(
    kind: FileKind,
    bytes: &[u8],
    reference: Option<&Reference>,
    tolerance_mm: f64,
    p: &mut Problems,
) -> Option<ReplayError> {
    let cache = match kind {
        FileKind::Mdd => cache::check_mdd(bytes, p),
        _ => cache::check_pc2(bytes, p),
    }?;
    let reference = reference?;
    let vertices = reference.vertex_count();
    cache::check_against_clip(
        &cache,
        reference.frames.len(),
        reference.frames.fps as f64,
        vertices,
        p,
    );
    if !p.passed() {
        return None;
    }
    let identity: Vec<u32> = (0..vertices as u32).collect();
    Some(compare(reference, &identity, tolerance_mm, |f| {
        cache.frames[f].iter().map(|q| q.map(f64::from)).collect()
    }))
}
