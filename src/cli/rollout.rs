//! `garmentbake rollout`: a dynamic model played over clips frame by frame, written as a point
//! cache (PC2, MDD, USD) or a compressed glTF, with its errors against reference simulations.

use super::args::{CollisionFixArgs, ComputeArgs, OutputArgs};
use super::Execute;
use crate::bake::sequence::{bake_sequence, SequenceReport};
use crate::eval::lbs_frames;
use crate::geometry::PointIndex;
use crate::io::point_cache::{read_pc2, write_cache, write_caches};
use crate::metrics::versus::{distances_mm, Ensemble, Simulations, Versus};
use crate::motion::{chain, load_clip, read_maps};
use crate::rig::weights::smooth_garment_skin;
use crate::rig::SkelAnimation;
use crate::rollout::timing::Timing;
use crate::rollout::{for_model, Init, Settings};
use crate::simulate::stats::{self, FrameStats, Series, Summary};
use crate::validate::{check_file, replay::Reference, Validation};
use anyhow::{bail, Context, Result};
use exporters::FileKind;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Play a dynamic garment model (`train-dynamic --stage dynamic`) over motion clips.
///
/// Each frame's garment is predicted from the previous frames' garment and the body's motion,
/// then becomes the next frame's history. Clips are resampled to the rate the model was trained
/// at (recorded in the output). Several --motion clips play one after another as one roll-out:
/// each later clip starts where the previous one ended, its first frames blended from the last
/// pose (--fade). Per frame, the decoded garment's edges are pulled back within 2 % of their
/// rest lengths (the strain limit), and a garment that crosses the body is pushed out, the edges
/// around the pushed vertices kept (the collision fix; --collision-solver paper: the paper's
/// Adam fit of a UV displacement map). --no-collision-fix --strain-iterations 0 shows the
/// network alone.
///
/// Writes the garment per frame as a point cache (.pc2, Blender's Mesh Cache reads it; .usda/
/// .usdc/.usd: time-sampled points). --reference SIM.pc2 (a `simulate` cache of the same clip)
/// measures the roll-out against it: after one step, over the first 50 frames, over the clip.
/// Several --reference simulations of the clip (e.g. `simulate --blend 1.1`, a lead-in 0.1 s
/// longer) also measure how far apart they are: a loose garment is chaotic, and a roll-out as
/// far from them as they are from each other is as close as a re-run of the simulator.
#[derive(clap::Args)]
pub struct Args {
    /// Dynamic model with its motion stage (.safetensors).
    #[arg(long)]
    pub model: PathBuf,
    /// BVH clip(s), played one after another.
    #[arg(long = "motion", required = true)]
    pub motions: Vec<PathBuf>,
    /// Joint-name map(s) (TOML) for the clips.
    #[arg(long = "map")]
    pub maps: Vec<PathBuf>,
    /// Where the roll-out starts: `rest` (the rest garment on the first pose, at rest) or a point
    /// cache whose first frame is the starting garment (e.g. the clip's simulation).
    #[arg(long, default_value = "rest")]
    pub init: String,
    /// Play only the first N frames (of the clips in a row).
    #[arg(long)]
    pub frames: Option<usize>,
    /// Frames over which a later clip blends in from the previous clip's last pose.
    #[arg(long, default_value_t = 15)]
    pub fade: usize,
    /// Output: a point cache (.pc2, .mdd, .usda/.usdc, .abc: time-sampled points), or a compressed
    /// glTF (.glb/.gltf: the garment skinned to the body's skeleton plus blend shapes from the
    /// singular directions of its un-skinned residual over the roll-out, their weights animated;
    /// plays in any glTF viewer).
    #[arg(long)]
    pub out: PathBuf,
    /// glTF output: keep the fewest blend shapes whose replay stays within this distance (mm) of
    /// every rolled-out vertex.
    #[arg(long, default_value_t = 1.0, value_parser = super::args::positive::<f32>())]
    pub tolerance_mm: f32,
    /// glTF output: store the blend shapes as 32-bit floats instead of 16-bit integers. By
    /// default they are quantized (KHR_mesh_quantization: half the bytes, the rounding counted
    /// in --tolerance-mm), which three.js and Blender read (both checked) as do most engines'
    /// glTF loaders; this flag is for readers without that extension.
    #[arg(long)]
    pub float_targets: bool,
    /// Also write the posed body per frame as a point cache.
    #[arg(long)]
    pub body_out: Option<PathBuf>,
    /// USD or Alembic --out: put the posed body in the same stage / archive, beside the garment
    /// (`/NAME/garment`, `/NAME/body`, one timeline), so the shot opens in usdview or a DCC with
    /// the body it was rolled out on.
    #[arg(long)]
    pub with_body: bool,
    /// A simulated cache of the same (single) clip to measure the roll-out against (and plain
    /// LBS beside it). Repeat for several simulations of the clip: the roll-out against each and
    /// against their mean, and the simulations against each other (their own spread); the
    /// first is the one --restart-every and --view use.
    #[arg(long = "reference", value_name = "SIM.pc2")]
    pub references: Vec<PathBuf>,
    /// With --reference: also roll the model out afresh every N frames of the clip, each time
    /// from the reference's own state there (its last three frames: the garment starts moving
    /// as simulated), for N frames, and report the mean error of these restarts. A long
    /// roll-out of a loose garment leaves any one simulation by chaos alone (two simulations of
    /// a clip whose lead-ins differ by 0.1 s can end centimetres apart); the restarts measure the
    /// model's dynamics over N frames at every part of the clip instead (the paper's
    /// "rollout-50", taken all along the clip).
    #[arg(long, value_name = "N", requires = "references")]
    pub restart_every: Option<usize>,
    /// Also write plain linear blend skinning of the rest garment (the fixed skin of the glTF
    /// output: proximity weights, no dynamics) per frame as a point cache, the baseline to
    /// compare with (e.g. `preview --side-by-side`).
    #[arg(long, value_name = "LBS.pc2")]
    pub lbs_out: Option<PathBuf>,
    /// Also write a page that plays the roll-out on the body in a browser (see `view`); with
    /// --reference, the simulation beside it and error colours against it.
    #[arg(long, value_name = "PAGE.html")]
    pub view: Option<PathBuf>,
    /// Check what was written as `garmentbake validate` does: its structure, and that it plays
    /// the roll-out just computed within --tolerance-mm at every frame (a glTF evaluated as the
    /// spec says, a point cache read back); exit 1 when it fails.
    #[arg(long)]
    pub validate: bool,
    /// Skip the per-frame collision fix.
    #[arg(long)]
    pub no_collision_fix: bool,
    #[command(flatten)]
    pub collision: CollisionFixArgs,
    #[command(flatten)]
    pub compute: ComputeArgs,
    #[command(flatten)]
    pub output: OutputArgs,
}

