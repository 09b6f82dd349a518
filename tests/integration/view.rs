//! `garmentbake view`: the page opened in headless Chromium (Debian `chromium`, SwiftShader WebGL,
//! no GPU, no network), its garment silhouette against `garmentbake preview`'s own rasterisation
//! of the same frame and camera, its clip selector against the file's animations, caches and
//! error colours, and bad input.

use crate::bake::{model, s};
use crate::common::*;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Panel size of the silhouette comparison (the page's window, the preview's panel).
const W: u32 = 360;
const H: u32 = 540;

/// Headless Chromium on `page` with `hash` (the page's URL state), every host unresolvable so a
/// page that needs the network fails; `--virtual-time-budget` lets the page's scripts finish.
fn chromium(page: &Path, hash: &str, args: &[&str]) -> std::process::Output {
    // A profile per page and URL state: two Chromiums at once (the VAT test's frames) must not
    // share one.
    let key = {
        use std::hash::{Hash, Hasher};
        let mut h = std::collections::hash_map::DefaultHasher::new();
        (hash, args).hash(&mut h);
        h.finish()
    };
    let profile = page.with_extension(format!("chromium-{key:016x}"));
    let url = format!("file://{}#{hash}", page.display());
    run_ok(
        Command::new("chromium")
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                // Containers (CI) often have a small /dev/shm.
                "--disable-dev-shm-usage",
                "--use-gl=swiftshader",
                "--enable-unsafe-swiftshader",
                "--hide-scrollbars",
                "--force-device-scale-factor=1",
                "--host-resolver-rules=MAP * ~NOTFOUND",
                "--virtual-time-budget=30000",
                &format!("--window-size={W},{H}"),
            ])
            .arg(format!("--user-data-dir={}", profile.display()))
            .args(args)
            .arg(url),
    )
}

/// The page's screenshot at `hash`.
fn screenshot(page: &Path, hash: &str, png: &Path) -> image::RgbImage {
    chromium(page, hash, &[&format!("--screenshot={}", png.display())]);
    image::open(png).expect("screenshot PNG").to_rgb8()
}

