use std::path::{Path, PathBuf};
use std::time::Instant;

use super::*;

const BG: [u8; 3] = [238, 238, 238];
const RED: [u8; 3] = [230, 20, 20];
const BLUE: [u8; 3] = [20, 20, 230];

/// Plain style for pixel-exact checks: no supersampling, floor line or label noise.
fn plain(w: u32, h: u32) -> SheetOptions {
    SheetOptions {
        panel_width: w,
        panel_height: h,
        background: BG,
        supersample: 1,
        floor_y: None,
        ..Default::default()
    }
}

fn panel<'a>(meshes: Vec<DrawMesh<'a>>, view: View) -> Panel<'a> {
    Panel {
        meshes,
        view,
        label: String::new(),
    }
}

fn mesh<'a>(positions: &'a [[f32; 3]], triangles: &'a [[u32; 3]], color: [u8; 3]) -> DrawMesh<'a> {
    DrawMesh {
        positions,
        triangles,
        color,
    }
}

/// 4 m square around the origin, front view.
fn square() -> Framing {
    Framing {
        view: View::Front,
        min: [-2.0, -2.0],
        max: [2.0, 2.0],
    }
}

fn px(img: &image::RgbImage, x: u32, y: u32) -> [u8; 3] {
    img.get_pixel(x, y).0
}

/// Bounding box (x0, y0, x1, y1) of pixels that differ from the background.
fn drawn_bbox(img: &image::RgbImage) -> Option<(u32, u32, u32, u32)> {
    let mut bb: Option<(u32, u32, u32, u32)> = None;
    for (x, y, p) in img.enumerate_pixels() {
        if p.0 != BG {
            let b = bb.get_or_insert((x, y, x, y));
            *b = (b.0.min(x), b.1.min(y), b.2.max(x), b.3.max(y));
        }
    }
    bb
}

const TRI: [[f32; 3]; 3] = [[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]];
const ONE_TRI: [[u32; 3]; 1] = [[0, 1, 2]];

#[test]
fn triangle_covers_expected_pixels_in_front_view() {
    let p = panel(vec![mesh(&TRI, &ONE_TRI, RED)], View::Front);
    // 4 m square framing in 100 px: 25 px/m, origin at the centre.
    let img = render_panel_with(&p, &square(), &plain(100, 100));
    // Triangle spans x 25..75, y 25 (apex) .. 75 (base); pixel centres sit at +0.5.
    assert_eq!(
        drawn_bbox(&img),
        Some((25, 26, 74, 74)),
        "apex row 25 has no pixel centre inside"
    );
    let c = px(&img, 50, 60);
    assert!(
        c[0] > 100 && c[1] < 40 && c[2] < 40,
        "interior should be shaded red, got {c:?}"
    );
    for (x, y) in [(5, 5), (30, 30), (70, 30), (50, 80), (95, 95)] {
        assert_eq!(px(&img, x, y), BG, "pixel ({x},{y}) should be background");
    }
}

#[test]
fn edge_on_triangle_draws_nothing_in_side_view() {
    let p = panel(vec![mesh(&TRI, &ONE_TRI, RED)], View::Side);
    let f = Framing {
        view: View::Side,
        ..square()
    };
    let img = render_panel_with(&p, &f, &plain(100, 100));
    assert_eq!(drawn_bbox(&img), None);
}

#[test]
fn views_are_not_mirrored() {
    // A triangle on the character's left (+X) and in front (+Z).
    let pos = [[0.5, 0.0, 0.5], [1.0, 0.0, 1.0], [0.75, 1.0, 0.75]];
    let meshes = || vec![mesh(&pos, &ONE_TRI, RED)];
    let centre_x = |view: View| {
        let f = Framing {
            view,
            min: [-2.0, -2.0],
            max: [2.0, 2.0],
        };
        let (x0, _, x1, _) = drawn_bbox(&render_panel_with(
            &panel(meshes(), view),
            &f,
            &plain(100, 100),
        ))
        .unwrap();
        (x0 + x1) / 2
    };
    assert!(
        centre_x(View::Front) > 50,
        "+X appears on the right in the front view"
    );
    assert!(
        centre_x(View::Back) < 50,
        "+X appears on the left in the back view"
    );
    assert!(
        centre_x(View::Side) < 50,
        "the character faces image-left in the side view"
    );
}

