//! The generative space: `S` (convolutions over the descriptor map) → `E_sta` → `Z` → `D` →
//! feature map `ξ` → per-vertex MLP `R(ξ_i, u_i)` → displacement `d_i` in the vertex's rest frame
//! `H0_i` → `ĝ_i = g0_i + H0_i d_i` → skinned by the anchors:
//! `g_i = Σ_j w_ij M_j ĝ_i`, `w_ij = softmax_j(−|g0_i − b0_j|² / 2ρ²_part(j))`.
//! Deviations from the paper, each for trainability on a laptop in minutes rather than 350 GPU
//! epochs: the kernel weights are taken at the rest garment `g0` (not at `ĝ`), so skinning can be
//! inverted; a linear path beside the networks (`Z += P(d* − μ)`, `d += μ + B Z`) starts as the
//! principal components of the training frames' unskinned displacements `d*`, so the untrained
//! space is already the best linear fit and the networks learn the rest (both are trained).
//! No instance norm (the 2×2 and 4×4 maps of the bottleneck have too few texels for per-map
//! statistics); LeakyReLU(0.2) everywhere.

use super::anchors::{BodyAnchors, PARTS};
use super::uv::UvRaster;
use crate::geometry::{v3, vertex_normals, TriMesh};
use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};
use tch::nn::{self, Module};
use tch::{Device, Kind, Tensor};

/// Sizes of the network.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SpaceShape {
    pub preset: String,
    /// The UV map is `map`×`map` texels (a power of two ≥ 8).
    pub map: usize,
    /// Body anchors (the model file's key stays `seeds`).
    #[serde(rename = "seeds")]
    pub anchors: usize,
    /// Channels of `S(M^P)`.
    pub features: usize,
    /// Channels after each stride-2 convolution of `E_sta`, down to 2×2.
    pub encoder: Vec<usize>,
    pub latent: usize,
    /// Channels of the decoded feature map `ξ`.
    pub xi: usize,
    /// Width and depth of `R`.
    pub mlp: usize,
    pub mlp_layers: usize,
    /// Each vertex's blended anchor rotation replaced by its nearest rotation (polar
    /// decomposition): a blend of anchors turned far apart (the skirt between legs in a split or
    /// a raised leg) is near singular, and undoing it throws a vertex metres off. False in
    /// models from before it (their plain blend is kept).
    #[serde(default)]
    pub rotation_blend: bool,
}

impl SpaceShape {
    /// `cpu` (64², 128 anchors, channels ≤ 256: trains on a laptop) or `paper` (128², 581 anchors,
    /// channels to 1024, as the reference; for a GPU).
    pub fn preset(name: &str) -> Result<SpaceShape> {
        let (map, anchors, features, encoder, xi, mlp, mlp_layers) = match name {
            "cpu" => (64, 128, 32, vec![32, 64, 128, 128, 256], 16, 128, 4),
            "paper" => (
                128,
                581,
                128,
                vec![128, 256, 512, 1024, 1024, 1024],
                128,
                256,
                6,
            ),
            _ => bail!("--preset {name}: cpu or paper"),
        };
        Ok(SpaceShape {
            preset: name.into(),
            map,
            anchors,
            features,
            encoder,
            latent: 64,
            xi,
            mlp,
            mlp_layers,
            rotation_blend: true,
        })
    }

    fn check(&self) -> Result<()> {
        if !self.map.is_power_of_two() || self.map < 8 || self.map >> self.encoder.len() != 2 {
            bail!(
                "map {} with {} encoder layers does not reach 2×2",
                self.map,
                self.encoder.len()
            );
        }
        if self.latent == 0 {
            bail!("--latent 0: the space needs at least one latent dimension");
        }
        Ok(())
    }
}

/// The garment and body data the network runs on, as tensors.
pub struct Consts {
    texel_vertices: Tensor,
    texel_weights: Tensor,
    mask: Tensor,
    /// Vertex UVs as a `grid_sampler` grid `[1, V, 1, 2]` in [−1, 1].
    grid: Tensor,
    uv: Tensor,
    /// `[V, 3, 3]`: rows normal, tangent, bitangent of each rest vertex.
    frames: Tensor,
    pub rest: Tensor,
    pub seed_rest: Tensor,
    seed_part: Tensor,
}

impl Consts {
    pub fn new(
        garment: &TriMesh,
        raster: &UvRaster,
        anchors: &BodyAnchors,
        device: Device,
    ) -> Consts {
        let t = raster.texel_vertices.len() as i64;
        let flat =
            |v: Vec<f32>, dims: &[i64]| Tensor::from_slice(&v).reshape(dims).to_device(device);
        let idx: Vec<i64> = raster
            .texel_vertices
            .iter()
            .flatten()
            .map(|&v| v as i64)
            .collect();
        let w: Vec<f32> = raster.texel_weights.iter().flatten().copied().collect();
        let covered: Vec<f32> = raster
            .texel_weights
            .iter()
            .map(|w| f32::from(w.iter().sum::<f32>() > 0.5))
            .collect();
        let n = raster.size as i64;
        let grid: Vec<f32> = raster
            .vertex_uv
            .iter()
            .flat_map(|p| [2.0 * p[0] - 1.0, 2.0 * p[1] - 1.0])
            .collect();
        let uv: Vec<f32> = raster.vertex_uv.iter().flatten().copied().collect();
        let v = garment.vertex_count() as i64;
        Consts {
            texel_vertices: Tensor::from_slice(&idx).to_device(device),
            texel_weights: flat(w, &[t, 3, 1]),
            mask: flat(covered, &[1, 1, n, n]),
            grid: flat(grid, &[1, v, 1, 2]),
            uv: flat(uv, &[v, 2]),
            frames: flat(rest_frames(garment), &[v, 3, 3]),
            rest: flat(
                garment.positions.iter().flatten().copied().collect(),
                &[v, 3],
            ),
            seed_rest: flat(
                anchors.rest.iter().flatten().copied().collect(),
                &[anchors.rest.len() as i64, 3],
            ),
            seed_part: Tensor::from_slice(
                &anchors.parts.iter().map(|&p| p as i64).collect::<Vec<_>>(),
            )
            .to_device(device),
        }
    }
}

