//! PC2 point caches (`POINTCACHE2`, version 1, little-endian float32), as Blender's Mesh Cache
//! modifier and 3ds Max read them: a 32-byte header, then every frame's points.
//!
//! Header: `char[12] "POINTCACHE2\0"`, `i32 version = 1`, `i32 points`, `f32 start_frame`,
//! `f32 sample_rate` (frames between samples), `i32 samples`.

use crate::asset::PointCache;
use crate::atomic::write_atomic_with;
use std::io::Write;
use std::path::Path;

pub const MAGIC: &[u8; 12] = b"POINTCACHE2\0";
pub const HEADER_LEN: usize = 32;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Header {
    pub version: i32,
    pub points: usize,
    pub start_frame: f32,
    pub sample_rate: f32,
    pub samples: usize,
}

#[derive(Debug, thiserror::Error)]
pub enum Pc2Error {
    #[error("{0}")]
    Invalid(String),
    #[error("{0}")]
    Io(#[from] std::io::Error),
    #[error("not a PC2 file: {0}")]
    Format(String),
}

/// Writes `cache` atomically, one sample per frame from its start frame (PC2 has no rate; the
/// cache's fps is the scene's).
pub fn write(path: &Path, cache: &PointCache) -> Result<(), Pc2Error> {
    let bytes = to_bytes(cache)?;
    write_atomic_with(path, |w| w.write_all(&bytes))?;
    Ok(())
}

/// The file's bytes: header, then every frame's points.
pub fn to_bytes(cache: &PointCache) -> Result<Vec<u8>, Pc2Error> {
    cache.check().map_err(Pc2Error::Invalid)?;
    let header = Header {
        version: 1,
        points: cache.point_count,
        start_frame: cache.start as f32,
        sample_rate: 1.0,
        samples: cache.frame_count(),
    };
    let mut bytes = Vec::with_capacity(HEADER_LEN + 12 * cache.points.len());
    bytes.extend_from_slice(&header_bytes(&header));
    for c in cache.points.iter().flatten() {
        bytes.extend_from_slice(&c.to_le_bytes());
    }
    Ok(bytes)
}

fn header_bytes(h: &Header) -> [u8; HEADER_LEN] {
    let mut b = [0u8; HEADER_LEN];
    b[..12].copy_from_slice(MAGIC);
    b[12..16].copy_from_slice(&h.version.to_le_bytes());
    b[16..20].copy_from_slice(&(h.points as i32).to_le_bytes());
    b[20..24].copy_from_slice(&h.start_frame.to_le_bytes());
    b[24..28].copy_from_slice(&h.sample_rate.to_le_bytes());
    b[28..32].copy_from_slice(&(h.samples as i32).to_le_bytes());
    b
}

/// Points of every frame.
pub type Frames = Vec<Vec<[f32; 3]>>;

/// Parses a PC2 file: header and frames (checks the size matches the header).
pub fn read(bytes: &[u8]) -> Result<(Header, Frames), Pc2Error> {
    if bytes.len() < HEADER_LEN || &bytes[..12] != MAGIC {
        return Err(Pc2Error::Format("missing POINTCACHE2 header".into()));
    }
    let i32_at = |o: usize| i32::from_le_bytes(bytes[o..o + 4].try_into().expect("4 bytes"));
    let f32_at = |o: usize| f32::from_le_bytes(bytes[o..o + 4].try_into().expect("4 bytes"));
    let (points, samples) = (i32_at(16), i32_at(28));
    if points < 0 || samples < 0 {
        return Err(Pc2Error::Format("negative point or sample count".into()));
    }
    let header = Header {
        version: i32_at(12),
        points: points as usize,
        start_frame: f32_at(20),
        sample_rate: f32_at(24),
        samples: samples as usize,
    };
    // In u128: two i32 counts from a corrupt header overflow usize (found by fuzzing).
    let want = HEADER_LEN as u128 + 12 * header.points as u128 * header.samples as u128;
    if bytes.len() as u128 != want {
        return Err(Pc2Error::Format(format!(
            "{} bytes, the header announces {want}",
            bytes.len()
        )));
    }
    let frames = bytes[HEADER_LEN..]
        .chunks_exact(12 * header.points.max(1))
        .map(|f| {
            f.chunks_exact(12)
                .map(|p| [0, 4, 8].map(|o| f32::from_le_bytes(p[o..o + 4].try_into().expect("4"))))
                .collect()
        })
        .collect();
    Ok((header, frames))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_layout() {
        let dir = std::env::temp_dir().join(format!("pc2-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("a.pc2");
        let frames = vec![
            vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]],
            vec![[7.0, 8.0, 9.0], [0.5, 0.25, -1.0]],
        ];
        let cache = PointCache {
            name: "a".into(),
            fps: 30.0,
            start: 12,
            triangles: Vec::new(),
            uvs: None,
            point_count: 2,
            points: frames.iter().flatten().copied().collect(),
        };
        write(&path, &cache).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(bytes.len(), 32 + 2 * 2 * 12);
        assert_eq!(&bytes[..12], b"POINTCACHE2\0");
        let (h, back) = read(&bytes).unwrap();
        assert_eq!(
            (h.version, h.points, h.samples, h.sample_rate, h.start_frame),
            (1, 2, 2, 1.0, 12.0)
        );
        assert_eq!(back, frames);
        let partial = PointCache {
            points: vec![[0.0; 3]; 3],
            ..cache
        };
        assert!(matches!(write(&path, &partial), Err(Pc2Error::Invalid(_))));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
