//! Model files across format versions: a file written by the previous version (v2, by the
//! garmentbake of commit 1935e54, kept in tests/fixtures/models/) loads and gives the garment it
//! gave then; `upgrade` rewrites it in the current version with the same tensors; a version this
//! build does not read is refused with one line saying which way it is off.

use crate::common::*;
use garmentbake::models::file::{self, ModelFile};
use garmentbake::rig::{JointTransform, Skeleton};
use nalgebra::{UnitQuaternion, Vector3};
use std::path::{Path, PathBuf};

/// The top, width 8, 2 epochs on 131_01 at 10 fps, written by 1935e54 (`train --body
/// samples/body.glb --garment samples/garments/top.obj --motion samples/motions/131_01.bvh --fps
/// 10 --epochs 2 --width 8 --threads 1 --seed 5`).
fn v2_model() -> PathBuf {
    root().join("tests/fixtures/models/top_v2.safetensors")
}

/// Its garment for [`test_poses`], computed by 1935e54 when it wrote the file.
fn v2_garment() -> PathBuf {
    root().join("tests/fixtures/models/top_v2.poses.pc2")
}

/// The rest pose, then every joint turned by 0.1 and by 0.25 rad about x, y or z in turn
/// (alternating sign): poses that need no clip reader, so the comparison holds whatever the
/// retargeting becomes. 1935e54's side built them with this same code.
fn test_poses(skeleton: &Skeleton) -> Vec<Vec<JointTransform>> {
    [0.0f32, 0.1, 0.25]
        .iter()
        .map(|&angle| {
            skeleton
                .rest
                .iter()
                .enumerate()
                .map(|(j, rest)| {
                    let axis = [Vector3::x_axis(), Vector3::y_axis(), Vector3::z_axis()][j % 3];
                    let sign = if j % 2 == 0 { 1.0 } else { -1.0 };
                    let mut t = *rest;
                    t.rotation =
                        rest.rotation * UnitQuaternion::from_axis_angle(&axis, sign * angle);
                    t
                })
                .collect()
        })
        .collect()
}

fn predicted(file: &ModelFile) -> Vec<Vec<[f32; 3]>> {
    let model = file.pbns().unwrap();
    let poses = test_poses(file.skeleton());
    model.predict_points(&model.batch(file.skeleton(), &poses, tch::Device::Cpu))
}

fn load(path: &Path) -> ModelFile {
    file::load(path, tch::Device::Cpu).unwrap_or_else(|e| panic!("{e:#}"))
}

/// Largest distance between two pose lists' garments, in mm.
fn max_mm(a: &[Vec<[f32; 3]>], b: &[Vec<[f32; 3]>]) -> f32 {
    assert_eq!(a.len(), b.len());
    1e3 * a
        .iter()
        .zip(b)
        .map(|(x, y)| max_distance(x, y))
        .fold(0.0, f32::max)
}

#[test]
fn a_model_written_in_the_previous_format_loads_and_predicts_as_it_did() {
    let file = load(&v2_model());
    assert_eq!(file.info.version, 2, "read as the v2 file it is");
    assert_eq!(
        file.info.written_by, None,
        "a v2 file does not name its build"
    );
    let now = predicted(&file);
    let then = garmentbake::io::point_cache::read_pc2(&v2_garment(), now[0].len(), 30.0)
        .unwrap()
        .into_points();
    assert_eq!(then.len(), 3);
    // The poses move the garment (so the comparison is not of three rest shapes): 0.25 rad
    // turns moved it up to 140 mm from rest here.
    assert!(max_mm(&now[..1], &now[2..]) > 50.0);
    // Measured: 0 (bit-identical, same CPU kernels); 1 µm leaves room for another CPU's.
    let off = max_mm(&now, &then);
    assert!(off <= 1e-3, "{off} mm from 1935e54's garment");
}