/// Each vertex's rest frame: normal, a tangent (the normal × a fixed axis, whichever of Y and X
/// is less parallel to it) and bitangent. Flattened `[V, 3, 3]`, rows n, t, b.
fn rest_frames(mesh: &TriMesh) -> Vec<f32> {
    vertex_normals(&mesh.positions, &mesh.triangles)
        .iter()
        .flat_map(|&n| {
            let n = v3(n);
            let axis = if n.y.abs() < 0.9 {
                nalgebra::Vector3::y()
            } else {
                nalgebra::Vector3::x()
            };
            let t = n.cross(&axis).normalize();
            let b = n.cross(&t);
            [n, t, b].into_iter().flat_map(|r| [r.x, r.y, r.z])
        })
        .collect()
}

pub struct Space {
    pub vs: nn::VarStore,
    pub shape: SpaceShape,
    /// `S`'s first layer, a 1×1 convolution over the `3N + 1` descriptor channels: weight
    /// `[C, 3N + 1]` (the last column reads the layout mask) and bias `[C]`.
    s0_weight: Tensor,
    s0_bias: Tensor,
    s: nn::Sequential,
    encoder: nn::Sequential,
    encoder_fc: nn::Linear,
    decoder_fc: nn::Linear,
    decoder: nn::Sequential,
    r: nn::Sequential,
    /// ln ρ per body part ([`PARTS`]).
    pub log_radius: Tensor,
    /// The linear path (see [`Space::init_linear`]): mean rest-frame displacement `[3V]`, the
    /// encoder's projection `[L, 3V]` and the decoder's basis `[L, 3V]`.
    linear_mean: Tensor,
    linear_encode: Tensor,
    linear_decode: Tensor,
    pub consts: Consts,
    /// The kernel weights once the space is frozen ([`Space::freeze`]).
    frozen_weights: Option<Tensor>,
    /// Frozen with `E_sta`'s and `R`'s output layers all zero (a space trained `--epochs 0`):
    /// the networks then add exactly nothing to `Z` and `d`, and are skipped.
    networks_idle: bool,
}

/// Initial kernel radius (metres): under the anchor spacing (~6 cm for the cpu preset on the skirt), so
/// each vertex starts on its few nearest anchors (the waist band then follows the hips within 2 cm).
pub const RADIUS0: f64 = 0.05;
/// `R`'s output scale: displacements start at millimetres.
const DISPLACEMENT_SCALE: f64 = 0.05;
/// A principal component whose spread is under this fraction of the largest is rank noise.
const RANK_TOLERANCE: f64 = 1e-5;

fn leaky() -> impl Module {
    nn::func(|x| x.leaky_relu())
}

impl Space {
    pub fn new(shape: SpaceShape, consts: Consts, device: Device) -> Result<Space> {
        shape.check()?;
        let vs = nn::VarStore::new(device);
        let root = vs.root();
        let input = 3 * shape.anchors as i64 + 1;
        let f = shape.features as i64;
        let bound = 1.0 / (input as f64).sqrt();
        let s0_weight = (&root / "s" / "0").var(
            "weight",
            &[f, input],
            nn::Init::Uniform {
                lo: -bound,
                up: bound,
            },
        );
        let s0_bias = (&root / "s" / "0").var(
            "bias",
            &[f],
            nn::Init::Uniform {
                lo: -bound,
                up: bound,
            },
        );
        let s = nn::seq()
            .add(leaky())
            .add(nn::conv2d(
                &root / "s" / "1",
                f,
                f,
                3,
                nn::ConvConfig {
                    padding: 1,
                    ..Default::default()
                },
            ))
            .add(leaky());
        let down = nn::ConvConfig {
            stride: 2,
            padding: 1,
            ..Default::default()
        };
        let up = nn::ConvTransposeConfig {
            stride: 2,
            padding: 1,
            ..Default::default()
        };
        let mut encoder = nn::seq();
        let mut c = f;
        for (k, &o) in shape.encoder.iter().enumerate() {
            encoder = encoder
                .add(nn::conv2d(&root / "enc" / k, c, o as i64, 4, down))
                .add(leaky());
            c = o as i64;
        }
        let bottleneck = c * 4;
        let latent = shape.latent as i64;
        // Zero: the untrained encoder is the linear path alone.
        let zero_linear = nn::LinearConfig {
            ws_init: nn::Init::Const(0.0),
            bs_init: Some(nn::Init::Const(0.0)),
            bias: true,
        };
        let encoder_fc = nn::linear(&root / "enc_fc", bottleneck, latent, zero_linear);
        let decoder_fc = nn::linear(&root / "dec_fc", latent, bottleneck, Default::default());
        let mut decoder = nn::seq();
        let outs: Vec<i64> = shape
            .encoder
            .iter()
            .rev()
            .skip(1)
            .map(|&o| o as i64)
            .chain([shape.xi as i64])
            .collect();
        for (k, &o) in outs.iter().enumerate() {
            decoder = decoder.add(nn::conv_transpose2d(&root / "dec" / k, c, o, 4, up));
            if k + 1 < outs.len() {
                decoder = decoder.add(leaky());
            }
            c = o;
        }
        let mut r = nn::seq();
        let mut width = shape.xi as i64 + 2;
        for k in 0..shape.mlp_layers {
            let last = k + 1 == shape.mlp_layers;
            let o = if last { 3 } else { shape.mlp as i64 };
            // The last layer starts at zero: the untrained space is plain anchor skinning of the rest garment.
            let config = if last {
                zero_linear
            } else {
                Default::default()
            };
            r = r.add(nn::linear(&root / "r" / k, width, o, config));
            if !last {
                r = r.add(leaky());
            }
            width = o;
        }
        let log_radius = root.var(
            "log_radius",
            &[PARTS.len() as i64],
            nn::Init::Const(RADIUS0.ln()),
        );
        let dof = 3 * consts.rest.size()[0];
        let zero = nn::Init::Const(0.0);
        let linear_mean = root.var("linear_mean", &[dof], zero);
        let linear_encode = root.var("linear_encode", &[latent, dof], zero);
        let linear_decode = root.var("linear_decode", &[latent, dof], zero);
        Ok(Space {
            vs,
            shape,
            s0_weight,
            s0_bias,
            s,
            encoder,
            encoder_fc,
            decoder_fc,
            decoder,
            r,
            log_radius,
            linear_mean,
            linear_encode,
            linear_decode,
            consts,
            frozen_weights: None,
            networks_idle: false,
        })
    }