/// Several simulations of the clip (two or more --reference).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct References {
    pub paths: Vec<PathBuf>,
    /// Every pair of simulations against each other, averaged: the simulator's own spread.
    pub spread: Versus,
    /// Each simulation against the mean garment of the others, averaged: how well re-running
    /// the simulator predicts a run it did not start from.
    pub from_the_others: Versus,
    /// The roll-out, and plain LBS, against each simulation and against their mean.
    pub rollout: Ensemble,
    pub lbs: Ensemble,
}

/// Roll-outs restarted from the reference every `frames` frames, `frames` long.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Restarts {
    pub frames: usize,
    /// Each restart's first frame (of the clip) and its error against the reference.
    pub each: Vec<(usize, Versus)>,
    /// Means over the restarts: after one step, and over each restart's frames.
    pub one_step_mm: f64,
    pub mean_mm: f64,
    /// The mean error `k` frames after a restart, k = 1 … `frames`: how fast the model leaves
    /// the simulated state.
    pub by_step_mm: Vec<f64>,
}

impl Restarts {
    /// From each restart's first frame, its error and its error per frame (frame 0 first).
    fn of(frames: usize, each: Vec<(usize, Versus, Vec<f64>)>) -> Restarts {
        let n = each.len().max(1) as f64;
        let by_step_mm = (1..=frames)
            .map(|k| each.iter().map(|e| e.2[k]).sum::<f64>() / n)
            .collect();
        Restarts {
            frames,
            one_step_mm: each.iter().map(|e| e.1.one_step_mm).sum::<f64>() / n,
            mean_mm: each.iter().map(|e| e.1.clip_mm).sum::<f64>() / n,
            by_step_mm,
            each: each.into_iter().map(|(start, v, _)| (start, v)).collect(),
        }
    }
}