#[test]
fn nearer_triangle_hides_farther_one_in_any_order() {
    let near: Vec<[f32; 3]> = TRI.iter().map(|p| [p[0], p[1], 0.5]).collect();
    let far: Vec<[f32; 3]> = TRI.iter().map(|p| [p[0] * 1.5, p[1] * 1.5, -0.5]).collect();
    let red = mesh(&near, &ONE_TRI, RED);
    let blue = mesh(&far, &ONE_TRI, BLUE);
    for order in [vec![red, blue], vec![blue, red]] {
        let img = render_panel_with(&panel(order, View::Front), &square(), &plain(100, 100));
        let c = px(&img, 50, 60);
        assert!(
            c[0] > 100 && c[2] < 40,
            "red must win at the centre, got {c:?}"
        );
        let c = px(&img, 50, 85);
        assert!(
            c[2] > 100 && c[0] < 40,
            "blue shows where red is absent, got {c:?}"
        );
    }
}

#[test]
fn back_faces_are_shaded_darker() {
    let flipped = [[0u32, 2, 1]];
    let front = render_panel_with(
        &panel(vec![mesh(&TRI, &ONE_TRI, RED)], View::Front),
        &square(),
        &plain(100, 100),
    );
    let back = render_panel_with(
        &panel(vec![mesh(&TRI, &flipped, RED)], View::Front),
        &square(),
        &plain(100, 100),
    );
    let (f, b) = (px(&front, 50, 60), px(&back, 50, 60));
    assert!(b != BG && b[0] > 30, "back face must be drawn, got {b:?}");
    assert!(
        b[0] < f[0],
        "back face {b:?} should be darker than front {f:?}"
    );
}

#[test]
fn framing_fit_adds_margin_and_keeps_aspect() {
    let f = Framing::fit([[0.0, 0.0, 0.0], [1.0, 2.0, 5.0]], View::Front);
    let close = |a: f32, b: f32| (a - b).abs() < 1e-5;
    assert!(close(f.min[0], -0.1) && close(f.min[1], -0.1), "{f:?}");
    assert!(close(f.max[0], 1.1) && close(f.max[1], 2.1), "{f:?}");
    // A 1 m square in a wide panel stays square.
    let pos = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
    ];
    let quad = [[0, 1, 2], [0, 2, 3]];
    let p = panel(vec![mesh(&pos, &quad, RED)], View::Front);
    let f = Framing::fit_meshes(&p.meshes, View::Front);
    let (x0, y0, x1, y1) = drawn_bbox(&render_panel_with(&p, &f, &plain(300, 100))).unwrap();
    let (bw, bh) = (x1 - x0 + 1, y1 - y0 + 1);
    assert!(bw.abs_diff(bh) <= 1, "square drawn as {bw}x{bh}");
    assert!(
        bh >= 88 && (x0 + x1).abs_diff(299) <= 2,
        "fills the height, centred: {x0}..{x1} x {y0}..{y1}"
    );
}

#[test]
fn framing_without_points_is_usable() {
    let f = Framing::fit(std::iter::empty(), View::Side);
    assert_eq!(f.min, [-1.0, -1.0]);
    let nan = Framing::fit([[f32::NAN, 0.0, 0.0]], View::Front);
    assert_eq!(nan.max, [1.0, 1.0]);
    assert!(Framing::fit([[1.0, 1.0, 1.0]], View::Front)
        .scale_for(100, 100)
        .is_finite());
}

