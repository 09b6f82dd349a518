//! Line charts as PNG (error against horizon, hem traces, spectra): axes with round ticks, one
//! polyline per series, a legend. Same built-in font as the contact sheets, so labels use its
//! characters (letters, digits, ` _-.:/()%`).

use super::font::{draw_text, text_width};
use image::{Rgb, RgbImage};

/// One line of a chart.
#[derive(Clone, Debug)]
pub struct Line {
    pub label: String,
    /// (x, y) points in order; non-finite ones break the line.
    pub points: Vec<(f64, f64)>,
    pub color: [u8; 3],
    /// Pixels wide (1 or more).
    pub width: u32,
}

/// A chart: title, axis names, lines.
#[derive(Clone, Debug)]
pub struct Chart {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub lines: Vec<Line>,
    /// Start the y axis at 0 (errors, powers) rather than at the data's minimum.
    pub y_from_zero: bool,
}

const MARGIN_LEFT: u32 = 70;
const MARGIN_RIGHT: u32 = 16;
const MARGIN_TOP: u32 = 40;
const MARGIN_BOTTOM: u32 = 44;
const AXIS: [u8; 3] = [60, 60, 60];
const GRID: [u8; 3] = [220, 220, 220];

/// Colours for the lines of a chart, cycled (simulations get greys by the caller).
pub const LINE_COLORS: [[u8; 3]; 6] = [
    [70, 120, 210],
    [210, 90, 70],
    [80, 170, 100],
    [200, 160, 60],
    [150, 80, 180],
    [40, 170, 190],
];

/// The chart drawn on a `width` × `height` white image.
pub fn line_chart(chart: &Chart, width: u32, height: u32) -> RgbImage {
    let mut img = RgbImage::from_pixel(width, height, Rgb([255, 255, 255]));
    let plot = Plot::new(chart, width, height);
    for (v, y) in ticks(plot.y0, plot.y1) {
        let row = plot.row(v);
        hline(&mut img, plot.left, plot.right, row, GRID);
        draw_text(
            &mut img,
            &y,
            plot.left.saturating_sub(text_width(&y, 1) + 6),
            row.saturating_sub(3),
            1,
            AXIS,
        );
    }
    for (v, x) in ticks(plot.x0, plot.x1) {
        let col = plot.col(v);
        vline(&mut img, col, plot.top, plot.bottom, GRID);
        draw_text(
            &mut img,
            &x,
            col.saturating_sub(text_width(&x, 1) / 2),
            plot.bottom + 6,
            1,
            AXIS,
        );
    }
    hline(&mut img, plot.left, plot.right, plot.bottom, AXIS);
    vline(&mut img, plot.left, plot.top, plot.bottom, AXIS);
    for line in &chart.lines {
        let mut last: Option<(f64, f64)> = None;
        for &(x, y) in &line.points {
            if !(x.is_finite() && y.is_finite()) {
                last = None;
                continue;
            }
            let here = (plot.fx(x), plot.fy(y));
            if let Some(from) = last {
                segment(&mut img, from, here, line.color, line.width, &plot);
            }
            last = Some(here);
        }
    }
    draw_text(&mut img, &chart.title, plot.left, 6, 2, AXIS);
    let xl = &chart.x_label;
    draw_text(
        &mut img,
        xl,
        (plot.left + plot.right) / 2 - text_width(xl, 1) / 2,
        height - 14,
        1,
        AXIS,
    );
    draw_text(
        &mut img,
        &chart.y_label,
        4,
        plot.top.saturating_sub(12),
        1,
        AXIS,
    );
    // (the title sits above it, from the plot's left edge)
    // Legend, top right inside the plot.
    let widest = chart
        .lines
        .iter()
        .map(|l| text_width(&l.label, 1))
        .max()
        .unwrap_or(0);
    let x = plot.right.saturating_sub(widest + 30);
    for (i, line) in chart.lines.iter().enumerate() {
        let y = plot.top + 6 + 12 * i as u32;
        for dy in 0..line.width.clamp(1, 3) {
            hline(&mut img, x, x + 18, y + 3 + dy, line.color);
        }
        draw_text(&mut img, &line.label, x + 22, y, 1, AXIS);
    }
    img
}

/// Several images one above the other (widths padded to the widest).
pub fn stack(images: &[RgbImage]) -> RgbImage {
    let w = images.iter().map(|i| i.width()).max().unwrap_or(1);
    let h = images.iter().map(|i| i.height()).sum::<u32>().max(1);
    let mut out = RgbImage::from_pixel(w, h, Rgb([255, 255, 255]));
    let mut y = 0;
    for img in images {
        image::imageops::replace(&mut out, img, 0, i64::from(y));
        y += img.height();
    }
    out
}

/// The plot area and the data ranges it shows.
struct Plot {
    left: u32,
    right: u32,
    top: u32,
    bottom: u32,
    x0: f64,
    x1: f64,
    y0: f64,
    y1: f64,
}

