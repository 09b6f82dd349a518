//! Blender as a subprocess: the job folder it reads, the run, and what it hands back.

use super::{Prepared, Scene, Settings, Simulation};
use crate::geometry::Frames;
use crate::geometry::TriMesh;
use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// The script Blender runs; part of every cache key.
pub const SCRIPT: &str = include_str!("cloth.py");

/// Blender's cloth gravity per frame² is 0.001 × g whatever the scene rate: one frame is
/// √0.001 s (measured: a free fall of 4.44 m in 30 frames at 30 and at 60 fps).
pub const BLENDER_FRAME_S: f64 = 0.031_622_776_601_683_79;

/// `explicit`, else $GARMENTBAKE_BLENDER, else `blender` on PATH.
pub fn find(explicit: Option<&Path>) -> Result<PathBuf> {
    let named = explicit
        .map(Path::to_path_buf)
        .or_else(|| std::env::var_os("GARMENTBAKE_BLENDER").map(PathBuf::from));
    let candidate = named.clone().unwrap_or_else(|| PathBuf::from("blender"));
    let found = if candidate.components().count() > 1 {
        candidate.is_file().then_some(candidate.clone())
    } else {
        std::env::var_os("PATH").and_then(|paths| {
            std::env::split_paths(&paths)
                .map(|d| d.join(&candidate))
                .find(|p| p.is_file())
        })
    };
    found.with_context(|| {
        format!(
            "Blender not found ({}): install it (Debian: apt-get install blender python3-numpy, or bash scripts/setup.sh) or pass --blender PATH",
            candidate.display()
        )
    })
}

/// The first line of `blender --version` ("Blender 3.4.1"), once per executable per process:
/// part of every cache key, so another Blender simulates again.
pub fn version(blender: &Path) -> Result<String> {
    static SEEN: std::sync::Mutex<Vec<(PathBuf, String)>> = std::sync::Mutex::new(Vec::new());
    let mut seen = SEEN.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((_, v)) = seen.iter().find(|(p, _)| p == blender) {
        return Ok(v.clone());
    }
    let out = Command::new(blender)
        .arg("--version")
        .stdin(Stdio::null())
        .output()
        .with_context(|| format!("cannot start Blender ({})", blender.display()))?;
    let text = String::from_utf8_lossy(&out.stdout);
    let Some(line) = text.lines().map(str::trim).find(|l| !l.is_empty()) else {
        bail!(
            "{} --version printed nothing ({}): is it Blender?",
            blender.display(),
            out.status
        );
    };
    seen.push((blender.to_path_buf(), line.to_string()));
    Ok(line.to_string())
}

/// job.json: everything the script reads besides the arrays.
#[derive(Serialize)]
struct Job<'a> {
    fps: f32,
    frames: usize,
    time_scale: f64,
    speed_limit: f32,
    pinned: &'a [u32],
    cloth: &'a crate::fabric::ClothSim,
    body: MeshFiles,
    garment: MeshFiles,
}

#[derive(Serialize)]
struct MeshFiles {
    vertices: usize,
    points: &'static str,
    triangles: &'static str,
    cache: &'static str,
}

/// result.json.
#[derive(Deserialize)]
struct Outcome {
    blender_version: String,
    frames_done: usize,
    failure: Option<Failure>,
    seconds: f64,
}

#[derive(Deserialize)]
struct Failure {
    frame: usize,
    reason: String,
}

/// The job folder's files (name, bytes), built in memory so their hash keys the cache before
/// anything is written.
pub type JobFiles = Vec<(&'static str, Vec<u8>)>;

/// Script, meshes, per-frame points and job.json for one simulation.
pub fn job_files(scene: &Scene, prepared: &Prepared, settings: &Settings) -> Result<JobFiles> {
    let mut files: JobFiles = vec![("cloth.py", SCRIPT.as_bytes().to_vec())];
    let body = mesh_files(
        &mut files,
        Role::Body,
        scene.body.mesh(),
        &prepared.body_frames,
    )?;
    let garment = mesh_files(
        &mut files,
        Role::Garment,
        &scene.garment.mesh,
        &prepared.garment_targets,
    )?;
    let job = Job {
        fps: prepared.fps(),
        frames: prepared.poses.len(),
        time_scale: 1.0 / (prepared.fps() as f64 * BLENDER_FRAME_S),
        speed_limit: settings.speed_limit,
        pinned: pinned(scene),
        cloth: &scene.fabric.simulate,
        body,
        garment,
    };
    files.push(("job.json", serde_json::to_vec_pretty(&job)?));
    Ok(files)
}

/// The fabric's pin set when it has one, else the garment sidecar's.
pub fn pinned<'a>(scene: &Scene<'a>) -> &'a [u32] {
    scene
        .fabric
        .pinned
        .as_deref()
        .unwrap_or(&scene.garment.sidecar.pinned)
}

