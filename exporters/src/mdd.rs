//! MDD point caches (Lightwave's layout, as Blender's MDD importer and Mesh Cache modifier read
//! them): everything big-endian — `i32 frames`, `i32 points`, `f32 time[frames]` (seconds),
//! then every frame's points as `f32 x, y, z`. Unlike PC2 the file carries each frame's time,
//! so the rate travels with it.

use crate::asset::PointCache;
use crate::atomic::write_atomic_with;
use std::io::Write;
use std::path::Path;

pub const HEADER_LEN: usize = 8;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Header {
    pub frames: usize,
    pub points: usize,
}

#[derive(Debug, thiserror::Error)]
pub enum MddError {
    #[error("{0}")]
    Invalid(String),
    #[error("{0}")]
    Io(#[from] std::io::Error),
    #[error("not an MDD file: {0}")]
    Format(String),
}

/// Writes `cache` atomically; frame f's time is (start + f) / fps.
pub fn write(path: &Path, cache: &PointCache) -> Result<(), MddError> {
    let bytes = to_bytes(cache)?;
    write_atomic_with(path, |w| w.write_all(&bytes))?;
    Ok(())
}

/// The file's bytes: header, frame times, then every frame's points.
pub fn to_bytes(cache: &PointCache) -> Result<Vec<u8>, MddError> {
    cache.check().map_err(MddError::Invalid)?;
    let frames = cache.frame_count();
    let mut bytes = Vec::with_capacity(HEADER_LEN + 4 * frames + 12 * cache.points.len());
    bytes.extend_from_slice(&(frames as i32).to_be_bytes());
    bytes.extend_from_slice(&(cache.point_count as i32).to_be_bytes());
    for f in 0..frames {
        bytes.extend_from_slice(&((cache.start + f) as f32 / cache.fps).to_be_bytes());
    }
    for c in cache.points.iter().flatten() {
        bytes.extend_from_slice(&c.to_be_bytes());
    }
    Ok(bytes)
}

/// A parsed MDD: header, frame times (seconds), every frame's points.
pub struct Mdd {
    pub header: Header,
    pub times: Vec<f32>,
    pub frames: Vec<Vec<[f32; 3]>>,
}

/// Parses an MDD file; the size must be exactly what the header announces.
pub fn read(bytes: &[u8]) -> Result<Mdd, MddError> {
    if bytes.len() < HEADER_LEN {
        return Err(MddError::Format(format!(
            "{} bytes, shorter than the 8-byte header",
            bytes.len()
        )));
    }
    let f32_at = |o: usize| f32::from_be_bytes(bytes[o..o + 4].try_into().expect("4 bytes"));
    let i32_at = |o: usize| i32::from_be_bytes(bytes[o..o + 4].try_into().expect("4 bytes"));
    let (frames, points) = (i32_at(0), i32_at(4));
    if frames <= 0 || points <= 0 {
        return Err(MddError::Format(format!(
            "the header announces {frames} frames of {points} points"
        )));
    }
    let header = Header {
        frames: frames as usize,
        points: points as usize,
    };
    let per_frame = 4 + 12 * header.points;
    // In u128: two i32 counts from a corrupt header overflow u64 (found by fuzzing).
    let want = HEADER_LEN as u128 + header.frames as u128 * per_frame as u128;
    if bytes.len() as u128 != want {
        let data = bytes.len() - HEADER_LEN;
        let holds = if data.is_multiple_of(per_frame) {
            format!("the data holds {} frames", data / per_frame)
        } else {
            format!("the data is not whole frames of {} points", header.points)
        };
        return Err(MddError::Format(format!(
            "the header's frame count is {} ({want} bytes), the file has {} bytes: {holds}",
            header.frames,
            bytes.len()
        )));
    }
    let times = (0..header.frames)
        .map(|f| f32_at(HEADER_LEN + 4 * f))
        .collect();
    let start = HEADER_LEN + 4 * header.frames;
    let frames = bytes[start..]
        .chunks_exact(12 * header.points)
        .map(|f| {
            f.chunks_exact(12)
                .map(|p| [0, 4, 8].map(|o| f32::from_be_bytes(p[o..o + 4].try_into().expect("4"))))
                .collect()
        })
        .collect();
    Ok(Mdd {
        header,
        times,
        frames,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_is_big_endian_with_times() {
        let cache = PointCache {
            name: "a".into(),
            fps: 4.0,
            start: 0,
            triangles: Vec::new(),
            uvs: None,
            point_count: 2,
            points: vec![
                [1.0, 2.0, 3.0],
                [4.0, 5.0, 6.0],
                [7.0, 8.0, 9.0],
                [0.5, 0.25, -1.0],
            ],
        };
        let bytes = to_bytes(&cache).unwrap();
        assert_eq!(bytes.len(), 8 + 2 * 4 + 2 * 2 * 12);
        assert_eq!(&bytes[..8], &[0, 0, 0, 2, 0, 0, 0, 2]);
        assert_eq!(&bytes[12..16], &0.25f32.to_be_bytes());
        assert_eq!(&bytes[16..20], &1.0f32.to_be_bytes());
        let back = read(&bytes).unwrap();
        assert_eq!(back.times, [0.0, 0.25]);
        // A span of a longer clip keeps its clip times.
        let later = read(
            &to_bytes(&PointCache {
                start: 6,
                ..cache.clone()
            })
            .unwrap(),
        )
        .unwrap();
        assert_eq!(later.times, [1.5, 1.75]);
        assert_eq!(back.frames[1], [[7.0, 8.0, 9.0], [0.5, 0.25, -1.0]]);
        let mut wrong = bytes.clone();
        wrong[3] = 3;
        let e = read(&wrong).err().unwrap().to_string();
        assert!(
            e.contains("frame count is 3") && e.contains("holds 2 frames"),
            "{e}"
        );
    }
}
