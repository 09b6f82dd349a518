//! `garmentbake bake` (PBNS → glTF) checked against `garmentbake eval` (the network) by readers we
//! did not write: the Khronos validator and three.js (every frame of the baked clip), and Blender.

use crate::common::*;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Small models trained once per test run (1 epoch, width 32, no pose coverage) with 4 and 8 influences: enough to
/// have a non-trivial PSD basis and skin; baking must reproduce whatever the network does.
fn train(influences: &str) -> PathBuf {
    let dir = out_dir(&format!("bake_model_{influences}"));
    let path = dir.join("skirt.safetensors");
    garmentbake_ok(&[
        "train",
        "--body",
        s("body.glb"),
        "--garment",
        s("garments/skirt.obj"),
        "--motion",
        s("motions/131_01.bvh"),
        "--epochs",
        "1",
        "--width",
        "32",
        "--influences",
        influences,
        "--threads",
        "1",
        "--seed",
        "3",
        // The fixture the bake and validate figures were measured on (docs/bake.md,
        // docs/validate.md): trained on the clip's own poses only. With pose coverage (the
        // default since) one epoch sees twice the poses and the 8-influence model's offsets need
        // more than 16 targets for the Blender check's 0.5 mm.
        "--coverage",
        "0",
        "--out",
        path.to_str().unwrap(),
    ]);
    path
}

thread_local! {
    static INFLUENCES: std::cell::Cell<u8> = const { std::cell::Cell::new(4) };
}

pub fn model() -> &'static PathBuf {
    static FOUR: OnceLock<PathBuf> = OnceLock::new();
    static EIGHT: OnceLock<PathBuf> = OnceLock::new();
    match INFLUENCES.with(|i| i.get()) {
        8 => EIGHT.get_or_init(|| train("8")),
        _ => FOUR.get_or_init(|| train("4")),
    }
}

pub fn s(rel: &str) -> &'static str {
    Box::leak(sample(rel).to_string_lossy().into_owned().into_boxed_str())
}

/// `garmentbake eval` of the test model on 131_02 at 30 fps into `out` (PC2 or USD cache).
pub fn eval_131_02(out: &Path) {
    garmentbake_ok(&[
        "eval",
        "--model",
        model().to_str().unwrap(),
        "--motion",
        s("motions/131_02.bvh"),
        "--fps",
        "30",
        "--out",
        out.to_str().unwrap(),
    ]);
}

/// 131_02 at 4 fps: the whole walk in 42 frames. eval's metrics cost about a fifth of a CPU
/// second per frame here (312 frames at 30 fps: 31–37 s on 2 cores), so caches whose checks hold frame by frame
/// (a writer's samples against the same command's PC2) are made at this rate.
pub const FRAMES_AT_4: usize = 42;

