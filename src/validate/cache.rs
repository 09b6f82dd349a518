//! Point caches (PC2, MDD) checked as files: the header, the size it announces, finite values,
//! and the frame times (MDD) or sampling (PC2) against a rate. A cache that passes comes back as
//! frames for the replay.

use super::Problems;
use exporters::{mdd, pc2};

/// A cache's frames and the rate its header implies (MDD carries times; PC2 does not).
pub struct Cache {
    pub points: usize,
    pub frames: Vec<Vec<[f32; 3]>>,
    pub fps: Option<f64>,
}

/// Checks a PC2 file; its frames when the layout is sound.
pub fn check_pc2(bytes: &[u8], p: &mut Problems) -> Option<Cache> {
    if let Some((want, samples, points)) = announced_pc2(bytes) {
        if (bytes.len() as u128) < want {
            p.error(
                "header",
                format!(
                    "truncated: {} bytes, the header announces {want} ({samples} samples of {points} points)",
                    bytes.len()
                ),
            );
            return None;
        }
    }
    let (header, frames) = match pc2::read(bytes) {
        Ok(x) => x,
        Err(e) => {
            p.error("header", e.to_string());
            return None;
        }
    };
    if header.version != 1 {
        p.error("header", format!("version {}, expected 1", header.version));
    }
    if header.points == 0 || header.samples == 0 {
        p.error(
            "header",
            format!(
                "{} samples of {} points: empty",
                header.samples, header.points
            ),
        );
    }
    if !header.start_frame.is_finite() {
        p.error("header", format!("start frame {}", header.start_frame));
    }
    if !(header.sample_rate.is_finite() && header.sample_rate > 0.0) {
        p.error(
            "header",
            format!(
                "sample rate {} (frames between samples) must be positive",
                header.sample_rate
            ),
        );
    }
    finite(&frames, p);
    Some(Cache {
        points: header.points,
        frames,
        fps: None,
    })
}

/// The size a PC2 header announces, with its sample and point counts (None: no PC2 header).
/// In u128: two i32 counts overflow u64.
fn announced_pc2(bytes: &[u8]) -> Option<(u128, u128, u128)> {
    if bytes.len() < pc2::HEADER_LEN || &bytes[..12] != pc2::MAGIC {
        return None;
    }
    let count =
        |o: usize| i32::from_le_bytes(bytes[o..o + 4].try_into().expect("4 bytes")).max(0) as u128;
    let (points, samples) = (count(16), count(28));
    Some((
        pc2::HEADER_LEN as u128 + 12 * points * samples,
        samples,
        points,
    ))
}

/// Checks an MDD file: layout, finite values, frame times strictly increasing and evenly spaced
/// (their spacing is the rate).
pub fn check_mdd(bytes: &[u8], p: &mut Problems) -> Option<Cache> {
    let file = match mdd::read(bytes) {
        Ok(f) => f,
        Err(e) => {
            p.error("header", e.to_string());
            return None;
        }
    };
    finite(&file.frames, p);
    let times = &file.times;
    if let Some(f) = times.iter().position(|t| !t.is_finite()) {
        p.error(
            format!("time {f}"),
            format!("frame time {} is not finite", times[f]),
        );
        return None;
    }
    if let Some(f) = times.windows(2).position(|w| w[1] <= w[0]) {
        p.error(
            format!("time {}", f + 1),
            format!(
                "frame times are not increasing: {} after {}",
                times[f + 1],
                times[f]
            ),
        );
        return None;
    }
    let fps = (times.len() > 1).then(|| {
        let span = (times[times.len() - 1] - times[0]) as f64;
        (times.len() - 1) as f64 / span
    });
    if let Some(fps) = fps {
        // Every step within 0.1 % of a frame of the mean spacing: one rate for the whole cache.
        if let Some(f) = times
            .windows(2)
            .position(|w| ((w[1] - w[0]) as f64 * fps - 1.0).abs() > 1e-3)
        {
            p.error(
                format!("time {}", f + 1),
                format!(
                    "frame times are not evenly spaced: step {} s where the cache's rate is {fps:.4} fps",
                    times[f + 1] - times[f]
                ),
            );
        }
    }
    Some(Cache {
        points: file.header.points,
        frames: file.frames,
        fps,
    })
}

fn finite(frames: &[Vec<[f32; 3]>], p: &mut Problems) {
    if let Some((f, v)) = frames.iter().enumerate().find_map(|(f, points)| {
        points
            .iter()
            .position(|q| q.iter().any(|c| !c.is_finite()))
            .map(|v| (f, v))
    }) {
        p.error(
            format!("frame {f}"),
            format!("point {v} is not finite: {:?}", frames[f][v]),
        );
    }
}

/// The cache's length and rate against the clip (or reference cache) it should play: same frame
/// count; for MDD, the same rate.
pub fn check_against_clip(
    cache: &Cache,
    frames: usize,
    fps: f64,
    vertices: usize,
    p: &mut Problems,
) {
    if cache.points != vertices {
        p.error(
            "header",
            format!(
                "{} points per frame, the reference has {vertices} (another garment?)",
                cache.points
            ),
        );
    }
    if cache.frames.len() != frames {
        let reference = if fps > 0.0 {
            format!("the clip at {fps} fps has {frames} (a wrong frame count or another --fps)")
        } else {
            format!("the reference has {frames}")
        };
        p.error(
            "header",
            format!("{} frames, {reference}", cache.frames.len()),
        );
    }
    // A rate of 0: unknown (a PC2 reference without --fps), nothing to compare with.
    if let Some(rate) = cache.fps.filter(|_| fps > 0.0) {
        if (rate / fps - 1.0).abs() > 1e-3 {
            p.error(
                "times",
                format!("the frame times give {rate:.4} fps, the clip plays at {fps} fps"),
            );
        }
    }
}