    /// `S`'s first layer applied to the body-relative descriptor map `M^P` of garments
    /// `g [B, V, 3]` against anchors `b [B, N, 3]`, without building the `3N`-channel map: a
    /// linear layer over `[g_i − b_j]_j` is `A g_i − Σ_j W_j b_j` with `A = Σ_j W_j`, and
    /// scattering vertices into texels (barycentric weights summing to one) commutes with it.
    /// Exactly the 1×1 convolution of the map; `[B, C, H, W]` before the activation.
    pub fn descriptor_features(&self, g: &Tensor, b: &Tensor) -> Tensor {
        let n = self.shape.anchors as i64;
        let c = self.s0_weight.size()[0];
        let w = self.s0_weight.narrow(1, 0, 3 * n).reshape([c, n, 3]);
        let a = w.sum_dim_intlist(1, false, Kind::Float);
        let offset = Tensor::einsum("cnk,bnk->bc", &[w, b.shallow_clone()], None::<i64>);
        let per_vertex = Tensor::einsum("ck,bvk->bvc", &[a, g.shallow_clone()], None::<i64>)
            - offset.unsqueeze(1);
        let map = self.scatter(&per_vertex);
        let mask = self.s0_weight.select(1, 3 * n).reshape([1, c, 1, 1]) * &self.consts.mask;
        map + mask + self.s0_bias.reshape([1, c, 1, 1])
    }

    /// Per-vertex channels `[B, V, C]` laid out in the UV map `[B, C, H, W]`: each texel the
    /// barycentric blend of its covering triangle's vertices (zero outside the layout).
    pub fn scatter(&self, per_vertex: &Tensor) -> Tensor {
        let (bs, c) = (per_vertex.size()[0], per_vertex.size()[2]);
        let k = &self.consts;
        let per = per_vertex
            .index_select(1, &k.texel_vertices)
            .reshape([bs, -1, 3, c]);
        let side = self.shape.map as i64;
        (per * &k.texel_weights)
            .sum_dim_intlist(2, false, Kind::Float)
            .permute([0, 2, 1])
            .reshape([bs, c, side, side])
    }

    /// `[1, 1, H, W]`: 1 on texels the garment's layout covers.
    pub fn layout_mask(&self) -> &Tensor {
        &self.consts.mask
    }

    /// A UV-space map `[B, C, H, W]` read at each vertex's UV (bilinear), `[B, V, C]`.
    pub fn at_vertices(&self, map: &Tensor) -> Tensor {
        let bs = map.size()[0];
        let grid = self.consts.grid.expand([bs, -1, 1, 2], false);
        map.grid_sampler(&grid, 0, 1, false)
            .squeeze_dim(3)
            .permute([0, 2, 1])
    }

    /// Where garments `g [B, V, 3]` go when they follow the anchors rigidly from transforms
    /// `before` to `now` (each vertex's blended transform undone, then redone).
    pub fn follow(&self, g: &Tensor, before: &Tensor, now: &Tensor) -> Tensor {
        self.skin(&self.unskin(g, before), now)
    }

    /// Garments `g [B, V, 3]` with each vertex's anchor-blended transform under `m` undone.
    pub fn unskin(&self, g: &Tensor, m: &Tensor) -> Tensor {
        let (rot, shift) = self.blended(m);
        inverse3(&rot)
            .matmul(&(g - shift).unsqueeze(3))
            .squeeze_dim(3)
    }

    /// `Z [B, L]` of garments `g` with anchors at `b` and anchor transforms `m`:
    /// `E_sta(S(M^P))` plus the linear path's projection of the unskinned displacements.
    pub fn encode(&self, g: &Tensor, b: &Tensor, m: &Tensor) -> Tensor {
        self.encode_keeping_features(g, b, m).1
    }

    /// [`Space::encode`] that also returns the `S(M^P)` it went through (the dynamic stage's
    /// input), so that callers needing both pay for `S` once.
    pub fn encode_keeping_features(&self, g: &Tensor, b: &Tensor, m: &Tensor) -> (Tensor, Tensor) {
        let features = self.static_features(g, b);
        let z = self.encode_features(&features) + self.linear_latent(g, m);
        (features, z)
    }

