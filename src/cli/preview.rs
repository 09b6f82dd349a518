//! `garmentbake preview`: a PNG contact sheet of the posed body, garments at rest, or garments
//! played by point caches (side by side, or coloured by the distance to a reference).

use super::args::{output_set, OutputArgs, PNG};
use super::Execute;
use crate::eval::model_frames;
use crate::garment::Garment;
use crate::io::gltf_body::read_body;
use crate::models::file::{self, check_skeleton};
use crate::motion::{chain, load_clip, read_maps};
use crate::preview::{
    contact_sheet, save_png, DrawMesh, ErrorBands, FramingMode, Panel, SheetOptions, View,
    BODY_GREY, GARMENT_COLORS,
};
use crate::rig::{JointTransform, Skeleton};
use anyhow::{bail, Result};
use serde::Serialize;
use std::path::PathBuf;

/// Render the body (grey) posed by a clip, front and side, to a PNG contact sheet.
///
/// Without --motion the body is drawn in its rest pose together with any --garment meshes
/// (coloured), which shows how garments sit on the body before training. With --model the
/// trained garment is drawn posed on the body (and, with --lbs, next to plain linear blend
/// skinning of the same garment, for comparison).
#[derive(clap::Args)]
pub struct Args {
    /// Skinned body (glTF/glb).
    #[arg(long)]
    pub body: PathBuf,
    /// BVH clip to pose the body with (rest pose when omitted). Several play one after another
    /// as one sequence, each later clip blended in over --fade frames (as `rollout` chains
    /// them), so a chained roll-out's cache can be shown.
    #[arg(long = "motion")]
    pub motions: Vec<PathBuf>,
    /// Frames over which a later --motion clip blends in from the previous clip's last pose.
    #[arg(long, default_value_t = 15)]
    pub fade: usize,
    /// Joint-name map(s) for the clip (TOML).
    #[arg(long = "map")]
    pub maps: Vec<PathBuf>,
    /// Garment mesh(es) drawn at rest, OBJ or USD (only without --motion).
    #[arg(long = "garment")]
    pub garments: Vec<PathBuf>,
    /// With --motion: one point cache per --garment (.pc2, one sample per clip frame, e.g. from
    /// `simulate` or `eval`) that poses it.
    #[arg(long = "cache")]
    pub caches: Vec<PathBuf>,
    /// The clip frame of each --cache's first sample (a cache of part of the clip, e.g. from
    /// `interpolate`); --error-vs always starts at frame 0.
    #[arg(long, default_value_t = 0)]
    pub cache_start: usize,
    /// With several --cache: draw each cached garment in its own panel (labelled by its file
    /// name), side by side per frame, instead of all on one body: model / simulation / LBS.
    #[arg(long)]
    pub side_by_side: bool,
    /// Colour each cached garment by its per-vertex distance to this cache of the same garment
    /// (e.g. the simulation): green under a tenth of --error-scale-mm, red at or past it.
    #[arg(long, value_name = "REF.pc2")]
    pub error_vs: Option<PathBuf>,
    /// The distance (mm) drawn red by --error-vs.
    #[arg(long, default_value_t = 50.0, value_parser = super::args::positive::<f64>())]
    pub error_scale_mm: f64,
    /// Resample the clip to this rate (the rate the caches were written at).
    #[arg(long, value_parser = super::args::positive::<f32>())]
    pub fps: Option<f32>,
    /// Trained PBNS model (.safetensors): draw its garment posed by the clip.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// With --model: add a panel of plain LBS (proximity weights, no PSD) next to each one.
    #[arg(long)]
    pub lbs: bool,
    /// Number of frames, evenly spaced over the clip.
    #[arg(long, default_value_t = 6)]
    pub frames: usize,
    /// Explicit frame numbers instead of --frames, e.g. 0,120,240.
    #[arg(long, value_delimiter = ',')]
    pub frame_list: Vec<usize>,
    /// Views per frame: front, side, back, three-quarter.
    #[arg(long, value_delimiter = ',', default_values_t = [ViewArg::Front, ViewArg::Side])]
    pub views: Vec<ViewArg>,
    /// Panel size in pixels.
    #[arg(long, default_value_t = 240)]
    pub width: u32,
    #[arg(long, default_value_t = 360)]
    pub height: u32,
    /// Output PNG.
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub output: OutputArgs,
}

/// The picture written.
#[derive(Serialize)]
pub struct Report {
    pub out: PathBuf,
    pub panels: usize,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum ViewArg {
    Front,
    Side,
    Back,
    ThreeQuarter,
}

impl std::fmt::Display for ViewArg {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        use clap::ValueEnum;
        f.write_str(
            self.to_possible_value()
                .expect("no skipped values")
                .get_name(),
        )
    }
}

impl From<ViewArg> for View {
    fn from(v: ViewArg) -> View {
        match v {
            ViewArg::Front => View::Front,
            ViewArg::Side => View::Side,
            ViewArg::Back => View::Back,
            ViewArg::ThreeQuarter => View::ThreeQuarter,
        }
    }
}

/// One posed frame: the body and the garments drawn with it.
struct Shot {
    label: String,
    body: Vec<[f32; 3]>,
    garments: Vec<Drawn>,
}

/// A garment's positions, its index among the garments, and per-vertex errors in mm with
/// --error-vs.
type Drawn = (Vec<[f32; 3]>, usize, Option<Vec<f64>>);

impl Execute for Args {
    type Report = Report;

    fn execute(&self, _say: &dyn Fn(&str)) -> Result<Report> {
        render(self)
    }

    fn print(r: &Report) {
        println!("wrote {} ({} panels)", r.out.display(), r.panels);
    }
}

