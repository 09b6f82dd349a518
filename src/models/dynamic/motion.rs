//! The dynamic-aware encoder (paper Sec. 5): from the previous garment state and the body's
//! motion to the next frame's latent. `C` maps the motion maps (garment velocity and
//! acceleration, in UV space) and the body-interaction map `C_t` to `E_t`; `E_dyn` maps
//! `[S(M^P_{t−1}), E_t]` to the latent `Z_t`, decoded by the frozen space.
//!
//! Choices beside the paper, each for a model that trains in minutes on a laptop:
//! - `E_dyn` is residual: `Z_t = E_sta(g_{t−1}) + ΔE(S(M^P_{t−1}), E_t)`, the frozen static
//!   encoder (with its linear path) of the previous garment plus a learnt change whose last layer
//!   starts at zero. The untrained model holds the previous frame's canonical shape and lets the
//!   anchors carry it: the virtual sample `E_t = 0` then starts at its target, and the loss keeps it
//!   there.
//! - One more per-vertex input: where each previous garment vertex would go if it followed the
//!   body rigidly from `t − 1` to `t` (the anchors' blended transforms, undone at `t − 1`, applied at
//!   `t`). It is the body's motion as the garment feels it; without it `E_t` sees the body only
//!   through contacts, and a skirt's swing is driven by the hips it does not touch at the hem.
//! - Vectors are expressed in the root joint's frame at `t` (turning in place is not a new motion).
//! - A linear path beside the networks, like the space's: `Z_t = W [Z^ball_t, Z^stay_t, Z_{t−1}, 1]`
//!   with `Z^stay_t` the static latent of the previous garment held still in the world against the
//!   current body, and `Z^ball_t` of it moved on at its velocity (pure inertia), both through the
//!   frozen static encoder. `W` starts as the ridge-regression fit of the training frames (an
//!   integrator in latent space: inertia, then a learnt pull back towards the body); the residual
//!   network `ΔE(S(M^P_{t−1}), E_t)` learns what it misses. The virtual sample `E_t = 0` (no relative
//!   motion) sees `Z^ball = Z^stay = Z_{t−1}`.
//! - Optional (`train-dynamic --body-drive`, not in the paper): the body drive `u_t` in the
//!   linear path, `Z_t = W [Z^ball_t, Z^stay_t, Z_{t−1}, 1, u_t]`, with `u_t` the local
//!   rotations of the joints that move the garment at `t` and their change per second, and the
//!   root's velocity and turn rate in its own frame. Without it the integrator sees the body
//!   only through the garment it carries, and a drifted roll-out has nothing to pull it back to
//!   the pose; the drive is the pose (and its speed) as a static deformation model sees it.

use super::frames::BodyFrames;
use super::learned::{self, LearnedDynamics};
use super::settle::PoseRegression;
use super::space::Space;
use serde::{Deserialize, Serialize};
use tch::nn::{self, Module};
use tch::{Kind, Tensor};

/// Sizes of the dynamic-aware encoder.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MotionShape {
    /// Channels of `E_t` (the output of `C`).
    pub features: usize,
    /// Channels after each stride-2 convolution of `E_dyn`, down to 2×2.
    pub encoder: Vec<usize>,
    /// σ of the interaction weight `a = exp(−|g_{t−1} − b_{t−1}|² / 2σ²)` (metres).
    pub sigma: f32,
    /// Joints whose rotations drive the linear path (see the module's notes); none: no drive
    /// (models from before it).
    #[serde(default)]
    pub drive_joints: Vec<usize>,
    /// Hidden widths of the learnt latent dynamics `D` (`learned`); none: the linear path
    /// alone (models from before it, or trained without it).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub dynamics: Vec<usize>,
    /// Past body drives `D` also sees, `u_{t−1} … u_{t−H}` (frames; 0: the current one alone,
    /// models from before it): the body's recent motion, so a swing can answer an
    /// acceleration rather than only the pose and speed of this frame.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub dynamics_history: usize,
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

impl MotionShape {
    /// Channel widths that follow the space's own encoder (same depth, so the map reaches 2×2).
    pub fn for_space(space_encoder: &[usize], features: usize) -> MotionShape {
        MotionShape {
            features,
            encoder: space_encoder.to_vec(),
            sigma: 0.05,
            drive_joints: Vec::new(),
            dynamics: Vec::new(),
            dynamics_history: 0,
        }
    }

    /// Width of the body drive `u_t`: per joint its rotation and their change (6 + 6), then the
    /// root's velocity (3) and turn (6).
    pub fn drive_width(&self) -> i64 {
        match self.drive_joints.len() as i64 {
            0 => 0,
            j => 12 * j + 9,
        }
    }
}