/// Frames per row of the stability table.
const WINDOW: usize = 100;

/// Metrics over one span of frames.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Window {
    pub first_frame: usize,
    pub last_frame: usize,
    /// Mean share of garment vertices inside the body (winding number), %.
    pub inside_pct: f64,
    pub mean_strain_pct: f64,
    pub max_strain_pct: f64,
    /// Fastest vertex (m/s).
    pub max_speed: f64,
}

impl Window {
    fn of(frames: &[FrameStats]) -> Window {
        let n = frames.len().max(1) as f64;
        let max = |f: fn(&FrameStats) -> f64| frames.iter().map(f).fold(0.0, f64::max);
        Window {
            first_frame: frames.first().map_or(0, |f| f.frame),
            last_frame: frames.last().map_or(0, |f| f.frame),
            inside_pct: frames.iter().map(|f| f.inside_pct).sum::<f64>() / n,
            mean_strain_pct: frames.iter().map(|f| f.strain_pct).sum::<f64>() / n,
            max_strain_pct: max(|f| f.strain_pct),
            max_speed: max(|f| f.max_speed),
        }
    }
}

#[derive(Serialize, Deserialize)]
pub struct Report {
    pub motions: Vec<PathBuf>,
    pub fps: f32,
    pub frames: usize,
    pub collision_fix: bool,
    /// The collision loss `Σ ReLU(margin − o)` (mm, summed over vertices), mean per frame, of the
    /// network's garment and of the garment written (after the fix).
    pub collision_loss_before_mm: f64,
    pub collision_loss_after_mm: f64,
    pub timing: Timing,
    /// Our metrics on the written frames (inside the body by winding number, strain, speed).
    pub summary: Summary,
    /// The same per 100 frames: whether a long roll-out drifts or blows up.
    pub windows: Vec<Window>,
    /// Against the (first) reference.
    pub reference: Option<Versus>,
    /// With several references: against each, and their own spread.
    pub references: Option<References>,
    /// With --restart-every: the model restarted from the reference along the clip.
    pub restarts: Option<Restarts>,
    /// Plain LBS of the rest garment against the same reference.
    pub lbs_reference: Option<Versus>,
    pub lbs_out: Option<PathBuf>,
    pub out: PathBuf,
    pub out_bytes: u64,
    /// For a glTF output: blend shapes kept and the replay error.
    pub baked: Option<SequenceReport>,
    pub body_out: Option<PathBuf>,
    /// With --view: the page and its size in bytes.
    pub view: Option<(PathBuf, u64)>,
    /// With --validate: the written file against the roll-out.
    pub validation: Option<Validation>,
}

impl Execute for Args {
    type Report = Report;

