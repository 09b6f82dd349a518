//! `garmentbake preview`: a PNG contact sheet of the posed body (and garments at rest).

use crate::io::gltf_body::{read_body, Body};
use crate::io::obj::read_obj;
use crate::motion::{load_clip, read_maps};
use crate::preview::{
    contact_sheet, save_png, DrawMesh, FramingMode, Panel, SheetOptions, View, BODY_GREY,
    GARMENT_COLORS,
};
use crate::rig::SkelAnimation;
use anyhow::{bail, Result};
use std::path::PathBuf;

/// Render the body (grey) posed by a clip, front and side, to a PNG contact sheet.
///
/// Without --motion the body is drawn in its rest pose together with any --garment OBJs
/// (coloured), which shows how garments sit on the body before training.
#[derive(clap::Args)]
pub struct Args {
    /// Skinned body (glTF/glb).
    #[arg(long)]
    body: PathBuf,
    /// BVH clip to pose the body with (rest pose when omitted).
    #[arg(long)]
    motion: Option<PathBuf>,
    /// Joint-name map(s) for the clip (TOML).
    #[arg(long = "map")]
    maps: Vec<PathBuf>,
    /// Garment OBJ(s) drawn at rest (only without --motion).
    #[arg(long = "garment")]
    garments: Vec<PathBuf>,
    /// Number of frames, evenly spaced over the clip.
    #[arg(long, default_value_t = 6)]
    frames: usize,
    /// Explicit frame numbers instead of --frames, e.g. 0,120,240.
    #[arg(long, value_delimiter = ',')]
    frame_list: Vec<usize>,
    /// Views per frame: front, side, back, three-quarter.
    #[arg(long, value_delimiter = ',', default_values_t = [ViewArg::Front, ViewArg::Side])]
    views: Vec<ViewArg>,
    /// Panel size in pixels.
    #[arg(long, default_value_t = 240)]
    width: u32,
    #[arg(long, default_value_t = 360)]
    height: u32,
    /// Output PNG.
    #[arg(long)]
    out: PathBuf,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum ViewArg {
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

pub fn run(args: Args) -> Result<i32> {
    let body = read_body(&args.body)?;
    let shots: Vec<(String, Vec<[f32; 3]>)> = match &args.motion {
        Some(path) => {
            if !args.garments.is_empty() {
                bail!("--garment is drawn at rest only; drop --motion (posing garments needs a trained model)");
            }
            let clip = load_clip(path, &read_maps(&args.maps)?, &body.skeleton, None)?;
            let frames = pick_frames(clip.animation.frame_count(), args.frames, &args.frame_list)?;
            frames
                .iter()
                .map(|&f| {
                    (
                        frame_label(&clip.animation, f),
                        posed(&body, &clip.animation, f),
                    )
                })
                .collect()
        }
        None => vec![("rest".to_string(), body.mesh.positions.clone())],
    };
    let garments = args
        .garments
        .iter()
        .map(|p| read_obj(p))
        .collect::<Result<Vec<_>, _>>()?;
    let mut panels = Vec::new();
    for (label, points) in &shots {
        for view in &args.views {
            let mut meshes = vec![DrawMesh {
                positions: points,
                triangles: &body.mesh.triangles,
                color: BODY_GREY,
            }];
            for (i, g) in garments.iter().enumerate() {
                let color = GARMENT_COLORS[i % GARMENT_COLORS.len()];
                meshes.push(DrawMesh {
                    positions: &g.mesh.positions,
                    triangles: &g.mesh.triangles,
                    color,
                });
            }
            panels.push(Panel {
                meshes,
                view: (*view).into(),
                label: format!("{label} {view}"),
            });
        }
    }
    let opts = SheetOptions {
        panel_width: args.width,
        panel_height: args.height,
        columns: (args.views.len() * shots.len()).min(args.views.len() * 3) as u32,
        // Each frame framed on its own: a walking body stays large and centred.
        framing: FramingMode::PerPanel,
        ..Default::default()
    };
    save_png(&contact_sheet(&panels, &opts), &args.out)?;
    println!("wrote {} ({} panels)", args.out.display(), panels.len());
    Ok(0)
}

fn frame_label(anim: &SkelAnimation, frame: usize) -> String {
    // Short: the panel is narrow and the clip name is in the file name.
    format!("f{} {:.2}s", frame, frame as f32 / anim.fps)
}

/// The frames to show: an explicit list, or `count` evenly spaced ones (first and last included).
pub(crate) fn pick_frames(total: usize, count: usize, list: &[usize]) -> Result<Vec<usize>> {
    if let Some(bad) = list.iter().find(|&&f| f >= total) {
        bail!("frame {bad} is past the end of the clip ({total} frames)");
    }
    if !list.is_empty() {
        return Ok(list.to_vec());
    }
    let count = count.clamp(1, total);
    Ok((0..count)
        .map(|i| {
            if count == 1 {
                0
            } else {
                i * (total - 1) / (count - 1)
            }
        })
        .collect())
}

fn posed(body: &Body, anim: &SkelAnimation, frame: usize) -> Vec<[f32; 3]> {
    let skinning = body.skeleton.skinning_matrices(&anim.local_pose(frame));
    body.skin.skin_points(&body.mesh.positions, &skinning)
}
