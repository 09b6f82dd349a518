//! Training the dynamic model's generative space (stage `space`) on simulated sequences:
//! `L = L_rec + L_rand + λ1·L_SDF + λ2·L_reg` (λ1 = 100, λ2 = 0.001) with
//! `L_rec = |G − G*|₁ + |ΔG − ΔG*|₁` (uniform Laplacian), `L_rand` the edge-length L1 of garments
//! decoded from random latents against the rest garment, `L_SDF` a hinge on the exact signed
//! distance to the rest body of the reconstructed canonical garments (floored at the target's own
//! depth), `L_reg = |mean z² − 1|`.
//! L1 terms are means over vertices and coordinates (metres).

use super::adam::Adam;
use super::{Blowup, Training};
use crate::body::Body;
use crate::fabric::Fabric;
use crate::garment::Garment;
use crate::geometry::sdf_grid::SdfGrid;
use crate::geometry::Frames;
use crate::geometry::{SurfaceIndex, TriMesh};
use crate::metrics::deviation::Deviation;
use crate::models::dynamic::space::Consts;
use crate::models::dynamic::{
    anchors::PARTS, BodyAnchors, BodyFrames, Dynamic, MeshEdges, MeshLaplacian, Space, SpaceShape,
    UvRaster,
};
use crate::models::file::{
    self, BodyInfo, DynamicEpoch, DynamicInfo, DynamicTraining, GarmentInfo, KindInfo, ModelFile,
    ModelInfo, SpaceTerms, FORMAT, VERSION,
};
use crate::models::Model;
use crate::rig::{weights, SkelAnimation};
use anyhow::{bail, Result};
use std::path::Path;
use tch::{Device, Kind, Tensor};

/// One simulated clip: its motion and the garment at each frame.
pub struct Sequence {
    pub name: String,
    pub clip: SkelAnimation,
    pub garment: Frames,
}

impl Sequence {
    /// A clip (`motion`, retargeted onto `body` at `fps`) and its simulation (`sim`, a point
    /// cache of `vertices` points per frame, no longer than the clip), named by the clip's file.
    pub fn load(
        motion: &Path,
        sim: &Path,
        maps: &crate::motion::ClipReader,
        body: &crate::body::Body,
        fps: Option<f32>,
        vertices: usize,
    ) -> Result<Sequence> {
        let clip = crate::motion::load_clip(motion, maps, body, fps)?.animation;
        let garment = crate::io::point_cache::read_pc2(sim, vertices, clip.fps)?;
        if garment.len() > clip.frame_count() {
            bail!(
                "{}: {} frames, but {} has {} at {} fps (simulated at another --fps?)",
                sim.display(),
                garment.len(),
                motion.display(),
                clip.frame_count(),
                clip.fps
            );
        }
        Ok(Sequence {
            name: motion
                .file_name()
                .map_or(String::new(), |n| n.to_string_lossy().into_owned()),
            clip,
            garment,
        })
    }

    /// The clip's pose at each simulated frame.
    pub fn poses(&self) -> Vec<Vec<crate::rig::JointTransform>> {
        (0..self.garment.len())
            .map(|f| self.clip.local_pose(f))
            .collect()
    }
}

#[derive(Clone, Debug)]
pub struct Settings {
    pub shape: SpaceShape,
    pub epochs: usize,
    pub batch: usize,
    pub learning_rate: f64,
    pub seed: u64,
    pub device: Device,
    /// Anchors are sampled on the body within this distance of the garment at rest (metres).
    pub anchor_reach: f32,
    /// Initial kernel radius of the anchor skinning, every part (metres).
    pub kernel_radius: f64,
    /// Random latents decoded per step for `L_rand` and `L_SDF`.
    pub random: usize,
    /// ε of the SDF hinge (metres).
    pub sdf_margin: f32,
}

pub const LAMBDA_SDF: f64 = 100.0;
pub const LAMBDA_REG: f64 = 0.001;
/// Learning-rate factor of the linear path (see `step`).
const LINEAR_LR: f64 = 0.001;
/// SDF grid: node spacing and padding around the garment (metres).
const SDF_SPACING: f32 = 0.008;
const SDF_PAD: f32 = 0.08;

