//! `train-swing`: a PBNS taught to swing from physics alone. Trained on the walk 131_01 from the
//! small PBNS of the bake tests, played on the other walk 131_02; the hem's motion beyond the
//! quasi-static PBNS (in the waist frame, each vertex's mean removed) is what the inertia term
//! and the motion history must produce.

use crate::common::*;
use garmentbake::metrics::hem;
use garmentbake::models::file::ModelFile;
use std::path::PathBuf;
use std::sync::OnceLock;

const EPOCHS: &str = "20";

/// A swing on the bake tests' PBNS, trained once per test run per inertia weight.
fn swing(inertia: &str) -> PathBuf {
    let dir = out_dir(&format!("swing_{inertia}"));
    let out = dir.join("swing.safetensors");
    garmentbake_ok(&[
        "train-swing",
        "--from",
        crate::bake::model().to_str().unwrap(),
        "--motion",
        crate::bake::s("motions/131_01.bvh"),
        "--fps",
        "30",
        "--epochs",
        EPOCHS,
        "--width",
        "64",
        "--shapes",
        "16",
        "--lr",
        "3e-3",
        "--inertia",
        inertia,
        "--threads",
        "1",
        "--out",
        out.to_str().unwrap(),
    ]);
    out
}

fn with_inertia() -> &'static PathBuf {
    static M: OnceLock<PathBuf> = OnceLock::new();
    M.get_or_init(|| swing("100"))
}

/// The garment of `model` over 131_02 at 30 fps (played in order from rest), and the waist's
/// skinning transform per frame.
fn play(model: &ModelFile) -> (Vec<Vec<[f32; 3]>>, Vec<nalgebra::Matrix4<f32>>) {
    let reader = garmentbake::motion::read_maps(&[] as &[PathBuf]).unwrap();
    let clip = garmentbake::motion::load_clip(
        &sample("motions/131_02.bvh"),
        &reader,
        &model.body,
        Some(30.0),
    )
    .unwrap()
    .animation;
    let poses: Vec<_> = (0..clip.frame_count())
        .map(|f| clip.local_pose(f))
        .collect();
    let network = model.pbns().unwrap();
    let frames = network.predict_points(&network.batch(model.skeleton(), &poses, tch::Device::Cpu));
    let skeleton = model.skeleton();
    let root = (0..skeleton.joint_count())
        .find(|&j| skeleton.parents[j].is_none())
        .unwrap();
    let waist = poses
        .iter()
        .map(|p| skeleton.skinning_matrices(p)[root])
        .collect();
    (frames, waist)
}

/// RMS (mm) of the hem's motion beyond the quasi-static PBNS the swing was trained on.
fn swing_beyond_pbns_mm(model: &ModelFile) -> f64 {
    let base = garmentbake::models::file::load(crate::bake::model(), tch::Device::Cpu).unwrap();
    let (frames, waist) = play(model);
    let (static_frames, _) = play(&base);
    let loop_ = hem::hem_loop(&model.garment).unwrap();
    let moving = hem::in_waist_frame(&frames, &loop_, &waist);
    let still = hem::in_waist_frame(&static_frames, &loop_, &waist);
    hem::amplitude_mm(&hem::residual(&moving, Some(&still)))
}

fn load(path: &std::path::Path) -> ModelFile {
    garmentbake::models::file::load(path, tch::Device::Cpu).unwrap()
}

/// With inertia the hem moves beyond the PBNS on a clip it never saw; trained without inertia
/// (the same potential, the same inputs) it does not.
#[test]
fn the_hem_swings_with_inertia_and_not_without() {
    // The swing without inertia first: under two test threads the shared one is trained meanwhile
    // by the test beside this one, instead of this test waiting for it and then training its own.
    let without = swing("0");
    let moving = swing_beyond_pbns_mm(&load(with_inertia()));
    let still = swing_beyond_pbns_mm(&load(&without));
    println!("hem beyond PBNS: {moving:.2} mm with inertia, {still:.2} mm without");
    // Measured: 37.6 mm with inertia (×100), 0.39 mm without.
    assert!(
        moving > 10.0 && moving > 10.0 * still,
        "{moving:.2} mm vs {still:.2} mm"
    );
}

/// The swing answers the motion: with the motion history zeroed (the same network, its motion
/// inputs normalised to nothing) the hem's motion beyond PBNS collapses.
#[test]
fn the_swing_follows_the_motion_history() {
    let mut model = load(with_inertia());
    let moving = swing_beyond_pbns_mm(&model);
    if let garmentbake::models::Model::Pbns(p) = &mut model.model {
        let s = p.swing.as_mut().unwrap();
        s.input_scale = s.input_scale.ones_like() * 1e30;
    }
    let blind = swing_beyond_pbns_mm(&model);
    println!("hem beyond PBNS: {moving:.2} mm with the history, {blind:.2} mm with it zeroed");
    // Measured: 37.6 mm with the history, 4.67 mm with it zeroed.
    assert!(moving > 3.0 * blind, "{moving:.2} mm vs {blind:.2} mm");
}