/// The page's DOM after its scripts ran.
fn dom(page: &Path, hash: &str) -> String {
    let out = chromium(page, hash, &["--dump-dom"]);
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Garment pixels: the blue of GARMENT_COLORS[0] under any shading (body and floor are grey).
fn garment_mask(img: &image::RgbImage) -> Vec<bool> {
    img.pixels()
        .map(|p| i32::from(p[2]) - i32::from(p[0]) > 30)
        .collect()
}

fn iou(a: &[bool], b: &[bool]) -> f64 {
    let both = a.iter().zip(b).filter(|(x, y)| **x && **y).count();
    let any = a.iter().zip(b).filter(|(x, y)| **x || **y).count();
    both as f64 / any.max(1) as f64
}

/// The options of the page's clip selector, in order.
fn clip_options(dom: &str) -> Vec<String> {
    let select = &dom[dom.find("<select id=\"clip\"").expect("clip selector")..];
    let select = &select[..select.find("</select>").expect("end of selector")];
    select
        .split("<option")
        .skip(1)
        .map(|o| o[o.find('>').unwrap() + 1..o.find("</option>").unwrap()].to_string())
        .collect()
}

/// The two clips baked at 10 fps with the body, and the page `bake --view` wrote.
fn baked(dir: &Path) -> (PathBuf, PathBuf) {
    let glb = dir.join("skirt.glb");
    let page = dir.join("skirt.html");
    let mut args = vec!["bake", "--model", model().to_str().unwrap()];
    args.extend(["--motion", s("motions/131_02.bvh")]);
    args.extend(["--motion", s("motions/131_01.bvh")]);
    args.extend(["--fps", "10", "--with-body", "--threads", "1"]);
    args.extend([
        "--out",
        glb.to_str().unwrap(),
        "--view",
        page.to_str().unwrap(),
    ]);
    garmentbake_ok(&args);
    (glb, page)
}

#[test]
fn page_matches_the_preview_silhouette_and_lists_every_clip() {
    let dir = out_dir("view_silhouette");
    let (glb, page) = baked(&dir);
    let html = std::fs::read_to_string(&page).unwrap();
    // Nothing fetched from anywhere: no external script, style or module.
    for external in ["src=\"http", "href=\"http", "import(\"http", "from 'http"] {
        assert!(!html.contains(external), "page refers to {external}…");
    }
    let inspect = garmentbake_json(&["inspect", glb.to_str().unwrap(), "--json"]);
    let names: Vec<String> = inspect["animations"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a["name"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(names, ["131_02", "131_01"]);
    let dom = dom(&page, "clip=131_01");
    assert!(dom.contains("data-ready=\"1\""), "the page did not finish");
    assert_eq!(
        clip_options(&dom),
        names,
        "the selector lists every animation"
    );
    for frame in [12, 61] {
        page_matches_preview(&page, &dir, frame, "bake page");
    }
}

/// Vertex animation textures in the page (issue 40): `eval --out walk.vat.exr --view walk.html`
/// plays the VAT's own mesh and textures in a vertex shader on the posed body, and its garment
/// silhouette matches `preview` of the network at the same frame (IoU ≥ 0.95, as the bake's page
/// above); `view walk.vat.png` plays the 16-bit VAT alone, its garment where the first page's
/// is with the body hidden (both frame the garment alone then).
#[test]
fn a_vat_plays_in_the_page_as_the_preview_shows_the_network() {
    let dir = out_dir("view_vat");
    let eval = |out: &Path, extra: &[&str]| {
        let mut args = vec!["eval", "--model", model().to_str().unwrap()];
        args.extend(["--motion", s("motions/131_02.bvh"), "--fps", "10"]);
        args.extend(["--threads", "1", "--out", out.to_str().unwrap()]);
        args.extend_from_slice(extra);
        garmentbake_ok(&args);
    };
    let page = dir.join("walk.html");
    let png = dir.join("walk16.vat.png");
    // The two evals (their metrics are most of the test's time) side by side, a thread each.
    std::thread::scope(|scope| {
        let exr = scope.spawn(|| {
            eval(
                &dir.join("walk.vat.exr"),
                &["--view", page.to_str().unwrap()],
            )
        });
        eval(&png, &[]);
        exr.join().unwrap();
    });
    let alone = dir.join("alone.html");
    let report = garmentbake_json(&[
        "view",
        png.to_str().unwrap(),
        "--out",
        alone.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(report["garment_vertices"], 2847, "{report}");
    // The two frames side by side, a thread each (their screenshots and previews are apart).
    let check = |frame: usize| {
        page_matches_preview(&page, &dir, frame, "VAT page");
        // The 16-bit VAT alone against the first page with its body hidden.
        let hash = format!("frame={frame}&view=front&ui=0&body=0");
        let bare = screenshot(&page, &hash, &dir.join(format!("bare_{frame}.png")));
        let own = screenshot(&alone, &hash, &dir.join(format!("alone_{frame}.png")));
        let score = iou(&garment_mask(&bare), &garment_mask(&own));
        eprintln!("view walk16.vat.png, frame {frame}: IoU {score:.4} with the eval page's VAT");
        assert!(score >= 0.95, "frame {frame}: IoU {score:.4} < 0.95");
    };
    std::thread::scope(|scope| {
        let later = scope.spawn(|| check(61));
        check(12);
        later.join().unwrap();
    });
}

/// The page's garment at `frame` of 131_02 (front view) against `preview` of the network at the
/// same frame: the same image size, a garment large enough to judge, IoU ≥ 0.95.
fn page_matches_preview(page: &Path, dir: &Path, frame: usize, what: &str) {
    let shot = screenshot(
        page,
        &format!("clip=131_02&frame={frame}&view=front&ui=0"),
        &dir.join(format!("page_{frame}.png")),
    );
    let preview = dir.join(format!("preview_{frame}.png"));
    garmentbake_ok(&[
        "preview",
        "--body",
        s("body.glb"),
        "--model",
        model().to_str().unwrap(),
        "--motion",
        s("motions/131_02.bvh"),
        "--fps",
        "10",
        "--frame-list",
        &frame.to_string(),
        "--views",
        "front",
        "--width",
        &W.to_string(),
        "--height",
        &H.to_string(),
        "--out",
        preview.to_str().unwrap(),
    ]);
    let preview = image::open(&preview).unwrap().to_rgb8();
    assert_eq!(shot.dimensions(), preview.dimensions());
    let (a, b) = (garment_mask(&shot), garment_mask(&preview));
    let score = iou(&a, &b);
    eprintln!(
        "{what}, frame {frame}: IoU {score:.4} with the preview ({} page, {} preview garment pixels)",
        a.iter().filter(|x| **x).count(),
        b.iter().filter(|x| **x).count()
    );
    assert!(
        b.iter().filter(|x| **x).count() > 2000,
        "garment too small to judge"
    );
    assert!(
        score >= 0.95,
        "{what}, frame {frame}: IoU {score:.4} < 0.95"
    );
}

/// The network's garment on the first frames of 131_02 at 10 fps, as the model's vertices
/// (what `eval` writes), shifted by `dx` metres along x.
fn network_cache(path: &Path, frames: usize, dx: f32) {
    let file = garmentbake::models::file::load(model(), tch::Device::Cpu).unwrap();
    let maps = garmentbake::motion::read_maps(&[] as &[PathBuf]).unwrap();
    let clip = garmentbake::motion::load_clip(
        &sample("motions/131_02.bvh"),
        &maps,
        &file.body,
        Some(10.0),
    )
    .unwrap();
    let poses: Vec<_> = (0..frames).map(|f| clip.animation.local_pose(f)).collect();
    let mut x = garmentbake::eval::model_frames(
        file.pbns().unwrap(),
        file.skeleton(),
        &poses,
        tch::Device::Cpu,
    );
    x.iter_mut().flatten().for_each(|p| p[0] += dx);
    let frames = garmentbake::geometry::Frames::new(x, 10.0);
    garmentbake::io::point_cache::write_cache(path, &file.garment, &frames).unwrap();
}

#[test]
fn caches_play_on_the_garment_and_error_colours_measure_their_distance() {
    let dir = out_dir("view_caches");
    let (glb, _) = baked(&dir);
    let net = dir.join("network.pc2");
    let shifted = dir.join("shifted.pc2");
    network_cache(&net, 20, 0.0);
    network_cache(&shifted, 20, 0.005);
    let page = dir.join("caches.html");
    let report = garmentbake_json(&[
        "view",
        glb.to_str().unwrap(),
        "--with",
        net.to_str().unwrap(),
        "--error-vs",
        shifted.to_str().unwrap(),
        "--out",
        page.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(report["caches"][0]["frames"], 20);
    assert_eq!(report["bytes"], std::fs::metadata(&page).unwrap().len());
    // The bake replays the network to a micrometre, the cache is the network: both are 5 mm from
    // the shifted reference at every vertex, if the cache maps onto the seam-split glTF vertices.
    let shown = dom(&page, "clip=131_02&frame=7");
    let legend = &shown[shown.find("id=\"legend-now\"").expect("legend")..];
    let legend = &legend[..legend.find("</div>").unwrap()];
    assert!(legend.contains("max this frame 5.00 mm"), "{legend}");
    // A reference that is also a --with cache is inlined once.
    let once = dir.join("once.html");
    let net_arg = net.to_str().unwrap();
    let report = garmentbake_json(&[
        "view",
        glb.to_str().unwrap(),
        "--with",
        net_arg,
        "--error-vs",
        net_arg,
        "--out",
        once.to_str().unwrap(),
        "--json",
    ]);
    let cache_b64 = 20 * 2808 * 12 * 4 / 3;
    let size = report["bytes"].as_u64().unwrap() as usize;
    assert!(size < std::fs::metadata(&page).unwrap().len() as usize - cache_b64 / 2);
    let dom = dom(&once, "clip=131_02&frame=7");
    assert!(
        dom.contains("max this frame 0.00 mm"),
        "the bake replays the network"
    );
    assert!(shown.contains("network</label>"), "the cache is listed");
}

#[test]
fn a_glb_without_animations_shows_the_rest_pose_with_a_message() {
    let dir = out_dir("view_rest");
    let page = dir.join("body.html");
    let report = garmentbake_json(&[
        "view",
        s("body.glb"),
        "--out",
        page.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(report["clips"].as_array().unwrap().len(), 0);
    let dom = dom(&page, "");
    assert!(
        dom.contains("has no animations: showing the rest pose"),
        "no message"
    );
    let shot = screenshot(&page, "view=front&ui=0", &dir.join("rest.png"));
    let shown = garment_mask(&shot).iter().filter(|x| **x).count();
    assert!(
        shown > (W * H / 10) as usize,
        "the rest pose is drawn ({shown} pixels)"
    );
}

#[test]
fn a_cache_of_another_mesh_is_one_error_line() {
    let dir = out_dir("view_bad_cache");
    let (glb, _) = baked(&dir);
    // A real cache, of the body: not the garment's vertex count.
    let body_cache = dir.join("body.pc2");
    let eval_page = dir.join("eval.html");
    garmentbake_ok(&[
        "eval",
        "--model",
        model().to_str().unwrap(),
        "--motion",
        s("motions/131_02.bvh"),
        "--fps",
        "1",
        "--threads",
        "1",
        "--out",
        dir.join("garment.pc2").to_str().unwrap(),
        "--body-out",
        body_cache.to_str().unwrap(),
        "--view",
        eval_page.to_str().unwrap(),
    ]);
    // eval --view: the network's cache on the body posed by the clip.
    let dom = dom(&eval_page, "frame=3");
    assert!(
        dom.contains("data-ready=\"1\""),
        "the eval page did not finish"
    );
    assert_eq!(clip_options(&dom), ["131_02"]);
    assert!(dom.contains("network</label>"), "the cache is listed");
    let page = dir.join("bad.html");
    let out = garmentbake(&[
        "view",
        glb.to_str().unwrap(),
        "--with",
        body_cache.to_str().unwrap(),
        "--out",
        page.to_str().unwrap(),
    ]);
    let err = one_error_line(&out, &page);
    assert!(
        err.contains("body.pc2") && err.contains("points per frame"),
        "{err}"
    );
    let out = garmentbake(&[
        "view",
        s("motions/131_02.bvh"),
        "--out",
        page.to_str().unwrap(),
    ]);
    let err = one_error_line(&out, &page);
    assert!(err.contains("not a binary glTF"), "{err}");
}

#[test]
fn serve_answers_with_the_same_page() {
    use std::io::{BufRead, Read, Write};
    let dir = out_dir("view_serve");
    let page = dir.join("body.html");
    garmentbake_ok(&["view", s("body.glb"), "--out", page.to_str().unwrap()]);
    let mut child = Command::new(env!("CARGO_BIN_EXE_garmentbake"))
        .args(["view", s("body.glb"), "--serve", "--port", "0"])
        .stderr(std::process::Stdio::piped())
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let mut line = String::new();
    std::io::BufReader::new(child.stderr.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let addr = line
        .split("http://")
        .nth(1)
        .and_then(|r| r.split('/').next())
        .unwrap_or_else(|| panic!("no address in {line:?}"))
        .to_string();
    let mut stream = std::net::TcpStream::connect(&addr).unwrap();
    stream
        .write_all(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n")
        .unwrap();
    let mut answer = Vec::new();
    stream.read_to_end(&mut answer).unwrap();
    child.kill().unwrap();
    child.wait().unwrap();
    let text = String::from_utf8(answer).unwrap();
    let body = &text[text.find("\r\n\r\n").unwrap() + 4..];
    assert!(text.starts_with("HTTP/1.1 200 OK"));
    assert_eq!(body, std::fs::read_to_string(&page).unwrap());
}