    fn execute(&self, say: &dyn Fn(&str)) -> Result<Report> {
        use super::args::{output_set, Writes, POINT_CACHE};
        let kinds = &[
            FileKind::Pc2,
            FileKind::Mdd,
            FileKind::Usd,
            FileKind::Alembic,
            FileKind::Gltf,
        ];
        let outputs = output_set(&[
            ("--out", Some(&self.out), Writes::Kinds(kinds)),
            ("--lbs-out", self.lbs_out.as_deref(), POINT_CACHE),
            ("--body-out", self.body_out.as_deref(), POINT_CACHE),
            ("--view", self.view.as_deref(), Writes::Page),
        ])?;
        let kind = FileKind::written(&self.out);
        if self.with_body && !matches!(kind, Some(FileKind::Usd | FileKind::Alembic)) {
            bail!(
                "{}: --with-body needs a USD or Alembic --out ({}): PC2, MDD and glTF caches hold one mesh (use --body-out)",
                self.out.display(),
                FileKind::extension_list(&[FileKind::Usd, FileKind::Alembic], true)
            );
        }
        let (file, _device) = self.compute.load_model(&self.model)?;
        let dynamic = file.dynamic()?;
        dynamic.motion()?;
        let info = file.info.dynamic()?;
        let fps = info.fps;
        let skeleton = &file.body.skeleton;
        let maps = read_maps(&self.maps)?;
        let clips = self
            .motions
            .iter()
            .map(|m| Ok(load_clip(m, &maps, skeleton, Some(fps))?.animation))
            .collect::<Result<Vec<_>>>()?;
        let mut poses = chain(&clips.iter().collect::<Vec<_>>(), self.fade);
        let clip_frames = poses.len();
        poses.truncate(self.frames.unwrap_or(poses.len()).max(1));
        let n = file.garment.vertex_count();
        let init = match self.init.as_str() {
            "rest" => Init::Rest,
            path => {
                let frames = read_pc2(std::path::Path::new(path), n)?;
                match frames.into_iter().next() {
                    Some(first) => Init::Moving(vec![first]),
                    None => bail!("{path}: the --init cache has no frames"),
                }
            }
        };
        if !self.references.is_empty() && self.motions.len() != 1 {
            bail!("--reference measures a single clip: give one --motion");
        }
        let references = self
            .references
            .iter()
            .map(|path| read_reference(path, n, (clip_frames, poses.len()), fps))
            .collect::<Result<Vec<_>>>()?;
        let reference = references.first();
        if let (Some(every), Some(r)) = (self.restart_every, reference) {
            if every == 0 || every >= r.len() {
                bail!(
                    "--restart-every {every}: give a number of frames from 1 to {} (the clip's frames − 1)",
                    r.len() - 1
                );
            }
        }
        let settings = self.collision.settings(!self.no_collision_fix)?;
        say(&format!(
            "the model plays at {fps} fps (its training rate): clips are resampled to it"
        ));
        let bar = crate::progress::bar(poses.len() as u64, "roll-out", self.output.json);
        let collision_fix = settings.collision_fix;
        let rollout = for_model(&file, &poses, &init, settings.clone(), &mut |f| {
            bar.set_position(f as u64 + 1)
        })?;
        bar.finish_and_clear();
        let restarts = match (self.restart_every, reference) {
            (Some(every), Some(r)) => Some(restarts(
                &file,
                &poses,
                r,
                every,
                &settings,
                self.output.json,
            )?),
            _ => None,
        };
        let (per_frame, summary) = stats::of(
            &Series::unpinned(&file.body, &file.garment, fps),
            &rollout.frames,
            &poses,
            &[],
            None,
        );
        let body = &file.body;
        let bodies = (self.body_out.is_some() || self.with_body)
            .then(|| lbs_frames(&body.skin, &body.mesh.positions, skeleton, &poses));
        let baked = outputs.write(&self.out, |out| match (kind, &bodies) {
            (Some(FileKind::Gltf), _) => self
                .write_gltf(out, &file, &poses, &rollout.frames, fps, say)
                .map(Some),
            (_, Some(b)) if self.with_body => {
                let meshes = [
                    ("garment", &file.garment, rollout.frames.as_slice()),
                    ("body", &body.mesh, b.as_slice()),
                ];
                write_caches(out, &meshes, fps).map(|()| None)
            }
            _ => write_cache(out, &file.garment, &rollout.frames, fps).map(|()| None),
        })?;
        let lbs = (self.lbs_out.is_some() || reference.is_some())
            .then(|| {
                let skin = Self::garment_skin(&file)?;
                let rest = &file.garment.positions;
                Ok::<_, anyhow::Error>(lbs_frames(&skin, rest, skeleton, &poses))
            })
            .transpose()?;
        if let (Some(path), Some(lbs)) = (&self.lbs_out, &lbs) {
            outputs.write(path, |p| write_cache(p, &file.garment, lbs, fps))?;
        }
        if let (Some(path), Some(b)) = (&self.body_out, &bodies) {
            outputs.write(path, |p| write_cache(p, &body.mesh, b, fps))?;
        }
        let view = match &self.view {
            Some(page) => {
                let names: Vec<String> = clips.iter().map(|c| c.name.clone()).collect();
                let bytes = outputs.write(page, |p| {
                    crate::pipeline::view::cache_page(
                        p,
                        (&file.body, &file.garment),
                        (&names.join(" + "), fps, &poses),
                        ("roll-out", &rollout.frames),
                        reference.map(|r| ("simulation", r.as_slice())),
                    )
                })?;
                Some((page.clone(), bytes))
            }
            None => None,
        };
        outputs.commit()?;
        // The file must play the frames just rolled out: a point cache vertex for vertex, a
        // glTF evaluated as the spec says (its seam-split vertices mapped by `sourceVertex`).
        let validation = self
            .validate
            .then(|| {
                let written = Reference::of_frames(
                    "roll-out",
                    rollout.frames.clone(),
                    fps,
                    file.garment.triangles.clone(),
                );
                check_file(&self.out, Some(&written), f64::from(self.tolerance_mm))
                    .map(|c| c.validation(Some("roll-out".into())))
            })
            .transpose()?;
        let (first, lbs_reference, all) =
            self.versus_references(&references, &rollout.frames, lbs.as_deref());
        Ok(Report {
            motions: self.motions.clone(),
            fps,
            frames: rollout.frames.len(),
            collision_fix,
            collision_loss_before_mm: mean_mm(&rollout.collision_before),
            collision_loss_after_mm: mean_mm(&rollout.collision_after),
            timing: Timing::of(&rollout.timings),
            summary,
            windows: per_frame.chunks(WINDOW).map(Window::of).collect(),
            lbs_reference,
            lbs_out: self.lbs_out.clone(),
            reference: first,
            references: all,
            restarts,
            out: self.out.clone(),
            out_bytes: std::fs::metadata(&self.out).map_or(0, |m| m.len()),
            baked,
            body_out: self.body_out.clone(),
            view,
            validation,
        })
    }

