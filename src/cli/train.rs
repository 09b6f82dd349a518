//! `garmentbake train`: unsupervised PBNS training of a garment on a body and motion clips.

use crate::garment::{count_inside, Garment};
use crate::geometry::Topology;
use crate::io::gltf_body::read_body;
use crate::models::file;
use crate::motion::{load_clip, read_maps};
use crate::train::fabric::Fabric;
use crate::train::{Blowup, Inputs, Settings, Trainer};
use anyhow::{bail, Context, Result};
use serde_json::json;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Train a PBNS garment model: MLP over the pose → PSD blend shapes → linear blend skinning,
/// minimising a physical potential (stretch, bending, body collision, gravity, pinning), no
/// simulation data needed.
///
/// Poses are taken from the clips (retargeted onto the body), balanced (a frame is kept only if
/// it differs enough from every kept one in the joints that move the garment) and split 85/15
/// into train / validation. The model file (.safetensors) is self-contained: `garmentbake eval`
/// and `inspect` need nothing else. A checkpoint with the optimizer state is written next to it
/// every epoch (NAME.ckpt.safetensors); `--resume` continues from it.
#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub inputs: InputArgs,
    /// Epochs (passes over the training poses).
    #[arg(long, default_value_t = 1000)]
    pub epochs: usize,
    /// Output model (.safetensors).
    #[arg(long)]
    pub out: PathBuf,
    /// Continue from OUT's checkpoint (same inputs and settings) up to --epochs.
    #[arg(long)]
    pub resume: bool,
    /// Treat input warnings (garment inside the body, bad faces) as errors.
    #[arg(long)]
    pub strict: bool,
    /// Print one JSON object per epoch and a final summary instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Inputs and settings shared by `train` and `bench train`.
#[derive(clap::Args)]
pub struct InputArgs {
    /// Skinned body (glTF/glb); metres, Y-up.
    #[arg(long)]
    pub body: PathBuf,
    /// Garment mesh in the body's rest pose: OBJ, or USD with one Mesh prim (.usd/.usda/.usdc/.usdz,
    /// converted to metres, Y-up); sidecar NAME.toml: pinned vertices.
    #[arg(long)]
    pub garment: PathBuf,
    /// BVH clip(s) the training poses come from; repeat for several.
    #[arg(long = "motion", required = true)]
    pub motions: Vec<PathBuf>,
    /// Joint-name map(s) for the clips (TOML).
    #[arg(long = "map")]
    pub maps: Vec<PathBuf>,
    /// Fabric: a FABRIC.toml or a preset name (cotton, silk, denim, jersey).
    #[arg(long, default_value = "cotton")]
    pub config: String,
    /// Seed: same seed and inputs → byte-identical model.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// cpu, cuda or cuda:N.
    #[arg(long, default_value = "cpu")]
    pub device: String,
    /// Poses per optimisation step.
    #[arg(long, default_value_t = 16)]
    pub batch: usize,
    /// Initial Adam learning rate (cosine decay to a tenth).
    #[arg(long, default_value_t = 1e-3)]
    pub lr: f64,
    /// MLP width = number of PSD blend shapes.
    #[arg(long, default_value_t = 256)]
    pub width: usize,
    /// Skin influences per vertex (4 or 8), fixed at initialisation.
    #[arg(long, default_value_t = 4)]
    pub influences: usize,
    /// Keep the proximity blend weights instead of optimising them.
    #[arg(long)]
    pub fixed_weights: bool,
    /// Pose balancing threshold (radians, per rotation component of the garment's joints).
    #[arg(long, default_value_t = 0.15)]
    pub pose_threshold: f32,
    /// Extra training poses per balanced one, each taking every limb chain (legs, spine, neck and
    /// head, arms) from a different real frame: covers pose combinations the clips lack.
    #[arg(long, default_value_t = 0)]
    pub recombine: usize,
    /// Epochs between refreshes of the nearest-body-vertex candidates.
    #[arg(long, default_value_t = 2)]
    pub refresh_every: usize,
    /// How candidates are refreshed: trees (CPU k-d trees on a worker thread), device (brute
    /// force with cdist + topk on the training device), auto (device on CUDA, else trees).
    #[arg(long, default_value = "auto", value_parser = ["auto", "trees", "device"])]
    pub refresh: String,
    /// Candidate body vertices kept per garment vertex.
    #[arg(long, default_value_t = 6)]
    pub candidates: usize,
    /// Learning rate of the blend-weight logits relative to --lr.
    #[arg(long, default_value_t = 10.0)]
    pub weights_lr_scale: f64,
    /// Initial blend weights: copy the body's within this distance (metres) of it at rest and
    /// interpolate them smoothly over the garment beyond (a skirt's hanging part).
    #[arg(long, default_value_t = 0.02)]
    pub inpaint_beyond: f32,
    /// Copy the body's weights by proximity everywhere (no inpainting).
    #[arg(long)]
    pub no_inpaint: bool,
    /// Epochs between validation passes (exact metrics on the held-out poses).
    #[arg(long, default_value_t = 5)]
    pub validate_every: usize,
    /// CPU threads (torch and the nearest-neighbour queries).
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
}