    /// The linear path's part of `Z` (all of it when [`Space::networks_idle`]).
    pub fn linear_latent(&self, g: &Tensor, m: &Tensor) -> Tensor {
        (self.rest_displacements(g, m) - &self.linear_mean).matmul(&self.linear_encode.tr())
    }

    /// Whether the frozen space's networks add nothing (their output layers are zero).
    pub fn networks_idle(&self) -> bool {
        self.networks_idle
    }

    /// Garments `g [B, V, 3]` unskinned by anchor transforms `m` (each vertex's blended transform
    /// inverted) and expressed as displacements in the vertices' rest frames, `[B, 3V]`: what
    /// [`Space::canonical`] would have to output to reproduce `g` exactly.
    pub fn rest_displacements(&self, g: &Tensor, m: &Tensor) -> Tensor {
        self.local_displacements(&self.unskin(g, m))
    }

    /// The linear path's latent of garments `g [B, V, 3]` under per-vertex transforms already
    /// blended ([`Space::posed`]): for callers that encode many garments under the same poses.
    pub fn linear_latent_posed(&self, g: &Tensor, posed: &Posed) -> Tensor {
        let local = posed
            .inverse
            .matmul(&(g - &posed.shift).unsqueeze(3))
            .squeeze_dim(3);
        (self.local_displacements(&local) - &self.linear_mean).matmul(&self.linear_encode.tr())
    }

    /// The linear path's step inputs `(Z_{t−1}, [Z^ball_t, Z^stay_t])` from the last two
    /// garments `g1 = g_{t−1}`, `g2 = g_{t−2}` and the poses at `t − 1` and `t`: `g_{t−1}` against
    /// the body at `t − 1`; the ballistic guess `2g_{t−1} − g_{t−2}` and `g_{t−1}` against the
    /// body at `t`. One definition for training (teacher-forced and unrolled) and roll-outs.
    pub fn linear_step_latents(
        &self,
        g1: &Tensor,
        g2: &Tensor,
        before: &Posed,
        now: &Posed,
    ) -> (Tensor, Tensor) {
        let ballistic = g1 * 2.0 - g2;
        let previous = self.linear_latent_posed(g1, before);
        let inertia = Tensor::cat(
            &[
                self.linear_latent_posed(&ballistic, now),
                self.linear_latent_posed(g1, now),
            ],
            1,
        );
        (previous, inertia)
    }

    /// Unskinned garments `[B, V, 3]` as displacements in the vertices' rest frames `[B, 3V]`.
    fn local_displacements(&self, local: &Tensor) -> Tensor {
        let k = &self.consts;
        Tensor::einsum(
            "vkc,bvc->bvk",
            &[k.frames.shallow_clone(), local - &k.rest],
            None::<i64>,
        )
        .flatten(1, 2)
    }

    /// Sets the linear path to the principal components of rest-frame displacements `d [F, 3V]`
    /// (from [`Space::rest_displacements`] of the training frames), scaled so that the latents
    /// of the training frames have unit variance: the untrained space is then the best linear
    /// `L`-dimensional fit of its training set, and the networks learn what is left.
    pub fn init_linear(&mut self, d: &Tensor) {
        tch::no_grad(|| {
            let mean = d.mean_dim(0, false, Kind::Float);
            let centred = d - &mean;
            let (_, singular, v) = centred.svd(true, true);
            let vh = v.tr();
            let l = self.linear_encode.size()[0].min(vh.size()[0]);
            let frames = d.size()[0].max(1) as f64;
            let sigma = (singular.narrow(0, 0, l) / frames.sqrt()).unsqueeze(1);
            // Fewer distinct frames than latents: the components past the frames' rank are
            // arbitrary directions of rounding noise (which ones depends on the CPU's kernels),
            // and dividing by their ~0 spread would blow that noise up into latents. They stay
            // zero: those latents are unused until the networks learn them.
            let used = sigma
                .gt_tensor(&(sigma.max() * RANK_TOLERANCE))
                .to_kind(Kind::Float);
            let basis = vh.narrow(0, 0, l) * &used;
            self.linear_mean.copy_(&mean);
            self.linear_encode
                .narrow(0, 0, l)
                .copy_(&(&basis / sigma.clamp_min(1e-12)));
            self.linear_decode.narrow(0, 0, l).copy_(&(&basis * &sigma));
        });
    }

    /// `S(M^P)`: the static feature map (the dynamic stage reuses it).
    pub fn static_features(&self, g: &Tensor, b: &Tensor) -> Tensor {
        self.s.forward(&self.descriptor_features(g, b))
    }

    /// `E_sta` on `S(M^P)` (the dynamic stage reuses `S` on its own).
    pub fn encode_features(&self, features: &Tensor) -> Tensor {
        let x = self.encoder.forward(features).flatten(1, -1);
        self.encoder_fc.forward(&x)
    }

    /// Canonical garments `ĝ [B, V, 3]` of latents `z [B, L]`.
    pub fn canonical(&self, z: &Tensor) -> Tensor {
        let bs = z.size()[0];
        let linear = z.matmul(&self.linear_decode) + &self.linear_mean;
        if self.networks_idle {
            return self.displaced(&linear);
        }
        let c = *self.shape.encoder.last().expect("encoder layers") as i64;
        let x = self
            .decoder_fc
            .forward(z)
            .leaky_relu()
            .reshape([bs, c, 2, 2]);
        let xi = self.decoder.forward(&x);
        let k = &self.consts;
        let per_vertex = self.at_vertices(&xi);
        let v = per_vertex.size()[1];
        let input = Tensor::cat(
            &[per_vertex, k.uv.unsqueeze(0).expand([bs, v, 2], false)],
            2,
        );
        self.displaced(&(self.r.forward(&input) * DISPLACEMENT_SCALE + linear.reshape([bs, v, 3])))
    }

