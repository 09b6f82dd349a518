//! `rollout`: a dynamic model played over clips frame by frame, written as a point cache or a
//! compressed glTF, measured on the way (our metrics per 100 frames), against reference
//! simulations (one, or several and their own spread) and by restarts from a reference's state.
//! The report and its text are in [`report`].

pub mod report;

use super::Feedback;
use crate::bake::compress::Targets;
use crate::bake::sequence::{bake_sequence, SequenceReport};
use crate::compute::Compute;
use crate::eval::lbs_frames;
use crate::geometry::{Frames, PointIndex};
use crate::io::point_cache::{read_pc2, write_cache_in, write_caches_in};
use crate::metrics::reference_error::{distances_mm, ReferenceError, Simulations};
use crate::models::file::ModelFile;
use crate::motion::{chain, load_clip};
use crate::pipeline::Clips;
use crate::rig::weights::smooth_garment_skin;
use crate::rig::{JointTransform, SkelAnimation};
use crate::rollout::timing::Timing;
use crate::rollout::{for_model, Init, Settings};
use crate::simulate::stats::{self, ClipSetup};
use crate::validate::{check_file, replay::Reference};
use anyhow::{bail, Context, Result};
use exporters::atomic::OutputSet;
use exporters::FileKind;
use report::{References, Report, Restarts, SpanMetrics, SPAN_FRAMES};
use std::path::{Path, PathBuf};

/// What to play and write (the flags of `garmentbake rollout`, resolved).
pub struct Request {
    /// Dynamic model with its motion stage.
    pub model: PathBuf,
    pub compute: Compute,
    /// Clips played one after another at the model's rate (theirs is ignored), each later one
    /// blended in over `fade` frames.
    pub clips: Clips,
    pub fade: usize,
    /// A point cache whose first frame is the starting garment; none: the rest garment.
    pub init: Option<PathBuf>,
    /// Play only the first N frames (of the clips in a row).
    pub frames: Option<usize>,
    /// The per-frame strain limit and collision fix.
    pub settings: Settings,
    /// Point cache or glTF (by extension).
    pub out: PathBuf,
    /// glTF: how many blend shapes to keep (a count, or the fewest within a replay tolerance).
    pub targets: Targets,
    /// The `validate` limit (mm).
    pub tolerance_mm: f32,
    /// glTF: 32-bit blend shapes instead of quantized ones.
    pub float_targets: bool,
    pub body_out: Option<PathBuf>,
    /// USD or Alembic `out`: the posed body beside the garment.
    pub with_body: bool,
    /// Simulations of the (single) clip to measure against; the first is the one restarts and
    /// the page use.
    pub references: Vec<PathBuf>,
    pub restart_every: Option<usize>,
    pub lbs_out: Option<PathBuf>,
    pub view: Option<PathBuf>,
    /// Check what was written against the roll-out.
    pub validate: bool,
    /// Units and up axis of the point caches written (`--out-units`, `--out-up`).
    pub space: exporters::CacheSpace,
}

