//! `preview`'s contact sheet: the body posed by clips (or at rest), garments at rest, played by
//! point caches or posed by a PBNS model (beside plain LBS), picked frames, laid out per view
//! (`preview::layout`).

use crate::body::Body;
use crate::eval::model_frames;
use crate::garment::Garment;
use crate::geometry::Frames;
use crate::io::gltf_body::read_body;
use crate::models::file::{self, check_skeleton};
use crate::motion::{chain, load_clip};
use crate::preview::layout::{shots_sheet, Drawn, Layout, Shot};
use crate::preview::View;
use crate::rig::JointTransform;
use anyhow::{bail, Result};
use std::path::PathBuf;

/// What to draw and how (the flags of `garmentbake preview`).
pub struct Request {
    /// Skinned body (glTF/glb).
    pub body: PathBuf,
    /// Clips played one after another at their `fps` (the rest pose when none).
    pub clips: super::Clips,
    /// Frames over which a later clip blends in from the previous clip's last pose.
    pub fade: usize,
    pub garments: Vec<PathBuf>,
    /// One point cache per garment (with clips).
    pub caches: Vec<PathBuf>,
    /// The clip frame of each cache's first sample; by default the start each cache records.
    pub cache_start: Option<usize>,
    /// Each cached garment in its own panel.
    pub side_by_side: bool,
    /// Colour cached garments by their distance to this cache.
    pub error_vs: Option<PathBuf>,
    pub error_scale_mm: f64,
    /// A PBNS model whose garment is posed by the clips.
    pub model: Option<PathBuf>,
    /// With a model: plain LBS beside it.
    pub lbs: bool,
    /// Frames evenly spaced over the clip, unless `frame_list` names them.
    pub frames: usize,
    pub frame_list: Vec<usize>,
    pub views: Vec<View>,
    pub width: u32,
    pub height: u32,
}

/// The contact sheet `request` asks for, and its number of panels.
pub fn sheet(args: &Request) -> Result<(image::RgbImage, usize)> {
    let body = read_body(&args.body)?;
    let model = match &args.model {
        Some(path) => {
            let m = file::load(path, tch::Device::Cpu)?;
            check_skeleton(
                m.skeleton(),
                &body.skeleton,
                &args.body.display().to_string(),
            )?;
            Some(m)
        }
        None => None,
    };
    if args.lbs && model.is_none() {
        bail!("--lbs compares with a trained model: add --model");
    }
    let garments = args
        .garments
        .iter()
        .map(|p| Garment::read(p))
        .collect::<Result<Vec<_>>>()?;
    if args.clips.motions.is_empty() && !args.caches.is_empty() {
        bail!("--cache plays a garment over a clip: add --motion");
    }
    let clip = if args.clips.motions.is_empty() {
        None
    } else {
        Some(played(args, &body)?)
    };
    let fps = clip.as_ref().map_or(0.0, |c| c.0);
    // A cache of part of the clip (from `interpolate`) records its first frame; --cache-start
    // overrides it for caches of other tools.
    let read = |p: &PathBuf, vertices: usize| {
        let frames = crate::io::point_cache::read_pc2(p, vertices, fps)?;
        let start = args.cache_start.unwrap_or(frames.start);
        Ok(frames.starting_at(start))
    };
    let caches = args
        .caches
        .iter()
        .zip(&garments)
        .map(|(p, g)| read(p, g.mesh.vertex_count()))
        .collect::<Result<Vec<_>>>()?;
    let poses: Vec<Shown> = match &clip {
        None => vec![("rest".to_string(), body.skeleton.rest.clone(), 0)],
        Some((fps, sequence)) => {
            let fps = *fps;
            if garments.len() != args.caches.len() {
                bail!("with --motion each --garment needs its --cache (a point cache from simulate or eval), or a trained model: --model");
            }
            // Evenly spaced frames cover what every cache holds.
            let start = caches.iter().map(|c| c.start).max().unwrap_or(0);
            let end = caches
                .iter()
                .map(|c| c.start + c.len())
                .fold(sequence.len(), usize::min);
            let frames = pick_frames(start..end.max(start + 1), args.frames, &args.frame_list)?;
            frames
                .iter()
                .map(|&f| (frame_label(fps, f), sequence[f].clone(), f))
                .collect()
        }
    };
    for (cache, path) in caches.iter().zip(&args.caches) {
        check_covers(cache, path, &poses)?;
    }
    let reference = match &args.error_vs {
        Some(path) => {
            let Some(first) = garments.first() else {
                bail!("--error-vs colours cached garments: add --garment and --cache");
            };
            // The reference (a whole simulation) keeps its own start: --cache-start is for --cache.
            let frames = crate::io::point_cache::read_pc2(path, first.mesh.vertex_count(), fps)?;
            check_covers(&frames, path, &poses)?;
            Some(frames)
        }
        None => None,
    };
    let mut triangles: Vec<&[[u32; 3]]> = garments
        .iter()
        .map(|g| g.mesh.triangles.as_slice())
        .collect();
    if let Some(m) = &model {
        triangles.push(&m.garment.triangles);
    }
    let mut shots = Vec::new();
    for (label, pose, frame) in &poses {
        let skinning = body.skeleton.skinning_matrices(pose);
        let body_points = body.skin.skin_points(&body.mesh().positions, &skinning);
        let errors = |points: &[[f32; 3]]| {
            // Only garments of the reference's mesh are coloured.
            reference
                .as_ref()
                .filter(|r| r[*frame - r.start].len() == points.len())
                .map(|r| crate::metrics::vertex_distances_mm(points, &r[*frame - r.start]))
        };
        let mut drawn: Vec<Drawn> = garments
            .iter()
            .enumerate()
            .map(|(i, g)| match caches.get(i) {
                Some(c) => {
                    let x = &c[*frame - c.start];
                    (x.clone(), i, errors(x))
                }
                None => (g.mesh.positions.clone(), i, None),
            })
            .collect();
        if args.side_by_side && model.is_none() {
            for (garment, path) in drawn.into_iter().zip(&args.caches) {
                let name = path
                    .file_stem()
                    .map_or(String::new(), |n| n.to_string_lossy().into_owned());
                let error = garment.2.as_ref().map_or(String::new(), |e| {
                    format!(" {:.1}mm", e.iter().sum::<f64>() / e.len().max(1) as f64)
                });
                shots.push(Shot {
                    label: format!("{label} {name}{error}"),
                    body: body_points.clone(),
                    garments: vec![garment],
                });
            }
            continue;
        }
        let Some(m) = &model else {
            shots.push(Shot {
                label: label.clone(),
                body: body_points,
                garments: drawn,
            });
            continue;
        };
        let g = garments.len();
        let x = model_frames(
            m.pbns()?,
            &body.skeleton,
            std::slice::from_ref(pose),
            tch::Device::Cpu,
        );
        drawn.push((x.into_iter().next().expect("one frame"), g, None));
        shots.push(Shot {
            label: format!("{label} model"),
            body: body_points.clone(),
            garments: drawn,
        });
        if args.lbs {
            let lbs = m.lbs.skin_points(&m.garment.positions, &skinning);
            shots.push(Shot {
                label: format!("{label} LBS"),
                body: body_points,
                garments: vec![(lbs, g, None)],
            });
        }
    }
    let side = if args.side_by_side && model.is_none() {
        args.caches.len().max(1)
    } else {
        1
    };
    let per_frame = args.views.len() * if args.lbs { 2 } else { side };
    let layout = Layout {
        views: &args.views,
        columns: if args.lbs || side > 1 {
            per_frame
        } else {
            (per_frame * poses.len()).min(per_frame * 3)
        } as u32,
        panel_width: args.width,
        panel_height: args.height,
        error_scale_mm: args.error_scale_mm,
    };
    Ok(shots_sheet(
        &shots,
        &body.mesh().triangles,
        &triangles,
        &layout,
    ))
}