/// The body drive `u_t` `[B, D]` from the body at `t − 1` and at `t` (see the module's notes);
/// `[B, 0]` without drive joints. `body_drive(before, before, ..)` is the drive of a body that
/// holds still at `t − 1` (the virtual sample).
pub fn body_drive(before: &BodyFrames, now: &BodyFrames, shape: &MotionShape, fps: f64) -> Tensor {
    let b = now.root.size()[0];
    let device = now.root.device();
    if shape.drive_joints.is_empty() {
        return Tensor::zeros([b, 0], (Kind::Float, device));
    }
    let joints: Vec<i64> = shape.drive_joints.iter().map(|&j| j as i64).collect();
    let joints = Tensor::from_slice(&joints).to_device(device);
    let pick = |f: &BodyFrames| f.rotations.index_select(1, &joints).flatten(1, -1);
    let (was, is) = (pick(before), pick(now));
    let spin = (&is - was) * fps;
    // Row vector times R: R^T x, the root's step in its own frame at t.
    let step = ((&now.origin - &before.origin) * fps)
        .unsqueeze(1)
        .bmm(&now.root)
        .squeeze_dim(1);
    // R_t^T R_{t−1}: the turn since the last frame, as 6-D features (0 when still).
    let eye = Tensor::eye(3, (Kind::Float, device)).narrow(1, 0, 2);
    let turn = (now.root.transpose(1, 2).bmm(&before.root).narrow(2, 0, 2) - eye)
        .transpose(1, 2)
        .reshape([b, 6])
        * fps;
    Tensor::cat(&[is, spin, step, turn], 1)
}

/// The body drive of every frame of a batch of bodies `[T, D]`: frame `t` against the body at
/// `previous[t]` (the frame before it, or itself at a clip's first frame: a body holding
/// still).
pub fn drives(bodies: &BodyFrames, previous: &Tensor, shape: &MotionShape, fps: f64) -> Tensor {
    tch::no_grad(|| body_drive(&bodies.select(previous), bodies, shape, fps))
}

/// The past drives `D` sees at frames `now` (rows of `drives`, each with the first frame of its
/// clip in `clip_first`): `[u_{t−1}, …, u_{t−count}]` `[B, count · D]`, frames before a clip's
/// first held at it (the body still before the clip, as a roll-out from its first frame has it).
pub fn past_drives(drives: &Tensor, now: &[i64], clip_first: &[i64], count: usize) -> Tensor {
    let device = drives.device();
    let rows: Vec<Tensor> = (1..=count as i64)
        .map(|k| {
            let idx: Vec<i64> = now
                .iter()
                .zip(clip_first)
                .map(|(&t, &first)| (t - k).max(first))
                .collect();
            drives.index_select(0, &Tensor::from_slice(&idx).to_device(device))
        })
        .collect();
    if rows.is_empty() {
        return Tensor::zeros([now.len() as i64, 0], (Kind::Float, device));
    }
    Tensor::cat(&rows, 1)
}

/// Per-vertex motion channels: velocity, acceleration and rigid-follow step, 3 each.
pub const MOTION_CHANNELS: i64 = 9;
/// Scales that bring the inputs to about unit size: velocities in m/s, accelerations in
/// m/s per frame, penetration depths in centimetres.
const FORCE_SCALE: f64 = 100.0;

/// The inputs at frame `t` for a batch, as the encoder needs them.
pub struct MotionInputs {
    /// `S(M^P_{t−1})` `[B, C, H, W]` (frozen space).
    pub static_features: Tensor,
    /// `E_sta` of the previous garment `[B, L]` (frozen space, linear path included).
    pub previous_latent: Tensor,
    /// `[Z^ball_t, Z^stay_t]` `[B, 2L]` (see the module's notes).
    pub inertia: Tensor,
    /// Per-vertex motion channels `[B, V, 9]` in the root frame at `t`.
    pub motion: Tensor,
    /// The interaction forces `a_ij · ReLU(−q_ij) · n_j` factored: their sizes
    /// `a_ij · ReLU(−q_ij)` `[B, V, N]` and the anchors' normals `n_j` `[B, N, 3]` in the root
    /// frame at `t` (the `[B, V, N, 3]` product is never built: `C`'s first layer is linear in it).
    pub contact: Tensor,
    pub contact_normals: Tensor,
    /// The body drive `u_t` `[B, D]`, and that of the body held still at `t − 1` (the virtual
    /// sample's).
    pub drive: Tensor,
    pub drive_still: Tensor,
}

/// One frame's history and body, batched: garments at `t−1, t−2, t−3` `[B, V, 3]`, the body at
/// `t − 1` and at `t`, and the frame rate.
pub struct History {
    pub garment: [Tensor; 3],
    pub before: BodyFrames,
    pub now: BodyFrames,
    pub fps: f64,
}

/// What only the frozen space gives, per frame: `S(M^P_{t−1})`, `E_sta(g_{t−1})` and the
/// inertia latents `[Z^ball_t, Z^stay_t]`.
pub struct StaticInputs {
    pub static_features: Tensor,
    pub previous_latent: Tensor,
    pub inertia: Tensor,
}