impl Settings {
    pub fn new(shape: SpaceShape) -> Settings {
        Settings {
            shape,
            epochs: 30,
            batch: 4,
            learning_rate: 3e-4,
            seed: 0,
            device: Device::Cpu,
            anchor_reach: 0.25,
            kernel_radius: crate::models::dynamic::space::RADIUS0,
            random: 2,
            sdf_margin: 0.003,
        }
    }
}

/// Frames as tensors: the garment `[F, V, 3]` and the body at each frame, clips one after
/// another (`clip_starts` gives each clip's first frame).
pub struct FrameData {
    pub garment: Tensor,
    pub body: BodyFrames,
    pub clip_starts: Vec<usize>,
}

impl FrameData {
    pub fn new(
        body: &Body,
        anchors: &BodyAnchors,
        sequences: &[Sequence],
        device: Device,
    ) -> FrameData {
        let (mut g, mut parts, mut clip_starts) = (Vec::new(), Vec::new(), Vec::new());
        let mut frames = 0;
        for s in sequences {
            clip_starts.push(frames);
            frames += s.garment.len();
            g.extend(s.garment.iter().flatten().flatten().copied());
            parts.push(BodyFrames::new(body, anchors, &s.poses(), device));
        }
        FrameData {
            garment: Tensor::from_slice(&g)
                .reshape([frames as i64, -1, 3])
                .to_device(device),
            body: BodyFrames::cat(&parts),
            clip_starts,
        }
    }

    pub fn len(&self) -> usize {
        self.garment.size()[0] as usize
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Indices of frames `start..start + n`.
    pub fn range(&self, start: usize, n: usize) -> Tensor {
        Tensor::arange_start(
            start as i64,
            (start + n) as i64,
            (Kind::Int64, self.garment.device()),
        )
    }

    pub fn batch(&self, idx: &Tensor) -> (Tensor, Tensor, Tensor) {
        (
            self.garment.index_select(0, idx),
            self.body.anchors.index_select(0, idx),
            self.body.transforms.index_select(0, idx),
        )
    }
}

/// Mesh operators for the losses: uniform Laplacian, edges and their rest lengths.
struct MeshOps {
    laplacian: MeshLaplacian,
    edges: MeshEdges,
    rest_lengths: Tensor,
}

impl MeshOps {
    fn new(mesh: &TriMesh, device: Device) -> MeshOps {
        let rest = Tensor::from_slice(
            &mesh
                .positions
                .iter()
                .flatten()
                .copied()
                .collect::<Vec<f32>>(),
        )
        .reshape([-1, 3])
        .to_device(device);
        let edges = MeshEdges::new(&mesh.triangles, device);
        let rest_lengths = edges.lengths(&rest.unsqueeze(0)).squeeze_dim(0);
        MeshOps {
            laplacian: MeshLaplacian::new(&mesh.triangles, mesh.vertex_count(), device),
            edges,
            rest_lengths,
        }
    }

    fn laplacian(&self, x: &Tensor) -> Tensor {
        self.laplacian.of(x)
    }
}

/// The rest body's exact signed distance as a `[1, 1, D, H, W]` volume for trilinear sampling.
struct Sdf {
    volume: Tensor,
    lo: Tensor,
    extent: Tensor,
}

impl Sdf {
    fn new(body: &Body, garment: &TriMesh, device: Device) -> Sdf {
        let surface = SurfaceIndex::new(&body.mesh().positions, &body.mesh().triangles);
        let (lo, hi) = bounds(&garment.positions);
        let grid = SdfGrid::new(&surface, lo, hi, SDF_PAD, SDF_SPACING);
        let [nx, ny, nz] = grid.dims.map(|d| d as i64);
        let extent: Vec<f32> = grid
            .dims
            .iter()
            .map(|&d| (d - 1) as f32 * grid.spacing)
            .collect();
        Sdf {
            volume: Tensor::from_slice(&grid.values)
                .reshape([1, 1, nz, ny, nx])
                .to_device(device),
            lo: Tensor::from_slice(&grid.lo).to_device(device),
            extent: Tensor::from_slice(&extent).to_device(device),
        }
    }

