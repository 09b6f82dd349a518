//! Simulations are slow and deterministic: each is stored once under the hash of exactly what
//! Blender is given (script, meshes, per-frame points, settings), which Blender runs it and which
//! build of garmentbake measures it ([`crate::build_id`]), so a second request with the same
//! inputs is read back instead of re-simulated, and an upgrade of either program simulates again.

use super::stats::{FrameStats, Summary};
use crate::geometry::Frames;
use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};

/// The folder `simulate` uses unless told otherwise (relative to the working directory).
pub const DEFAULT_DIR: &str = "runs/sim";

/// What is kept next to the garment's frames.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Entry {
    pub blender_version: String,
    pub seconds: f64,
    pub simulated_frames: usize,
    pub lead_in: usize,
    pub summary: Summary,
    pub frames: Vec<FrameStats>,
}

/// Hex SHA-256 of the build id, Blender's version (`blender --version`'s first line) and every
/// job file (name and bytes).
pub fn key(build: &str, blender: &str, files: &super::blender::JobFiles) -> String {
    let mut h = Sha256::new();
    for part in [build, blender] {
        h.update((part.len() as u64).to_le_bytes());
        h.update(part.as_bytes());
    }
    for (name, bytes) in files {
        h.update((name.len() as u64).to_le_bytes());
        h.update(name.as_bytes());
        h.update((bytes.len() as u64).to_le_bytes());
        h.update(bytes);
    }
    crate::io::digest::to_hex(&h.finalize())
}

fn paths(dir: &Path, key: &str) -> (PathBuf, PathBuf) {
    (
        dir.join(format!("{key}.pc2")),
        dir.join(format!("{key}.json")),
    )
}

/// The stored simulation, when both its files are there and whole.
pub fn load(dir: &Path, key: &str, vertices: usize, fps: f32) -> Option<(Frames, Entry)> {
    let (pc2, json) = paths(dir, key);
    let entry: Entry = serde_json::from_slice(&std::fs::read(json).ok()?).ok()?;
    let (header, frames) = exporters::pc2::read(&std::fs::read(pc2).ok()?).ok()?;
    (header.points == vertices && frames.len() == entry.summary.frames)
        .then_some((Frames::new(frames, fps), entry))
}

/// Stores a simulation (frames first, so an entry's JSON never names missing frames).
pub fn store(dir: &Path, key: &str, frames: &Frames, entry: &Entry) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let (pc2, json) = paths(dir, key);
    let cache = exporters::PointCache {
        name: key.into(),
        fps: frames.fps,
        start: frames.start,
        triangles: Vec::new(),
        uvs: None,
        point_count: frames.first().map_or(0, Vec::len),
        points: frames.iter().flatten().copied().collect(),
    };
    exporters::pc2::write(&pc2, &cache).map_err(|e| anyhow::anyhow!("{e}"))?;
    exporters::atomic::write_atomic(&json, &serde_json::to_vec_pretty(entry)?)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_key_changes_with_the_build_blender_and_every_byte() {
        let files: super::super::blender::JobFiles = vec![("job.json", b"{}".to_vec())];
        let k = key("1935e54", "Blender 3.4.1", &files);
        assert_eq!(k, key("1935e54", "Blender 3.4.1", &files));
        assert_ne!(k, key("7f7d33d", "Blender 3.4.1", &files), "another build");
        assert_ne!(
            k,
            key("1935e54", "Blender 4.2.0", &files),
            "another Blender"
        );
        let other: super::super::blender::JobFiles = vec![("job.json", b"{ }".to_vec())];
        assert_ne!(k, key("1935e54", "Blender 3.4.1", &other), "another job");
    }
}