impl StaticInputs {
    /// Through the frozen space (no gradients). The three encodes (`g_{t−1}` against the body
    /// at `t − 1`; the ballistic guess and `g_{t−1}` against the body at `t`) run as one batch,
    /// and `S(M^P_{t−1})` is the first one's feature map rather than a fourth pass.
    pub fn new(space: &Space, h: &History) -> StaticInputs {
        tch::no_grad(|| {
            let (g, b, m) = Self::stacked(h);
            let (features, z) = space.encode_keeping_features(&g, &b, &m);
            let bs = h.garment[0].size()[0];
            let (previous_latent, inertia) = Self::split(&z, bs);
            StaticInputs {
                // A copy, not a view: a view would keep all three maps alive (3× the memory
                // when a trainer holds every frame's).
                static_features: features.narrow(0, 0, bs).copy(),
                previous_latent,
                inertia,
            }
        })
    }

    /// The three garments to encode (`g_{t−1}` against the body at `t − 1`; the ballistic
    /// guess and `g_{t−1}` against the body at `t`) as one batch: garments, anchors, transforms.
    fn stacked(h: &History) -> (Tensor, Tensor, Tensor) {
        let [g1, g2, _] = &h.garment;
        let ballistic = g1 * 2.0 - g2;
        let (before, now) = (&h.before, &h.now);
        (
            Tensor::cat(&[g1, &ballistic, g1], 0),
            Tensor::cat(&[&before.anchors, &now.anchors, &now.anchors], 0),
            Tensor::cat(&[&before.transforms, &now.transforms, &now.transforms], 0),
        )
    }

    /// Latents of a [`StaticInputs::stacked`] batch of `3 × bs` into `Z_{t−1}` and the inertia.
    fn split(z: &Tensor, bs: i64) -> (Tensor, Tensor) {
        let z = z.split(bs, 0);
        (z[0].shallow_clone(), Tensor::cat(&[&z[1], &z[2]], 1))
    }

    /// Frames `idx` of precomputed inputs.
    pub fn select(&self, idx: &Tensor) -> StaticInputs {
        StaticInputs {
            static_features: self.static_features.index_select(0, idx),
            previous_latent: self.previous_latent.index_select(0, idx),
            inertia: self.inertia.index_select(0, idx),
        }
    }
}

/// The encoder's inputs from a history (no gradients). `known`: the frozen space's part when
/// already computed (training precomputes it).
pub fn motion_inputs(
    space: &Space,
    h: &History,
    shape: &MotionShape,
    known: Option<StaticInputs>,
) -> MotionInputs {
    tch::no_grad(|| {
        let [g1, g2, g3] = &h.garment;
        let statics = known.unwrap_or_else(|| StaticInputs::new(space, h));
        let velocity = (g1 - g2) * h.fps;
        let acceleration = (g1 - g2 * 2.0 + g3) * h.fps;
        let follow = (space.follow(g1, &h.before.transforms, &h.now.transforms) - g1) * h.fps;
        let world = Tensor::cat(&[velocity, acceleration, follow], 2);
        let (b, v) = (world.size()[0], world.size()[1]);
        // Row vectors times R: R^T x, the vector in the root's frame.
        let motion = world
            .reshape([b, v * 3, 3])
            .bmm(&h.now.root)
            .reshape([b, v, MOTION_CHANNELS]);
        MotionInputs {
            static_features: statics.static_features,
            previous_latent: statics.previous_latent,
            inertia: statics.inertia,
            motion,
            contact: contact_sizes(g1, h, shape.sigma),
            contact_normals: h.now.normals.bmm(&h.now.root),
            drive: body_drive(&h.before, &h.now, shape, h.fps),
            drive_still: body_drive(&h.before, &h.before, shape, h.fps),
        }
    })
}

/// `a_ij · ReLU(−q_ij)` `[B, V, N]` with `q_ij = (g_{t−1,i} − b_{t,j}) · n_{t,j}` (previous
/// garment against the current anchors' tangent planes) and `a_ij = exp(−|g_{t−1,i} − b_{t−1,j}|²
/// / 2σ²)` (only anchors that were near the vertex push it): the size of the force along `n_j`.
/// Dot products as matrix products, so that no `[B, V, N, 3]` tensor is built.
fn contact_sizes(g1: &Tensor, h: &History, sigma: f32) -> Tensor {
    let (anchors_now, normals) = (&h.now.anchors, &h.now.normals);
    let plane = (anchors_now * normals)
        .sum_dim_intlist(2, false, Kind::Float)
        .unsqueeze(1);
    let q = g1.bmm(&normals.transpose(1, 2)) - plane;
    let before = &h.before.anchors;
    let square = |x: &Tensor| x.square().sum_dim_intlist(2, false, Kind::Float);
    let near = (square(g1).unsqueeze(2) + square(before).unsqueeze(1)
        - g1.bmm(&before.transpose(1, 2)) * 2.0)
        .clamp_min(0.0);
    let a = (-near / (2.0 * (sigma as f64).powi(2))).exp();
    a * (-q).relu() * FORCE_SCALE
}