impl InputArgs {
    /// Reads and checks everything; warnings go to stderr (errors with `strict`).
    pub fn load(&self, epochs: usize, strict: bool, quiet: bool) -> Result<(Inputs, Settings)> {
        // One torch thread trains while the k-d tree refresh runs on the other core(s): on two
        // shared cores this beats two torch threads, whose barriers stall when a core is busy.
        let others = self.threads.saturating_sub(1).max(1);
        set_threads(others, others);
        let body = read_body(&self.body)?;
        let garment = Garment::read(&self.garment)?;
        check_garment(&garment, &body, &self.garment, strict, quiet)?;
        let fabric = Fabric::load(&self.config)?;
        let maps = read_maps(&self.maps)?;
        let mut clips = Vec::new();
        let mut motion_names = Vec::new();
        for m in &self.motions {
            clips.push(load_clip(m, &maps, &body.skeleton, None)?.animation);
            motion_names.push(
                m.file_name()
                    .map_or(String::new(), |n| n.to_string_lossy().into_owned()),
            );
        }
        let device = parse_device(&self.device)?;
        let settings = Settings {
            epochs,
            batch: self.batch,
            learning_rate: self.lr,
            width: self.width,
            influences: self.influences,
            train_weights: !self.fixed_weights,
            seed: self.seed,
            pose_threshold: self.pose_threshold,
            recombine: self.recombine,
            refresh_every: self.refresh_every,
            dense_refresh: match self.refresh.as_str() {
                "device" => true,
                "trees" => false,
                _ => device.is_cuda(),
            },
            candidates: self.candidates.max(1),
            weights_lr_scale: self.weights_lr_scale,
            validate_every: self.validate_every,
            inpaint_beyond: (!self.no_inpaint).then_some(self.inpaint_beyond),
            device,
            ..Settings::default()
        };
        Ok((
            Inputs {
                body,
                garment,
                fabric,
                clips,
                motion_names,
            },
            settings,
        ))
    }
}

/// Thread budget: torch and rayon (nearest-neighbour queries, metrics) pools.
pub(crate) fn set_threads(torch: usize, rayon: usize) {
    tch::set_num_threads(torch.max(1) as i32);
    // Fails only if the pool already exists (a second call in tests): keep that one.
    let _ = rayon::ThreadPoolBuilder::new()
        .num_threads(rayon.max(1))
        .build_global();
}

pub(crate) fn parse_device(s: &str) -> Result<tch::Device> {
    let device = match s {
        "cpu" => tch::Device::Cpu,
        "cuda" => tch::Device::Cuda(0),
        _ => match s.strip_prefix("cuda:").and_then(|n| n.parse().ok()) {
            Some(n) => tch::Device::Cuda(n),
            None => bail!("--device {s}: expected cpu, cuda or cuda:N"),
        },
    };
    if device != tch::Device::Cpu && !tch::Cuda::is_available() {
        bail!(
            "--device {s}: CUDA is not available to this build (libtorch without CUDA, or no GPU)"
        );
    }
    Ok(device)
}