impl Plot {
    fn new(chart: &Chart, width: u32, height: u32) -> Plot {
        let finite = || {
            chart
                .lines
                .iter()
                .flat_map(|l| l.points.iter())
                .filter(|(x, y)| x.is_finite() && y.is_finite())
        };
        let range = |v: &mut dyn Iterator<Item = f64>| {
            v.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
                (a.min(x), b.max(x))
            })
        };
        let (mut x0, mut x1) = range(&mut finite().map(|p| p.0));
        let (mut y0, mut y1) = range(&mut finite().map(|p| p.1));
        if !x0.is_finite() {
            (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
        }
        if chart.y_from_zero {
            y0 = y0.min(0.0);
        }
        if x1 - x0 < 1e-12 {
            x1 = x0 + 1.0;
        }
        if y1 - y0 < 1e-12 {
            y1 = y0 + 1.0;
        }
        // Round outwards to the tick step, with a little headroom for the legend.
        let (_, ystep) = step(y0, y1);
        let y1 = ((y1 + 0.15 * (y1 - y0)) / ystep).ceil() * ystep;
        let y0 = (y0 / ystep).floor() * ystep;
        Plot {
            left: MARGIN_LEFT,
            right: width.saturating_sub(MARGIN_RIGHT).max(MARGIN_LEFT + 1),
            top: MARGIN_TOP,
            bottom: height.saturating_sub(MARGIN_BOTTOM).max(MARGIN_TOP + 1),
            x0,
            x1,
            y0,
            y1,
        }
    }

    fn fx(&self, x: f64) -> f64 {
        self.left as f64 + (x - self.x0) / (self.x1 - self.x0) * (self.right - self.left) as f64
    }

    fn fy(&self, y: f64) -> f64 {
        self.bottom as f64 - (y - self.y0) / (self.y1 - self.y0) * (self.bottom - self.top) as f64
    }

    fn col(&self, x: f64) -> u32 {
        self.fx(x).round().max(0.0) as u32
    }

    fn row(&self, y: f64) -> u32 {
        self.fy(y).round().max(0.0) as u32
    }

    fn inside(&self, x: i64, y: i64) -> bool {
        x >= self.left as i64
            && x <= self.right as i64
            && y >= self.top as i64
            && y <= self.bottom as i64
    }
}

/// A round tick step (1, 2 or 5 × 10^k) giving about five ticks, and its decimals.
fn step(a: f64, b: f64) -> (usize, f64) {
    let raw = (b - a) / 5.0;
    let mag = 10f64.powf(raw.log10().floor());
    let s = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag);
    ((-s.log10().floor()).max(0.0) as usize, s)
}

/// Tick values in [a, b] and their labels.
fn ticks(a: f64, b: f64) -> Vec<(f64, String)> {
    let (decimals, s) = step(a, b);
    // A hair of slack: 0.3 / 0.1 is 2.9999999999999996.
    let first = (a / s - 1e-9).ceil() as i64;
    let last = (b / s + 1e-9).floor() as i64;
    (first..=last)
        .map(|i| {
            let v = i as f64 * s;
            (v, format!("{v:.decimals$}"))
        })
        .collect()
}

fn hline(img: &mut RgbImage, x0: u32, x1: u32, y: u32, c: [u8; 3]) {
    if y < img.height() {
        for x in x0..=x1.min(img.width() - 1) {
            img.put_pixel(x, y, Rgb(c));
        }
    }
}

fn vline(img: &mut RgbImage, x: u32, y0: u32, y1: u32, c: [u8; 3]) {
    if x < img.width() {
        for y in y0..=y1.min(img.height() - 1) {
            img.put_pixel(x, y, Rgb(c));
        }
    }
}

/// A thick segment by stepping along it one pixel at a time (clipped to the plot area).
fn segment(img: &mut RgbImage, a: (f64, f64), b: (f64, f64), c: [u8; 3], width: u32, plot: &Plot) {
    let steps = ((b.0 - a.0).abs().max((b.1 - a.1).abs()).ceil() as usize).max(1);
    let half = width.max(1) as i64 / 2;
    for s in 0..=steps {
        let t = s as f64 / steps as f64;
        let (x, y) = (
            (a.0 + t * (b.0 - a.0)).round() as i64,
            (a.1 + t * (b.1 - a.1)).round() as i64,
        );
        for dx in -half..=(width.max(1) as i64 - 1 - half) {
            for dy in -half..=(width.max(1) as i64 - 1 - half) {
                let (px, py) = (x + dx, y + dy);
                if plot.inside(px, py) && px < img.width() as i64 && py < img.height() as i64 {
                    img.put_pixel(px as u32, py as u32, Rgb(c));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_flat_line_lands_on_its_row_and_ticks_are_round() {
        let chart = Chart {
            title: "E(K)".into(),
            x_label: "K".into(),
            y_label: "MM".into(),
            lines: vec![
                Line {
                    label: "A".into(),
                    points: (0..=10).map(|k| (k as f64, 5.0)).collect(),
                    color: [255, 0, 0],
                    width: 1,
                },
                Line {
                    label: "B".into(),
                    points: (0..=10).map(|k| (k as f64, k as f64)).collect(),
                    color: [0, 0, 255],
                    width: 1,
                },
            ],
            y_from_zero: true,
        };
        let img = line_chart(&chart, 400, 300);
        let plot = Plot::new(&chart, 400, 300);
        // The red line runs along y = 5's row across the middle of the plot.
        let row = plot.row(5.0);
        let red = (plot.left + 5..plot.right - 5)
            .filter(|&x| img.get_pixel(x, row).0 == [255, 0, 0])
            .count();
        assert!(
            red as u32 > (plot.right - plot.left) / 2,
            "{red} red pixels on row {row}"
        );
        // The blue diagonal passes through (5, 5) too, and through (10, 10) at the right edge.
        assert_eq!(img.get_pixel(plot.col(10.0), plot.row(10.0)).0, [0, 0, 255]);
        let labels = |a, b| ticks(a, b).into_iter().map(|t| t.1).collect::<Vec<_>>();
        assert_eq!(labels(0.0, 12.0), ["0", "5", "10"]);
        assert_eq!(labels(0.0, 0.3), ["0.0", "0.1", "0.2", "0.3"]);
        let two = stack(&[img.clone(), img]);
        assert_eq!((two.width(), two.height()), (400, 600));
    }
}