    /// The rest garment moved by rest-frame displacements `d [B, V, 3]` (or `[B, 3V]`).
    pub fn displaced(&self, d: &Tensor) -> Tensor {
        self.offset_canonical(&self.consts.rest, d)
    }

    /// Canonical garments `[B, V, 3]` moved by displacements `d` in the vertices' rest frames.
    pub fn offset_canonical(&self, canonical: &Tensor, d: &Tensor) -> Tensor {
        let d = d.reshape([d.size()[0], -1, 3]);
        canonical
            + Tensor::einsum(
                "bvk,vkc->bvc",
                &[d, self.consts.frames.shallow_clone()],
                None::<i64>,
            )
    }

    /// Each vertex's anchor-blended transform under anchor transforms `m [B, N, 12]` (row-major
    /// 3×4): rotation part `[B, V, 3, 3]` and translation `[B, V, 3]`. The weights are
    /// `softmax_j(−|g0_i − b0_j|² / 2ρ²_part(j))` at the REST garment `g0` (the paper evaluates
    /// them at the decoded `ĝ`): fixed weights make the skinning invertible per vertex, which
    /// [`Space::rest_displacements`] needs.
    pub fn blended(&self, m: &Tensor) -> (Tensor, Tensor) {
        let k = &self.consts;
        let w = match &self.frozen_weights {
            Some(w) => w.shallow_clone(),
            None => self.kernel_weights(),
        };
        let (bs, v) = (m.size()[0], k.rest.size()[0]);
        let a = w
            .unsqueeze(0)
            .expand([bs, v, -1], false)
            .bmm(m)
            .reshape([bs, v, 3, 4]);
        let rot = a.narrow(3, 0, 3);
        let rot = match self.shape.rotation_blend {
            true => nearest_rotation(&rot),
            false => rot,
        };
        (rot, a.select(3, 3))
    }

    /// `w_ij` `[V, N]` at the current radii.
    fn kernel_weights(&self) -> Tensor {
        let k = &self.consts;
        let d2 = (k.rest.unsqueeze(1) - k.seed_rest.unsqueeze(0))
            .square()
            .sum_dim_intlist(2, false, Kind::Float);
        let rho2 = (self.log_radius.index_select(0, &k.seed_part) * 2.0).exp();
        (-d2 / (rho2 * 2.0)).softmax(1, Kind::Float)
    }

    /// Fixes every parameter (the dynamic stage and roll-outs use the space as trained) and
    /// keeps the kernel weights, which then never change, instead of recomputing them per call.
    pub fn freeze(&mut self) {
        self.vs.freeze();
        self.frozen_weights = Some(tch::no_grad(|| self.kernel_weights()));
        let r_last = self
            .vs
            .variables()
            .keys()
            .filter_map(|n| {
                n.strip_prefix("r.")?
                    .split('.')
                    .next()?
                    .parse::<usize>()
                    .ok()
            })
            .max();
        let mut outputs = vec!["enc_fc.weight".to_string(), "enc_fc.bias".to_string()];
        outputs.extend(
            r_last
                .map(|k| [format!("r.{k}.weight"), format!("r.{k}.bias")])
                .into_iter()
                .flatten(),
        );
        self.networks_idle = all_zero(&self.vs, &outputs);
    }

    /// Skins canonical garments `[B, V, 3]` by the anchors' transforms `m [B, N, 12]`.
    pub fn skin(&self, canonical: &Tensor, m: &Tensor) -> Tensor {
        let (rotation, shift) = self.blended(m);
        skin_by(canonical, &rotation, &shift)
    }

    /// Each vertex's blended transform under anchor transforms `m [B, N, 12]`, blended once
    /// for callers that skin and unskin many garments under the same poses (no gradients).
    pub fn posed(&self, m: &Tensor) -> Posed {
        tch::no_grad(|| {
            let (rotation, shift) = self.blended(m);
            Posed {
                inverse: inverse3(&rotation),
                rotation,
                shift,
            }
        })
    }

    /// Encode → decode → skin: the space's reconstruction of garments `g` with anchors at `b`
    /// and anchor transforms `m`; also returns `z` and the canonical garments.
    pub fn reconstruct(&self, g: &Tensor, b: &Tensor, m: &Tensor) -> (Tensor, Tensor, Tensor) {
        let z = self.encode(g, b, m);
        let canonical = self.canonical(&z);
        (self.skin(&canonical, m), z, canonical)
    }

    /// Sets every part's kernel radius (metres), before training.
    pub fn set_radius(&mut self, radius: f64) -> Result<()> {
        if !(radius.is_finite() && radius > 0.0) {
            bail!("the kernel radius must be a positive length, not {radius} m");
        }
        let _ = tch::no_grad(|| self.log_radius.fill_(radius.ln()));
        Ok(())
    }

    /// The learnt kernel radius per body part (metres).
    pub fn radii(&self) -> Vec<f64> {
        let r: Vec<f32> = tch::no_grad(|| self.log_radius.exp())
            .try_into()
            .unwrap_or_default();
        r.into_iter().map(f64::from).collect()
    }

    /// Trainable tensors by name, sorted (the file's and Adam's order).
    pub fn parameters(&self) -> Vec<(String, Tensor)> {
        sorted_variables(&self.vs)
    }