/// Vertices inside the body at rest, non-manifold edges and degenerate faces.
fn check_garment(
    garment: &Garment,
    body: &crate::io::gltf_body::Body,
    path: &Path,
    strict: bool,
    quiet: bool,
) -> Result<()> {
    let mesh = &garment.mesh;
    let n = mesh.vertex_count();
    let mut problems = Vec::new();
    let inside = count_inside(&mesh.positions, &body.mesh.positions, &body.normals)?;
    if inside * 20 > n {
        problems.push(format!(
            "{inside} of {n} vertices ({:.1} %) are inside the body at rest (more than 5 %): fit the garment first (push it out of the body)",
            100.0 * inside as f64 / n as f64
        ));
    }
    let topo = Topology::new(mesh);
    if !topo.non_manifold_edges.is_empty() {
        let [a, b] = topo.non_manifold_edges[0];
        problems.push(format!(
            "{} non-manifold edges (3 or more faces; first: vertices {a}-{b}): they get no bending term",
            topo.non_manifold_edges.len()
        ));
    }
    let degenerate = mesh.degenerate_faces(1e-12);
    if !degenerate.is_empty() {
        problems.push(format!(
            "{} degenerate (zero-area) faces (first: face {}): their normals are undefined",
            degenerate.len(),
            degenerate[0]
        ));
    }
    for p in &problems {
        if strict {
            bail!("{}: {p} (--strict)", path.display());
        }
        if !quiet {
            eprintln!("warning: {}: {p}", path.display());
        }
    }
    Ok(())
}

/// `runs/skirt.safetensors` → `runs/skirt.ckpt.safetensors`.
pub fn checkpoint_path(out: &Path) -> PathBuf {
    let stem = out
        .file_stem()
        .map_or("model".into(), |s| s.to_string_lossy().into_owned());
    out.with_file_name(format!("{stem}.ckpt.safetensors"))
}

pub fn run(args: Args) -> Result<i32> {
    let started = Instant::now();
    let (inputs, settings) = args.inputs.load(args.epochs, args.strict, args.json)?;
    if let Some(dir) = args.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    let mut trainer = Trainer::new(inputs, settings)?;
    let ckpt = checkpoint_path(&args.out);
    if args.resume {
        let saved = file::load(&ckpt, trainer.settings.device)
            .with_context(|| "--resume needs the checkpoint of an earlier run")?;
        trainer.resume(saved, &ckpt)?;
    }
    let p = &trainer.poses;
    if !args.json {
        let names: Vec<&str> = p
            .joints
            .iter()
            .map(|&j| trainer.file.body.skeleton.joint_names[j].as_str())
            .collect();
        let recombined = p.train.iter().filter(|x| x.recombined).count();
        println!(
            "poses: {} balanced of {} frames ({} train + {recombined} recombined, {} validation; threshold {} rad on {})",
            p.train.len() - recombined + p.validation.len(),
            p.frames_seen,
            p.train.len() - recombined,
            p.validation.len(),
            trainer.settings.pose_threshold,
            names.join(", ")
        );
        let t = &trainer.file.info.training;
        if t.inpainted > 0 {
            println!(
                "initial weights: {} of {} vertices hang farther than {} m from the body: inpainted",
                t.inpainted,
                trainer.model().shape.vertices,
                t.inpaint_beyond.unwrap_or_default()
            );
        }
        if trainer.epoch() > 0 {
            println!("resuming after epoch {}", trainer.epoch());
        }
    }
    let bar = super::progress(
        (args.epochs.saturating_sub(trainer.epoch())) as u64,
        "epochs",
        args.json,
    );
    while trainer.epoch() < args.epochs {
        let epoch_start = Instant::now();
        let record = match trainer.run_epoch(|_, _| {}) {
            Ok(r) => r,
            Err(blowup) => {
                bar.abandon();
                return Err(blown_up(blowup, trainer.epoch(), &ckpt));
            }
        };
        let save_start = Instant::now();
        trainer.save(&ckpt, true)?;
        let save_s = save_start.elapsed().as_secs_f64();
        let t = &record.train;
        bar.set_message(format!(
            "edge {:.2} mm  bend {:.4}  collided {:.2} %  gravity {:.3} J",
            t.edge_mm, t.bend, t.collided_pct, t.gravity_j
        ));
        bar.inc(1);
        if args.json {
            println!(
                "{}",
                json!({ "epoch": record.epoch, "loss": record.loss, "terms": terms_json(&record.terms),
                        "train": record.train, "validation": record.validation,
                        "learning_rate": trainer.learning_rate(record.epoch - 1),
                        "seconds": epoch_start.elapsed().as_secs_f64(), "checkpoint_seconds": save_s })
            );
        }
    }
    bar.finish_and_clear();
    trainer.save(&args.out, false)?;
    let seconds = started.elapsed().as_secs_f64();
    let last = trainer.file.info.history.last().cloned();
    let split = split_json(&trainer.times);
    if args.json {
        println!(
            "{}",
            json!({ "out": args.out.display().to_string(), "checkpoint": ckpt.display().to_string(),
                    "epochs": trainer.epoch(), "seconds": seconds, "last": last, "phases": split })
        );
    } else {
        if let Some(r) = last {
            let (t, v) = (&r.train, &r.validation);
            println!(
                "epoch {}: train edge {:.3} mm, bend {:.4}, collided {:.2} %, gravity {:.4} J",
                r.epoch, t.edge_mm, t.bend, t.collided_pct, t.gravity_j
            );
            if let Some(v) = v {
                println!(
                    "validation ({} poses): edge {:.3} mm, bend {:.4}, collided {:.2} %, gravity {:.4} J",
                    trainer.poses.validation.len(), v.edge_mm, v.bend, v.collided_pct, v.gravity_j
                );
            }
        }
        println!("{}", split_line(&trainer.times));
        println!("wrote {} ({:.0} s)", args.out.display(), seconds);
    }
    Ok(0)
}