    fn print(r: &Report) {
        let t = &r.timing;
        println!(
            "rolled out {} frames at {} fps ({} clip(s)); collision fix {}",
            r.frames,
            r.fps,
            r.motions.len(),
            if r.collision_fix { "on" } else { "off" }
        );
        println!(
            "ms per frame: input maps {:.1}, encoder {:.1}, decode + skinning {:.1} (network {:.1}); strain limit {:.1}; collision {:.1} (fix ran on {} frames, {:.2} ms per iteration)",
            t.inputs_ms, t.encoder_ms, t.decode_ms, t.network_ms, t.strain_ms, t.collision_ms, t.fixed_frames, t.ms_per_collision_iteration
        );
        println!(
            "collision loss Σ ReLU(margin − o) per frame: {:.2} mm before the fix, {:.2} mm written",
            r.collision_loss_before_mm, r.collision_loss_after_mm
        );
        let s = &r.summary;
        println!(
            "inside the body (winding number): {:.3} % of vertices on average, worst frame {} ({} vertices); edge strain mean {:.2} %, worst {:.2} %; fastest vertex {:.2} m/s",
            s.inside.inside_pct, s.inside.worst_frame, s.inside.worst_frame_vertices, s.mean_strain_pct, s.max_strain_pct, s.max_speed
        );
        if r.windows.len() > 1 {
            println!("frames      inside %  strain % (mean, worst)  fastest m/s");
            for w in &r.windows {
                println!(
                    "{:>4}-{:<4}  {:>8.3}  {:>7.2} {:>7.2}         {:>6.2}",
                    w.first_frame,
                    w.last_frame,
                    w.inside_pct,
                    w.mean_strain_pct,
                    w.max_strain_pct,
                    w.max_speed
                );
            }
        }
        if let Some(v) = &r.reference {
            println!(
                "vs reference (vertex L2): after 1 step {:.2} mm, first 50 frames {:.2} mm, whole clip {:.2} mm, max {:.1} mm (frame {})",
                v.one_step_mm, v.first_50_mm, v.clip_mm, v.max_mm, v.worst_frame
            );
        }
        if let Some(s) = &r.restarts {
            println!(
                "restarted from the reference every {} frames ({} restarts, {} frames each): after 1 step {:.2} mm, over the restarts {:.2} mm",
                s.frames,
                s.each.len(),
                s.frames,
                s.one_step_mm,
                s.mean_mm
            );
            let steps: Vec<String> = [1, 2, 5, 10, 25, 50, 100]
                .iter()
                .filter_map(|&k| Some(format!("{k}: {:.1}", s.by_step_mm.get(k - 1)?)))
                .collect();
            println!(
                "  mean error k frames after a restart (mm): {}",
                steps.join(", ")
            );
        }
        if let Some(v) = &r.lbs_reference {
            println!(
                "plain LBS vs reference: after 1 step {:.2} mm, first 50 frames {:.2} mm, whole clip {:.2} mm, max {:.1} mm (frame {})",
                v.one_step_mm, v.first_50_mm, v.clip_mm, v.max_mm, v.worst_frame
            );
        }
        if let Some(all) = &r.references {
            print_references(all);
        }
        if let Some(b) = &r.baked {
            println!(
                "glTF: {} blend shapes (residual rank {}), {}, weights 0 to {:.3}, within {:.3} mm of the roll-out (mean {:.4} mm)",
                b.targets,
                b.rank,
                if b.quantized {
                    "16-bit (KHR_mesh_quantization; --float-targets for 32-bit)"
                } else {
                    "32-bit floats"
                },
                b.max_weight,
                b.max_error_m * 1e3,
                b.mean_error_m * 1e3
            );
        }
        println!(
            "wrote {} ({} bytes, {:.0} per frame)",
            r.out.display(),
            r.out_bytes,
            r.out_bytes as f64 / r.frames.max(1) as f64
        );
        for b in r.body_out.iter().chain(&r.lbs_out) {
            println!("wrote {}", b.display());
        }
        if let Some((page, bytes)) = &r.view {
            println!("wrote {} ({:.1} MB)", page.display(), *bytes as f64 / 1e6);
        }
        if let Some(v) = &r.validation {
            v.print();
        }
    }

