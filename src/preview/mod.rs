//! Software rasteriser for PNG previews of posed bodies and draped garments.
//!
//! Self-contained on purpose: plain slices in, `image::RgbImage` / PNG out, so the
//! CLI can show a contact sheet of frames without a GPU or a font crate.
//!
//! Conventions: metres, Y-up, right-handed, characters face +Z. Projection is
//! orthographic; every view looks horizontally, so world `y` is always image-up.
//! * [`View::Front`]: camera on +Z looking to -Z (world +X is image right, so the
//!   character's left hand appears on the image's right, as when facing a person).
//! * [`View::Side`]: camera on +X looking to -X (the character faces image left).
//! * [`View::Back`]: camera on -Z looking to +Z.
//! * [`View::ThreeQuarter`]: camera on (+X, +Z) at 45°, looking at the character's
//!   front-left.

mod font;
mod framing;
pub mod layout;
pub mod plot;
mod raster;
mod sheet;
#[cfg(test)]
mod tests;

use std::path::Path;

pub use font::{draw_text, has_glyph};
pub use framing::{Framing, FramingMode, View};
pub use sheet::{contact_sheet, render_panel, render_panel_with};

/// Suggested colour for the body, so garments read against it.
pub const BODY_GREY: [u8; 3] = [175, 175, 178];
/// Suggested garment colours (cycled when several garments are drawn).
pub const GARMENT_COLORS: [[u8; 3]; 4] = [
    [70, 120, 210],
    [210, 90, 70],
    [80, 170, 100],
    [200, 160, 60],
];

/// Colours from "within a tenth of the scale" (green) to "at or past it" (red).
pub const ERROR_COLORS: [[u8; 3]; 5] = [
    [60, 170, 90],
    [150, 200, 60],
    [240, 200, 50],
    [240, 130, 40],
    [210, 40, 40],
];
/// The error bands' lower edges as fractions of the scale (band 0 starts at 0).
pub const ERROR_EDGES: [f64; 4] = [0.1, 0.3, 0.6, 1.0];

/// A mesh's triangles sorted into the [`ERROR_COLORS`] bands by their largest vertex error
/// against `scale` (same unit), so a picture shows where an error is.
pub struct ErrorBands {
    bands: Vec<Vec<[u32; 3]>>,
}

impl ErrorBands {
    pub fn new(triangles: &[[u32; 3]], vertex_errors: &[f64], scale: f64) -> ErrorBands {
        let band = |e: f64| {
            ERROR_EDGES
                .iter()
                .filter(|&&edge| e >= edge * scale)
                .count()
        };
        let mut bands = vec![Vec::new(); ERROR_COLORS.len()];
        for t in triangles {
            let e = t
                .iter()
                .map(|&v| vertex_errors[v as usize])
                .fold(0.0, f64::max);
            bands[band(e)].push(*t);
        }
        ErrorBands { bands }
    }

    /// One mesh per band, drawn at `positions`.
    pub fn meshes<'a>(&'a self, positions: &'a [[f32; 3]]) -> Vec<DrawMesh<'a>> {
        self.bands
            .iter()
            .zip(ERROR_COLORS)
            .map(|(triangles, color)| DrawMesh {
                positions,
                triangles,
                color,
            })
            .collect()
    }
}

/// One triangle mesh to draw in a single flat colour (shaded by the renderer).
#[derive(Clone, Copy, Debug)]
pub struct DrawMesh<'a> {
    pub positions: &'a [[f32; 3]],
    pub triangles: &'a [[u32; 3]],
    pub color: [u8; 3],
}

/// One cell of a contact sheet: meshes drawn together from one view, with a label.
#[derive(Clone, Debug)]
pub struct Panel<'a> {
    pub meshes: Vec<DrawMesh<'a>>,
    pub view: View,
    pub label: String,
}

/// Layout and style of a contact sheet (also used by [`render_panel_with`]).
#[derive(Clone, Debug, PartialEq)]
pub struct SheetOptions {
    pub panel_width: u32,
    pub panel_height: u32,
    /// Panels per row; rows are filled in order (row-major). 0 is treated as 1.
    pub columns: u32,
    pub background: [u8; 3],
    /// Shared (default): one framing per view over all panels, so frames are comparable.
    pub framing: FramingMode,
    /// Render at this factor and box-downsample (1 = off, clamped to 1..=4).
    pub supersample: u32,
    /// Height of the floor line in metres (`None` draws no line).
    pub floor_y: Option<f32>,
    /// Font pixel size of the labels; a sheet whose longest label does not fit a panel at this
    /// size draws every label at size 1 (the same size everywhere, never clipped).
    pub label_scale: u32,
}

impl Default for SheetOptions {
    fn default() -> Self {
        SheetOptions {
            panel_width: 320,
            panel_height: 480,
            columns: 4,
            background: [238, 238, 238],
            framing: FramingMode::Shared,
            supersample: 2,
            floor_y: Some(0.0),
            label_scale: 2,
        }
    }
}

/// Write `img` as PNG to `path` atomically ([`exporters::atomic`]), so a reader never sees a
/// half-written preview; the error names the path.
pub fn save_png(img: &image::RgbImage, path: &Path) -> std::io::Result<()> {
    exporters::atomic::write_atomic_with(path, |w| {
        img.write_to(w, image::ImageFormat::Png)
            .map_err(std::io::Error::other)
    })
}