/// Plays `request`, writes its outputs through `outputs` (checked by the caller before any work,
/// committed here) and measures the roll-out.
pub fn run(request: &Request, outputs: OutputSet, feedback: &Feedback) -> Result<Report> {
    let r = request;
    let kind = FileKind::written(&r.out);
    if r.with_body && !matches!(kind, Some(FileKind::Usd | FileKind::Alembic)) {
        bail!(
            "{}: --with-body needs a USD or Alembic --out ({}): PC2, MDD and glTF caches hold one mesh (use --body-out)",
            r.out.display(),
            FileKind::extension_list(&[FileKind::Usd, FileKind::Alembic], true)
        );
    }
    if r.validate && (kind == Some(FileKind::Vat) || r.space != exporters::CacheSpace::NATIVE) {
        bail!(
            "{}: --validate reads glTF and point caches in metres, Y-up: drop --validate for a VAT or with --out-units / --out-up",
            r.out.display()
        );
    }
    let device = r.compute.apply()?;
    let file = crate::models::file::load(&r.model, device)?;
    let dynamic = file.dynamic()?;
    dynamic.motion()?;
    let info = file.info.dynamic()?;
    let fps = info.fps;
    let skeleton = &file.body.skeleton;
    let reader = r.clips.reader()?;
    let clips = r
        .clips
        .motions
        .iter()
        .map(|m| Ok(load_clip(m, &reader, &file.body, Some(fps))?.animation))
        .collect::<Result<Vec<_>>>()?;
    let mut poses = chain(&clips.iter().collect::<Vec<_>>(), r.fade);
    let clip_frames = poses.len();
    poses.truncate(r.frames.unwrap_or(poses.len()).max(1));
    let n = file.garment.vertex_count();
    let init = match &r.init {
        None => Init::Rest,
        Some(path) => {
            let frames = read_pc2(path, n, fps)?;
            match frames.into_points().into_iter().next() {
                Some(first) => Init::Moving(vec![first]),
                None => bail!("{}: the --init cache has no frames", path.display()),
            }
        }
    };
    if !r.references.is_empty() && r.clips.motions.len() != 1 {
        bail!("--reference measures a single clip: give one --motion");
    }
    let references = r
        .references
        .iter()
        .map(|path| read_reference(path, n, (clip_frames, poses.len()), fps))
        .collect::<Result<Vec<_>>>()?;
    let reference = references.first();
    if let (Some(every), Some(first)) = (r.restart_every, reference) {
        if every == 0 || every >= first.len() {
            bail!(
                "--restart-every {every}: give a number of frames from 1 to {} (the clip's frames − 1)",
                first.len() - 1
            );
        }
    }
    let settings = &r.settings;
    (feedback.say)(&format!(
        "the model plays at {fps} fps (its training rate): clips are resampled to it"
    ));
    let bar = crate::progress::bar(poses.len() as u64, "roll-out", feedback.hide_bars);
    let collision_fix = settings.collision_fix;
    let rollout = for_model(
        &file,
        &poses,
        0..poses.len(),
        &init,
        settings.clone(),
        &mut |f| bar.set_position(f as u64 + 1),
    )?;
    bar.finish_and_clear();
    let restarts = match (r.restart_every, reference) {
        (Some(every), Some(first)) => Some(restarts(
            &file,
            &poses,
            first,
            every,
            settings,
            feedback.hide_bars,
        )?),
        _ => None,
    };
    let (per_frame, summary) = stats::of(
        &ClipSetup::unpinned(&file.body, &file.garment, fps),
        &rollout.frames,
        &poses,
        &[],
        None,
    );
    let body = &file.body;
    let lbs_clip = |skin: &crate::rig::Skin, rest: &[[f32; 3]]| {
        Frames::new(lbs_frames(skin, rest, skeleton, &poses), fps)
    };
    let bodies =
        (r.body_out.is_some() || r.with_body).then(|| lbs_clip(&body.skin, &body.mesh().positions));
    let baked = outputs.write(&r.out, |out| match (kind, &bodies) {
        (Some(FileKind::Gltf), _) => {
            write_gltf(r, out, &file, &poses, &rollout.frames, fps, feedback.say).map(Some)
        }
        (_, Some(b)) if r.with_body => {
            let meshes = [
                ("garment", &file.garment, &rollout.frames),
                ("body", body.mesh(), b),
            ];
            write_caches_in(out, &meshes, r.space).map(|()| None)
        }
        _ => write_cache_in(out, &file.garment, &rollout.frames, r.space).map(|()| None),
    })?;
    let lbs = (r.lbs_out.is_some() || reference.is_some())
        .then(|| {
            let skin = garment_skin(&file)?;
            let rest = &file.garment.positions;
            Ok::<_, anyhow::Error>(lbs_clip(&skin, rest))
        })
        .transpose()?;
    if let (Some(path), Some(lbs)) = (&r.lbs_out, &lbs) {
        outputs.write(path, |p| write_cache_in(p, &file.garment, lbs, r.space))?;
    }
    if let (Some(path), Some(b)) = (&r.body_out, &bodies) {
        outputs.write(path, |p| write_cache_in(p, body.mesh(), b, r.space))?;
    }
    let view = match &r.view {
        Some(page) => {
            let names: Vec<String> = clips.iter().map(|c| c.name.clone()).collect();
            let vat = super::view::staged_vat(&outputs, &r.out)?;
            let bytes = outputs.write(page, |p| {
                super::view::cache_page(
                    p,
                    (&file.body, &file.garment),
                    (&names.join(" + "), fps, &poses),
                    ("roll-out", &rollout.frames),
                    reference.map(|r| ("simulation", r.as_slice())),
                    vat.as_ref(),
                )
            })?;
            Some((page.clone(), bytes))
        }
        None => None,
    };
    outputs.commit()?;
    // The file must play the frames just rolled out: a point cache vertex for vertex, a
    // glTF evaluated as the spec says (its seam-split vertices mapped by `sourceVertex`).
    let validation = r
        .validate
        .then(|| {
            let written = Reference::of_frames(
                "roll-out",
                rollout.frames.clone(),
                file.garment.triangles.clone(),
            );
            check_file(&r.out, Some(&written), f64::from(r.tolerance_mm))
                .map(|c| c.validation(Some("roll-out".into())))
        })
        .transpose()?;
    let (first, lbs_reference, all) = errors_against_references(
        &r.references,
        &references,
        &rollout.frames,
        lbs.as_ref().map(|l| l.as_slice()),
    );
    Ok(Report {
        motions: r.clips.motions.clone(),
        fps,
        frames: rollout.frames.len(),
        collision_fix,
        collision_loss_before_mm: mean_mm(&rollout.collision_before),
        collision_loss_after_mm: mean_mm(&rollout.collision_after),
        timing: Timing::of(&rollout.timings),
        summary,
        spans: per_frame.chunks(SPAN_FRAMES).map(SpanMetrics::of).collect(),
        lbs_reference,
        lbs_out: r.lbs_out.clone(),
        reference: first,
        references: all,
        restarts,
        out: r.out.clone(),
        out_bytes: std::fs::metadata(&r.out).map_or(0, |m| m.len()),
        baked,
        body_out: r.body_out.clone(),
        view,
        validation,
    })
}