    /// Signed distance `[B, V]` of points `[B, V, 3]`.
    fn at(&self, p: &Tensor) -> Tensor {
        let (b, v) = (p.size()[0], p.size()[1]);
        let g = ((p - &self.lo) / &self.extent * 2.0 - 1.0).reshape([1, b * v, 1, 1, 3]);
        self.volume.grid_sampler(&g, 0, 1, true).reshape([b, v])
    }
}

fn bounds(points: &[[f32; 3]]) -> ([f32; 3], [f32; 3]) {
    points
        .iter()
        .fold(([f32::MAX; 3], [f32::MIN; 3]), |(lo, hi), p| {
            (
                std::array::from_fn(|k| lo[k].min(p[k])),
                std::array::from_fn(|k| hi[k].max(p[k])),
            )
        })
}

/// The generative-space trainer.
pub struct SpaceTrainer {
    pub file: ModelFile,
    pub data: FrameData,
    settings: Settings,
    adam: Adam,
    ops: MeshOps,
    /// Built at the first network step: the exact distance grid costs seconds of winding
    /// numbers, and the linear path (`--epochs 0`, the documented recipe) never reads it.
    sdf: std::cell::OnceCell<Sdf>,
}

/// Per-vertex distances of predictions `[F, V, 3]` from the truth, in mm.
pub fn deviation(pred: &Tensor, truth: &Tensor) -> Deviation {
    let d = (pred - truth)
        .square()
        .sum_dim_intlist(2, false, Kind::Float)
        .sqrt()
        * 1e3;
    let per_frame: Vec<Vec<f32>> = d.try_into().unwrap_or_default();
    Deviation::of(&per_frame)
}

impl SpaceTrainer {
    pub fn new(
        body: Body,
        garment: Garment,
        fabric: Fabric,
        sequences: &[Sequence],
        settings: Settings,
    ) -> Result<SpaceTrainer> {
        if sequences.is_empty() || settings.batch == 0 {
            bail!("nothing to train on: give --motion clips with their --sim caches, and a positive --batch");
        }
        tch::manual_seed(settings.seed as i64);
        let device = settings.device;
        let raster = UvRaster::new(&garment.mesh, settings.shape.map, &garment.name)?;
        let anchors = BodyAnchors::sample(
            &body,
            &garment.mesh.positions,
            settings.shape.anchors,
            settings.anchor_reach,
        )?;
        let consts = Consts::new(&garment.mesh, &raster, &anchors, device);
        let mut space = Space::new(settings.shape.clone(), consts, device)?;
        space.set_radius(settings.kernel_radius)?;
        let data = FrameData::new(&body, &anchors, sequences, device);
        space.init_linear(&tch::no_grad(|| {
            crate::models::predict_chunks(data.len(), |s, n| {
                let (g, _, m) = data.batch(&data.range(s, n));
                space.rest_displacements(&g, &m)
            })
        }));
        let ops = MeshOps::new(&garment.mesh, device);
        let index = crate::geometry::PointIndex::new(&body.mesh().positions)?;
        let lbs = weights::smooth_garment_skin(
            &garment.mesh,
            &body.skin,
            body.skeleton.joint_count(),
            &index,
        );
        let params = space.parameters();
        let adam = Adam::new(
            &params
                .iter()
                .map(|(n, t)| (n.clone(), t))
                .collect::<Vec<_>>(),
        );
        let pinned = fabric
            .pinned
            .clone()
            .unwrap_or_else(|| garment.sidecar.pinned.clone());
        let info = ModelInfo {
            format: FORMAT.into(),
            version: VERSION,
            // Stamped by `file::save` with the build that writes it.
            written_by: None,
            skeleton: body.skeleton.to_plain(),
            garment: GarmentInfo::of(&garment, &pinned),
            body: BodyInfo::of(&body),
            fabric,
            model: KindInfo::Dynamic(Box::new(DynamicInfo {
                shape: settings.shape.clone(),
                anchors: anchors.vertices.clone(),
                anchor_parts: anchors.parts.clone(),
                parts: PARTS.iter().map(|p| p.to_string()).collect(),
                radii: space.radii(),
                fps: sequences[0].clip.fps,
                training: DynamicTraining {
                    stages: vec!["space".into()],
                    seed: settings.seed,
                    epochs: 0,
                    batch: settings.batch,
                    learning_rate: settings.learning_rate,
                    motions: sequences
                        .iter()
                        .map(|s| format!("{} ({} frames)", s.name, s.garment.len()))
                        .collect(),
                    frames: data.len(),
                },
                history: Vec::new(),
                motion: None,
            })),
        };
        let file = ModelFile {
            model: Model::Dynamic(Box::new(Dynamic {
                space,
                motion: None,
            })),
            info,
            lbs,
            garment: garment.mesh,
            body,
            extra: Vec::new(),
            coverage: None,
        };
        Ok(SpaceTrainer {
            file,
            data,
            settings,
            adam,
            ops,
            sdf: std::cell::OnceCell::new(),
        })
    }

