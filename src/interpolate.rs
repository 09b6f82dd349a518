//! Latent interpolation: the garments a trained generative space decodes along the straight
//! line between the latents of two frames. A smooth space gives plausible garments all the way
//! (no blow-up, nothing through the body); a space that only memorised its frames does not.

use crate::geometry::Frames;
use crate::models::dynamic::{BodyAnchors, BodyFrames};
use crate::models::file::ModelFile;
use crate::rig::JointTransform;
use anyhow::{bail, Result};
use tch::{Kind, Tensor};

/// The decoded garments, one per clip frame `a..=b` (numbered from `a`), and the two end
/// latents.
pub struct LatentPath {
    pub frames: Frames,
    pub z_a: Vec<f32>,
    pub z_b: Vec<f32>,
}

/// Clip frame `a + k` decodes `(1 − t)·z_a + t·z_b` with `t = k / (b − a)`, skinned by that
/// frame's anchors: the body keeps moving while the garment's latent goes in a straight line from
/// the encoding of the simulated garment at frame `a` to that of frame `b`. `sim` may hold
/// fewer frames than `poses` (a simulation of the clip's first frames); both ends must be in it.
pub fn between(
    file: &ModelFile,
    poses: &[Vec<JointTransform>],
    sim: &Frames,
    (a, b): (usize, usize),
) -> Result<LatentPath> {
    let frames = poses.len().min(sim.len());
    if a >= b || b >= frames {
        bail!("frames {a} and {b}: need a < b < {frames} (the frames simulated)");
    }
    let (garment_a, garment_b) = (&sim[a], &sim[b]);
    let space = &file.dynamic()?.space;
    let info = file.info.dynamic()?;
    let anchors = BodyAnchors::from_vertices(&file.body, &info.anchors, &info.anchor_parts)?;
    let device = space.consts.rest.device();
    let bodies = BodyFrames::new(&file.body, &anchors, &poses[a..=b], device);
    let ends = Tensor::from_slice(&[0i64, (b - a) as i64]).to_device(device);
    let at_ends = bodies.select(&ends);
    let flat: Vec<f32> = garment_a
        .iter()
        .chain(garment_b)
        .flatten()
        .copied()
        .collect();
    let g = Tensor::from_slice(&flat)
        .reshape([2, -1, 3])
        .to_device(device);
    let (garments, z) = tch::no_grad(|| {
        let z = space.encode(&g, &at_ends.anchors, &at_ends.transforms);
        let t = Tensor::linspace(0.0, 1.0, (b - a + 1) as i64, (Kind::Float, device)).unsqueeze(1);
        let path = z.get(0).unsqueeze(0) * (1.0 - &t) + z.get(1).unsqueeze(0) * &t;
        let garments = space.skin(&space.canonical(&path), &bodies.transforms);
        (garments, z)
    });
    let v = garment_a.len();
    let flat: Vec<f32> = garments.reshape([-1]).try_into()?;
    let latent = |i: i64| -> Result<Vec<f32>> { Ok(z.get(i).try_into()?) };
    Ok(LatentPath {
        frames: Frames::new(
            flat.chunks_exact(3 * v)
                .map(|f| f.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
                .collect(),
            sim.fps,
        )
        .starting_at(sim.start + a),
        z_a: latent(0)?,
        z_b: latent(1)?,
    })
}