    fn exit_code(r: &Report) -> i32 {
        i32::from(r.validation.as_ref().is_some_and(|v| !v.passed))
    }
}

impl Args {
    /// The roll-out and plain LBS (present whenever there is a reference) against the first
    /// reference, and with two or more, against each, their mean and their own spread (each
    /// distance computed once: the first reference's are the ensembles' first).
    fn versus_references(
        &self,
        references: &[Vec<Vec<[f32; 3]>>],
        rollout: &[Vec<[f32; 3]>],
        lbs: Option<&[Vec<[f32; 3]>]>,
    ) -> (Option<Versus>, Option<Versus>, Option<References>) {
        let (Some(first), Some(lbs)) = (references.first(), lbs) else {
            return (None, None, None);
        };
        let Some(sims) = Simulations::new(references) else {
            return (
                Some(Versus::between(rollout, first)),
                Some(Versus::between(lbs, first)),
                None,
            );
        };
        let all = References {
            paths: self.references.clone(),
            spread: sims.spread(),
            from_the_others: sims.from_the_others(),
            rollout: sims.ensemble(rollout),
            lbs: sims.ensemble(lbs),
        };
        (Some(all.rollout.each[0]), Some(all.lbs.each[0]), Some(all))
    }

    /// The fixed skin of the model's garment: the LBS baseline and the glTF's skin.
    fn garment_skin(file: &crate::models::file::ModelFile) -> Result<crate::rig::Skin> {
        let body = &file.body;
        let index = PointIndex::new(&body.mesh.positions)?;
        Ok(smooth_garment_skin(
            &file.garment,
            &body.skin,
            body.skeleton.joint_count(),
            &index,
        ))
    }