#[test]
fn upgrade_rewrites_the_previous_format_with_the_same_tensors() {
    let dir = out_dir("upgrade_v2");
    let v3 = dir.join("top_v3.safetensors");
    let report = garmentbake_json(&[
        "upgrade",
        v2_model().to_str().unwrap(),
        "--out",
        v3.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(report["from_version"], 2, "{report:#}");
    assert_eq!(report["to_version"], 3, "{report:#}");
    assert_eq!(report["rewritten"], true, "{report:#}");

    // Its description says v3 (read by `inspect`), its tensors are the v2 file's byte for byte.
    let inspected = garmentbake_json(&["inspect", v3.to_str().unwrap(), "--json"]);
    assert_eq!(inspected["description"]["version"], 3);
    assert_eq!(
        inspected["description"]["written_by"],
        serde_json::Value::Null
    );
    let (old, new) = (
        std::fs::read(v2_model()).unwrap(),
        std::fs::read(&v3).unwrap(),
    );
    let (old, new) = (
        safetensors::SafeTensors::deserialize(&old).unwrap(),
        safetensors::SafeTensors::deserialize(&new).unwrap(),
    );
    let mut names = old.names();
    names.sort();
    let mut new_names = new.names();
    new_names.sort();
    assert_eq!(names, new_names);
    for name in names {
        let (a, b) = (old.tensor(name).unwrap(), new.tensor(name).unwrap());
        assert_eq!(
            (a.dtype(), a.shape(), a.data()),
            (b.dtype(), b.shape(), b.data()),
            "{name}"
        );
    }
    let upgraded = load(&v3);
    assert_eq!(upgraded.info.version, 3);
    assert_eq!(upgraded.info.written_by, None, "still unknown");
    assert_eq!(
        max_mm(&predicted(&upgraded), &predicted(&load(&v2_model()))),
        0.0
    );

    // Upgrading a current file writes nothing.
    let before = std::fs::read(&v3).unwrap();
    let again = garmentbake_json(&["upgrade", v3.to_str().unwrap(), "--json"]);
    assert_eq!(again["rewritten"], false, "{again:#}");
    assert_eq!(std::fs::read(&v3).unwrap(), before);
}

/// The v3 file with its version number replaced (same length, so the header stays valid).
fn with_version(dir: &Path, version: u32) -> PathBuf {
    let v3 = dir.join("current.safetensors");
    garmentbake_json(&[
        "upgrade",
        v2_model().to_str().unwrap(),
        "--out",
        v3.to_str().unwrap(),
        "--json",
    ]);
    let bytes = std::fs::read(&v3).unwrap();
    let (from, to) = (r#"\"version\":3,"#, format!(r#"\"version\":{version},"#));
    let at = bytes
        .windows(from.len())
        .position(|w| w == from.as_bytes())
        .expect("the description's version");
    let mut edited = bytes.clone();
    edited[at..at + from.len()].copy_from_slice(to.as_bytes());
    let path = dir.join(format!("v{version}.safetensors"));
    std::fs::write(&path, edited).unwrap();
    path
}

#[test]
fn versions_this_build_does_not_read_are_one_line_saying_which_way() {
    let dir = out_dir("model_versions");
    for (version, says) in [
        (9, "newer than this build reads"),
        (1, "older than this build reads"),
    ] {
        let model = with_version(&dir, version);
        let out = dir.join("out.pc2");
        let run = garmentbake_in_root(&[
            "eval",
            "--model",
            model.to_str().unwrap(),
            "--motion",
            "samples/motions/131_01.bvh",
            "--out",
            out.to_str().unwrap(),
        ]);
        let err = one_error_line(&run, &out);
        assert!(
            err.contains(model.to_str().unwrap()) && err.contains(says),
            "{err}"
        );
        let upgraded = dir.join("upgraded.safetensors");
        let run = garmentbake(&[
            "upgrade",
            model.to_str().unwrap(),
            "--out",
            upgraded.to_str().unwrap(),
        ]);
        one_error_line(&run, &upgraded);
    }
}