#[test]
fn contact_sheet_has_grid_dimensions() {
    let panels: Vec<Panel> = (0..5)
        .map(|_| panel(vec![mesh(&TRI, &ONE_TRI, RED)], View::Front))
        .collect();
    let opts = SheetOptions {
        panel_width: 40,
        panel_height: 30,
        columns: 2,
        ..Default::default()
    };
    let img = contact_sheet(&panels, &opts);
    assert_eq!(img.dimensions(), (80, 90));
    assert_eq!(contact_sheet(&[], &opts).dimensions(), (80, 30));
}

#[test]
fn shared_framing_shows_motion_per_panel_does_not() {
    let left: Vec<[f32; 3]> = TRI.iter().map(|p| [p[0] - 3.0, p[1], p[2]]).collect();
    let right: Vec<[f32; 3]> = TRI.iter().map(|p| [p[0] + 3.0, p[1], p[2]]).collect();
    let panels = vec![
        panel(vec![mesh(&left, &ONE_TRI, RED)], View::Front),
        panel(vec![mesh(&right, &ONE_TRI, RED)], View::Front),
    ];
    let centres = |mode| {
        let opts = SheetOptions {
            framing: mode,
            columns: 2,
            ..plain(100, 100)
        };
        let sheet = contact_sheet(&panels, &opts);
        [0, 100].map(|x| {
            let cell = image::imageops::crop_imm(&sheet, x, 0, 100, 100).to_image();
            let (x0, _, x1, _) = drawn_bbox(&cell).unwrap();
            (x0 + x1) / 2
        })
    };
    let [a, b] = centres(FramingMode::Shared);
    assert!(
        a < 40 && b > 60,
        "shared framing keeps world positions: {a} {b}"
    );
    let [a, b] = centres(FramingMode::PerPanel);
    assert!(
        a.abs_diff(50) <= 2 && b.abs_diff(50) <= 2,
        "per-panel framing centres each: {a} {b}"
    );
}

#[test]
fn labels_change_pixels_and_cover_the_charset() {
    let mut p = panel(vec![], View::Front);
    let blank = render_panel(&p, 300, 100, &square());
    p.label = "Frame 12: t 0.5s (40%)".into();
    let labelled = render_panel(&p, 300, 100, &square());
    let changed: Vec<(u32, u32)> = blank
        .enumerate_pixels()
        .zip(labelled.pixels())
        .filter(|((_, _, a), b)| a != b)
        .map(|((x, y, _), _)| (x, y))
        .collect();
    assert!(changed.len() > 50, "only {} pixels changed", changed.len());
    // Text sits in the top-left corner: 7 font rows at scale 2.
    let (y0, y1) = (
        changed.iter().map(|c| c.1).min().unwrap(),
        changed.iter().map(|c| c.1).max().unwrap(),
    );
    let x0 = changed.iter().map(|c| c.0).min().unwrap();
    assert!(
        x0 < 10 && y0 < 10 && y1 - y0 == 13,
        "label at x {x0}, rows {y0}..{y1}"
    );
    let charset = "0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz _-.:/()%";
    assert!(charset.chars().all(has_glyph));
    assert!(!has_glyph('='));
}