fn blown_up(b: Blowup, epochs_done: usize, ckpt: &Path) -> anyhow::Error {
    let kept = if epochs_done > 0 {
        format!(
            "the checkpoint of epoch {epochs_done} is kept: {}",
            ckpt.display()
        )
    } else {
        "no epoch finished, so there is no checkpoint".to_string()
    };
    anyhow::anyhow!("{b}; {kept} (lower --lr or the fabric's λ for that term, then --resume)")
}

fn terms_json(t: &[f64; 5]) -> serde_json::Value {
    json!({ "edge": t[0], "bend": t[1], "collision": t[2], "gravity": t[3], "pin": t[4] })
}

/// Share of the step time per phase (refreshes counted as nearest neighbour).
pub(crate) fn split_json(t: &crate::train::PhaseTimes) -> serde_json::Value {
    let total = t.total().as_secs_f64().max(1e-12);
    let pct = |d: std::time::Duration| 100.0 * d.as_secs_f64() / total;
    json!({
        "seconds": total, "steps": t.steps, "poses": t.poses,
        "poses_per_s": t.poses as f64 / total,
        "forward_pct": pct(t.forward), "losses_pct": pct(t.losses),
        "nearest_pct": pct(t.nearest + t.refresh), "nearest_refresh_pct": pct(t.refresh),
        "backward_pct": pct(t.backward), "validation_seconds": t.validation.as_secs_f64(),
    })
}

pub(crate) fn split_line(t: &crate::train::PhaseTimes) -> String {
    let total = t.total().as_secs_f64().max(1e-12);
    let pct = |d: std::time::Duration| 100.0 * d.as_secs_f64() / total;
    format!(
        "time split: forward {:.1} %, losses {:.1} %, nearest neighbour {:.1} % (refresh {:.1} %), backward+Adam {:.1} %; {:.0} poses/s",
        pct(t.forward),
        pct(t.losses),
        pct(t.nearest + t.refresh),
        pct(t.refresh),
        pct(t.backward),
        t.poses as f64 / total
    )
}
