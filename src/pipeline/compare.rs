//! `compare`: caches of one clip (and the dynamic models that played them) read and checked
//! against the clip, the body and the garment, then measured against perturbed simulations of
//! the clip by `crate::compare` (which also renders the report as text).

use super::Clips;
use crate::compare::{compare, Cache, Inputs, Report, Settings};
use crate::compute::Compute;
use crate::garment::Garment;
use crate::io::gltf_body::read_body;
use crate::io::point_cache::read_pc2;
use crate::models::file::check_skeleton;
use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};

/// What to compare (the flags of `garmentbake compare`, resolved).
pub struct Request {
    /// Skinned body the caches were played on.
    pub body: PathBuf,
    /// The garment the caches play; its lowest boundary loop is the hem.
    pub garment: PathBuf,
    /// The clip (exactly one), at the caches' rate.
    pub clips: Clips,
    /// Simulations of the clip (two or more).
    pub sims: Vec<PathBuf>,
    /// Caches to compare, by name.
    pub caches: Vec<(String, PathBuf)>,
    /// The dynamic model that played a cache (by the cache's name): restarted for e(k).
    pub models: Vec<(String, PathBuf)>,
    /// The quasi-static cache (by name) the hem's swing is measured beyond.
    pub baseline: Option<String>,
    /// Compare only the clip's first N frames.
    pub frames: Option<usize>,
    /// Where restarted models run.
    pub compute: Compute,
    pub settings: Settings,
}

/// Reads and checks `request`'s files, then compares (plots written as they are drawn).
pub fn run(request: &Request) -> Result<Report> {
    let r = request;
    let settings = &r.settings;
    if r.sims.len() < 2 {
        bail!(
            "--sim: give two or more simulations of the clip (got {}; e.g. simulate --perturb 0, 1, 2)",
            r.sims.len()
        );
    }
    if settings.restart_every == 0 {
        bail!("--restart-every 0: give a number of frames of 1 or more");
    }
    if !(settings.max_lag_s.is_finite() && settings.max_lag_s >= 0.0) {
        bail!(
            "--max-lag {}: give a non-negative number of seconds",
            settings.max_lag_s
        );
    }
    for (i, (name, _)) in r.caches.iter().enumerate() {
        if settings.with_mean && *name == crate::compare::RUNS_MEAN {
            bail!("--cache {name}=…: the name --with-mean gives the runs' mean garment");
        }
        if r.caches[..i].iter().any(|(n, _)| n == name) {
            bail!("--cache {name}=…: the name is given twice");
        }
    }
    let index_of = |flag: &str, name: &str| {
        r.caches
            .iter()
            .position(|(n, _)| *n == name)
            .with_context(|| format!("{flag} {name}: no --cache of that name"))
    };
    let baseline = r
        .baseline
        .as_deref()
        .map(|b| index_of("--baseline", b))
        .transpose()?;
    let models: Vec<(usize, &Path)> = r
        .models
        .iter()
        .map(|(name, path)| Ok((index_of("--model", name)?, path.as_path())))
        .collect::<Result<_>>()?;
    let body = read_body(&r.body)?;
    let garment = Garment::read(&r.garment)?;
    let n = garment.mesh.vertex_count();
    let (motion, clip) = r.clips.load_single(&body)?;
    let fps = clip.animation.fps;
    let clip_frames = clip.animation.frame_count();
    let played = r.frames.unwrap_or(clip_frames);
    if played < 2 || played > clip_frames {
        bail!("--frames {played}: give 2 to {clip_frames} (the clip's frames at {fps} fps)");
    }
    let poses: Vec<_> = (0..played).map(|f| clip.animation.local_pose(f)).collect();
    let read = |path: &Path| {
        let mut frames = read_pc2(path, n, fps)?;
        if frames.len() != clip_frames && frames.len() != played {
            bail!(
                "{}: {} frames, {} has {clip_frames} at {fps} fps (another clip or rate?)",
                path.display(),
                frames.len(),
                motion.display(),
            );
        }
        frames.truncate(played);
        Ok(frames)
    };
    let sims = r.sims.iter().map(|p| read(p)).collect::<Result<Vec<_>>>()?;
    let mut caches = r
        .caches
        .iter()
        .map(|(name, path)| {
            Ok(Cache {
                name: name.clone(),
                frames: read(path)?,
                model: None,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    for (i, path) in models {
        let file = crate::models::file::load(path, r.compute.apply()?)?;
        file.dynamic()
            .and_then(|d| d.motion().map(|_| ()))
            .with_context(|| {
                format!(
                    "{}: not a dynamic model with its motion stage",
                    path.display()
                )
            })?;
        check_skeleton(
            file.skeleton(),
            &body.skeleton,
            &r.body.display().to_string(),
        )?;
        if file.garment.vertex_count() != n {
            bail!(
                "{}: the model's garment has {} vertices, {} has {n}",
                path.display(),
                file.garment.vertex_count(),
                r.garment.display()
            );
        }
        let model_fps = file.info.dynamic()?.fps;
        if (model_fps - fps).abs() > 1e-3 {
            bail!(
                "{}: the model plays at {model_fps} fps, the clip is at {fps} (give --fps {model_fps})",
                path.display(),
            );
        }
        caches[i].model = Some(file);
    }
    r.compute.apply()?;
    let inputs = Inputs {
        body: &body,
        garment: &garment.mesh,
        poses: &poses,
        fps,
        simulations: &sims,
        caches: &caches,
        baseline,
    };
    compare(&inputs, settings)
}