fn frame_label(fps: f32, frame: usize) -> String {
    // Short: the panel is narrow and the clip name is in the file name.
    format!("f{} {:.2}s", frame, frame as f32 / fps)
}

/// The --motion clips' poses one after another (`motion::chain`) and their shared rate.
fn played(args: &Request, body: &Body) -> Result<(f32, Vec<Vec<JointTransform>>)> {
    let reader = args.clips.reader()?;
    let clips = args
        .clips
        .motions
        .iter()
        .map(|m| Ok(load_clip(m, &reader, body, args.clips.fps)?.animation))
        .collect::<Result<Vec<_>>>()?;
    let fps = clips.first().map_or(30.0, |c| c.fps);
    if let Some((m, c)) = args
        .clips
        .motions
        .iter()
        .zip(&clips)
        .find(|(_, c)| (c.fps - fps).abs() > 1e-3)
    {
        bail!(
            "{}: plays at {} fps, the first clip at {fps}: give --fps to play them at one rate",
            m.display(),
            c.fps
        );
    }
    Ok((fps, chain(&clips.iter().collect::<Vec<_>>(), args.fade)))
}

/// The frames to show: an explicit list, or `count` evenly spaced ones (first and last included).
fn pick_frames(span: std::ops::Range<usize>, count: usize, list: &[usize]) -> Result<Vec<usize>> {
    if let Some(bad) = list.iter().find(|&&f| f >= span.end) {
        bail!(
            "frame {bad} is past the last frame there is to show ({}: the clip's end, or a --cache's)",
            span.end - 1
        );
    }
    if !list.is_empty() {
        return Ok(list.to_vec());
    }
    let total = span.len().max(1);
    let count = count.clamp(1, total);
    Ok((0..count)
        .map(|i| {
            span.start
                + if count == 1 {
                    0
                } else {
                    i * (total - 1) / (count - 1)
                }
        })
        .collect())
}

/// A posed frame to draw: label, pose, clip frame.
type Shown = (String, Vec<JointTransform>, usize);

/// Checks that a cache whose first sample is clip frame `start` holds every drawn frame (index
/// it by frame − `start`).
fn check_covers(frames: &Frames, path: &std::path::Path, poses: &[Shown]) -> Result<()> {
    let start = frames.start;
    let first = poses.iter().map(|p| p.2).min().unwrap_or(0);
    let last = poses.iter().map(|p| p.2).max().unwrap_or(0);
    if first < start {
        bail!(
            "{}: starts at clip frame {start} (its own start, or --cache-start), frame {first} asked for",
            path.display()
        );
    }
    if frames.len() + start <= last {
        bail!(
            "{}: {} frames from frame {start}, frame {last} asked for (was it written at another --fps?)",
            path.display(),
            frames.len()
        );
    }
    Ok(())
}