    pub fn space(&self) -> &Space {
        match &self.file.model {
            Model::Dynamic(d) => &d.space,
            Model::Pbns(_) => unreachable!("a dynamic trainer holds a dynamic model"),
        }
    }

    fn info_mut(&mut self) -> &mut DynamicInfo {
        match &mut self.file.info.model {
            KindInfo::Dynamic(d) => d,
            KindInfo::Pbns(_) => unreachable!("a dynamic trainer holds a dynamic model"),
        }
    }

    pub fn info(&self) -> &DynamicInfo {
        match &self.file.info.model {
            KindInfo::Dynamic(d) => d,
            KindInfo::Pbns(_) => unreachable!("a dynamic trainer holds a dynamic model"),
        }
    }

    fn sdf(&self) -> &Sdf {
        self.sdf
            .get_or_init(|| Sdf::new(&self.file.body, &self.file.garment, self.settings.device))
    }

    /// Cosine decay from the learning rate to a tenth of it.
    fn learning_rate(&self, epoch: usize) -> f64 {
        super::cosine_rate(self.settings.learning_rate, epoch, self.settings.epochs)
    }

    /// One optimisation step on frames `idx`: the weighted terms and the batch's mean error (m).
    fn step(&mut self, idx: &Tensor, lr: f64) -> (SpaceTerms, f64) {
        let (g, b, m) = self.data.batch(idx);
        let space = self.space();
        let (pred, z, canonical) = space.reconstruct(&g, &b, &m);
        let positions = (&pred - &g).abs().mean(Kind::Float);
        let laplacian = (self.ops.laplacian(&pred) - self.ops.laplacian(&g))
            .abs()
            .mean(Kind::Float);
        let latent = (z.square().mean_dim(1, false, Kind::Float) - 1.0)
            .abs()
            .mean(Kind::Float)
            * LAMBDA_REG;
        let zr = Tensor::randn(
            [self.settings.random as i64, space.shape.latent as i64],
            (Kind::Float, self.settings.device),
        );
        let random = space.canonical(&zr);
        let random_edges = (self.ops.edges.lengths(&random) - &self.ops.rest_lengths)
            .abs()
            .mean(Kind::Float);
        // The hinge's floor is where the data already is: an unskinned simulated frame can lie
        // inside the rest body (cloth pressed between moving limbs), and pushing its
        // reconstruction out would fight L_rec. Not applied to random latents: held to the mean
        // garment's floor it dominated the loss and undid the reconstructions (skirt on 131_01,
        // 8.1 → 32 mm training error in 3 epochs).
        let eps = self.settings.sdf_margin as f64;
        let floor = tch::no_grad(|| {
            self.sdf()
                .at(&space.displaced(&space.rest_displacements(&g, &m)))
        });
        let sdf = (floor.clamp_max(eps) - self.sdf().at(&canonical))
            .relu()
            .mean(Kind::Float)
            * LAMBDA_SDF;
        let loss = &positions + &laplacian + &random_edges + &sdf + &latent;
        loss.backward();
        let err = tch::no_grad(|| {
            (&pred - &g)
                .square()
                .sum_dim_intlist(2, false, Kind::Float)
                .sqrt()
                .mean(Kind::Float)
                .double_value(&[])
        });
        let (names, params): (Vec<String>, Vec<Tensor>) = space.parameters().into_iter().unzip();
        // Adam moves every entry by about the learning rate: the linear path's entries are a
        // thousand times smaller than the networks' weights, so its steps are scaled to match.
        let lrs: Vec<f64> = names
            .iter()
            .map(|n| {
                if n.starts_with("linear_") {
                    lr * LINEAR_LR
                } else {
                    lr
                }
            })
            .collect();
        self.adam.update(&params, &lrs);
        let v = |t: &Tensor| t.double_value(&[]);
        (
            SpaceTerms {
                positions: v(&positions),
                laplacian: v(&laplacian),
                random_edges: v(&random_edges),
                sdf: v(&sdf),
                latent: v(&latent),
            },
            err,
        )
    }

    /// Reconstructions of every frame of `data` (no gradients), `[F, V, 3]`.
    pub fn reconstruct(space: &Space, data: &FrameData) -> Tensor {
        crate::models::predict_chunks(data.len(), |s, n| {
            let (g, b, m) = data.batch(&data.range(s, n));
            space.reconstruct(&g, &b, &m).0
        })
    }

