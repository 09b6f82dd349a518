//! `eval`: a trained PBNS model over one clip, written as a point cache (and the posed body, and
//! a page), with the PBNS metrics beside plain linear blend skinning and the clip's pose coverage.

use crate::compute::Compute;
use crate::eval::{
    compare_frames, lbs_frames, model_frames, outside_weights, ClipCoverage, Comparison,
    OverlapSummary,
};
use crate::geometry::Frames;
use crate::io::gltf_body::read_body;
use crate::io::point_cache::write_cache_in;
use crate::metrics::{body_edges_under, ClothGeometry, Inside, Metrics};
use crate::models::coverage::OutsideWeights;
use crate::models::file::check_skeleton;
use anyhow::{bail, Result};
use exporters::atomic::OutputSet;
use serde::{Deserialize, Serialize};
use std::fmt::{self, Display, Formatter};
use std::path::PathBuf;

/// What to evaluate and write (the flags of `garmentbake eval`, resolved).
pub struct Request {
    /// Trained PBNS model.
    pub model: PathBuf,
    /// The clip (one motion), read at the model's rate.
    pub clips: super::Clips,
    /// Body to collide with; none: the model's own.
    pub body: Option<PathBuf>,
    /// The garment's point cache.
    pub out: PathBuf,
    /// The posed body's point cache.
    pub body_out: Option<PathBuf>,
    /// A page that plays the garment cache on the body.
    pub view: Option<PathBuf>,
    /// Keep each blend-shape weight within its range over the training poses.
    pub clamp_weights: bool,
    /// Units and up axis of the caches written.
    pub space: exporters::CacheSpace,
    pub compute: Compute,
}

/// Metrics of the model and of plain LBS over one clip.
#[derive(Serialize, Deserialize)]
pub struct Report {
    pub model: Option<String>,
    pub clip: String,
    pub motion: PathBuf,
    pub frames: usize,
    pub fps: f32,
    pub garment_vertices: usize,
    pub metrics: SeriesMetrics,
    /// Inside the body by the generalised winding number of the posed body mesh (exact; the
    /// `collided_pct` of `metrics` is the training proxy, the side of the nearest body vertex).
    pub inside: SeriesInside,
    pub strain_pct: Strain,
    pub body_overlap_vertices: OverlapSummary,
    /// Per-frame distance to the training poses and the metrics within / beyond the trained
    /// range (absent for models trained before the coverage report).
    pub coverage: Option<CoverageReport>,
    pub clamped_weights: bool,
    /// With --clamp-weights: the network's weights that lay outside the training range (the
    /// ones clamping changed).
    pub clamped: Option<OutsideWeights>,
    pub pc2: PathBuf,
    pub body_out: Option<PathBuf>,
    /// With --view: the page and its size in bytes.
    pub view: Option<(PathBuf, u64)>,
}

#[derive(Serialize, Deserialize)]
pub struct SeriesMetrics {
    pub model: Metrics,
    pub lbs: Metrics,
}

#[derive(Serialize, Deserialize)]
pub struct SeriesInside {
    pub model: Inside,
    pub lbs: Inside,
}

impl SeriesMetrics {
    /// From a comparison of the model (first series) and plain LBS (second).
    fn of(c: &Comparison) -> SeriesMetrics {
        SeriesMetrics {
            model: c.metrics[0],
            lbs: c.metrics[1],
        }
    }
}

impl SeriesInside {
    fn of(c: &Comparison) -> SeriesInside {
        SeriesInside {
            model: c.inside[0],
            lbs: c.inside[1],
        }
    }
}

/// A clip's pose coverage and the figures of its frames within and beyond the trained range.
#[derive(Serialize, Deserialize)]
pub struct CoverageReport {
    #[serde(flatten)]
    pub clip: ClipCoverage,
    /// The 8 frames farthest from the training poses (farthest first): the ones to look at.
    pub farthest: Vec<usize>,
    pub within: Option<Split>,
    pub beyond_range: Option<Split>,
}

/// Model and plain-LBS figures over a subset of a clip's frames.
#[derive(Serialize, Deserialize)]
pub struct Split {
    pub frames: usize,
    pub metrics: SeriesMetrics,
    pub inside: SeriesInside,
}

/// Mean edge strain |e − e_T| / e_T (%).
#[derive(Serialize, Deserialize)]
pub struct Strain {
    pub model: f64,
    pub lbs: f64,
    /// The skinned body under the garment: a garment that does not slide over it stretches as much.
    pub body_under_garment: f64,
}