    /// Copies stored values into the parameters (shapes must match).
    pub fn load_parameters(&mut self, stored: &[(String, Tensor)]) -> Result<()> {
        load_variables(&mut self.vs, stored)
    }
}

/// A var store's tensors by name, sorted (the file's and Adam's order).
/// Whether every one of the named variables exists and is all zero.
/// Per-vertex blended transforms of a batch of poses ([`Space::posed`]): rotations
/// `[B, V, 3, 3]`, their inverses and translations `[B, V, 3]`.
pub struct Posed {
    pub rotation: Tensor,
    pub inverse: Tensor,
    pub shift: Tensor,
}

impl Posed {
    /// Canonical garments `[B, V, 3]` skinned by these transforms ([`Space::skin`]).
    pub fn skin(&self, canonical: &Tensor) -> Tensor {
        skin_by(canonical, &self.rotation, &self.shift)
    }

    /// The poses `idx` of the batch.
    pub fn select(&self, idx: &Tensor) -> Posed {
        Posed {
            rotation: self.rotation.index_select(0, idx),
            inverse: self.inverse.index_select(0, idx),
            shift: self.shift.index_select(0, idx),
        }
    }

    /// Batches joined in order.
    pub fn cat(parts: &[Posed]) -> Posed {
        let join =
            |f: fn(&Posed) -> &Tensor| Tensor::cat(&parts.iter().map(f).collect::<Vec<_>>(), 0);
        Posed {
            rotation: join(|p| &p.rotation),
            inverse: join(|p| &p.inverse),
            shift: join(|p| &p.shift),
        }
    }
}

fn skin_by(canonical: &Tensor, rotation: &Tensor, shift: &Tensor) -> Tensor {
    rotation.matmul(&canonical.unsqueeze(3)).squeeze_dim(3) + shift
}

pub fn all_zero(vs: &nn::VarStore, names: &[String]) -> bool {
    let vars = vs.variables();
    names.iter().all(|n| {
        vars.get(n)
            .is_some_and(|t| tch::no_grad(|| t.abs().max().double_value(&[])) == 0.0)
    })
}

pub fn sorted_variables(vs: &nn::VarStore) -> Vec<(String, Tensor)> {
    let mut v: Vec<(String, Tensor)> = vs.variables().into_iter().collect();
    v.sort_by(|a, b| a.0.cmp(&b.0));
    v
}

/// Copies stored values into a var store's tensors (every one present, shapes equal).
pub fn load_variables(vs: &mut nn::VarStore, stored: &[(String, Tensor)]) -> Result<()> {
    let mut vars = vs.variables();
    for (name, t) in stored {
        let Some(p) = vars.get_mut(name) else {
            continue;
        };
        if p.size() != t.size() {
            bail!(
                "tensor '{name}' has shape {:?}, the network expects {:?}",
                t.size(),
                p.size()
            );
        }
        tch::no_grad(|| p.copy_(t));
    }
    if let Some(missing) = vars.keys().find(|n| !stored.iter().any(|(s, _)| s == *n)) {
        bail!("missing tensor '{missing}'");
    }
    Ok(())
}

/// Inverses of 3×3 matrices `[..., 3, 3]` by the adjugate: elementwise over the batch, where a
/// batched LU (`Tensor::inverse`) loops over thousands of tiny factorisations (3 × 2808 per
/// roll-out step: 1.8 → 0.9 ms at 1 thread). The blended transforms are well conditioned (a
/// convex blend of rotations near each other), so the closed form loses nothing.
pub fn inverse3(m: &Tensor) -> Tensor {
    let e = |r: i64, c: i64| m.select(-2, r).select(-1, c);
    let cof = |r0: i64, r1: i64, c0: i64, c1: i64| e(r0, c0) * e(r1, c1) - e(r0, c1) * e(r1, c0);
    // Rows of the adjugate (the transposed cofactor matrix).
    let rows = [
        [cof(1, 2, 1, 2), -cof(0, 2, 1, 2), cof(0, 1, 1, 2)],
        [-cof(1, 2, 0, 2), cof(0, 2, 0, 2), -cof(0, 1, 0, 2)],
        [cof(1, 2, 0, 1), -cof(0, 2, 0, 1), cof(0, 1, 0, 1)],
    ];
    let det = e(0, 0) * &rows[0][0] + e(0, 1) * &rows[1][0] + e(0, 2) * &rows[2][0];
    let adjugate = Tensor::stack(&rows.map(|r| Tensor::stack(&r, -1)), -2);
    adjugate / det.unsqueeze(-1).unsqueeze(-1)
}

/// Newton steps of [`nearest_rotation`]: from a blend of rotations up to ~170° apart (det 1e-2)
/// the scaled iteration is orthonormal to 1e-6 after 6; 8 leave a margin.
const POLAR_STEPS: usize = 8;

