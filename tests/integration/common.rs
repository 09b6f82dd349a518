//! Shared helpers for the integration tests: paths, running our binary and the independent readers.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

pub fn sample(rel: &str) -> PathBuf {
    root().join("samples").join(rel)
}

/// A fresh scratch folder per test under target/test-out.
pub fn out_dir(test: &str) -> PathBuf {
    let dir = root().join("target/test-out").join(test);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create test output dir");
    dir
}

pub fn garmentbake(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_garmentbake"))
        .args(args)
        .output()
        .expect("run garmentbake")
}

/// Runs `cmd` and panics with its stderr unless it succeeds; returns its output.
pub fn run_ok(cmd: &mut Command) -> Output {
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("cannot run {cmd:?}: {e}"));
    assert!(
        out.status.success(),
        "{cmd:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Runs garmentbake and panics with its stderr unless it succeeds; returns stdout.
pub fn garmentbake_ok(args: &[&str]) -> String {
    let out = garmentbake(args);
    assert!(
        out.status.success(),
        "garmentbake {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Khronos glTF validator (tools/node/validate.mjs): (errors+warnings == 0, summary line).
pub fn khronos_validate(file: &Path) -> (bool, String) {
    let out = Command::new("node")
        .arg(root().join("tools/node/validate.mjs"))
        .arg(file)
        .output()
        .expect("node is installed by scripts/setup.sh");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.success(), text)
}

/// three.js GLTFLoader + AnimationMixer in Node: world positions of every mesh at `times`.
pub fn threejs_positions(file: &Path, times: &[f32], animation: usize) -> serde_json::Value {
    let json = file.with_extension("three.json");
    let times: Vec<String> = times.iter().map(|t| format!("{t:.9}")).collect();
    let out = Command::new("node")
        .arg(root().join("tools/node/skin_eval.mjs"))
        .arg(file)
        .args([
            "--times",
            &times.join(","),
            "--animation",
            &animation.to_string(),
            "--out",
        ])
        .arg(&json)
        .output()
        .expect("node");
    assert!(
        out.status.success(),
        "skin_eval failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_str(&std::fs::read_to_string(&json).expect("three.js result")).expect("JSON")
}

/// three.js's replay of the mesh named "garment" in `file` at `times` against a point cache, the
/// file's vertices mapped to the cache's by `map` (a JSON list, the bake's `source_vertex`):
/// the max error over every time and vertex, in metres.
pub fn threejs_cache_error(file: &Path, times: &[f64], pc2: &Path, map: &Path) -> f64 {
    let times: Vec<String> = times.iter().map(|t| format!("{t:.9}")).collect();
    let json = file.with_extension("three.json");
    run_ok(
        Command::new("node")
            .arg(root().join("tools/node/skin_eval.mjs"))
            .arg(file)
            .args(["--times", &times.join(","), "--mesh", "garment", "--pc2"])
            .arg(pc2)
            .arg("--pc2-map")
            .arg(map)
            .arg("--out")
            .arg(&json),
    );
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(json).unwrap()).unwrap();
    assert_eq!(
        v["meshes"][0]["frames"].as_array().unwrap().len(),
        times.len()
    );
    v["meshes"][0]["max_error"].as_f64().unwrap()
}

/// Blender's own glTF importer, evaluated at scene `frames` with the scene at `fps`.
pub fn blender_positions(file: &Path, frames: &[usize], fps: f32) -> serde_json::Value {
    let json = file.with_extension("blender.json");
    let frames: Vec<String> = frames.iter().map(|f| f.to_string()).collect();
    let out = Command::new("blender")
        .args(["-b", "--factory-startup", "--python"])
        .arg(root().join("tools/blender/eval_gltf.py"))
        .arg("--")
        .arg(file)
        .args([
            "--frames",
            &frames.join(","),
            "--fps",
            &fps.to_string(),
            "--out",
        ])
        .arg(&json)
        .output()
        .expect("blender is installed by scripts/setup.sh");
    assert!(
        out.status.success(),
        "blender failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_str(&std::fs::read_to_string(&json).expect("blender result")).expect("JSON")
}

/// Flat `[x0, y0, z0, ...]` JSON numbers.
pub fn flat_positions(v: &serde_json::Value) -> Vec<[f32; 3]> {
    let a: Vec<f32> = v
        .as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_f64().expect("number") as f32)
        .collect();
    a.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
}

pub fn max_distance(a: &[[f32; 3]], b: &[[f32; 3]]) -> f32 {
    assert_eq!(a.len(), b.len(), "vertex counts differ");
    a.iter()
        .zip(b)
        .map(|(p, q)| {
            ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
        })
        .fold(0.0, f32::max)
}

/// Raw little-endian f32 frames (what tools/usd/check.py reads as `--reference`).
pub fn write_reference(path: &Path, frames: impl IntoIterator<Item = Vec<[f32; 3]>>) {
    let bytes: Vec<u8> = frames
        .into_iter()
        .flatten()
        .flatten()
        .flat_map(f32::to_le_bytes)
        .collect();
    std::fs::write(path, bytes).unwrap();
}

/// usd-core's own view of a USD file (tools/usd/check.py, run by the project venv's Python):
/// (exit status 0, the JSON it printed).
pub fn usd_check(args: &[&str]) -> (bool, serde_json::Value) {
    let out = Command::new(root().join(".venv/bin/python"))
        .arg(root().join("tools/usd/check.py"))
        .args(args)
        .output()
        .expect("the project venv is made by scripts/setup.sh");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let json = serde_json::from_str(&stdout).unwrap_or_else(|e| {
        panic!(
            "check.py {args:?} printed no JSON ({e}): {stdout}{}",
            String::from_utf8_lossy(&out.stderr)
        )
    });
    (out.status.success(), json)
}

/// A target path that is an existing folder holding an "old output" file: writing the whole file
/// works, the final rename over the folder fails. Returns (target, the old file inside it).
pub fn occupied_target(dir: &Path, name: &str) -> (PathBuf, PathBuf) {
    let target = dir.join(name);
    std::fs::create_dir_all(&target).expect("create the occupying folder");
    let old = target.join("old-output");
    std::fs::write(&old, b"old bytes").expect("write the old output");
    (target, old)
}

/// After a failed write into `dir`: the old output is unchanged and nothing else is there.
pub fn assert_left_untouched(dir: &Path, old: &Path) {
    assert_eq!(std::fs::read(old).expect("old output kept"), b"old bytes");
    let names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(
        names.len(),
        1,
        "a temporary file was left behind: {names:?}"
    );
}

/// The unit square in the xz plane (y up), split along the diagonal 1-2: the hand-computed
/// loss and metric tests fold it by lifting vertex 1.
pub fn unit_square() -> garmentbake::geometry::TriMesh {
    garmentbake::geometry::TriMesh::new(
        vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 1.0],
        ],
        vec![[0, 2, 1], [1, 2, 3]],
    )
}