/// `garmentbake eval --threads 1` of the test model on 131_02 at 4 fps into `out`, then `extra`.
pub fn eval_131_02_at_4(out: &Path, extra: &[&str]) {
    let mut args = vec![
        "eval",
        "--model",
        model().to_str().unwrap(),
        "--motion",
        s("motions/131_02.bvh"),
        "--fps",
        "4",
        "--threads",
        "1",
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    garmentbake_ok(&args);
}

/// [`eval_131_02_at_4`] into `name` (walk.pc2, walk.mdd, walk.usdc, walk.abc) in a folder the
/// tests share: one eval per test run per model and name, by whichever test asks first; the
/// others wait for it and read the same file (read it, never write it or beside it).
pub fn shared_eval_131_02_at_4(name: &str) -> PathBuf {
    type Made = std::sync::Arc<OnceLock<PathBuf>>;
    static MADE: OnceLock<std::sync::Mutex<std::collections::HashMap<(PathBuf, String), Made>>> =
        OnceLock::new();
    let model = model();
    let cell = MADE
        .get_or_init(Default::default)
        .lock()
        .unwrap()
        .entry((model.clone(), name.to_string()))
        .or_default()
        .clone();
    cell.get_or_init(|| {
        let tag = model
            .parent()
            .unwrap()
            .file_name()
            .unwrap()
            .to_string_lossy();
        let dir = root().join(format!("target/test-out/eval_131_02_at_4_{tag}"));
        std::fs::create_dir_all(&dir).unwrap();
        let out = dir.join(name);
        eval_131_02_at_4(&out, &[]);
        out
    })
    .clone()
}

/// The network's garment on 131_02 at 30 fps (the reference) and its garment vertex map, copied
/// into `dir`. `eval` runs once per model: with its metrics it is the slowest step here.
fn reference(dir: &Path) -> PathBuf {
    static FOUR: OnceLock<PathBuf> = OnceLock::new();
    static EIGHT: OnceLock<PathBuf> = OnceLock::new();
    let made = |name: &str| {
        let shared = out_dir(&format!("bake_reference_{name}"));
        evaluated_reference(&shared);
        shared
    };
    let shared = match INFLUENCES.with(|i| i.get()) {
        8 => EIGHT.get_or_init(|| made("8")),
        _ => FOUR.get_or_init(|| made("4")),
    };
    for name in ["ref.pc2", "map.json"] {
        std::fs::copy(shared.join(name), dir.join(name)).unwrap();
    }
    dir.join("ref.pc2")
}

/// `eval` of the current model into `dir/ref.pc2`, and the bake's garment vertex map.
fn evaluated_reference(dir: &Path) {
    eval_131_02(&dir.join("ref.pc2"));
    let file = garmentbake::models::file::load(model(), tch::Device::Cpu).unwrap();
    let skin = file.pbns().unwrap().skin();
    let mesh =
        garmentbake::bake::skinned_mesh_asset("garment", &file.garment, None, &skin, [0.0; 3]);
    std::fs::write(
        dir.join("map.json"),
        serde_json::to_string(&mesh.source_vertex).unwrap(),
    )
    .unwrap();
}

pub fn bake(dir: &Path, name: &str, extra: &[&str]) -> PathBuf {
    let (out, printed) = bake_printing(dir, name, extra);
    eprintln!("{printed}");
    out
}

/// `bake … --json`: the file and the report.
fn bake_json(dir: &Path, name: &str, extra: &[&str]) -> (PathBuf, serde_json::Value) {
    let (out, printed) = bake_printing(dir, name, &[extra, &["--json"]].concat());
    let report = serde_json::from_str(&printed).expect("bake --json prints a report");
    (out, report)
}

/// Bakes the test model on 131_02 at 30 fps into `dir/name`: the file and what bake printed.
fn bake_printing(dir: &Path, name: &str, extra: &[&str]) -> (PathBuf, String) {
    let out = dir.join(name);
    let mut args = vec![
        "bake",
        "--model",
        model().to_str().unwrap(),
        "--motion",
        s("motions/131_02.bvh"),
        "--fps",
        "30",
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let printed = garmentbake_ok(&args);
    (out, printed)
}

/// three.js replay of every frame against the reference cache: max error in metres.
fn threejs_max_error(glb: &Path, dir: &Path, frames: usize) -> f64 {
    let times: Vec<f64> = (0..frames).map(|f| f as f64 / 30.0).collect();
    threejs_cache_error(glb, &times, &dir.join("ref.pc2"), &dir.join("map.json"))
}

const FRAMES_131_02_AT_30: usize = 312;

/// How far the bake's own replay error may lie from three.js's: measured 0.0014 mm apart on the
/// full basis (0.0005 vs 0.0019 mm, both f32 noise), 0.0001 mm at 0.27 mm and 0.0000 mm at
/// 0.92 mm (the compressed and pruned bakes).
const BAKE_VS_THREEJS_MM: f64 = 0.015;

/// Bakes with `args`, validates the file, and checks three.js's replay of every frame against the
/// network within `limit_m`, and that the bake's own "replay error vs network" says the same.
fn threejs_case(test: &str, args: &[&str], limit_m: f64) {
    let dir = out_dir(test);
    reference(&dir);
    let (glb, baked) = bake_json(&dir, "out.glb", args);
    let (ok, report) = khronos_validate(&glb);
    assert!(ok, "{report}");
    let err = threejs_max_error(&glb, &dir, FRAMES_131_02_AT_30);
    eprintln!(
        "{test} {args:?}: three.js vs eval, every frame: max {:.4} mm",
        err * 1e3
    );
    assert!(err <= limit_m, "max error {:.4} mm", err * 1e3);
    // The bake measures its replay against the network's forward pass, not against the basis
    // and skin it was made from (that comparison agreed with itself whatever was read out of
    // the network): it must find what three.js finds against `eval`.
    let own = baked["report"]["clips"][0]["max_mm"].as_f64().unwrap() / 1e3;
    eprintln!(
        "{test}: bake's own replay error {:.4} mm, three.js {:.4} mm",
        own * 1e3,
        err * 1e3
    );
    assert!(
        (own - err).abs() * 1e3 < BAKE_VS_THREEJS_MM,
        "bake says {:.4} mm, three.js {:.4} mm",
        own * 1e3,
        err * 1e3
    );
}

// three.js (r170) reads JOINTS_0/WEIGHTS_0 only: it plays at most 4 influences, so the
// independent check of 8-influence files is Blender's (below) and USD's.
#[test]
fn full_basis_replays_the_network_in_threejs() {
    // Measured 0.002 mm (docs/bake.md): a few times that, so a real replay error fails.
    threejs_case("bake_full", &[], 0.01e-3);
}

#[test]
fn dropping_blend_shapes_fails_the_1_mm_replay_check() {
    // The negative case of the tolerance checks. The 8-influence model pruned to 4 needs its
    // corrective blend shapes (pruning alone costs tens of mm); one target cannot carry them, so
    // the same three.js replay check must see more than 1 mm.
    INFLUENCES.with(|i| i.set(8));
    let dir = out_dir("bake_one_target");
    reference(&dir);
    let glb = bake(
        &dir,
        "out.glb",
        &["--influences", "4", "--max-targets", "1"],
    );
    let err = threejs_max_error(&glb, &dir, FRAMES_131_02_AT_30);
    eprintln!("1 target: three.js vs eval max {:.3} mm", err * 1e3);
    assert!(err > 1e-3, "max error {:.4} mm", err * 1e3);
}

#[test]
fn compressed_to_a_tolerance_stays_within_it_in_threejs() {
    threejs_case(
        "bake_tolerance",
        &["--influences", "4", "--tolerance-mm", "1"],
        1e-3,
    );
}

#[test]
fn pruning_8_influences_to_4_is_compensated_within_the_tolerance_in_threejs() {
    INFLUENCES.with(|i| i.set(8));
    threejs_case(
        "bake_pruned",
        &["--influences", "4", "--tolerance-mm", "1"],
        1e-3,
    );
}

#[test]
fn blender_plays_the_baked_garment_with_8_influences() {
    INFLUENCES.with(|i| i.set(8));
    let dir = out_dir("bake_blender");
    let pc2 = reference(&dir);
    let glb = bake(&dir, "b.glb", &["--influences", "8", "--max-targets", "16"]);
    // Blender's importer widens a shape key's slider range to its FIRST animated value only
    // (io_scene_gltf2 3.4, `min(coords[1:2])`), so later weights outside [min(0, w₀), max(1, w₀)]
    // are clamped: a trained skirt's 131_02 bake played up to 57 mm wrong before the weights
    // were made to run from 0 to at most 1. This test model's weights are too small for the
    // clamp to show in millimetres, so the range itself is checked (fails with the weights left
    // as the network gives them), and Blender at every 25th frame.
    let weights = morph_weights(&glb);
    assert!(
        weights.iter().all(|w| (0.0..=1.0).contains(w)),
        "weights from {} to {}",
        weights.iter().copied().fold(f32::INFINITY, f32::min),
        weights.iter().copied().fold(f32::NEG_INFINITY, f32::max)
    );
    let frames: Vec<usize> = (0..312).step_by(25).chain([311]).collect();
    let result = blender_positions(&glb, &frames, 30.0);
    let (_, cache) = exporters::pc2::read(&std::fs::read(pc2).unwrap()).unwrap();
    let map: Vec<u32> =
        serde_json::from_str(&std::fs::read_to_string(dir.join("map.json")).unwrap()).unwrap();
    let mesh = result["meshes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|m| m["gltf_mesh"] == 0)
        .expect("garment mesh");
    assert_eq!(
        mesh["shape_key_count"], 16,
        "16 targets (Basis not counted)"
    );
    for (i, &f) in frames.iter().enumerate() {
        let blender = flat_positions(&mesh["frames"][i]["positions"]);
        let reference: Vec<[f32; 3]> = map.iter().map(|&v| cache[f][v as usize]).collect();
        let err = max_distance(&blender, &reference);
        eprintln!("Blender vs eval, frame {f}: max {:.4} mm", err * 1e3);
        // Measured at most 0.13 mm (frame 311: 16 of the 8-influence model's targets).
        assert!(err < 0.5e-3, "frame {f}: {:.3} mm", err * 1e3);
    }
}

#[test]
fn bake_is_deterministic_and_never_leaves_a_partial_file() {
    let dir = out_dir("bake_determinism");
    let a = bake(&dir, "a.glb", &["--max-targets", "8"]);
    let b = bake(&dir, "b.glb", &["--max-targets", "8"]);
    assert_eq!(std::fs::read(a).unwrap(), std::fs::read(b).unwrap());
    // A write that fails late (after the whole file is written) keeps the old output.
    let late = out_dir("bake_late_failure");
    for name in ["x.glb", "x.usdc"] {
        let (target, old) = occupied_target(&late, name);
        let out = garmentbake(&[
            "bake",
            "--model",
            model().to_str().unwrap(),
            "--motion",
            s("motions/131_02.bvh"),
            "--fps",
            "30",
            "--out",
            target.to_str().unwrap(),
        ]);
        assert_eq!(out.status.code(), Some(2));
        assert!(String::from_utf8_lossy(&out.stderr).contains(target.to_str().unwrap()));
        assert_left_untouched(&late, &old);
        std::fs::remove_dir_all(&target).unwrap();
    }
}

/// Raw little-endian f32 frames × points × 3, the reference format of tools/usd/check.py.
fn write_f32(path: &Path, frames: &[Vec<[f32; 3]>], map: Option<&[u32]>) {
    let mut bytes = Vec::new();
    for frame in frames {
        let points: Vec<[f32; 3]> = match map {
            Some(m) => m.iter().map(|&v| frame[v as usize]).collect(),
            None => frame.clone(),
        };
        for p in points.iter().flatten() {
            bytes.extend_from_slice(&p.to_le_bytes());
        }
    }
    std::fs::write(path, bytes).unwrap();
}

#[test]
fn usd_bake_replays_the_network_in_usdskel_and_the_usd_cache_equals_the_pc2() {
    let dir = out_dir("bake_usd");
    let pc2 = reference(&dir);
    let (_, frames) = exporters::pc2::read(&std::fs::read(&pc2).unwrap()).unwrap();
    // eval's USD point cache reads back equal to the same command's PC2 (131_02 at 4 fps, the
    // caches the cache tests share).
    let usd_cache = shared_eval_131_02_at_4("walk.usdc");
    let few = shared_eval_131_02_at_4("walk.pc2");
    let (_, few) = exporters::pc2::read(&std::fs::read(few).unwrap()).unwrap();
    assert_eq!(few.len(), FRAMES_AT_4);
    write_f32(&dir.join("ref.f32"), &few, None);
    let (ok, points) = usd_check(&[
        "points",
        usd_cache.to_str().unwrap(),
        "--reference",
        dir.join("ref.f32").to_str().unwrap(),
    ]);
    assert!(ok, "{points}");
    eprintln!(
        "USD cache vs PC2: max {} m over {} frames",
        points["max_abs"], points["frames"]
    );
    assert_eq!(points["frames"], FRAMES_AT_4, "{points}");
    assert!(points["max_abs"].as_f64().unwrap() <= 1e-5);
    // UsdSkel's own skinning of the baked file against the network.
    let usd = bake(&dir, "skirt.usdc", &[]);
    let (valid, report) = usd_check(&["validate", usd.to_str().unwrap()]);
    assert!(
        valid && report["errors"].as_array().unwrap().is_empty(),
        "{report}"
    );
    let map: Vec<u32> =
        serde_json::from_str(&std::fs::read_to_string(dir.join("map.json")).unwrap()).unwrap();
    write_f32(&dir.join("ref_split.f32"), &frames, Some(&map));
    let (ok, replay) = usd_check(&[
        "replay",
        usd.to_str().unwrap(),
        "--mesh",
        "garment",
        "--reference",
        dir.join("ref_split.f32").to_str().unwrap(),
    ]);
    assert!(ok, "{replay}");
    eprintln!(
        "UsdSkel replay vs eval: max {} mm over {} frames",
        replay["max_mm"], replay["compared_frames"]
    );
    // Measured 0.0005 mm: f32 noise; ten times that fails a real replay error.
    assert!(replay["max_mm"].as_f64().unwrap() <= 0.005);
}

/// The `coverage` entries of a bake's JSON report: (clip, threshold, distance, beyond).
fn bake_coverage(json: &str) -> Vec<(String, f64, Vec<f64>, Vec<usize>)> {
    let v: serde_json::Value = serde_json::from_str(json).unwrap();
    v["coverage"]
        .as_array()
        .expect("bake reports coverage per clip")
        .iter()
        .map(|c| {
            let nums = |k: &str| -> Vec<f64> {
                c[k].as_array()
                    .unwrap()
                    .iter()
                    .map(|x| x.as_f64().unwrap())
                    .collect()
            };
            (
                c["clip"].as_str().unwrap().to_string(),
                c["threshold"].as_f64().unwrap(),
                nums("distance"),
                nums("beyond").into_iter().map(|f| f as usize).collect(),
            )
        })
        .collect()
}

#[test]
fn bake_reports_each_clips_coverage_and_the_cut_held_out_clip_is_all_beyond() {
    let dir = out_dir("bake_coverage");
    let glb = dir.join("x.glb");
    let bake_json = |motion: &str| {
        garmentbake_ok(&[
            "bake",
            "--model",
            model().to_str().unwrap(),
            "--motion",
            s("motions/131_01.bvh"),
            "--motion",
            motion,
            "--max-targets",
            "8",
            "--json",
            "--out",
            glb.to_str().unwrap(),
        ])
    };
    let first = bake_json(s("motions/01_01.bvh"));
    let report = bake_coverage(&first);
    let names: Vec<&str> = report.iter().map(|c| c.0.as_str()).collect();
    assert_eq!(names, ["131_01", "01_01"]);
    for (clip, threshold, distance, beyond) in &report {
        let expected: Vec<usize> = (0..distance.len())
            .filter(|&f| distance[f] >= *threshold)
            .collect();
        assert_eq!(beyond, &expected, "{clip}");
    }
    // The training clip holds the training poses; the other subject's clip reaches beyond them
    // (the fixture is trained on 131_01 alone, whose own held-out distances 131_02 stays within).
    assert!(report[0].2.contains(&0.0));
    let beyond = &report[1].3;
    let max = report[1].2.iter().copied().fold(0.0, f64::max);
    eprintln!(
        "threshold {}, 01_01 max {max}, {} beyond",
        report[1].1,
        beyond.len()
    );
    assert!(
        !beyond.is_empty(),
        "no 01_01 frame beyond the trained range"
    );
    // The held-out clip (docs/pbns.md): those frames cut into a BVH are all beyond.
    let json = dir.join("bake.json");
    std::fs::write(&json, &first).unwrap();
    let cut = dir.join("01_01.bvh");
    run_ok(
        std::process::Command::new("python3")
            .arg(root().join("scripts/cut_bvh.py"))
            .arg(sample("motions/01_01.bvh"))
            .arg(&cut)
            .arg("--beyond-in")
            .arg(&json),
    );
    let held = bake_coverage(&bake_json(cut.to_str().unwrap()));
    assert_eq!(held[1].2.len(), beyond.len());
    for (f, d) in held[1].2.iter().enumerate() {
        assert!(
            *d >= held[1].1,
            "cut frame {f} at {d} rad, within the range"
        );
    }
    // A frame number past the clip is one error line, exit 2.
    let out = std::process::Command::new("python3")
        .arg(root().join("scripts/cut_bvh.py"))
        .arg(sample("motions/01_01.bvh"))
        .arg(dir.join("never.bvh"))
        .args(["--frames", "3,9000"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).starts_with("error: "));
    assert!(!dir.join("never.bvh").exists());
}

/// Every animated morph-target weight of a glTF, read by the `gltf` crate.
fn morph_weights(file: &Path) -> Vec<f32> {
    let (doc, buffers, _) = gltf::import(file).unwrap();
    doc.animations()
        .flat_map(|a| a.channels().collect::<Vec<_>>())
        .filter_map(|c| {
            let reader = c.reader(|b| Some(&buffers[b.index()]));
            match reader.read_outputs()? {
                gltf::animation::util::ReadOutputs::MorphTargetWeights(w) => {
                    Some(w.into_f32().collect::<Vec<f32>>())
                }
                _ => None,
            }
        })
        .flatten()
        .collect()
}

/// `bench bake` (issue 40): the test model on 131_02 at 10 fps, 8 targets. Printed, both rows
/// side by side: our bake by phase and Blender's glTF export of the same asset, and their ratio;
/// as JSON, the file it timed is byte for byte the glb `bake` writes with the same flags (its
/// SHA-256), Blender's export read and written (its import and export times, a file of its
/// own), the ratio its export time over ours. No wall-clock limit is asserted: the machine's
/// load decides those. Seen failing with the bench's bake asking for the body as well
/// (`with_body: true`): its file's digest then differs from `bake`'s.
#[test]
fn bench_bake_times_the_file_bake_writes_beside_blenders_export() {
    let dir = out_dir("bench_bake");
    let m = model().to_str().unwrap();
    let clip = [
        "--model",
        m,
        "--motion",
        s("motions/131_02.bvh"),
        "--fps",
        "10",
        "--max-targets",
        "8",
        "--threads",
        "1",
    ];
    let bench = |extra: &[&str]| garmentbake_ok(&[&["bench", "bake"], &clip[..], extra].concat());
    let text = bench(&[]);
    eprintln!("{text}");
    let ours = text
        .lines()
        .find(|l| l.starts_with("garmentbake bake: "))
        .unwrap_or_else(|| panic!("no row for our bake: {text}"));
    for phase in ["network", "svd", "normals", "replay", "write"] {
        assert!(ours.contains(&format!("{phase} ")), "{phase}: {ours}");
    }
    assert!(
        text.lines()
            .any(|l| l.starts_with("Blender ") && l.contains("glTF export of the same asset: ")),
        "no row for Blender's export: {text}"
    );
    assert!(
        text.lines().any(|l| l.starts_with("the bake is ")),
        "{text}"
    );
    let r: serde_json::Value = serde_json::from_str(&bench(&["--json"])).unwrap();
    eprintln!("{r}");
    let out = dir.join("bake.glb");
    garmentbake_ok(&[&["bake"], &clip[..], &["--out", out.to_str().unwrap()]].concat());
    let written = std::fs::read(&out).unwrap();
    assert_eq!(
        r["sha256"],
        garmentbake::io::digest::sha256_hex(&written),
        "the bench's glb is not bake's"
    );
    assert_eq!(r["bytes"], written.len() as u64);
    assert_eq!(r["targets"], 8);
    let number = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
    let bake_s = number(&r["bake_s"]);
    let phases: f64 = r["phases"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| number(&p[1]))
        .sum();
    assert!(
        bake_s > 0.0 && (bake_s - phases - number(&r["write_s"])).abs() < 1e-6,
        "{r}"
    );
    let blender = &r["blender"];
    let export_s = number(&blender["export_s"]);
    assert!(export_s > 0.0 && number(&blender["import_s"]) > 0.0, "{r}");
    assert!(blender["bytes"].as_u64().unwrap_or(0) > 0, "{r}");
    assert!(
        (number(&blender["ratio"]) - export_s / bake_s).abs() < 1e-9 * export_s / bake_s,
        "{r}"
    );
}
