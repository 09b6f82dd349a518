//! Bad input gets one clear line on stderr naming the file and the problem, a non-zero exit code,
//! and never a panic trace.

use crate::common::*;
use std::path::Path;

/// Runs garmentbake expecting the bad-input failure (exit code 2); returns the single stderr line.
fn fails(args: &[&str]) -> String {
    let out = garmentbake(args);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
    assert!(!stderr.contains("panicked"), "panic: {stderr}");
    // A clip read before the failure leaves its `reading:` log line; the error is the one line.
    let lines: Vec<&str> = stderr
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with("reading: "))
        .collect();
    assert_eq!(lines.len(), 1, "one line expected, got: {stderr}");
    assert!(lines[0].starts_with("error: "), "{stderr}");
    lines[0].to_string()
}

fn pose_with(motion: &Path, out: &Path) -> String {
    fails(&[
        "pose",
        "--body",
        sample("body.glb").to_str().unwrap(),
        "--motion",
        motion.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ])
}

#[test]
fn truncated_bvh_is_reported_with_the_frames_found() {
    let dir = out_dir("err_truncated");
    let text = std::fs::read_to_string(sample("motions/131_01.bvh")).unwrap();
    let cut = dir.join("cut.bvh");
    std::fs::write(&cut, &text[..text.len() / 2]).unwrap();
    let out = dir.join("x.glb");
    let msg = pose_with(&cut, &out);
    assert!(msg.contains("cut.bvh") && msg.contains("994"), "{msg}");
    assert!(!out.exists(), "no output on failure");
}

#[test]
fn bvh_joint_unknown_to_every_map_is_named() {
    let dir = out_dir("err_joint");
    let text = std::fs::read_to_string(sample("motions/01_01.bvh"))
        .unwrap()
        .replacen("JOINT LeftUpLeg", "JOINT LeftThigh", 1);
    let clip = dir.join("renamed.bvh");
    std::fs::write(&clip, text).unwrap();
    let msg = pose_with(&clip, &dir.join("x.glb"));
    assert!(
        msg.contains("renamed.bvh") && msg.contains("LeftThigh") && msg.contains("--map"),
        "{msg}"
    );
}

#[test]
fn obj_face_index_out_of_range_is_reported_with_its_line() {
    let dir = out_dir("err_obj");
    let obj = dir.join("bad.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 9\n").unwrap();
    let msg = fails(&["inspect", obj.to_str().unwrap()]);
    assert!(
        msg.contains("bad.obj:5") && msg.contains("out of range"),
        "{msg}"
    );
}

#[test]
fn glb_without_a_skin_is_not_a_body() {
    let dir = out_dir("err_noskin");
    let glb = dir.join("static.glb");
    let mesh = exporters::asset::Mesh {
        name: "tri".into(),
        points: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        triangles: vec![[0, 1, 2]],
        source_vertex: vec![0, 1, 2],
        ..Default::default()
    };
    exporters::gltf::write(
        &exporters::BakedAsset {
            meshes: vec![mesh],
            ..Default::default()
        },
        &glb,
    )
    .unwrap();
    let msg = fails(&[
        "pose",
        "--body",
        glb.to_str().unwrap(),
        "--motion",
        sample("motions/131_01.bvh").to_str().unwrap(),
        "--out",
        dir.join("x.glb").to_str().unwrap(),
    ]);
    assert!(
        msg.contains("static.glb") && msg.contains("no skinned mesh"),
        "{msg}"
    );
}

#[test]
fn a_write_that_fails_late_leaves_the_old_output_and_no_temp_file() {
    let dir = out_dir("late_write_failure");
    // The whole file is written, then the final rename fails: the target is a folder that holds
    // the "old output". It must stay as it was, and no temporary file may remain.
    let (target, old) = occupied_target(&dir, "x.glb");
    let msg = fails(&[
        "pose",
        "--body",
        sample("body.glb").to_str().unwrap(),
        "--motion",
        sample("motions/131_01.bvh").to_str().unwrap(),
        "--out",
        target.to_str().unwrap(),
    ]);
    assert!(msg.contains(target.to_str().unwrap()), "{msg}");
    assert_left_untouched(&dir, &old);
}

/// The commands listed in the `Commands:` section of `garmentbake PATH.. --help` (clap's command
/// tree as the binary prints it), without clap's own `help`.
fn subcommands(path: &[String]) -> Vec<String> {
    let args: Vec<&str> = path.iter().map(String::as_str).chain(["--help"]).collect();
    let help = garmentbake_ok(&args);
    help.lines()
        .skip_while(|l| l.trim() != "Commands:")
        .skip(1)
        .take_while(|l| !l.trim().is_empty())
        // A command's line starts two spaces in; wrapped descriptions are indented further.
        .filter(|l| l.starts_with("  ") && !l.starts_with("   "))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|c| *c != "help")
        .map(str::to_string)
        .collect()
}

/// Every command and every subcommand, taken from the binary's own help so a new one is covered
/// without editing this test, prints its usage and options (a clap definition error, e.g. two
/// flags with one short name, panics only when that command is parsed).
#[test]
fn every_command_has_help() {
    let mut pending: Vec<Vec<String>> = subcommands(&[]).into_iter().map(|c| vec![c]).collect();
    let top_level = pending.len();
    let mut checked = Vec::new();
    while let Some(cmd) = pending.pop() {
        let mut args: Vec<&str> = cmd.iter().map(String::as_str).collect();
        args.push("--help");
        let out = garmentbake_ok(&args);
        let usage = format!("Usage: garmentbake {}", cmd.join(" "));
        assert!(out.contains(&usage), "{cmd:?}: {out}");
        assert!(out.contains("-h, --help"), "{cmd:?}: {out}");
        for sub in subcommands(&cmd) {
            pending.push([cmd.clone(), vec![sub]].concat());
        }
        checked.push(cmd.join(" "));
    }
    // The README's command table has 14 commands; `bench` has subcommands of its own.
    assert!(top_level >= 14, "{top_level} commands: {checked:?}");
    assert!(
        checked.iter().any(|c| c.starts_with("bench ")),
        "{checked:?}"
    );
    let top = garmentbake_ok(&["--help"]);
    assert!(top.contains("metres, Y-up"), "{top}");
}

#[test]
fn inspect_describes_each_sample_kind() {
    let glb = garmentbake_ok(&["inspect", "--json", sample("body.glb").to_str().unwrap()]);
    let v: serde_json::Value = serde_json::from_str(&glb).unwrap();
    assert_eq!(v["skins"][0]["joints"].as_array().unwrap().len(), 31);
    let bvh: serde_json::Value = serde_json::from_str(&garmentbake_ok(&[
        "inspect",
        "--json",
        sample("motions/131_02.bvh").to_str().unwrap(),
    ]))
    .unwrap();
    assert_eq!(bvh["frames"], 1247);
    let obj: serde_json::Value = serde_json::from_str(&garmentbake_ok(&[
        "inspect",
        "--json",
        sample("garments/skirt.obj").to_str().unwrap(),
    ]))
    .unwrap();
    assert_eq!(
        obj["boundary_loops"].as_array().unwrap().len(),
        2,
        "waist and hem"
    );
}
