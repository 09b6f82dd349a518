//! The motion-guided dynamic garment model (Zhang et al., "Motion Guided Deep Dynamic 3D
//! Garments"). Stage 1, the generative space of garment deformations: a garment frame, measured
//! relative to body anchor points and laid out in its UV map, is encoded to a latent `Z`; the
//! decoder gives per-vertex displacements in each vertex's rest frame and the garment is skinned
//! by the anchors with distance-based weights whose kernel radius is learnt per body part.
//! Stage 2, the dynamic-aware encoder: the previous garment state and the body's motion give the
//! next frame's latent, rolled out frame after frame.

pub mod anchors;
pub mod frames;
pub mod learned;
pub mod motion;
pub mod settle;
pub mod space;
pub mod uv;

pub use anchors::BodyAnchors;
pub use frames::BodyFrames;
pub use motion::{MotionEncoder, MotionShape};
pub use space::{Space, SpaceShape};
pub use uv::UvRaster;

/// A dynamic model: the generative space and, once stage 2 is trained, its motion encoder.
pub struct Dynamic {
    pub space: Space,
    pub motion: Option<MotionEncoder>,
}

impl Dynamic {
    /// The motion encoder, or an error saying the model has only its space.
    pub fn motion(&self) -> anyhow::Result<&MotionEncoder> {
        self.motion.as_ref().ok_or_else(|| {
            anyhow::anyhow!("this dynamic model has only its generative space (stage 1); train its motion encoder with `garmentbake train-dynamic --stage dynamic --from MODEL`")
        })
    }

    /// Whether every network's output layer is zero (both stages trained `--epochs 0`): a
    /// roll-out step is then exactly the linear paths' ([`Dynamic::linear_step_inputs`]), with
    /// no networks' inputs to build.
    pub fn linear_only(&self) -> bool {
        self.space.networks_idle() && self.motion.as_ref().is_some_and(|m| m.residual_idle())
    }

    /// A roll-out step's inputs from its history, networks' inputs included.
    pub fn step_inputs(&self, h: &motion::History) -> anyhow::Result<StepInputs> {
        let encoder = self.motion()?;
        Ok(StepInputs::Full(motion::motion_inputs(
            &self.space,
            h,
            &encoder.shape,
            None,
        )))
    }

    /// A roll-out step's inputs when the model is [`Dynamic::linear_only`]: the linear path's
    /// latents of the history's last two garments under the poses at `t − 1` and `t` (blended
    /// once per frame by the caller, [`Space::posed`]), the body drive, and `past`, the drives
    /// before this frame that the learnt dynamics see ([`Dynamic::past_drives`]).
    pub fn linear_step_inputs(
        &self,
        h: &motion::History,
        (before, now): (&space::Posed, &space::Posed),
        past: tch::Tensor,
    ) -> anyhow::Result<StepInputs> {
        let encoder = self.motion()?;
        let [g1, g2, _] = &h.garment;
        let (previous, inertia) =
            tch::no_grad(|| self.space.linear_step_latents(g1, g2, before, now));
        Ok(StepInputs::Linear {
            previous,
            inertia,
            drive: motion::body_drive(&h.before, &h.now, &encoder.shape, h.fps),
            past,
        })
    }

    /// The body drives of a clip's frames `[T, D]` (each frame against the one before, the
    /// first against itself) when the learnt dynamics see past drives; `[T, 0]` otherwise.
    pub fn clip_drives(&self, bodies: &BodyFrames, fps: f64) -> anyhow::Result<tch::Tensor> {
        let encoder = self.motion()?;
        let n = bodies.root.size()[0];
        let device = bodies.root.device();
        if encoder.past_width() == 0 {
            return Ok(tch::Tensor::zeros([n, 0], (tch::Kind::Float, device)));
        }
        let previous = tch::Tensor::arange(n, (tch::Kind::Int64, device))
            .f_sub_scalar(1)?
            .clamp_min(0);
        Ok(motion::drives(bodies, &previous, &encoder.shape, fps))
    }