/// The swing baked into ≤ 16 blend shapes over one weight track: Khronos-clean, and three.js's
/// replay of every frame of 131_02, and Blender's importer on every 25th, within 1 mm of the
/// network played in order.
#[test]
fn a_baked_swing_replays_the_network_in_threejs_and_blender() {
    let dir = out_dir("swing_bake");
    let model = load(with_inertia());
    let (frames, _) = play(&model);
    let reference = dir.join("ref.pc2");
    let cache = exporters::PointCache {
        name: "swing".into(),
        fps: 30.0,
        start: 0,
        triangles: Vec::new(),
        uvs: None,
        point_count: frames[0].len(),
        points: frames.iter().flatten().copied().collect(),
    };
    exporters::pc2::write(&reference, &cache).unwrap();
    let skin = model.pbns().unwrap().skin();
    let mesh =
        garmentbake::bake::skinned_mesh_asset("garment", &model.garment, None, &skin, [0.0; 3]);
    let map = dir.join("map.json");
    std::fs::write(&map, serde_json::to_string(&mesh.source_vertex).unwrap()).unwrap();
    let glb = dir.join("swing.glb");
    let report = garmentbake_json(&[
        "bake",
        "--model",
        with_inertia().to_str().unwrap(),
        "--motion",
        crate::bake::s("motions/131_02.bvh"),
        "--max-targets",
        "16",
        "--out",
        glb.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(report["report"]["targets"], 16, "{report}");
    let (ok, log) = khronos_validate(&glb);
    assert!(ok, "{log}");
    let times: Vec<f64> = (0..frames.len()).map(|f| f as f64 / 30.0).collect();
    let error_mm = 1000.0 * threejs_cache_error(&glb, &times, &reference, &map);
    println!(
        "three.js replay of the 16-target swing bake: max {error_mm:.3} mm over {} frames",
        frames.len()
    );
    assert!(error_mm < 1.0, "{error_mm:.3} mm");
    // Blender's own glTF importer, every 25th frame and the last, against the same network.
    let picked: Vec<usize> = (0..frames.len())
        .step_by(25)
        .chain([frames.len() - 1])
        .collect();
    let result = crate::common::blender_positions(&glb, &picked, 30.0);
    let garment = result["meshes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|m| m["gltf_mesh"] == 0)
        .expect("garment mesh");
    assert_eq!(garment["shape_key_count"], 16, "{garment}");
    let mut worst_mm = 0.0f32;
    for (i, &f) in picked.iter().enumerate() {
        let blender = crate::common::flat_positions(&garment["frames"][i]["positions"]);
        let network: Vec<[f32; 3]> = mesh
            .source_vertex
            .iter()
            .map(|&v| frames[f][v as usize])
            .collect();
        worst_mm = worst_mm.max(1000.0 * crate::common::max_distance(&blender, &network));
    }
    println!(
        "Blender 3.4 replay of the same bake: max {worst_mm:.3} mm over {} frames",
        picked.len()
    );
    assert!(worst_mm < 1.0, "{worst_mm:.3} mm");
}

/// `bench swing` times the trainer `train-swing` builds on the same inputs: the frames and steps
/// it reports are the training's, and the recipe's time is its setup plus 30 of its epochs.
#[test]
fn bench_swing_times_the_training_it_projects() {
    let bench = |more: &[&'static str]| {
        let mut args = vec![
            "bench",
            "swing",
            "--from",
            crate::bake::model().to_str().unwrap(),
            "--motion",
            crate::bake::s("motions/131_01.bvh"),
        ];
        args.extend(more);
        args
    };
    let report = garmentbake_json(&bench(&[
        "--fps",
        "30",
        "--epochs",
        "1",
        "--shapes",
        "16",
        "--threads",
        "1",
        "--json",
    ]));
    let r = &report;
    // 131_01 at 30 fps: 249 frames (docs/dynamic.md); 245 sequence starts (a 3-frame unroll
    // after two earlier frames), 16 sequences of 3 frames a step: 6 steps.
    assert_eq!(r["frames"], 249, "{report}");
    assert_eq!(r["steps_per_epoch"], 6, "{report}");
    let f = |k: &str| r[k].as_f64().unwrap();
    assert!(f("epoch_s") > 0.0 && f("setup_s") > 0.0, "{report}");
    assert_eq!(r["recipe_epochs"], 30);
    assert!((f("recipe_s") - (f("setup_s") + 30.0 * f("epoch_s"))).abs() < 1e-6 * f("recipe_s"));
    assert!((f("frames_per_s") - 249.0 / f("epoch_s")).abs() < 1e-6 * f("frames_per_s"));
    let output = garmentbake(&bench(&["--epochs", "0"]));
    assert_eq!(
        one_error_line(&output, &out_dir("bench_swing").join("nothing")),
        "error: --epochs must be at least 1: nothing would be timed"
    );
}