    /// Per-vertex L2 error of the space's reconstructions of `data`.
    pub fn measure(space: &Space, data: &FrameData) -> Deviation {
        deviation(&Self::reconstruct(space, data), &data.garment)
    }

    fn adam_params(&self) -> Vec<(String, Tensor)> {
        self.space().parameters()
    }
}

impl Training for SpaceTrainer {
    type Record = DynamicEpoch;

    fn epochs_done(&self) -> usize {
        self.info().history.len()
    }

    fn run_epoch(&mut self) -> Result<DynamicEpoch, Blowup> {
        let epoch = self.epochs_done();
        // Each epoch's randomness from (seed, epoch): a resumed run draws the same.
        tch::manual_seed(
            (self.settings.seed as i64)
                .wrapping_mul(1_000_003)
                .wrapping_add(epoch as i64),
        );
        let lr = self.learning_rate(epoch);
        let n = self.data.len() as i64;
        let order = Tensor::randperm(n, (Kind::Int64, self.settings.device));
        let batch = self.settings.batch as i64;
        let mut sum = SpaceTerms::default();
        let (mut err, mut steps) = (0.0, 0usize);
        for (step, start) in (0..n).step_by(batch as usize).enumerate() {
            let idx = order.narrow(0, start, batch.min(n - start));
            let (t, e) = self.step(&idx, lr);
            Blowup::check(
                &[
                    ("positions", t.positions),
                    ("laplacian", t.laplacian),
                    ("random edges", t.random_edges),
                    ("sdf", t.sdf),
                    ("latent", t.latent),
                ],
                epoch,
                step,
            )?;
            sum.positions += t.positions;
            sum.laplacian += t.laplacian;
            sum.random_edges += t.random_edges;
            sum.sdf += t.sdf;
            sum.latent += t.latent;
            err += e;
            steps += 1;
        }
        let k = steps.max(1) as f64;
        let terms = SpaceTerms {
            positions: sum.positions / k,
            laplacian: sum.laplacian / k,
            random_edges: sum.random_edges / k,
            sdf: sum.sdf / k,
            latent: sum.latent / k,
        };
        let record = DynamicEpoch {
            epoch: epoch + 1,
            loss: terms.total(),
            terms,
            learning_rate: lr,
            train_mean_mm: 1e3 * err / k,
        };
        let radii = self.space().radii();
        let info = self.info_mut();
        info.history.push(record.clone());
        info.training.epochs = info.history.len();
        info.radii = radii;
        Ok(record)
    }

    fn save(&mut self, path: &Path, checkpoint: bool) -> Result<()> {
        self.file.extra = if checkpoint {
            let p = self.adam_params();
            self.adam
                .state(&p.iter().map(|(n, t)| (n.clone(), t)).collect::<Vec<_>>())
        } else {
            Vec::new()
        };
        file::save(path, &self.file)
    }

    fn resume(&mut self, path: &Path) -> Result<()> {
        let checkpoint = file::load(path, self.settings.device)?;
        let theirs = checkpoint.info.dynamic()?;
        let mine = self.info();
        if theirs.shape != mine.shape
            || theirs.anchors != mine.anchors
            || theirs.training.seed != mine.training.seed
            || checkpoint.info.garment.rest_hash != self.file.info.garment.rest_hash
            || theirs.training.motions != mine.training.motions
        {
            bail!("{}: checkpoint was made with other inputs or settings (garment, clips, preset, seed); start without --resume", path.display());
        }
        let history = theirs.history.clone();
        let stored = checkpoint.dynamic()?.space.parameters();
        let Model::Dynamic(dynamic) = &mut self.file.model else {
            unreachable!("a dynamic trainer holds a dynamic model")
        };
        dynamic.space.load_parameters(&stored)?;
        let p = self.adam_params();
        self.adam.restore(
            &p.iter().map(|(n, t)| (n.clone(), t)).collect::<Vec<_>>(),
            &checkpoint.extra,
        )?;
        let info = self.info_mut();
        info.training.epochs = history.len();
        info.history = history;
        Ok(())
    }

    fn describe(r: &DynamicEpoch) -> String {
        format!("loss {:.4} mean {:.1} mm", r.loss, r.train_mean_mm)
    }
}