fn scratch_dir(name: &str) -> PathBuf {
    let dir =
        std::env::temp_dir().join(format!("garmentbake_preview_{name}_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn save_png_round_trips() {
    let p = panel(vec![mesh(&TRI, &ONE_TRI, RED)], View::Front);
    let img = render_panel(&p, 64, 48, &square());
    let dir = scratch_dir("save");
    let path = dir.join("x.png");
    save_png(&img, &path).unwrap();
    let back = image::open(&path).unwrap().to_rgb8();
    assert_eq!(back, img);
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(
        leftovers,
        vec![std::ffi::OsString::from("x.png")],
        "temp file must be renamed away"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn save_png_reports_unwritable_path() {
    let img = image::RgbImage::new(4, 4);
    let err = save_png(&img, Path::new("/nonexistent/x.png")).unwrap_err();
    let msg = err.to_string();
    assert!(
        msg.contains("/nonexistent/x.png"),
        "message must name the path: {msg}"
    );
}

// ---- real mesh -------------------------------------------------------------

const BASE_OBJ: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../shared/data/makehuman/base.obj"
);
/// MakeHuman body vertices; later ones are helper geometry (clothes proxies, joints).
const BODY_VERTS: usize = 13380;

type TriMesh = (Vec<[f32; 3]>, Vec<[u32; 3]>);

/// Minimal OBJ read: `v` and `f` only, fan-triangulated, body vertices only,
/// decimetres → metres, lifted so the feet stand on y = 0.
fn load_body() -> Option<TriMesh> {
    let text = std::fs::read_to_string(BASE_OBJ).ok()?;
    let mut pos = Vec::new();
    let mut tris = Vec::new();
    for line in text.lines() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") if pos.len() < BODY_VERTS => {
                let c: Vec<f32> = it
                    .take(3)
                    .map(|s| s.parse::<f32>().unwrap() * 0.1)
                    .collect();
                pos.push([c[0], c[1], c[2]]);
            }
            Some("f") => {
                let idx: Vec<u32> = it
                    .map(|s| s.split('/').next().unwrap().parse::<u32>().unwrap() - 1)
                    .collect();
                if idx.iter().all(|&i| (i as usize) < BODY_VERTS) {
                    tris.extend((1..idx.len() - 1).map(|k| [idx[0], idx[k], idx[k + 1]]));
                }
            }
            _ => {}
        }
    }
    let min_y = pos.iter().map(|p| p[1]).fold(f32::INFINITY, f32::min);
    pos.iter_mut().for_each(|p| p[1] -= min_y);
    Some((pos, tris))
}

/// Open flared cone around the hips: a stand-in garment (`rings`×`around` vertices).
fn skirt(body: &[[f32; 3]], rings: u32, around: u32) -> TriMesh {
    // Torso vertices at waist height (|x| < 0.2 m leaves out the hanging hands).
    let waist: Vec<&[f32; 3]> = body
        .iter()
        .filter(|p| (0.95..1.05).contains(&p[1]) && p[0].abs() < 0.2)
        .collect();
    let n = waist.len().max(1) as f32;
    let cx = waist.iter().map(|p| p[0]).sum::<f32>() / n;
    let cz = waist.iter().map(|p| p[2]).sum::<f32>() / n;
    let mut pos = Vec::new();
    for r in 0..rings {
        let t = r as f32 / (rings - 1) as f32;
        let (y, radius) = (1.02 - 0.45 * t, 0.17 + 0.16 * t);
        for a in 0..around {
            let phi = a as f32 / around as f32 * std::f32::consts::TAU;
            pos.push([cx + radius * phi.cos(), y, cz + radius * phi.sin()]);
        }
    }
    let mut tris = Vec::new();
    for r in 0..rings - 1 {
        for a in 0..around {
            let (i, j) = (r * around + a, r * around + (a + 1) % around);
            tris.push([i, i + around, j]);
            tris.push([j, i + around, j + around]);
        }
    }
    (pos, tris)
}