    /// The roll-out as a skinned, blend-shaped glTF (see `bake::sequence`), on the body's
    /// skeleton with the same fixed skin as the model's LBS baseline.
    fn write_gltf(
        &self,
        out: &std::path::Path,
        file: &crate::models::file::ModelFile,
        poses: &[Vec<crate::rig::JointTransform>],
        frames: &[Vec<[f32; 3]>],
        fps: f32,
        say: &dyn Fn(&str),
    ) -> Result<SequenceReport> {
        let body = &file.body;
        let skin = Self::garment_skin(file)?;
        let animation = SkelAnimation::from_poses("rollout", fps, poses);
        say("compressing the roll-out into blend shapes");
        let (mut asset, report) = bake_sequence(
            &body.skeleton,
            &file.garment,
            &skin,
            &animation,
            frames,
            self.tolerance_mm * 1e-3,
            !self.float_targets,
        )?;
        asset.provenance = vec![
            ("generator".into(), "garmentbake rollout".into()),
            ("model".into(), self.model.display().to_string()),
        ];
        exporters::write(&asset, out).with_context(|| format!("writing {}", out.display()))?;
        Ok(report)
    }
}

fn mean_mm(per_frame: &[f64]) -> f64 {
    1e3 * per_frame.iter().sum::<f64>() / per_frame.len().max(1) as f64
}

/// The model rolled out for `every` frames from the reference's state at frames 0, `every`,
/// 2·`every`, … (whole restarts only), each measured against the reference.
fn restarts(
    file: &crate::models::file::ModelFile,
    poses: &[Vec<crate::rig::JointTransform>],
    reference: &[Vec<[f32; 3]>],
    every: usize,
    settings: &Settings,
    quiet: bool,
) -> Result<Restarts> {
    let starts: Vec<usize> = (0..reference.len().saturating_sub(every))
        .step_by(every)
        .collect();
    let bar = crate::progress::bar((starts.len() * every) as u64, "restarts", quiet);
    let mut each = Vec::with_capacity(starts.len());
    for (k, &start) in starts.iter().enumerate() {
        let span = start..=start + every;
        let init = Init::Moving(reference[start.saturating_sub(2)..=start].to_vec());
        let rollout = for_model(
            file,
            &poses[span.clone()],
            &init,
            settings.clone(),
            &mut |f| bar.set_position((k * every + f) as u64),
        )?;
        let per_frame = distances_mm(&rollout.frames, &reference[span]);
        let mean = per_frame.iter().map(|d| d.0).collect();
        each.push((start, Versus::of(&per_frame), mean));
    }
    bar.finish_and_clear();
    Ok(Restarts::of(every, each))
}

/// A simulated cache of the clip: it covers the clip, or the frames played (--frames); cut to
/// the frames played. `frames`: (the clip's, played).
fn read_reference(
    path: &std::path::Path,
    vertices: usize,
    (clip, played): (usize, usize),
    fps: f32,
) -> Result<Vec<Vec<[f32; 3]>>> {
    let mut frames = read_pc2(path, vertices)?;
    if frames.len() != clip && frames.len() != played {
        bail!(
            "{}: {} frames, the clip has {clip} at {fps} fps (simulated at another rate?)",
            path.display(),
            frames.len(),
        );
    }
    frames.truncate(played);
    Ok(frames)
}

/// Several simulations: the roll-out and LBS against each, against their mean, and the
/// simulations against each other, each as "after 1 step / first 50 frames / whole clip".
fn print_references(all: &References) {
    let spans = |v: &Versus| {
        format!(
            "{:.2} / {:.2} / {:.2} mm",
            v.one_step_mm, v.first_50_mm, v.clip_mm
        )
    };
    println!(
        "against {} simulations (vertex L2, after 1 step / first 50 frames / whole clip):",
        all.paths.len()
    );
    for ((path, m), l) in all.paths.iter().zip(&all.rollout.each).zip(&all.lbs.each) {
        println!(
            "  {}: roll-out {}, plain LBS {}",
            path.display(),
            spans(m),
            spans(l)
        );
    }
    println!(
        "  roll-out, mean over the simulations: {} (their mean garment: {})",
        spans(&all.rollout.mean_of_each),
        spans(&all.rollout.versus_mean)
    );
    println!(
        "  plain LBS, mean over the simulations: {} (their mean garment: {})",
        spans(&all.lbs.mean_of_each),
        spans(&all.lbs.versus_mean)
    );
    println!(
        "  the simulations from each other (mean over pairs): {} — the simulator defines the garment only to this",
        spans(&all.spread)
    );
    println!(
        "  each simulation from the mean garment of the others: {} — re-simulating predicts a run this well",
        spans(&all.from_the_others)
    );
}