/// Writes the job's files into `dir`.
pub fn write_job(dir: &Path, files: &JobFiles) -> Result<()> {
    for (name, bytes) in files {
        std::fs::write(dir.join(name), bytes)
            .with_context(|| format!("writing {name} in {}", dir.display()))?;
    }
    Ok(())
}

#[derive(Clone, Copy)]
enum Role {
    Body,
    Garment,
}

fn mesh_files(
    files: &mut JobFiles,
    role: Role,
    mesh: &TriMesh,
    frames: &Frames,
) -> Result<MeshFiles> {
    let (name, points, triangles, cache) = match role {
        Role::Body => ("body", "body_points.f32", "body_triangles.u32", "body.pc2"),
        Role::Garment => (
            "garment",
            "garment_points.f32",
            "garment_triangles.u32",
            "garment.pc2",
        ),
    };
    let floats = mesh
        .positions
        .iter()
        .flatten()
        .flat_map(|c| c.to_le_bytes());
    let ints = mesh
        .triangles
        .iter()
        .flatten()
        .flat_map(|i| i.to_le_bytes());
    let pc = exporters::PointCache {
        name: name.into(),
        fps: frames.fps,
        start: frames.start,
        triangles: Vec::new(),
        uvs: None,
        point_count: mesh.vertex_count(),
        points: frames.iter().flatten().copied().collect(),
    };
    files.push((points, floats.collect()));
    files.push((triangles, ints.collect()));
    files.push((
        cache,
        exporters::pc2::to_bytes(&pc).map_err(|e| anyhow::anyhow!("{e}"))?,
    ));
    Ok(MeshFiles {
        vertices: mesh.vertex_count(),
        points,
        triangles,
        cache,
    })
}

/// Runs Blender on the job in `dir`; `on_frame(k)` after each of the k simulated frames.
pub fn run(
    dir: &Path,
    settings: &Settings,
    vertices: usize,
    fps: f32,
    lead_in: usize,
    on_frame: &dyn Fn(usize),
) -> Result<Simulation> {
    let mut child = Command::new(&settings.blender)
        .args(["-b", "--factory-startup", "-noaudio", "-t"])
        .arg(settings.threads.to_string())
        .arg("--python")
        .arg(dir.join("cloth.py"))
        .arg("--")
        .arg(dir)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .with_context(|| format!("cannot start Blender ({})", settings.blender.display()))?;
    let mut stderr = child.stderr.take().expect("piped");
    let errors = std::thread::spawn(move || {
        let mut text = String::new();
        let _ = stderr.read_to_string(&mut text);
        text
    });
    for line in BufReader::new(child.stdout.take().expect("piped")).lines() {
        if let Some(k) = line?
            .strip_prefix("frame ")
            .and_then(|k| k.trim().parse::<usize>().ok())
        {
            on_frame(k + 1);
        }
    }
    let status = child.wait()?;
    let errors = errors.join().unwrap_or_default();
    if !status.success() {
        bail!("Blender failed ({status}): {}", tail(&errors));
    }
    let outcome: Outcome = serde_json::from_slice(&std::fs::read(dir.join("result.json"))?)
        .context("Blender's result.json")?;
    if let Some(f) = outcome.failure {
        bail!("{}", explosion_message(f.frame, lead_in, &f.reason));
    }
    let garment = Frames::new(
        read_frames(&dir.join("garment.f32"), vertices, outcome.frames_done)?,
        fps,
    );
    Ok(Simulation {
        garment,
        blender_version: outcome.blender_version,
        seconds: outcome.seconds,
        simulated_frames: outcome.frames_done,
    })
}

/// "exploded at frame N" in the clip's numbering, or in the lead-in.
pub fn explosion_message(frame: usize, lead_in: usize, reason: &str) -> String {
    let at = match frame.checked_sub(lead_in) {
        Some(f) => format!("frame {f} of the clip"),
        None => format!("lead-in frame {frame} of {lead_in} (before the clip)"),
    };
    format!("the cloth simulation exploded at {at}: {reason}; nothing written (raise [simulate] quality / collision_quality in the fabric)")
}

fn read_frames(path: &Path, vertices: usize, frames: usize) -> Result<Vec<Vec<[f32; 3]>>> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let want = frames * vertices * 12;
    if bytes.len() != want {
        bail!("{}: {} bytes, expected {want}", path.display(), bytes.len());
    }
    let floats: Vec<f32> = bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().expect("4 bytes")))
        .collect();
    Ok(floats
        .chunks_exact(vertices * 3)
        .map(|f| f.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect())
        .collect())
}

/// The last lines of Blender's stderr, on one line.
fn tail(text: &str) -> String {
    let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    lines[lines.len().saturating_sub(3)..].join(" | ")
}

/// A scratch folder removed when dropped.
pub struct WorkDir(pub PathBuf);

impl WorkDir {
    pub fn new() -> Result<WorkDir> {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos());
        let dir =
            std::env::temp_dir().join(format!("garmentbake-sim-{}-{nanos}", std::process::id()));
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        Ok(WorkDir(dir))
    }
}

impl Drop for WorkDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}