/// `C` and the residual `E_dyn`.
pub struct MotionEncoder {
    pub vs: nn::VarStore,
    pub shape: MotionShape,
    /// `C`'s first layer, a 1×1 convolution over the per-vertex channels (motion `[C, 9]`,
    /// forces `[C, N, 3]`, the layout mask `[C]`, bias `[C]`), applied per vertex and then
    /// scattered to texels (it commutes with the barycentric scatter, as `S`'s does).
    c0_motion: Tensor,
    c0_forces: Tensor,
    c0_mask: Tensor,
    c0_bias: Tensor,
    c: nn::Sequential,
    encoder: nn::Sequential,
    encoder_fc: nn::Linear,
    /// The linear path `W` `[L, 3L + 1 + D]` (see the module's notes).
    linear: Tensor,
    /// The learnt latent dynamics beside `W` (`MotionShape::dynamics`).
    pub dynamics: Option<LearnedDynamics>,
}

impl MotionEncoder {
    pub fn new(shape: MotionShape, space: &Space, device: tch::Device) -> MotionEncoder {
        let vs = nn::VarStore::new(device);
        let root = vs.root() / "motion";
        let f = shape.features as i64;
        let n = space.shape.anchors as i64;
        let fan_in = (MOTION_CHANNELS + 3 * n + 1) as f64;
        let bound = 1.0 / fan_in.sqrt();
        let uniform = nn::Init::Uniform {
            lo: -bound,
            up: bound,
        };
        let c0 = &root / "c0";
        let c0_motion = c0.var("motion", &[f, MOTION_CHANNELS], uniform);
        let c0_forces = c0.var("forces", &[f, n, 3], uniform);
        let c0_mask = c0.var("mask", &[f], uniform);
        let c0_bias = c0.var("bias", &[f], uniform);
        let same = nn::ConvConfig {
            padding: 1,
            ..Default::default()
        };
        let c = nn::seq()
            .add(nn::func(|x| x.leaky_relu()))
            .add(nn::conv2d(&root / "c1", f, f, 3, same))
            .add(nn::func(|x| x.leaky_relu()));
        let down = nn::ConvConfig {
            stride: 2,
            padding: 1,
            ..Default::default()
        };
        let mut encoder = nn::seq();
        let mut channels = space.shape.features as i64 + f;
        for (k, &o) in shape.encoder.iter().enumerate() {
            encoder = encoder
                .add(nn::conv2d(&root / "enc" / k, channels, o as i64, 4, down))
                .add(nn::func(|x| x.leaky_relu()));
            channels = o as i64;
        }
        // Zero: the untrained encoder keeps the previous frame's latent.
        let zero = nn::LinearConfig {
            ws_init: nn::Init::Const(0.0),
            bs_init: Some(nn::Init::Const(0.0)),
            bias: true,
        };
        let encoder_fc = nn::linear(
            &root / "enc_fc",
            channels * 4,
            space.shape.latent as i64,
            zero,
        );
        let l = space.shape.latent as i64;
        // Starts as "keep the previous latent" until fitted (`init_linear`).
        let width = 3 * l + 1 + shape.drive_width();
        let linear = root.var("linear", &[l, width], nn::Init::Const(0.0));
        tch::no_grad(|| {
            linear
                .narrow(1, 2 * l, l)
                .copy_(&Tensor::eye(l, (Kind::Float, device)))
        });
        let dynamics = (!shape.dynamics.is_empty()).then(|| {
            LearnedDynamics::new(
                &(&root / learned::PATH),
                3 * l + (1 + shape.dynamics_history as i64) * shape.drive_width(),
                &shape.dynamics,
                l,
            )
        });
        MotionEncoder {
            linear,
            dynamics,
            vs,
            shape,
            c0_motion,
            c0_forces,
            c0_mask,
            c0_bias,
            c,
            encoder,
            encoder_fc,
        }
    }

    /// `E_t = C(M^{V,V̇}_{t−1}, C_t)` `[B, F, H, W]`.
    pub fn dynamic_features(&self, space: &Space, x: &MotionInputs) -> Tensor {
        // Σ_jk W_cjk s_ij n_jk = Σ_j s_ij U_jc with U_jc = Σ_k W_cjk n_jk.
        let per_seed = Tensor::einsum(
            "bnk,cnk->bnc",
            &[
                x.contact_normals.shallow_clone(),
                self.c0_forces.shallow_clone(),
            ],
            None::<i64>,
        );
        let per_vertex = x.motion.matmul(&self.c0_motion.tr()) + x.contact.bmm(&per_seed);
        let map = space.scatter(&per_vertex);
        let f = self.shape.features as i64;
        let first = map
            + self.c0_mask.reshape([1, f, 1, 1]) * space.layout_mask()
            + self.c0_bias.reshape([1, f, 1, 1]);
        self.c.forward(&first)
    }