/// Runs garmentbake in the repository root (so sample paths can be relative).
pub fn garmentbake_in_root(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_garmentbake"))
        .current_dir(root())
        .args(args)
        .output()
        .expect("run garmentbake")
}

/// The one `error:` line of a bad-input failure (exit code 2), checking `out` was not written.
/// Progress lines before it (stderr off a terminal gets `progress: …` once work has run a
/// second, e.g. a simulation that explodes at its third frame) are the log's, not the error's.
pub fn one_error_line(output: &Output, out: &Path) -> String {
    let err = String::from_utf8_lossy(&output.stderr).into_owned();
    assert_eq!(output.status.code(), Some(2), "{err}");
    let lines: Vec<&str> = err
        .lines()
        .filter(|l| {
            !l.trim().is_empty() && !l.starts_with("progress: ") && !l.starts_with("reading: ")
        })
        .collect();
    assert_eq!(lines.len(), 1, "{err}");
    assert!(lines[0].starts_with("error: "), "{err}");
    assert!(!out.exists(), "nothing written on failure");
    lines[0].to_string()
}

/// Runs garmentbake in the repository root with `--json` among `args`; panics with its stderr
/// unless it succeeds; returns the report.
pub fn garmentbake_json(args: &[&str]) -> serde_json::Value {
    let out = garmentbake_in_root(args);
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("a JSON report")
}

/// Lowest vertex height of the vertices mostly skinned to `joints`, for every frame.
pub fn lowest_vertex(
    body: &garmentbake::body::Body,
    anim: &garmentbake::rig::SkelAnimation,
    joints: &[usize],
) -> Vec<f32> {
    let region: Vec<u32> = (0..body.mesh().vertex_count() as u32)
        .filter(|&v| {
            body.skin
                .vertex(v as usize)
                .max_by(|a, b| a.1.total_cmp(&b.1))
                .is_some_and(|(j, _)| joints.contains(&j))
        })
        .collect();
    let pts: Vec<[f32; 3]> = region
        .iter()
        .map(|&v| body.mesh().positions[v as usize])
        .collect();
    let sub = body.skin.subset(&region);
    (0..anim.frame_count())
        .map(|f| {
            let skinning = body.skeleton.skinning_matrices(&anim.local_pose(f));
            sub.skin_points(&pts, &skinning)
                .iter()
                .map(|p| p[1])
                .fold(f32::INFINITY, f32::min)
        })
        .collect()
}

/// The simulation cache the tests share: a simulation is run once per build.
pub fn sim_cache() -> &'static str {
    static CACHE: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    CACHE.get_or_init(|| {
        root()
            .join("target/test-out/sim-cache")
            .display()
            .to_string()
    })
}

/// `simulate` of the sample skirt on 131_01 at 30 fps for `frames` frames, with paths relative to
/// the repository root ([`garmentbake_in_root`]); add the lead-in, the cache and `--out`.
pub fn skirt_simulation(frames: &str) -> Vec<&str> {
    let mut args = vec!["simulate"];
    args.extend(SKIRT_ON_131_01);
    args.extend(["--fps", "30", "--frames", frames]);
    args
}

/// The inputs of the dynamic tests (relative to the repository root): the sample body, the
/// sample skirt and the walk 131_01.
pub const SKIRT_ON_131_01: [&str; 6] = [
    "--body",
    "samples/body.glb",
    "--garment",
    "samples/garments/skirt.obj",
    "--motion",
    "samples/motions/131_01.bvh",
];

/// The short lead-in of the tests' simulations (settle 0.1 s, blend 0.2 s), cached in
/// [`sim_cache`]: a few seconds of Blender per build instead of the default second of lead-in.
pub fn short_lead_in_cached() -> [&'static str; 6] {
    ["--settle", "0.1", "--blend", "0.2", "--cache", sim_cache()]
}

/// A shipped clip (`samples/motions/NAME.bvh`) retargeted onto `body`, read as `pose` reads it,
/// at its own rate or `fps`.
pub fn sample_clip(
    body: &garmentbake::body::Body,
    name: &str,
    fps: Option<f32>,
) -> garmentbake::rig::SkelAnimation {
    garmentbake::motion::load_clip(
        &sample(&format!("motions/{name}.bvh")),
        &Default::default(),
        body,
        fps,
    )
    .unwrap()
    .animation
}