/// Evaluates `request`, writes its outputs through `outputs` (checked by the caller before any
/// work, committed here) and measures the model and plain LBS.
pub fn run(request: &Request, outputs: OutputSet) -> Result<Report> {
    let r = request;
    let device = r.compute.apply()?;
    let mut model = crate::models::file::load(&r.model, device)?;
    if r.clamp_weights && model.coverage.is_none() {
        bail!(
            "{}: --clamp-weights needs the blend-shape weight range stored by `train` since the coverage report; retrain the model",
            r.model.display()
        );
    }
    model.pbns()?;
    let body = match &r.body {
        Some(path) => {
            let b = read_body(path)?;
            check_skeleton(model.skeleton(), &b.skeleton, &path.display().to_string())?;
            b
        }
        None => model.body.clone(),
    };
    let fps = crate::models::swing::clip_rate(model.pbns()?, r.clips.fps)?;
    let (motion, clip) = r.clips.load_single_at(&body, fps)?;
    let anim = &clip.animation;
    let poses: Vec<_> = (0..anim.frame_count())
        .map(|f| anim.local_pose(f))
        .collect();
    let clamped = match (&model.coverage, r.clamp_weights) {
        (Some(c), true) => {
            let outside = outside_weights(model.pbns()?, c, &body.skeleton, &poses, device);
            let (lo, hi) = (c.weight_min.clone(), c.weight_max.clone());
            if let crate::models::Model::Pbns(p) = &mut model.model {
                p.clamp_weights(&lo, &hi);
            }
            Some(outside)
        }
        _ => None,
    };
    let network = model.pbns()?;
    let garment = Frames::new(
        model_frames(network, &body.skeleton, &poses, device),
        anim.fps,
    );
    let lbs = lbs_frames(&model.lbs, &model.garment.positions, &body.skeleton, &poses);
    let geometry = ClothGeometry::new(&model.garment, model.info.fabric.density);
    let under = body_edges_under(&body, &model.garment.positions, UNDER);
    // Per frame once: the coverage split below means subsets of the same figures.
    let per_frame = compare_frames(&geometry, &[&garment, &lbs], &body, &under, &poses);
    let comparison = Comparison::of(&per_frame.iter().collect::<Vec<_>>(), 2);
    let space = r.space;
    outputs.write(&r.out, |p| {
        write_cache_in(p, &model.garment, &garment, space)
    })?;
    if let Some(path) = &r.body_out {
        let frames = Frames::new(
            lbs_frames(&body.skin, &body.mesh().positions, &body.skeleton, &poses),
            anim.fps,
        );
        outputs.write(path, |p| write_cache_in(p, body.mesh(), &frames, space))?;
    }
    let view = match &r.view {
        Some(page) => {
            let vat = crate::pipeline::view::staged_vat(&outputs, &r.out)?;
            let bytes = outputs.write(page, |p| {
                crate::pipeline::view::cache_page(
                    p,
                    (&body, &model.garment),
                    (&anim.name, anim.fps, &poses),
                    ("network", &garment),
                    None,
                    vat.as_ref(),
                )
            })?;
            Some((page.clone(), bytes))
        }
        None => None,
    };
    outputs.commit()?;
    let coverage = model.coverage.as_ref().map(|c| {
        let (clip, farthest) = ClipCoverage::of_clip(c, &network.feature_joints, anim);
        let split = |frames: Vec<usize>| {
            (!frames.is_empty()).then(|| {
                let picked: Vec<_> = frames.iter().map(|&f| &per_frame[f]).collect();
                let c = Comparison::of(&picked, 2);
                Split {
                    frames: frames.len(),
                    metrics: SeriesMetrics::of(&c),
                    inside: SeriesInside::of(&c),
                }
            })
        };
        CoverageReport {
            farthest,
            within: split(clip.within()),
            beyond_range: split(clip.beyond.clone()),
            clip,
        }
    });
    Ok(Report {
        model: r
            .model
            .file_name()
            .map(|n| n.to_string_lossy().into_owned()),
        clip: anim.name.clone(),
        motion: motion.to_path_buf(),
        frames: anim.frame_count(),
        fps: anim.fps,
        garment_vertices: network.shape.vertices,
        metrics: SeriesMetrics::of(&comparison),
        inside: SeriesInside::of(&comparison),
        strain_pct: Strain {
            model: comparison.strain_pct[0],
            lbs: comparison.strain_pct[1],
            body_under_garment: comparison.body_strain_pct,
        },
        body_overlap_vertices: OverlapSummary::of(&comparison.body_overlap),
        coverage,
        clamped_weights: r.clamp_weights,
        clamped,
        pc2: r.out.clone(),
        body_out: r.body_out.clone(),
        view,
    })
}

