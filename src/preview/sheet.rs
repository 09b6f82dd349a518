//! Panels (one view of some meshes) and contact sheets (a grid of panels).

use super::font::{draw_text, text_width};
use super::framing::{Framing, FramingMode, View};
use super::raster::{Camera, Target};
use super::{Panel, SheetOptions};

const LABEL_MARGIN: u32 = 6;
/// Depth jump (metres) that draws an outline; see `Target::outline`.
const OUTLINE_DEPTH: f32 = 0.03;

/// Render one panel of `w`×`h` pixels with the default style (2× supersampling,
/// floor line at y = 0, light background). See [`render_panel_with`].
pub fn render_panel(panel: &Panel, w: u32, h: u32, framing: &Framing) -> image::RgbImage {
    let opts = SheetOptions {
        panel_width: w,
        panel_height: h,
        ..SheetOptions::default()
    };
    render_panel_with(panel, framing, &opts)
}

/// Render one panel using the size and style of `opts` (`columns` and `framing` mode
/// are ignored). `framing` must be made for `panel.view`; if its view differs the panel
/// is fitted to its own meshes instead, since another view's rectangle means nothing here.
pub fn render_panel_with(panel: &Panel, framing: &Framing, opts: &SheetOptions) -> image::RgbImage {
    let (w, h) = (opts.panel_width, opts.panel_height);
    if w == 0 || h == 0 {
        return image::RgbImage::new(w, h);
    }
    let own;
    let framing = if framing.view == panel.view {
        framing
    } else {
        own = Framing::fit_meshes(&panel.meshes, panel.view);
        &own
    };
    let ss = opts.supersample.clamp(1, 4) as usize;
    let (tw, th) = (w as usize * ss, h as usize * ss);
    let mut target = Target::new(tw, th, opts.background);
    let cam = Camera::new(panel.view, framing, tw, th);
    if let Some(floor_y) = opts.floor_y {
        // One output pixel thick, drawn first so meshes cover it.
        let y0 = (cam.row_of(floor_y) - ss as f32 * 0.5).round() as i64;
        target.fill_rows(y0, y0 + ss as i64, floor_color(opts.background));
    }
    for mesh in &panel.meshes {
        target.draw_mesh(&cam, mesh);
    }
    // Ignore depth steps of a few pixels so steep but continuous surfaces stay clean.
    target.outline(OUTLINE_DEPTH.max(4.0 / cam.scale()));
    let mut img = target.downsample(ss);
    let ink = text_color(opts.background);
    let scale = label_scale(std::slice::from_ref(panel), opts);
    draw_text(
        &mut img,
        &panel.label,
        LABEL_MARGIN,
        LABEL_MARGIN,
        scale,
        ink,
    );
    img
}

/// Lay `panels` out row-major in a grid of `opts.columns` columns. With
/// [`FramingMode::Shared`] every panel of a view uses one framing fitted to all of
/// them, so frames are comparable. An empty list gives one blank row.
pub fn contact_sheet(panels: &[Panel], opts: &SheetOptions) -> image::RgbImage {
    let (w, h) = (opts.panel_width, opts.panel_height);
    let cols = opts.columns.max(1);
    let rows = (panels.len() as u32).div_ceil(cols).max(1);
    let mut sheet = image::RgbImage::from_pixel(cols * w, rows * h, image::Rgb(opts.background));
    let mut shared: Vec<Framing> = Vec::new();
    let framings: Vec<Framing> = panels
        .iter()
        .map(|panel| match opts.framing {
            FramingMode::PerPanel => Framing::fit_meshes(&panel.meshes, panel.view),
            FramingMode::Shared => shared_framing(&mut shared, panels, panel.view),
        })
        .collect();
    let opts = &SheetOptions {
        label_scale: label_scale(panels, opts),
        ..opts.clone()
    };
    for (i, img) in render_all(panels, &framings, opts).iter().enumerate() {
        let (col, row) = (i as u32 % cols, i as u32 / cols);
        image::imageops::replace(&mut sheet, img, (col * w) as i64, (row * h) as i64);
    }
    sheet
}

/// `opts.label_scale` if every label fits its panel at that size, else 1.
fn label_scale(panels: &[Panel], opts: &SheetOptions) -> u32 {
    let fits =
        |p: &Panel| text_width(&p.label, opts.label_scale) + 2 * LABEL_MARGIN <= opts.panel_width;
    if panels.iter().all(fits) {
        opts.label_scale.max(1)
    } else {
        1
    }
}

/// Render panels on scoped threads (panels are independent), results in input order.
fn render_all(panels: &[Panel], framings: &[Framing], opts: &SheetOptions) -> Vec<image::RgbImage> {
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(panels.len());
    if threads <= 1 {
        return panels
            .iter()
            .zip(framings)
            .map(|(p, f)| render_panel_with(p, f, opts))
            .collect();
    }
    let chunk = panels.len().div_ceil(threads);
    std::thread::scope(|scope| {
        let workers: Vec<_> = panels
            .chunks(chunk)
            .zip(framings.chunks(chunk))
            .map(|(ps, fs)| {
                scope.spawn(move || {
                    ps.iter()
                        .zip(fs)
                        .map(|(p, f)| render_panel_with(p, f, opts))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        workers
            .into_iter()
            .flat_map(|t| t.join().expect("panel render thread panicked"))
            .collect()
    })
}

/// The framing for `view` over all panels, computed once per view.
fn shared_framing(cache: &mut Vec<Framing>, panels: &[Panel], view: View) -> Framing {
    if let Some(f) = cache.iter().find(|f| f.view == view) {
        return *f;
    }
    let f = Framing::fit_panels(panels, view);
    cache.push(f);
    f
}

fn luminance(c: [u8; 3]) -> f32 {
    0.299 * c[0] as f32 + 0.587 * c[1] as f32 + 0.114 * c[2] as f32
}

/// Dark text on light backgrounds and vice versa.
fn text_color(background: [u8; 3]) -> [u8; 3] {
    if luminance(background) > 128.0 {
        [30, 30, 30]
    } else {
        [235, 235, 235]
    }
}

/// A grey clearly off the background, whichever way it leans.
fn floor_color(background: [u8; 3]) -> [u8; 3] {
    let target = if luminance(background) > 128.0 {
        120.0
    } else {
        150.0
    };
    background.map(|c| (c as f32 * 0.3 + target * 0.7) as u8)
}