    /// The past drives the learnt dynamics see at frame `t` of a clip, from its
    /// [`Dynamic::clip_drives`] (`[1, 0]` when they see none).
    pub fn past_drives(&self, drives: &tch::Tensor, t: usize) -> anyhow::Result<tch::Tensor> {
        let encoder = self.motion()?;
        Ok(motion::past_drives(
            drives,
            &[t as i64],
            &[0],
            encoder.past_frames(),
        ))
    }

    /// The next frame's latent from its inputs (no gradients), held per dimension inside
    /// `range` (`[1, L]` bounds) when given: a roll-out's step.
    pub fn next_latent(
        &self,
        x: &StepInputs,
        range: Option<&(tch::Tensor, tch::Tensor)>,
    ) -> anyhow::Result<tch::Tensor> {
        let encoder = self.motion()?;
        let z = tch::no_grad(|| match x {
            StepInputs::Full(x) => {
                encoder.latent(x, Some(&encoder.dynamic_features(&self.space, x)))
            }
            StepInputs::Linear {
                previous,
                inertia,
                drive,
                past,
            } => encoder.integrate(inertia, previous, drive, past),
        });
        Ok(match range {
            Some((lo, hi)) => z.clamp_tensor(Some(lo), Some(hi)),
            None => z,
        })
    }
}

/// What a roll-out step feeds the motion encoder.
pub enum StepInputs {
    Full(motion::MotionInputs),
    /// The linear path's inputs alone: `Z_{t−1}`, `[Z^ball_t, Z^stay_t]` and the body drive,
    /// and the past drives the learnt dynamics see (`motion::past_drives`; none without them).
    Linear {
        previous: tch::Tensor,
        inertia: tch::Tensor,
        drive: tch::Tensor,
        past: tch::Tensor,
    },
}

/// The garment's uniform Laplacian `x − mean of its neighbours`, per vertex of `x [B, V, 3]`,
/// as one gather and one scatter.
pub struct MeshLaplacian {
    src: tch::Tensor,
    dst: tch::Tensor,
    degree: tch::Tensor,
}

impl MeshLaplacian {
    pub fn new(triangles: &[[u32; 3]], vertices: usize, device: tch::Device) -> MeshLaplacian {
        let (mut src, mut dst) = (Vec::new(), Vec::new());
        let mut degree = vec![0f32; vertices];
        for [a, b] in crate::geometry::edges::unique_edges(triangles) {
            src.extend([a as i64, b as i64]);
            dst.extend([b as i64, a as i64]);
            degree[a as usize] += 1.0;
            degree[b as usize] += 1.0;
        }
        let t = |v: &[i64]| tch::Tensor::from_slice(v).to_device(device);
        MeshLaplacian {
            src: t(&src),
            dst: t(&dst),
            degree: tch::Tensor::from_slice(&degree)
                .reshape([1, -1, 1])
                .to_device(device)
                .clamp_min(1.0),
        }
    }

    pub fn of(&self, x: &tch::Tensor) -> tch::Tensor {
        let sum = x
            .zeros_like()
            .index_add(1, &self.dst, &x.index_select(1, &self.src));
        x - sum / &self.degree
    }
}

/// A garment's unique edges, for edge-length terms: `lengths(x [B, V, 3]) → [B, E]`.
pub struct MeshEdges {
    edges: tch::Tensor,
}

impl MeshEdges {
    pub fn new(triangles: &[[u32; 3]], device: tch::Device) -> MeshEdges {
        let flat: Vec<i64> = crate::geometry::edges::unique_edges(triangles)
            .iter()
            .flatten()
            .map(|&v| v as i64)
            .collect();
        MeshEdges {
            edges: tch::Tensor::from_slice(&flat)
                .reshape([-1, 2])
                .to_device(device),
        }
    }

    pub fn lengths(&self, x: &tch::Tensor) -> tch::Tensor {
        let a = x.index_select(1, &self.edges.select(1, 0));
        let b = x.index_select(1, &self.edges.select(1, 1));
        (a - b)
            .square()
            .sum_dim_intlist(2, false, tch::Kind::Float)
            .clamp_min(1e-12)
            .sqrt()
    }
}