impl Display for Report {
    fn fmt(&self, f: &mut Formatter) -> fmt::Result {
        let r = self;
        writeln!(
            f,
            "{}: {} frames at {} fps, {} garment vertices",
            r.motion.display(),
            r.frames,
            r.fps,
            r.garment_vertices
        )?;
        writeln!(
            f,
            "{:<12} {:>10} {:>10} {:>13} {:>22} {:>12}",
            "", "edge (mm)", "bend", "collided (%)", "of which body overlap", "gravity (J)"
        )?;
        for (name, x) in [("model", &r.metrics.model), ("plain LBS", &r.metrics.lbs)] {
            writeln!(f, "{}", row(name, x))?;
        }
        writeln!(f,
        "inside the body by winding number (exact; \"collided\" above is the nearest-vertex proxy training minimises):"
    )?;
        writeln!(
            f,
            "{:<12} {:>10} {:>22} {:>28} {:>14}",
            "", "inside (%)", "of which body overlap", "depth p50 / p99 / max (mm)", "worst frame"
        )?;
        for (name, x) in [("model", &r.inside.model), ("plain LBS", &r.inside.lbs)] {
            writeln!(f, "{}", inside_row(name, x))?;
        }
        let s = &r.strain_pct;
        writeln!(f,
        "edge strain |e − e_T| / e_T: model {:.2} %, plain LBS {:.2} %; the skinned body under the garment {:.2} %",
        s.model, s.lbs, s.body_under_garment
    )?;
        let o = &r.body_overlap_vertices;
        writeln!(f,
        "body vertices inside another part of the skinned body: median {} per frame, most {} (frame {})",
        o.median, o.most, o.worst_frame
    )?;
        match &r.coverage {
            Some(c) => coverage_lines(f, c)?,
            None => writeln!(f,
            "coverage: this model has no training poses stored (trained before the coverage report)"
        )?,
        }
        if let Some(c) = &r.clamped {
            writeln!(f,
            "blend-shape weights clamped to their range over the training poses: {} of {} values were outside it ({:.2} %), in {} of {} frames",
            c.outside,
            c.values,
            100.0 * c.outside as f64 / c.values.max(1) as f64,
            c.frames,
            r.frames
        )?;
        }
        writeln!(f, "wrote {}", r.pc2.display())?;
        if let Some((page, bytes)) = &r.view {
            writeln!(
                f,
                "wrote {} ({:.1} MB)",
                page.display(),
                *bytes as f64 / 1e6
            )?;
        }
        Ok(())
    }
}

/// Body skin within this distance of the garment at rest counts as under it (metres).
const UNDER: f32 = 0.02;

fn coverage_lines(f: &mut Formatter, c: &CoverageReport) -> fmt::Result {
    writeln!(f, "{}", c.clip.line(&c.farthest))?;
    for (name, split) in [("within", &c.within), ("beyond", &c.beyond_range)] {
        if let Some(s) = split {
            writeln!(
                f,
                "  {name} the range ({} frames): edge model {:.3} / LBS {:.3} mm, inside model {:.2} / LBS {:.2} %",
                s.frames,
                s.metrics.model.edge_mm,
                s.metrics.lbs.edge_mm,
                s.inside.model.inside_pct,
                s.inside.lbs.inside_pct
            )?;
        }
    }
    Ok(())
}

fn inside_row(name: &str, m: &Inside) -> String {
    let depth = format!(
        "{:.2} / {:.2} / {:.2}",
        m.depth_p50_mm, m.depth_p99_mm, m.depth_max_mm
    );
    let worst = format!("{} ({} v)", m.worst_frame, m.worst_frame_vertices);
    format!(
        "{name:<12} {:>10.2} {:>22.2} {depth:>28} {worst:>14}",
        m.inside_pct, m.inside_overlap_pct
    )
}

fn row(name: &str, m: &Metrics) -> String {
    format!(
        "{name:<12} {:>10.3} {:>10.4} {:>13.2} {:>22.2} {:>12.4}",
        m.edge_mm, m.bend, m.collided_pct, m.collided_overlap_pct, m.gravity_j
    )
}