/// The roll-out and plain LBS (present whenever there is a reference) against the first
/// reference, and with two or more, against each, their mean and their own spread (each
/// distance computed once: the first reference's are the ensembles' first).
fn errors_against_references(
    paths: &[PathBuf],
    references: &[Frames],
    rollout: &[Vec<[f32; 3]>],
    lbs: Option<&[Vec<[f32; 3]>]>,
) -> (
    Option<ReferenceError>,
    Option<ReferenceError>,
    Option<References>,
) {
    let (Some(first), Some(lbs)) = (references.first(), lbs) else {
        return (None, None, None);
    };
    let Some(sims) = Simulations::new(references) else {
        return (
            Some(ReferenceError::between(rollout, first)),
            Some(ReferenceError::between(lbs, first)),
            None,
        );
    };
    let all = References {
        paths: paths.to_vec(),
        spread: sims.spread(),
        from_the_others: sims.from_the_others(),
        rollout: sims.ensemble(rollout),
        lbs: sims.ensemble(lbs),
    };
    (Some(all.rollout.each[0]), Some(all.lbs.each[0]), Some(all))
}

/// The fixed skin of the model's garment: the LBS baseline and the glTF's skin.
fn garment_skin(file: &ModelFile) -> Result<crate::rig::Skin> {
    let body = &file.body;
    let index = PointIndex::new(&body.mesh().positions)?;
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
    r: &Request,
    out: &Path,
    file: &ModelFile,
    poses: &[Vec<JointTransform>],
    frames: &[Vec<[f32; 3]>],
    fps: f32,
    say: &dyn Fn(&str),
) -> Result<SequenceReport> {
    let body = &file.body;
    let skin = garment_skin(file)?;
    let animation = SkelAnimation::from_poses("rollout", fps, poses);
    say("compressing the roll-out into blend shapes");
    let (mut asset, report) = bake_sequence(
        &body.skeleton,
        &file.garment,
        &skin,
        &animation,
        frames,
        r.targets,
        !r.float_targets,
    )?;
    asset.provenance = vec![
        ("generator".into(), "garmentbake rollout".into()),
        ("model".into(), r.model.display().to_string()),
    ];
    exporters::write(&asset, out).with_context(|| format!("writing {}", out.display()))?;
    Ok(report)
}

fn mean_mm(per_frame: &[f64]) -> f64 {
    1e3 * per_frame.iter().sum::<f64>() / per_frame.len().max(1) as f64
}

/// The model rolled out for `every` frames from the reference's state at frames 0, `every`,
/// 2·`every`, … (whole restarts only), each measured against the reference.
fn restarts(
    file: &ModelFile,
    poses: &[Vec<JointTransform>],
    reference: &[Vec<[f32; 3]>],
    every: usize,
    settings: &Settings,
    hide_bar: bool,
) -> Result<Restarts> {
    let starts: Vec<usize> = (0..reference.len().saturating_sub(every))
        .step_by(every)
        .collect();
    let bar = crate::progress::bar((starts.len() * every) as u64, "restarts", hide_bar);
    let mut each = Vec::with_capacity(starts.len());
    for (k, &start) in starts.iter().enumerate() {
        let span = start..=start + every;
        let init = Init::Moving(reference[start.saturating_sub(2)..=start].to_vec());
        let rollout = for_model(
            file,
            poses,
            start..start + every + 1,
            &init,
            settings.clone(),
            &mut |f| bar.set_position((k * every + f) as u64),
        )?;
        let per_frame = distances_mm(&rollout.frames, &reference[span]);
        let mean = per_frame.iter().map(|d| d.0).collect();
        each.push((start, ReferenceError::of(&per_frame), mean));
    }
    bar.finish_and_clear();
    Ok(Restarts::of(every, each))
}

/// A simulated cache of the clip: it covers the clip, or the frames played (--frames); cut to
/// the frames played. `frames`: (the clip's, played).
fn read_reference(
    path: &Path,
    vertices: usize,
    (clip, played): (usize, usize),
    fps: f32,
) -> Result<Frames> {
    let mut frames = read_pc2(path, vertices, fps)?;
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