fn render(args: &Args) -> Result<Report> {
    let outputs = output_set(&[("--out", Some(&args.out), PNG)])?;
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
    let caches = args
        .caches
        .iter()
        .zip(&garments)
        .map(|(p, g)| crate::io::point_cache::read_pc2(p, g.mesh.vertex_count()))
        .collect::<Result<Vec<_>>>()?;
    let poses: Vec<Shown> = if args.motions.is_empty() {
        if !args.caches.is_empty() {
            bail!("--cache plays a garment over a clip: add --motion");
        }
        vec![("rest".to_string(), body.skeleton.rest.clone(), 0)]
    } else {
        if garments.len() != args.caches.len() {
            bail!("with --motion each --garment needs its --cache (a point cache from simulate or eval), or a trained model: --model");
        }
        let (fps, sequence) = played(args, &body.skeleton)?;
        // Evenly spaced frames cover what every cache holds.
        let start = if caches.is_empty() {
            0
        } else {
            args.cache_start
        };
        let end = caches
            .iter()
            .map(|c| start + c.len())
            .fold(sequence.len(), usize::min);
        let frames = pick_frames(start..end.max(start + 1), args.frames, &args.frame_list)?;
        frames
            .iter()
            .map(|&f| (frame_label(fps, f), sequence[f].clone(), f))
            .collect()
    };
    for (cache, path) in caches.iter().zip(&args.caches) {
        check_covers(cache, path, &poses, args.cache_start)?;
    }
    let reference = match &args.error_vs {
        Some(path) => {
            let Some(first) = garments.first() else {
                bail!("--error-vs colours cached garments: add --garment and --cache");
            };
            let frames = crate::io::point_cache::read_pc2(path, first.mesh.vertex_count())?;
            check_covers(&frames, path, &poses, 0)?;
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
        let body_points = body.skin.skin_points(&body.mesh.positions, &skinning);
        let errors = |points: &[[f32; 3]]| {
            // Only garments of the reference's mesh are coloured.
            reference
                .as_ref()
                .filter(|r| r[*frame].len() == points.len())
                .map(|r| crate::metrics::vertex_distances_mm(points, &r[*frame]))
        };
        let mut drawn: Vec<Drawn> = garments
            .iter()
            .enumerate()
            .map(|(i, g)| match caches.get(i) {
                Some(c) => {
                    let x = &c[*frame - args.cache_start];
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
    // Error bands per drawn garment, kept alive for the panels that borrow them.
    let bands: Vec<Vec<Option<ErrorBands>>> = shots
        .iter()
        .map(|shot| {
            shot.garments
                .iter()
                .map(|(_, i, e)| {
                    e.as_ref()
                        .map(|e| ErrorBands::new(triangles[*i], e, args.error_scale_mm))
                })
                .collect()
        })
        .collect();
    let mut panels = Vec::new();
    for (shot, bands) in shots.iter().zip(&bands) {
        for view in &args.views {
            let mut meshes = vec![DrawMesh {
                positions: &shot.body,
                triangles: &body.mesh.triangles,
                color: BODY_GREY,
            }];
            for ((points, i, _), band) in shot.garments.iter().zip(bands) {
                match band {
                    Some(b) => meshes.extend(b.meshes(points)),
                    None => meshes.push(DrawMesh {
                        positions: points,
                        triangles: triangles[*i],
                        color: GARMENT_COLORS[*i % GARMENT_COLORS.len()],
                    }),
                }
            }
            panels.push(Panel {
                meshes,
                view: (*view).into(),
                label: format!("{} {view}", shot.label),
            });
        }
    }
    let side = if args.side_by_side && model.is_none() {
        args.caches.len().max(1)
    } else {
        1
    };
    let per_frame = args.views.len() * if args.lbs { 2 } else { side };
    let opts = SheetOptions {
        panel_width: args.width,
        panel_height: args.height,
        columns: if args.lbs || side > 1 {
            per_frame
        } else {
            (per_frame * poses.len()).min(per_frame * 3)
        } as u32,
        // Each frame framed on its own: a walking body stays large and centred.
        framing: FramingMode::PerPanel,
        ..Default::default()
    };
    let sheet = contact_sheet(&panels, &opts);
    outputs.write(&args.out, |p| save_png(&sheet, p))?;
    outputs.commit()?;
    Ok(Report {
        out: args.out.clone(),
        panels: panels.len(),
    })
}

fn frame_label(fps: f32, frame: usize) -> String {
    // Short: the panel is narrow and the clip name is in the file name.
    format!("f{} {:.2}s", frame, frame as f32 / fps)
}

/// The --motion clips' poses one after another (`motion::chain`) and their shared rate.
fn played(args: &Args, skeleton: &Skeleton) -> Result<(f32, Vec<Vec<JointTransform>>)> {
    let maps = read_maps(&args.maps)?;
    let clips = args
        .motions
        .iter()
        .map(|m| Ok(load_clip(m, &maps, skeleton, args.fps)?.animation))
        .collect::<Result<Vec<_>>>()?;
    let fps = clips.first().map_or(30.0, |c| c.fps);
    if let Some((m, c)) = args
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
pub(crate) fn pick_frames(
    span: std::ops::Range<usize>,
    count: usize,
    list: &[usize],
) -> Result<Vec<usize>> {
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
fn check_covers(
    frames: &[Vec<[f32; 3]>],
    path: &std::path::Path,
    poses: &[Shown],
    start: usize,
) -> Result<()> {
    let first = poses.iter().map(|p| p.2).min().unwrap_or(0);
    let last = poses.iter().map(|p| p.2).max().unwrap_or(0);
    if first < start {
        bail!(
            "{}: starts at clip frame {start} (--cache-start), frame {first} asked for",
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
