//! A mesh's frames over time: what simulations, roll-outs, evaluations and point caches hold.
//!
//! One type so the rate and the first frame travel with the points: a cache written from it
//! records both where its format has a place (PC2's start frame, MDD's times, USD's time codes,
//! Alembic's start time, a VAT's sidecar), and code that only reads the points borrows it as a
//! slice of frames (`&[Vec<[f32; 3]>]`, through `Deref`).

use std::ops::{Deref, DerefMut};

/// Every frame's points of one mesh, the rate they play at and the clip frame the first one is.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Frames {
    /// `points[f][v]`: vertex `v` at frame `start + f`.
    pub points: Vec<Vec<[f32; 3]>>,
    /// Frames per second.
    pub fps: f32,
    /// The clip frame of `points[0]` (0 unless the sequence is a span of a longer clip).
    pub start: usize,
}

impl Frames {
    /// `points` from the clip's first frame at `fps`.
    pub fn new(points: Vec<Vec<[f32; 3]>>, fps: f32) -> Frames {
        Frames {
            points,
            fps,
            start: 0,
        }
    }

    /// The same frames numbered from clip frame `start`.
    pub fn starting_at(self, start: usize) -> Frames {
        Frames { start, ..self }
    }

    /// The points, giving up the rate and start.
    pub fn into_points(self) -> Vec<Vec<[f32; 3]>> {
        self.points
    }
}

impl Deref for Frames {
    type Target = Vec<Vec<[f32; 3]>>;
    fn deref(&self) -> &Self::Target {
        &self.points
    }
}

impl DerefMut for Frames {
    fn deref_mut(&mut self) -> &mut Self::Target {
        &mut self.points
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_span_keeps_its_rate_and_reads_as_its_points() {
        let f = Frames::new(vec![vec![[0.0; 3]; 2]; 3], 30.0).starting_at(45);
        assert_eq!((f.len(), f[0].len(), f.start, f.fps), (3, 2, 45, 30.0));
        let slice: &[Vec<[f32; 3]>] = &f;
        assert_eq!(slice.len(), 3);
    }
}