    /// `Z_t = W [Z^ball_t, Z^stay_t, Z_{t−1}, 1, u_t] + ΔE(S(M^P_{t−1}), E_t)`; `e = None` is the
    /// virtual sample `E_t = 0` (no relative motion: `Z^ball = Z^stay = Z_{t−1}`, the body
    /// still at `t − 1`).
    pub fn latent(&self, x: &MotionInputs, e: Option<&Tensor>) -> Tensor {
        let s = x.static_features.size();
        let zeros;
        let (e, inertia, drive) = match e {
            Some(e) => (e, x.inertia.shallow_clone(), &x.drive),
            None => {
                zeros = Tensor::zeros(
                    [s[0], self.shape.features as i64, s[2], s[3]],
                    (Kind::Float, x.static_features.device()),
                );
                (&zeros, x.previous_latent.repeat([1, 2]), &x.drive_still)
            }
        };
        let input = Tensor::cat(&[x.static_features.shallow_clone(), e.shallow_clone()], 1);
        let h = self.encoder.forward(&input).flatten(1, -1);
        // `D` is fitted only beside an idle residual (train::unroll), so none sees past drives here.
        let past = Tensor::zeros(
            [s[0], self.past_width()],
            (Kind::Float, x.static_features.device()),
        );
        self.integrate(&inertia, &x.previous_latent, drive, &past) + self.encoder_fc.forward(&h)
    }

    /// The latent integrator: the linear path `W [...]` plus the learnt dynamics `D(x_t)` when
    /// the model has them (`learned`); `past` the drives before this frame `D` sees
    /// ([`past_drives`], [`MotionEncoder::past_width`] columns).
    pub fn integrate(
        &self,
        inertia: &Tensor,
        previous: &Tensor,
        drive: &Tensor,
        past: &Tensor,
    ) -> Tensor {
        let linear = self.linear_latent(inertia, previous, drive);
        match &self.dynamics {
            Some(d) => linear + d.forward(&LearnedDynamics::inputs(inertia, previous, drive, past)),
            None => linear,
        }
    }

    /// Past frames whose drives `D` sees (0 without `D` or without history).
    pub fn past_frames(&self) -> usize {
        match self.dynamics {
            Some(_) => self.shape.dynamics_history,
            None => 0,
        }
    }

    /// Columns of the past drives `D` sees.
    pub fn past_width(&self) -> i64 {
        self.past_frames() as i64 * self.shape.drive_width()
    }

    /// Gives the encoder learnt dynamics with hidden `widths` that also see `history` past
    /// drives (their output zero: the model plays as before until `train::unroll` fits them).
    /// Replaces any it had.
    pub fn add_dynamics(&mut self, widths: &[usize], history: usize) {
        let l = self.linear.size()[0];
        self.shape.dynamics = widths.to_vec();
        self.shape.dynamics_history = history;
        let root = self.vs.root() / "motion";
        self.dynamics = Some(LearnedDynamics::new(
            &(&root / learned::PATH),
            3 * l + (1 + history as i64) * self.shape.drive_width(),
            widths,
            l,
        ));
    }

    /// `W [Z^ball_t, Z^stay_t, Z_{t−1}, 1, u_t]`: the whole latent when
    /// [`MotionEncoder::residual_idle`].
    pub fn linear_latent(&self, inertia: &Tensor, previous: &Tensor, drive: &Tensor) -> Tensor {
        Self::linear_input(inertia, previous, drive).matmul(&self.linear.tr())
    }

    /// Whether the residual `ΔE` adds nothing (its output layer is zero: `--epochs 0`).
    pub fn residual_idle(&self) -> bool {
        super::space::all_zero(
            &self.vs,
            &[
                "motion.enc_fc.weight".to_string(),
                "motion.enc_fc.bias".to_string(),
            ],
        )
    }

    /// `[Z^ball, Z^stay, Z_{t−1}, 1, u_t]` `[B, 3L + 1 + D]`.
    fn linear_input(inertia: &Tensor, previous: &Tensor, drive: &Tensor) -> Tensor {
        let ones = previous.ones_like().narrow(1, 0, 1);
        Tensor::cat(
            &[
                inertia.shallow_clone(),
                previous.shallow_clone(),
                ones,
                drive.shallow_clone(),
            ],
            1,
        )
    }