#[test]
fn renders_makehuman_body_sheet() {
    let (pos, tris) = load_body()
        .unwrap_or_else(|| panic!("{BASE_OBJ} not found (../shared must sit beside the repo)"));
    let (spos, stris) = skirt(&pos, 40, 72);
    let body = mesh(&pos, &tris, BODY_GREY);
    let garment = mesh(&spos, &stris, GARMENT_COLORS[0]);
    let views = [View::Front, View::Side, View::Back, View::ThreeQuarter];
    let mut panels: Vec<Panel> = views
        .iter()
        .map(|&v| Panel {
            meshes: vec![body],
            view: v,
            label: format!("body {v:?}"),
        })
        .collect();
    panels.extend(views.iter().map(|&v| Panel {
        meshes: vec![body, garment],
        view: v,
        label: format!("skirt {v:?} (f.1)"),
    }));
    let opts = SheetOptions::default();
    let sheet = contact_sheet(&panels, &opts);
    assert_eq!(sheet.dimensions(), (4 * 320, 2 * 480));

    // Upright: the front-view body (A-pose) is taller than wide and centred horizontally.
    let bare = Panel {
        label: String::new(),
        ..panels[0].clone()
    };
    let front = render_panel_with(
        &bare,
        &Framing::fit_panels(&panels, View::Front),
        &plain(320, 480),
    );
    let (x0, y0, x1, y1) = drawn_bbox(&front).unwrap();
    assert!(
        y1 - y0 > x1 - x0 && (x0 + x1).abs_diff(319) < 30,
        "{x0},{y0}..{x1},{y1}"
    );

    let dir = std::env::var_os("GARMENTBAKE_PREVIEW_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| scratch_dir("body"));
    let out = dir.join("body_test.png");
    save_png(&sheet, &out).unwrap();
    eprintln!("wrote {}", out.display());
}

/// Timing: 12 panels of a 13k-vertex body + 3k-vertex garment.
/// `cargo test --release -- --ignored --nocapture timing`
#[test]
#[ignore]
fn timing_twelve_panels() {
    let Some((pos, tris)) = load_body() else {
        return;
    };
    let (spos, stris) = skirt(&pos, 42, 72);
    assert!(spos.len() >= 3000);
    let body = mesh(&pos, &tris, BODY_GREY);
    let garment = mesh(&spos, &stris, GARMENT_COLORS[1]);
    let panels: Vec<Panel> = (0..12)
        .map(|i| Panel {
            meshes: vec![body, garment],
            view: if i % 2 == 0 { View::Front } else { View::Side },
            label: format!("frame {i}"),
        })
        .collect();
    let opts = SheetOptions::default();
    let _ = contact_sheet(&panels, &opts); // warm up
    let t = Instant::now();
    let runs = 5;
    for _ in 0..runs {
        let _ = contact_sheet(&panels, &opts);
    }
    eprintln!(
        "12 panels 320x480 (ss 2): {:.1} ms",
        t.elapsed().as_secs_f64() * 1000.0 / runs as f64
    );
}

#[test]
fn a_label_too_long_for_its_panel_shrinks_every_label_of_the_sheet() {
    let mut short = panel(vec![], View::Front);
    short.label = "F0".into();
    let mut long = panel(vec![], View::Front);
    long.label = "F1246 10.38S MODEL FRONT".into(); // 24 glyphs: 288 px at size 2
    let ink_rows = |panels: &[Panel], w: u32| {
        let sheet = contact_sheet(
            panels,
            &SheetOptions {
                columns: 1,
                ..plain(w, 60)
            },
        );
        let rows: Vec<u32> = sheet
            .enumerate_pixels()
            .filter(|(_, y, p)| *y < 60 && p.0 != BG)
            .map(|(_, y, _)| y)
            .collect();
        rows.iter().max().unwrap() - rows.iter().min().unwrap() + 1
    };
    // The short label alone fits at size 2 (14 rows); next to the long one, both are size 1.
    assert_eq!(ink_rows(std::slice::from_ref(&short), 240), 14);
    assert_eq!(ink_rows(&[short, long], 240), 7);
}

#[test]
fn error_bands_colour_each_triangle_by_its_largest_vertex_error() {
    // Errors in mm against a 50 mm scale: band edges at 5, 15, 30 and 50 mm.
    let triangles = [[0, 1, 2], [1, 2, 3], [2, 3, 4], [3, 4, 5]];
    let errors = [0.0, 1.0, 4.9, 14.0, 31.0, 50.0];
    let bands = ErrorBands::new(&triangles, &errors, 50.0);
    let points = [[0.0f32; 3]; 6];
    let per_band: Vec<Vec<[u32; 3]>> = bands
        .meshes(&points)
        .iter()
        .map(|m| m.triangles.to_vec())
        .collect();
    assert_eq!(
        per_band,
        vec![
            vec![[0, 1, 2]],
            vec![[1, 2, 3]],
            vec![],
            vec![[2, 3, 4]],
            vec![[3, 4, 5]],
        ]
    );
    let colors: Vec<[u8; 3]> = bands.meshes(&points).iter().map(|m| m.color).collect();
    assert_eq!(colors, ERROR_COLORS.to_vec());
}