/// The nearest rotations (the orthogonal factor of the polar decomposition) of 3×3 matrices
/// `[..., 3, 3]`, by the determinant-scaled Newton iteration `X ← (γX + (γX)^{−T}) / 2`,
/// `γ = |det X|^{−1/3}` (Higham 1986): elementwise over the batch, like [`inverse3`], where
/// thousands of tiny SVDs would loop. A blend of rotations has a positive determinant, so the
/// result is a rotation; a determinant below 1e-9 is held there (such a blend has no nearest
/// rotation to speak of, and any bounded answer keeps its vertex near the body).
pub fn nearest_rotation(m: &Tensor) -> Tensor {
    let mut x = m.shallow_clone();
    for _ in 0..POLAR_STEPS {
        let e = |r: i64, c: i64| x.select(-2, r).select(-1, c);
        let det = e(0, 0) * (e(1, 1) * e(2, 2) - e(1, 2) * e(2, 1))
            - e(0, 1) * (e(1, 0) * e(2, 2) - e(1, 2) * e(2, 0))
            + e(0, 2) * (e(1, 0) * e(2, 1) - e(1, 1) * e(2, 0));
        let gamma = det
            .abs()
            .clamp_min(1e-9)
            .pow_tensor_scalar(-1.0 / 3.0)
            .unsqueeze(-1)
            .unsqueeze(-1);
        let scaled = &x * &gamma;
        x = (inverse3(&scaled).transpose(-1, -2) + scaled) * 0.5;
    }
    x
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::geometry::test_meshes::grid;
    use crate::geometry::FaceVaryingUv;

    /// A rotation by `angle` about the unit `axis` (Rodrigues).
    fn rotation(axis: [f64; 3], angle: f64) -> Tensor {
        let k = Tensor::from_slice(&[
            0.0, -axis[2], axis[1], axis[2], 0.0, -axis[0], -axis[1], axis[0], 0.0,
        ])
        .reshape([3, 3]);
        let eye = Tensor::eye(3, (Kind::Double, Device::Cpu));
        eye + &k * angle.sin() + k.matmul(&k) * (1.0 - angle.cos())
    }

    #[test]
    fn nearest_rotation_keeps_rotations_and_straightens_far_apart_blends() {
        let r = rotation([0.0, 0.6, 0.8], 0.7);
        let kept = nearest_rotation(&r.unsqueeze(0));
        let diff = (kept.squeeze_dim(0) - &r).abs().max().double_value(&[]);
        assert!(diff < 1e-9, "a rotation moved by {diff}");
        // Two legs turned 170° apart about one axis, blended half and half: the blend
        // (det 0.0076, singular values 1, 0.087, 0.087) is nearly singular; its nearest
        // rotation is the half-way turn, 85° from each.
        let a = rotation([1.0, 0.0, 0.0], 0.0);
        let b = rotation([1.0, 0.0, 0.0], 170f64.to_radians());
        let blend = (&a + &b) * 0.5;
        let q = nearest_rotation(&blend.unsqueeze(0)).squeeze_dim(0);
        let eye = Tensor::eye(3, (Kind::Double, Device::Cpu));
        let off = (q.tr().matmul(&q) - &eye).abs().max().double_value(&[]);
        assert!(off < 1e-6, "not orthonormal by {off}");
        let half = rotation([1.0, 0.0, 0.0], 85f64.to_radians());
        let diff = (&q - half).abs().max().double_value(&[]);
        assert!(diff < 1e-6, "not the half-way turn: {diff}");
        // The plain blend's inverse is 11.5× longer than a rotation's; the rotation's is 1.
        let stretch = |m: &Tensor| {
            inverse3(m)
                .matmul(&Tensor::from_slice(&[0.0, 0.0, 1.0]).reshape([3, 1]))
                .norm()
                .double_value(&[])
        };
        assert!(stretch(&blend) > 11.0, "{}", stretch(&blend));
        assert!((stretch(&q) - 1.0).abs() < 1e-6, "{}", stretch(&q));
    }

    #[test]
    fn the_adjugate_inverse_equals_lu() {
        tch::manual_seed(3);
        // Near rotations, as blended anchor transforms are.
        let m = Tensor::randn([2, 50, 3, 3], (Kind::Float, tch::Device::Cpu)) * 0.3
            + Tensor::eye(3, (Kind::Float, tch::Device::Cpu));
        let ours = inverse3(&m);
        let lu = m.inverse();
        let off = (&ours - &lu).abs().max().double_value(&[]);
        assert!(off < 1e-5, "adjugate vs LU: {off}");
        let identity = m.matmul(&ours) - Tensor::eye(3, (Kind::Float, tch::Device::Cpu));
        assert!(identity.abs().max().double_value(&[]) < 1e-5);
    }

    /// A 3-anchor space on an 8² map over a small grid garment.
    pub(crate) fn small_space() -> (Space, TriMesh) {
        let mut mesh = grid(3, 3, 0.1);
        let uv: Vec<[f32; 2]> = mesh
            .positions
            .iter()
            .map(|p| [p[0] * 10.0, p[1] * 10.0])
            .collect();
        mesh.uv = Some(FaceVaryingUv {
            coords: uv,
            triangles: mesh.triangles.clone(),
        });
        let raster = UvRaster::new(&mesh, 8, "grid").unwrap();
        let anchors = BodyAnchors {
            vertices: vec![0, 1, 2],
            rest: vec![[0.0, -0.1, 0.0], [0.3, -0.1, 0.0], [0.0, -0.1, 0.3]],
            parts: vec![0, 1, 2],
        };
        let consts = Consts::new(&mesh, &raster, &anchors, Device::Cpu);
        let shape = SpaceShape {
            preset: "test".into(),
            map: 8,
            anchors: 3,
            features: 4,
            encoder: vec![4, 4],
            latent: 5,
            xi: 3,
            mlp: 8,
            mlp_layers: 2,
            rotation_blend: true,
        };
        tch::manual_seed(1);
        (Space::new(shape, consts, Device::Cpu).unwrap(), mesh)
    }

    #[test]
    fn factored_first_layer_equals_the_convolution_of_the_full_descriptor_map() {
        let (space, mesh) = small_space();
        let v = mesh.vertex_count() as i64;
        let g = Tensor::randn([2, v, 3], (Kind::Float, Device::Cpu));
        let b = Tensor::randn([2, 3, 3], (Kind::Float, Device::Cpu));
        // The paper's map: [g_i − b_j]_j per vertex, scattered to texels, plus the mask channel.
        let rel = (g.unsqueeze(2) - b.unsqueeze(1)).reshape([2, v, 9]);
        let k = &space.consts;
        let per = rel
            .index_select(1, &k.texel_vertices)
            .reshape([2, -1, 3, 9]);
        let map = (per * &k.texel_weights)
            .sum_dim_intlist(2, false, Kind::Float)
            .permute([0, 2, 1])
            .reshape([2, 9, 8, 8]);
        let map = Tensor::cat(&[map, k.mask.expand([2, 1, 8, 8], false)], 1);
        let conv = map.conv2d(
            &space.s0_weight.reshape([4, 10, 1, 1]),
            Some(&space.s0_bias),
            [1, 1],
            [0, 0],
            [1, 1],
            1,
        );
        let fast = space.descriptor_features(&g, &b);
        let diff = (conv - fast).abs().max().double_value(&[]);
        assert!(diff < 1e-5, "factored S0 differs by {diff}");
    }

    #[test]
    fn the_untrained_space_is_seed_skinning_of_the_rest_garment() {
        let (space, mesh) = small_space();
        let z = Tensor::randn([1, 5], (Kind::Float, Device::Cpu));
        let canonical = space.canonical(&z);
        let rest = space.consts.rest.unsqueeze(0);
        assert!(
            (&canonical - &rest).abs().max().double_value(&[]) < 1e-7,
            "R starts at zero"
        );
        // Every anchor translated by t: the garment moves by t.
        let mut m = [0f32; 12];
        (m[0], m[5], m[10], m[3], m[7], m[11]) = (1.0, 1.0, 1.0, 0.5, -0.25, 2.0);
        let m = Tensor::from_slice(&m)
            .reshape([1, 1, 12])
            .expand([1, 3, 12], false)
            .contiguous();
        let posed = space.skin(&canonical, &m);
        let shift = Tensor::from_slice(&[0.5f32, -0.25, 2.0]).reshape([1, 1, 3]);
        assert!((posed - rest - shift).abs().max().double_value(&[]) < 1e-6);
        assert_eq!(mesh.vertex_count(), 16);
    }

    /// Three frames: random anchor transforms near identity `[3, 3, 12]`, random garments.
    fn random_frames(space: &Space) -> (Tensor, Tensor) {
        let eye = Tensor::from_slice(&[1f32, 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0.]);
        let m =
            eye.reshape([1, 1, 12]) + Tensor::randn([3, 3, 12], (Kind::Float, Device::Cpu)) * 0.2;
        let v = space.consts.rest.size()[0];
        let g = space.consts.rest.unsqueeze(0)
            + Tensor::randn([3, v, 3], (Kind::Float, Device::Cpu)) * 0.05;
        (m, g)
    }

    #[test]
    fn unskinning_inverts_skinning_and_the_linear_path_fits_its_frames() {
        let (mut space, _) = small_space();
        let (m, g) = random_frames(&space);
        let d = space.rest_displacements(&g, &m);
        let back = space.skin(&space.displaced(&d), &m);
        let diff = (&back - &g).abs().max().double_value(&[]);
        assert!(diff < 1e-4, "skin(unskin(g)) differs by {diff}");
        // Three frames span two directions around their mean; 5 latents hold them exactly.
        space.init_linear(&d);
        let b = Tensor::zeros([3, 3, 3], (Kind::Float, Device::Cpu));
        let (rebuilt, z, _) = space.reconstruct(&g, &b, &m);
        let diff = (&rebuilt - &g).abs().max().double_value(&[]);
        assert!(diff < 1e-4, "linear path misses its own frames by {diff}");
        // The training latents have unit variance per used dimension.
        let var: Vec<f32> = z
            .narrow(1, 0, 2)
            .var_dim(0, false, false)
            .try_into()
            .unwrap();
        assert!(var.iter().all(|&x| (x - 1.0).abs() < 1e-3), "{var:?}");
    }
    #[test]
    fn a_frozen_space_with_zero_output_layers_skips_its_networks_exactly() {
        let (mut space, _) = small_space();
        let (m, g) = random_frames(&space);
        let b = Tensor::randn([3, 3, 3], (Kind::Float, Device::Cpu)) * 0.1;
        space.init_linear(&space.rest_displacements(&g, &m));
        space.freeze();
        assert!(space.networks_idle(), "untrained output layers are zero");
        let fast = (
            space.encode(&g, &b, &m),
            space.canonical(&space.encode(&g, &b, &m)),
        );
        space.networks_idle = false;
        let slow = (
            space.encode(&g, &b, &m),
            space.canonical(&space.encode(&g, &b, &m)),
        );
        for (a, b) in [(&fast.0, &slow.0), (&fast.1, &slow.1)] {
            let diff = (a - b).abs().max().double_value(&[]);
            assert!(
                diff == 0.0,
                "skipping the networks changed a result by {diff}"
            );
        }
        let shape = super::super::MotionShape::for_space(&space.shape.encoder, 2);
        let motion = super::super::MotionEncoder::new(shape, &space, Device::Cpu);
        assert!(
            motion.residual_idle(),
            "the untrained residual's output layer is zero"
        );
        // A trained output layer is not skipped.
        tch::no_grad(|| {
            let _ = space.vs.variables()["enc_fc.bias"].get(0).fill_(0.1);
        });
        space.freeze();
        assert!(!space.networks_idle());
    }
}
