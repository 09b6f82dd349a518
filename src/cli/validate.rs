//! `garmentbake validate`: the pipeline gate — exit 0 only when a file is right.

use super::args::OutputArgs;
use super::Execute;
use crate::validate::{check_gltf, Problem, Problems};
use anyhow::{bail, Context, Result};
use exporters::FileKind;
use serde::Serialize;
use std::path::PathBuf;

/// Check one file the way a pipeline's CI would, with our own readers (no Node, no Blender).
///
/// glTF / GLB: the container (GLB header and chunks), the JSON schema and its references,
/// buffer views inside their buffers, accessor layouts, strides and declared min/max, the
/// formats each attribute semantic allows, finite floats, unit normals, skin weights
/// (non-negative, summing to 1) and joints (unique, inside the skin), morph targets consistent
/// across primitives and with `weights`, animation samplers (strictly increasing times, output
/// counts), channel targets, an acyclic node tree, skins whose joints and inverse bind matrices
/// agree. Tolerances are the Khronos validator's.
///
/// Exit code: 0 the file passes, 1 it fails (every problem is listed, located by JSON pointer),
/// 2 it could not be read at all (missing file, unknown extension).
#[derive(clap::Args)]
pub struct Args {
    /// The file to check: .glb / .gltf.
    pub file: PathBuf,
    #[command(flatten)]
    pub output: OutputArgs,
}

#[derive(Serialize)]
pub struct Report {
    pub file: PathBuf,
    pub format: String,
    pub passed: bool,
    pub errors: Vec<Problem>,
    pub warnings: Vec<Problem>,
}

impl Execute for Args {
    type Report = Report;

    fn execute(&self, _say: &dyn Fn(&str)) -> Result<Report> {
        let path = &self.file;
        let kind = FileKind::of(path);
        if kind != Some(FileKind::Gltf) {
            bail!(
                "{}: cannot validate this kind of file; use {}",
                path.display(),
                FileKind::extension_list(&[FileKind::Gltf], true)
            );
        }
        let bytes =
            std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
        let mut problems = Problems::default();
        check_gltf(path, &bytes, &mut problems);
        Ok(Report {
            file: path.clone(),
            format: "glTF".into(),
            passed: problems.passed(),
            errors: problems.errors,
            warnings: problems.warnings,
        })
    }

    fn print(r: &Report) {
        let verdict = if r.passed { "passes" } else { "FAILS" };
        println!(
            "{}: {} ({} errors, {} warnings)",
            r.file.display(),
            verdict,
            r.errors.len(),
            r.warnings.len()
        );
        for (severity, list) in [("error", &r.errors), ("warning", &r.warnings)] {
            for p in list {
                println!("  {severity} {}: {}", p.at, p.message);
            }
        }
    }

    fn exit_code(r: &Report) -> i32 {
        if r.passed {
            0
        } else {
            1
        }
    }
}
