//! `validate`: is this file right? Structure read by our own code (glTF/GLB, PC2, MDD; no Node
//! or Blender at run time), and, given the model and clip, the file replayed as its format's
//! spec evaluates it against the model's own evaluation, in mm.

pub mod accessor;
pub mod cache;
pub mod container;
pub mod replay;
pub mod scene;
pub mod structure;

use serde::Serialize;
use std::path::Path;

/// One finding, located by a JSON pointer (glTF) or a byte/frame position (caches).
#[derive(Clone, Debug, Serialize, PartialEq)]
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
