//! `bench bake`: the PBNS bake timed by phase beside Blender's glTF exporter writing the same
//! asset (our glb imported into Blender, then exported as a glb; the export alone is timed).

use crate::bake::pbns::{bake, BakeOptions, Targets};
use crate::motion::load_clip;
use anyhow::{bail, Context, Result};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The Blender script: import our glb, time the export of it.
const EXPORT_SCRIPT: &str = include_str!("blender_gltf_export.py");

/// What to bake (the flags of `bench bake`, resolved).
pub struct Request {
    pub model: PathBuf,
    pub clips: super::Clips,
    pub targets: Targets,
    /// Also time Blender's exporter on the asset.
    pub blender: bool,
    pub device: tch::Device,
}

#[derive(Serialize)]
pub struct Report {
    pub frames: usize,
    pub targets: usize,
    pub vertices: usize,
    /// Loading the model and retargeting the clips.
    pub load_s: f64,
    /// The bake's phases (`bake::pbns::BakeReport::phases`) and the glb's writing.
    pub phases: Vec<(String, f64)>,
    pub write_s: f64,
    /// The bake and its writing: the work Blender's export does (its phases summed).
    pub bake_s: f64,
    pub bytes: u64,
    /// SHA-256 of the glb timed: the bytes `bake` writes for the same flags.
    pub sha256: String,
    pub blender: Option<BlenderExport>,
}

#[derive(Serialize)]
pub struct BlenderExport {
    pub version: String,
    /// Blender's importer reading our glb (not part of the comparison).
    pub import_s: f64,
    pub export_s: f64,
    pub bytes: u64,
    /// Blender's export time over our bake's.
    pub ratio: f64,
}

/// Bakes `request` into a temporary folder, timed; then Blender's export of the same asset.
pub fn run(request: &Request, say: &dyn Fn(&str)) -> Result<Report> {
    let clock = Instant::now();
    let model = crate::models::file::load(&request.model, request.device)?;
    let reader = request.clips.reader()?;
    let fps = crate::models::swing::clip_rate(model.pbns()?, request.clips.fps)?;
    let clips = request
        .clips
        .motions
        .iter()
        .map(|p| load_clip(p, &reader, &model.body, fps).map(|c| c.animation))
        .collect::<Result<Vec<_>>>()?;
    let load_s = clock.elapsed().as_secs_f64();
    let opts = BakeOptions {
        targets: request.targets,
        influences: None,
        with_body: false,
    };
    say("baking");
    let (asset, report) = bake(&model, &clips, &opts, request.device)?;
    let dir = std::env::temp_dir().join(format!("garmentbake-bench-bake-{}", std::process::id()));
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot make {}", dir.display()))?;
    let ours = dir.join("ours.glb");
    let clock = Instant::now();
    exporters::write(&asset, &ours).with_context(|| format!("writing {}", ours.display()))?;
    let write_s = clock.elapsed().as_secs_f64();
    let bake_s = report.phases.iter().map(|p| p.1).sum::<f64>() + write_s;
    let blender = if request.blender {
        say("Blender: importing the glb, timing its glTF export");
        let b = blender_export(&ours, &dir.join("blender.glb"))?;
        Some(BlenderExport {
            ratio: b.export_s / bake_s.max(1e-9),
            ..b
        })
    } else {
        None
    };
    let written = std::fs::read(&ours).with_context(|| format!("cannot read {}", ours.display()));
    let _ = std::fs::remove_dir_all(&dir);
    let written = written?;
    Ok(Report {
        frames: report.clips.iter().map(|c| c.error.frames).sum(),
        targets: report.targets,
        vertices: model.garment.vertex_count(),
        load_s,
        phases: report.phases,
        write_s,
        bake_s,
        bytes: written.len() as u64,
        sha256: crate::io::digest::sha256_hex(&written),
        blender,
    })
}

/// Blender (Debian's, or `$GARMENTBAKE_BLENDER`) importing `glb` and exporting it to `out`, timed.
fn blender_export(glb: &Path, out: &Path) -> Result<BlenderExport> {
    let blender = crate::simulate::blender::find(None)?;
    let script = glb.with_file_name("export_gltf.py");
    std::fs::write(&script, EXPORT_SCRIPT)?;
    let o = std::process::Command::new(&blender)
        .args(["-b", "--factory-startup", "--python"])
        .arg(&script)
        .arg("--")
        .args([glb, out])
        .output()
        .with_context(|| format!("cannot run {}", blender.display()))?;
    let text = String::from_utf8_lossy(&o.stdout);
    let Some(line) = text.lines().find_map(|l| l.strip_prefix("GB_EXPORT ")) else {
        bail!(
            "Blender's glTF export did not finish: {}",
            String::from_utf8_lossy(&o.stderr)
                .lines()
                .last()
                .unwrap_or("no output")
        );
    };
    let v: serde_json::Value = serde_json::from_str(line)?;
    let num = |k: &str| v[k].as_f64().unwrap_or(f64::NAN);
    Ok(BlenderExport {
        version: v["version"].as_str().unwrap_or_default().to_string(),
        import_s: num("import_s"),
        export_s: num("export_s"),
        bytes: std::fs::metadata(out).map_or(0, |m| m.len()),
        ratio: f64::NAN,
    })
}

impl std::fmt::Display for Report {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        writeln!(
            f,
            "{} frames, {} garment vertices, {} blend shapes ({:.2} MB glb); model and clips loaded in {:.2} s",
            self.frames,
            self.vertices,
            self.targets,
            self.bytes as f64 / 1e6,
            self.load_s
        )?;
        let phases: Vec<String> = self
            .phases
            .iter()
            .map(|(name, s)| format!("{name} {s:.2}"))
            .collect();
        writeln!(
            f,
            "garmentbake bake: {:.2} s ({}, write {:.2})",
            self.bake_s,
            phases.join(", "),
            self.write_s
        )?;
        match &self.blender {
            Some(b) => writeln!(
                f,
                "Blender {} glTF export of the same asset: {:.2} s ({:.2} MB; its import took {:.2} s)\nthe bake is {:.1}x Blender's export",
                b.version,
                b.export_s,
                b.bytes as f64 / 1e6,
                b.import_s,
                b.ratio
            ),
            None => writeln!(f, "Blender not run (--no-blender)"),
        }
    }
}