    /// Fits the linear path to frames' inputs and their simulated latents `target [F, L]` by
    /// ridge regression towards its current value (at first "keep the previous latent"). The
    /// fit runs in the basis of what each input adds, `[Z^ball − Z^stay, Z^stay − Z_{t−1},
    /// Z_{t−1}]`: the garment going on at its own velocity, the body moving under it, and the
    /// state they start from. Each block's penalty is `ridge` times its own mean square (the
    /// constant's that of `Z_{t−1}`), each drive column's `drive_ridge` times its own (radians,
    /// m/s). One penalty for the three plain inputs, scaled by their joint mean square, shrank
    /// the two motion terms (their mean square a fifth of the state's on the skirt) about five
    /// times harder than the state, and the swing came out damped and late
    /// (docs/lab/2026-12-07-ridge-by-block-and-a-slower-settle.md). A stronger pull trades
    /// one-step accuracy for a roll-out that does not amplify its own errors.
    pub fn init_linear(
        &mut self,
        inertia: &Tensor,
        previous: &Tensor,
        drive: &Tensor,
        target: &Tensor,
        ridge: f64,
        drive_ridge: f64,
    ) {
        tch::no_grad(|| {
            let l = previous.size()[1];
            let double = |t: &Tensor| t.to_kind(Kind::Double);
            let (ball, stay) = (inertia.narrow(1, 0, l), inertia.narrow(1, l, l));
            let motions = Tensor::cat(&[&ball - &stay, &stay - previous], 1);
            let x = double(&Self::linear_input(&motions, previous, drive));
            let gram = x.tr().matmul(&x);
            let diagonal = gram.diagonal(0, 0, 1);
            let mean_square = |block: i64| diagonal.narrow(0, block * l, l).mean(Kind::Double);
            let state = mean_square(2);
            // A joint the clips never turn about an axis gives a zero column: a floor keeps
            // the system solvable (its weight stays at zero).
            let drive_columns = diagonal
                .narrow(0, 3 * l + 1, drive.size()[1])
                .maximum(&(&state * 1e-6))
                * drive_ridge;
            let penalty = Tensor::cat(
                &[
                    mean_square(0).expand([l], false) * ridge,
                    mean_square(1).expand([l], false) * ridge,
                    state.expand([l + 1], false) * ridge,
                    drive_columns,
                ],
                0,
            );
            let keep = to_difference_basis(&double(&self.linear.tr()), l);
            let rhs = x.tr().matmul(&double(target)) + &keep * penalty.unsqueeze(1);
            let v = Tensor::linalg_solve(&(gram + penalty.diag(0)), &rhs, true);
            self.linear
                .copy_(&from_difference_basis(&v, l).tr().to_kind(Kind::Float));
        });
    }

    /// Settles the fitted linear path towards the pose's garment:
    /// `W ← keep · W + (1 − keep) [0, 0, 0, P]` (see `settle`). Needs the body drive.
    pub fn settle_towards(&mut self, pose: &PoseRegression, keep: f64) {
        tch::no_grad(|| {
            let own = 3 * self.linear.size()[0];
            let tail = self.linear.size()[1] - own;
            assert_eq!(pose.weights.size(), [own / 3, tail], "P must be [L, 1 + D]");
            let _ = self.linear.g_mul_scalar_(keep);
            let _ = self
                .linear
                .narrow(1, own, tail)
                .g_add_(&(&pose.weights * (1.0 - keep)));
        });
    }

    /// Trainable tensors by name, sorted (the file's and Adam's order).
    pub fn parameters(&self) -> Vec<(String, Tensor)> {
        super::space::sorted_variables(&self.vs)
    }

    /// Copies stored values into the parameters (shapes must match).
    pub fn load_parameters(&mut self, stored: &[(String, Tensor)]) -> anyhow::Result<()> {
        super::space::load_variables(&mut self.vs, stored)
    }
}

/// `W x = W_ball Z^ball + W_stay Z^stay + W_prev Z_{t−1} + …` written as
/// `v_a a + v_b b + v_c c + …` over `a = Z^ball − Z^stay`, `b = Z^stay − Z_{t−1}`, `c = Z_{t−1}`:
/// `v_a = W_ball`, `v_b = W_ball + W_stay`, `v_c = v_b + W_prev`. Rows are inputs (`W`
/// transposed), `l` the latent size; the rows after the three blocks (constant, drive) pass
/// through.
fn to_difference_basis(w: &Tensor, l: i64) -> Tensor {
    let rows = w.size()[0];
    let v_a = w.narrow(0, 0, l);
    let v_b = &v_a + w.narrow(0, l, l);
    let v_c = &v_b + w.narrow(0, 2 * l, l);
    Tensor::cat(&[v_a, v_b, v_c, w.narrow(0, 3 * l, rows - 3 * l)], 0)
}

