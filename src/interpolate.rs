//! Latent interpolation: the garments a trained generative space decodes along the straight
//! line between the latents of two frames. A smooth space gives plausible garments all the way
//! (no blow-up, nothing through the body); a space that only memorised its frames does not.

use crate::models::dynamic::{BodyFrames, Seeds};
use crate::models::file::ModelFile;
use crate::rig::JointTransform;
use anyhow::{bail, Result};
use tch::{Kind, Tensor};

/// The decoded garments, one per clip frame `a..=b`, and the two end latents.
pub struct LatentPath {
    pub frames: Vec<Vec<[f32; 3]>>,
    pub z_a: Vec<f32>,
    pub z_b: Vec<f32>,
}

/// Clip frame `a + k` decodes `(1 − t)·z_a + t·z_b` with `t = k / (b − a)`, skinned by that
/// frame's seeds: the body keeps moving while the garment's latent goes in a straight line from
/// the encoding of `garment_a` (at pose `a`) to that of `garment_b` (at pose `b`).
pub fn between(
    file: &ModelFile,
    poses: &[Vec<JointTransform>],
    (a, garment_a): (usize, &[[f32; 3]]),
    (b, garment_b): (usize, &[[f32; 3]]),
) -> Result<LatentPath> {
    if a >= b || b >= poses.len() {
        bail!(
            "frames {a} and {b}: need a < b < {} (the clip's frames)",
            poses.len()
        );
    }
    let space = &file.dynamic()?.space;
    let info = file.info.dynamic()?;
    let seeds = Seeds::from_vertices(&file.body, &info.seeds, &info.seed_parts)?;
    let device = space.consts.rest.device();
    let bodies = BodyFrames::new(&file.body, &seeds, &poses[a..=b], device);
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
        let z = space.encode(&g, &at_ends.seeds, &at_ends.transforms);
        let t = Tensor::linspace(0.0, 1.0, (b - a + 1) as i64, (Kind::Float, device)).unsqueeze(1);
        let path = z.get(0).unsqueeze(0) * (1.0 - &t) + z.get(1).unsqueeze(0) * &t;
        let garments = space.skin(&space.canonical(&path), &bodies.transforms);
        (garments, z)
    });
    let v = garment_a.len();
    let flat: Vec<f32> = garments.reshape([-1]).try_into()?;
    let latent = |i: i64| -> Result<Vec<f32>> { Ok(z.get(i).try_into()?) };
    Ok(LatentPath {
        frames: flat
            .chunks_exact(3 * v)
            .map(|f| f.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
            .collect(),
        z_a: latent(0)?,
        z_b: latent(1)?,
    })
}
