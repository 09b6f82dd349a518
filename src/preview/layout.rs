//! A contact sheet of posed shots: each shot (a body and the garments drawn with it) becomes
//! one panel per view, garments coloured by their index or by their per-vertex error bands.

use super::{
    contact_sheet, DrawMesh, ErrorBands, FramingMode, Panel, SheetOptions, View, BODY_GREY,
    GARMENT_COLORS,
};

/// One posed frame: the body and the garments drawn with it.
pub struct Shot {
    pub label: String,
    pub body: Vec<[f32; 3]>,
    pub garments: Vec<Drawn>,
}

/// A garment's positions, its index among the garments (its triangles and colour), and per-vertex
/// errors in mm when it is coloured by its distance to a reference.
pub type Drawn = (Vec<[f32; 3]>, usize, Option<Vec<f64>>);

/// How the shots are laid out.
pub struct Layout<'a> {
    pub views: &'a [View],
    pub columns: u32,
    pub panel_width: u32,
    pub panel_height: u32,
    /// The error (mm) drawn red.
    pub error_scale_mm: f64,
}

/// The sheet of `shots` (the body's triangles, each garment index's triangles) and its number
/// of panels.
pub fn shots_sheet(
    shots: &[Shot],
    body_triangles: &[[u32; 3]],
    triangles: &[&[[u32; 3]]],
    layout: &Layout,
) -> (image::RgbImage, usize) {
    // Error bands per drawn garment, kept alive for the panels that borrow them.
    let bands: Vec<Vec<Option<ErrorBands>>> = shots
        .iter()
        .map(|shot| {
            shot.garments
                .iter()
                .map(|(_, i, e)| {
                    e.as_ref()
                        .map(|e| ErrorBands::new(triangles[*i], e, layout.error_scale_mm))
                })
                .collect()
        })
        .collect();
    let mut panels = Vec::new();
    for (shot, bands) in shots.iter().zip(&bands) {
        for &view in layout.views {
            let mut meshes = vec![DrawMesh {
                positions: &shot.body,
                triangles: body_triangles,
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
                view,
                label: format!("{} {}", shot.label, name(view)),
            });
        }
    }
    let opts = SheetOptions {
        panel_width: layout.panel_width,
        panel_height: layout.panel_height,
        columns: layout.columns,
        // Each frame framed on its own: a walking body stays large and centred.
        framing: FramingMode::PerPanel,
        ..Default::default()
    };
    (contact_sheet(&panels, &opts), panels.len())
}

/// A view's name in a panel's label, as `preview --views` spells it.
fn name(view: View) -> &'static str {
    match view {
        View::Front => "front",
        View::Side => "side",
        View::Back => "back",
        View::ThreeQuarter => "three-quarter",
    }
}