/// The inverse of [`to_difference_basis`].
fn from_difference_basis(v: &Tensor, l: i64) -> Tensor {
    let rows = v.size()[0];
    let (v_a, v_b, v_c) = (v.narrow(0, 0, l), v.narrow(0, l, l), v.narrow(0, 2 * l, l));
    Tensor::cat(
        &[
            v_a.shallow_clone(),
            &v_b - &v_a,
            &v_c - &v_b,
            v.narrow(0, 3 * l, rows - 3 * l),
        ],
        0,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::models::dynamic::space::tests::small_space;
    use tch::Device;

    fn random(shape: &[i64]) -> Tensor {
        Tensor::randn(shape, (Kind::Float, Device::Cpu)) * 0.2
    }

    fn frames(bs: i64, n: i64) -> BodyFrames {
        BodyFrames {
            anchors: random(&[bs, n, 3]),
            transforms: random(&[bs, n, 12]),
            normals: random(&[bs, n, 3]),
            root: random(&[bs, 3, 3]),
            origin: random(&[bs, 3]),
            rotations: random(&[bs, 4, 6]),
        }
    }

    #[test]
    fn factored_contact_equals_the_dense_interaction_forces_through_the_first_layer() {
        let (space, mesh) = small_space();
        let (bs, v, n) = (2, mesh.vertex_count() as i64, 3);
        tch::manual_seed(5);
        let h = History {
            garment: [
                random(&[bs, v, 3]),
                random(&[bs, v, 3]),
                random(&[bs, v, 3]),
            ],
            before: frames(bs, n),
            now: frames(bs, n),
            fps: 30.0,
        };
        let sigma = 0.2;
        let encoder = MotionEncoder::new(MotionShape::for_space(&[4, 4], 4), &space, Device::Cpu);
        let mut shape = MotionShape::for_space(&[4, 4], 4);
        shape.sigma = sigma;
        let x = motion_inputs(&space, &h, &shape, None);
        // The paper's forces, built in full: a_ij · ReLU(−q_ij) · n_j, in the root frame.
        let g1 = &h.garment[0];
        let q = ((g1.unsqueeze(2) - h.now.anchors.unsqueeze(1)) * h.now.normals.unsqueeze(1))
            .sum_dim_intlist(3, false, Kind::Float);
        let a = ((g1.unsqueeze(2) - h.before.anchors.unsqueeze(1))
            .square()
            .sum_dim_intlist(3, false, Kind::Float)
            / (-2.0 * (sigma as f64).powi(2)))
        .exp();
        let forces = ((a * (-q).relu() * FORCE_SCALE).unsqueeze(3) * h.now.normals.unsqueeze(1))
            .reshape([bs, -1, 3])
            .bmm(&h.now.root)
            .reshape([bs, v, n, 3]);
        let dense = Tensor::einsum(
            "bvnk,cnk->bvc",
            &[forces, encoder.c0_forces.shallow_clone()],
            None::<i64>,
        );
        let per_seed = Tensor::einsum(
            "bnk,cnk->bnc",
            &[
                x.contact_normals.shallow_clone(),
                encoder.c0_forces.shallow_clone(),
            ],
            None::<i64>,
        );
        let factored = x.contact.bmm(&per_seed);
        let scale = dense.abs().max().double_value(&[]);
        assert!(scale > 1e-3, "the test's garment must touch the anchors");
        let error = (dense - factored).abs().max().double_value(&[]);
        assert!(
            error < 1e-5 * scale,
            "factored {error} vs dense scale {scale}"
        );
    }

    /// A rotation about the vertical (Y) axis `[3, 3]`.
    fn yaw(angle: f64) -> Tensor {
        let (c, s) = (angle.cos() as f32, angle.sin() as f32);
        Tensor::from_slice(&[c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c]).reshape([3, 3])
    }

    #[test]
    fn the_body_drive_is_the_motion_in_the_roots_frame_and_zero_for_a_still_body() {
        let mut shape = MotionShape::for_space(&[4], 4);
        shape.drive_joints = vec![1, 3];
        let fps = 30.0;
        tch::manual_seed(9);
        let mut before = frames(1, 2);
        let mut now = frames(1, 2);
        // The root turns by 0.1 rad and steps 1 cm along its own x between the frames.
        before.root = yaw(0.3).unsqueeze(0);
        now.root = yaw(0.4).unsqueeze(0);
        before.origin = Tensor::from_slice(&[0.5f32, 1.0, -0.2]).unsqueeze(0);
        now.origin = &before.origin + now.root.select(2, 0) * 0.01;
        let u = body_drive(&before, &now, &shape, fps);
        assert_eq!(u.size(), [1, shape.drive_width()]);
        let step: Vec<f32> = u.narrow(1, 24, 3).reshape([-1]).try_into().unwrap();
        let expected = [0.3f32, 0.0, 0.0];
        for (a, b) in step.iter().zip(expected) {
            assert!((a - b).abs() < 1e-5, "step {step:?} vs {expected:?}");
        }
        let turn = u.narrow(1, 27, 6).abs().max().double_value(&[]);
        assert!(
            (turn - 0.1 * fps).abs() < 0.05 * fps,
            "turn {turn} per second"
        );
        // Turning the whole motion about the vertical leaves it unchanged.
        let (mut b2, mut n2) = (
            before.select(&Tensor::from_slice(&[0i64])),
            now.select(&Tensor::from_slice(&[0i64])),
        );
        let r = yaw(1.3);
        b2.root = r.matmul(&before.root);
        n2.root = r.matmul(&now.root);
        b2.origin = before.origin.matmul(&r.tr());
        n2.origin = now.origin.matmul(&r.tr());
        let moved = (body_drive(&b2, &n2, &shape, fps) - &u)
            .abs()
            .max()
            .double_value(&[]);
        assert!(
            moved < 1e-4,
            "the drive changed by {moved} when the world turned"
        );
        // A body holding still: its rotations, and no motion at all.
        let still = body_drive(&before, &before, &shape, fps);
        let motion = still
            .narrow(1, 12, shape.drive_width() - 12)
            .abs()
            .max()
            .double_value(&[]);
        assert!(motion < 1e-4, "a still body moves by {motion}");
        let pose = before
            .rotations
            .index_select(1, &Tensor::from_slice(&[1i64, 3]))
            .reshape([1, 12]);
        assert!(
            (still.narrow(1, 0, 12) - pose)
                .abs()
                .max()
                .double_value(&[])
                < 1e-7
        );
        // No drive joints: no drive.
        assert_eq!(
            body_drive(&before, &now, &MotionShape::for_space(&[4], 4), fps).size(),
            [1, 0]
        );
    }

    #[test]
    fn past_drives_are_the_frames_before_held_at_their_clips_first() {
        // Frame t's drive is the number t (one column); two clips starting at frames 0 and 5.
        let drives = Tensor::arange(8, (Kind::Float, tch::Device::Cpu)).reshape([8, 1]);
        let past = past_drives(&drives, &[3, 6, 5], &[0, 5, 5], 3);
        let rows: Vec<Vec<f32>> = Vec::<Vec<f32>>::try_from(&past).unwrap();
        // u_{t−1}, u_{t−2}, u_{t−3}: frame 3 sees 2, 1, 0; frame 6 sees 5 and then its clip's
        // first frame again; a clip's first frame sees only itself.
        assert_eq!(
            rows,
            vec![vec![2., 1., 0.], vec![5., 5., 5.], vec![5., 5., 5.]]
        );
        assert_eq!(past_drives(&drives, &[3], &[0], 0).size(), [1, 0]);
    }

    #[test]
    fn the_linear_fit_shrinks_each_input_by_its_own_spread() {
        let (space, _) = small_space();
        let mut encoder =
            MotionEncoder::new(MotionShape::for_space(&[4, 4], 4), &space, Device::Cpu);
        let l = space.shape.latent as i64;
        tch::manual_seed(3);
        let f = 4000;
        // The state spreads 5× wider than the motions riding on it, as on the skirt.
        let state = Tensor::randn([f, l], (Kind::Float, Device::Cpu));
        let own = Tensor::randn([f, l], (Kind::Float, Device::Cpu)) * 0.2;
        let body = Tensor::randn([f, l], (Kind::Float, Device::Cpu)) * 0.2;
        let stay = &state + &body;
        let inertia = Tensor::cat(&[&stay + &own, stay.shallow_clone()], 1);
        // The garment keeps its state and goes on at its own velocity.
        let target = &state + &own;
        let none = Tensor::zeros([f, 0], (Kind::Float, Device::Cpu));
        encoder.init_linear(&inertia, &state, &none, &target, 0.1, 1.0);
        let probe = |ball: &Tensor, stay: &Tensor, previous: &Tensor| {
            let i = Tensor::cat(&[ball, stay], 1);
            let z = encoder.linear_latent(
                &i,
                previous,
                &Tensor::zeros([1, 0], (Kind::Float, Device::Cpu)),
            );
            let constant = encoder.linear_latent(
                &Tensor::zeros([1, 2 * l], (Kind::Float, Device::Cpu)),
                &Tensor::zeros([1, l], (Kind::Float, Device::Cpu)),
                &Tensor::zeros([1, 0], (Kind::Float, Device::Cpu)),
            );
            (z - constant).sum(Kind::Double).double_value(&[]) / l as f64
        };
        let unit = Tensor::ones([1, l], (Kind::Float, Device::Cpu));
        let zero = unit.zeros_like();
        // Its own velocity, penalised by its own spread: 1 / (1 + 0.1) of it is kept.
        let velocity = probe(&unit, &zero, &zero);
        assert!(
            (velocity - 1.0 / 1.1).abs() < 0.03,
            "the velocity's coefficient {velocity}"
        );
        // A state held still stays where it is (the prior and the fit agree).
        let held = probe(&unit, &unit, &unit);
        assert!((held - 1.0).abs() < 0.02, "the state's coefficient {held}");
    }

    #[test]
    fn the_difference_basis_maps_back_to_the_same_weights() {
        tch::manual_seed(3);
        let (l, extra) = (4, 3);
        let w = Tensor::randn([3 * l + extra, 5], (Kind::Double, Device::Cpu));
        let v = to_difference_basis(&w, l);
        // v_c is the sum of the three latent blocks' weights: what a constant latent sees.
        let sum = w.narrow(0, 0, l) + w.narrow(0, l, l) + w.narrow(0, 2 * l, l);
        assert!(f64::try_from((v.narrow(0, 2 * l, l) - sum).abs().max()).unwrap() < 1e-12);
        let back = from_difference_basis(&v, l);
        assert!(f64::try_from((back - &w).abs().max()).unwrap() < 1e-12);
    }
}
