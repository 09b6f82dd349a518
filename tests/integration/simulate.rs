//! `simulate`: Blender's cloth on our posed body, checked by our own geometry (not Blender's
//! numbers): nothing ends inside the body, pins follow it, the clip plays in real seconds along
//! our -Y, the same inputs give the same bytes, and failures write nothing.

use crate::common::*;
use garmentbake::body::PosedBody;
use garmentbake::geometry::{SurfaceIndex, TriMesh};
use garmentbake::io::obj::write_obj;
use std::path::{Path, PathBuf};

/// The skirt's top 8 cm (its waist band and hips, pins kept): a small garment that touches
/// the body everywhere.
fn waist_band(dir: &Path) -> PathBuf {
    let skirt = garmentbake::garment::Garment::read(&sample("garments/skirt.obj")).unwrap();
    let top = skirt
        .mesh
        .positions
        .iter()
        .map(|p| p[1])
        .fold(f32::MIN, f32::max);
    let keep: Vec<bool> = skirt
        .mesh
        .positions
        .iter()
        .map(|p| p[1] > top - 0.08)
        .collect();
    let mut index = vec![u32::MAX; keep.len()];
    let mut positions = Vec::new();
    for (v, _) in keep.iter().enumerate().filter(|(_, k)| **k) {
        index[v] = positions.len() as u32;
        positions.push(skirt.mesh.positions[v]);
    }
    let triangles = skirt
        .mesh
        .triangles
        .iter()
        .filter(|t| t.iter().all(|&v| keep[v as usize]))
        .map(|t| t.map(|v| index[v as usize]))
        .collect();
    let pinned: Vec<u32> = skirt
        .sidecar
        .pinned
        .iter()
        .map(|&v| index[v as usize])
        .filter(|&v| v != u32::MAX)
        .collect();
    assert!(pinned.len() > 20, "the band keeps the waist pins");
    let obj = dir.join("band.obj");
    write_obj(
        &obj,
        &TriMesh::new(positions, triangles),
        "waist band of the sample skirt",
    )
    .unwrap();
    std::fs::write(dir.join("band.toml"), format!("pinned = {pinned:?}\n")).unwrap();
    obj
}

fn simulate(garment: &Path, out: &Path, extra: &[&str]) -> serde_json::Value {
    let mut args = vec![
        "simulate",
        "--body",
        "samples/body.glb",
        "--garment",
        garment.to_str().unwrap(),
        "--motion",
        "samples/motions/01_01.bvh",
        "--fps",
        "30",
        "--out",
        out.to_str().unwrap(),
        "--no-cache",
        "--json",
    ];
    args.extend_from_slice(extra);
    garmentbake_json(&args)
}

#[test]
fn a_waist_band_on_a_walking_body_stays_outside_and_pins_follow_within_a_millimetre() {
    let dir = out_dir("sim_band");
    let band = waist_band(&dir);
    let pc2 = dir.join("band.pc2");
    let short = ["--frames", "8", "--threads", "1"];
    let report = simulate(&band, &pc2, &short);
    let garment = garmentbake::garment::Garment::read(&band).unwrap();
    let frames = garmentbake::io::point_cache::read_pc2(&pc2, garment.mesh.vertex_count(), 30.0)
        .unwrap()
        .into_points();
    assert_eq!(frames.len(), 8);

    // Inside: our winding number of the posed body, recomputed here from the file.
    let body = garmentbake::io::gltf_body::read_body(&sample("body.glb")).unwrap();
    let clip = garmentbake::motion::load_clip(
        &sample("motions/01_01.bvh"),
        &Default::default(),
        &body,
        Some(30.0),
    )
    .unwrap();
    let pins = &garment.sidecar.pinned;
    let rest_index = garmentbake::geometry::PointIndex::new(&body.mesh().positions).unwrap();
    let under: Vec<usize> = pins
        .iter()
        .map(|&v| rest_index.nearest(garment.mesh.positions[v as usize]).0 as usize)
        .collect();
    let mut worst_pin = 0.0f32;
    for (f, x) in frames.iter().enumerate() {
        let pose = clip.animation.local_pose(f);
        let posed = PosedBody::new(&body, &pose);
        let surface = SurfaceIndex::new(&posed.points, &body.mesh().triangles);
        let deep: Vec<(usize, f32)> = x
            .iter()
            .enumerate()
            .filter(|(_, p)| surface.is_inside(**p))
            .map(|(v, p)| (v, surface.distance(*p)))
            .collect();
        assert!(
            deep.is_empty(),
            "frame {f}: {} vertices inside the body (vertex, depth m): {:?}",
            deep.len(),
            &deep[..deep.len().min(5)]
        );
        // Pins ride the skin vertex under them: its skinning transform applied to the pin at rest.
        let skinning = body.skeleton.skinning_matrices(&pose);
        for (&v, &b) in pins.iter().zip(&under) {
            let m = body.skin.blended(b, &skinning);
            let p = garment.mesh.positions[v as usize];
            let target = m.transform_point(&nalgebra::Point3::new(p[0], p[1], p[2]));
            let q = x[v as usize];
            worst_pin = worst_pin.max((target - nalgebra::Point3::new(q[0], q[1], q[2])).norm());
        }
    }
    assert!(
        worst_pin < 1e-3,
        "a pinned vertex is {worst_pin} m off the skin it is pinned to"
    );
    let drift = report["summary"]["pinned_error_max_mm"].as_f64().unwrap();
    assert!(drift < 1.0, "the report says pins drift {drift} mm");
    assert_eq!(report["frames"], 8);
    assert_eq!(report["per_frame"].as_array().unwrap().len(), 8);

    // Same inputs, another thread count: the same bytes.
    let again = dir.join("again.pc2");
    simulate(&band, &again, &["--frames", "8", "--threads", "2"]);
    assert_eq!(
        std::fs::read(&pc2).unwrap(),
        std::fs::read(&again).unwrap(),
        "not deterministic"
    );
}

/// An `n`×`n` grid patch, `size` metres wide, horizontal, centred at `c`.
fn patch(dir: &Path, name: &str, c: [f32; 3], size: f32, n: u32) -> PathBuf {
    let step = size / (n - 1) as f32;
    let positions = (0..n * n)
        .map(|k| {
            [
                c[0] - size / 2.0 + (k % n) as f32 * step,
                c[1],
                c[2] - size / 2.0 + (k / n) as f32 * step,
            ]
        })
        .collect();
    let triangles = (0..n - 1)
        .flat_map(|j| (0..n - 1).map(move |i| (j * n + i, n)))
        .flat_map(|(a, n)| [[a, a + n, a + 1], [a + 1, a + n, a + n + 1]])
        .collect();
    let obj = dir.join(format!("{name}.obj"));
    write_obj(&obj, &TriMesh::new(positions, triangles), "a test patch").unwrap();
    obj
}

/// A fabric with no air drag, so a free fall is ½ g t².
fn still_air(dir: &Path) -> PathBuf {
    let path = dir.join("still.toml");
    std::fs::write(&path, "name = \"still\"\nedge = 50.0\nbend = 1e-3\ndensity = 0.15\n[simulate]\nair_damping = 0.0\n").unwrap();
    path
}

fn mean(frame: &[[f32; 3]], axis: usize) -> f64 {
    frame.iter().map(|p| p[axis] as f64).sum::<f64>() / frame.len() as f64
}

#[test]
fn a_free_patch_falls_half_g_t_squared_along_minus_y_at_any_frame_rate() {
    let dir = out_dir("sim_fall");
    let obj = patch(&dir, "patch", [1.5, 1.2, 0.0], 0.3, 6);
    let fabric = still_air(&dir);
    for fps in ["30", "60"] {
        let pc2 = dir.join(format!("fall{fps}.pc2"));
        let report = {
            let mut args = vec![
                "simulate",
                "--body",
                "samples/body.glb",
                "--garment",
                obj.to_str().unwrap(),
                "--motion",
                "samples/motions/131_01.bvh",
                "--fps",
                fps,
                "--out",
                pc2.to_str().unwrap(),
                "--config",
                fabric.to_str().unwrap(),
                "--frames",
                "10",
                "--settle",
                "0",
                "--blend",
                "0",
                "--no-cache",
                "--json",
            ];
            args.push("--threads");
            args.push("1");
            garmentbake_json(&args)
        };
        assert_eq!(report["lead_in_frames"], 0);
        let frames = garmentbake::io::point_cache::read_pc2(&pc2, 36, 30.0)
            .unwrap()
            .into_points();
        let t = 9.0 / fps.parse::<f64>().unwrap();
        let drop = mean(&frames[0], 1) - mean(&frames[9], 1);
        let expected = 0.5 * 9.81 * t * t;
        assert!(
            (drop / expected - 1.0).abs() < 0.03,
            "{fps} fps: fell {drop} m in {t} s, ½gt² = {expected}"
        );
        for axis in [0, 2] {
            let moved = (mean(&frames[9], axis) - mean(&frames[0], axis)).abs();
            assert!(moved < 1e-3, "{fps} fps: moved {moved} m along axis {axis}");
        }
    }
}

#[test]
fn failures_name_their_cause_and_write_nothing() {
    let dir = out_dir("sim_fail");
    let obj = patch(&dir, "patch", [1.5, 1.2, 0.0], 0.3, 6);
    let out = dir.join("x.pc2");
    let run = |extra: &[&str], garment: &Path| {
        let mut args = vec![
            "simulate",
            "--body",
            "samples/body.glb",
            "--garment",
            garment.to_str().unwrap(),
            "--motion",
            "samples/motions/131_01.bvh",
            "--fps",
            "30",
            "--out",
            out.to_str().unwrap(),
            "--frames",
            "6",
            "--settle",
            "0",
            "--blend",
            "0",
            "--no-cache",
        ];
        args.extend_from_slice(extra);
        let o = garmentbake_in_root(&args);
        one_error_line(&o, &out)
    };
    // A falling patch passes 0.5 m/s between frames 2 and 3: taken for an explosion.
    let err = run(&["--speed-limit", "0.5"], &obj);
    assert!(
        err.contains("exploded at frame 3 of the clip") && err.contains("m/s"),
        "{err}"
    );
    let err = run(&["--blender", "/nonexistent/blender"], &obj);
    assert!(
        err.contains("Blender not found") && err.contains("apt-get install blender"),
        "{err}"
    );
    let inside = patch(&dir, "inside", [0.0, 1.1, 0.0], 0.08, 4);
    let err = run(&[], &inside);
    assert!(err.contains("inside the body"), "{err}");
}

/// The cache reads a repeat back, and keys on which Blender simulates as well as on the job:
/// the same request to another Blender (here a wrapper reporting another version) simulates
/// again. (Before, the key held the job and the package version only, and an upgraded
/// Blender's request was served the old Blender's frames.)
#[test]
fn the_cache_reads_a_repeat_back_and_simulates_again_for_another_blender() {
    let dir = out_dir("sim_cache");
    let obj = patch(&dir, "patch", [1.5, 1.2, 0.0], 0.3, 6);
    let fabric = still_air(&dir);
    let cache = dir.join("cache");
    let next = dir.join("blender-next");
    std::fs::write(
        &next,
        "#!/bin/sh\n# Blender itself, reporting another version.\n\
         if [ \"$1\" = --version ]; then echo 'Blender 99.0.0 (test wrapper)'; exit 0; fi\n\
         exec blender \"$@\"\n",
    )
    .unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&next, std::fs::Permissions::from_mode(0o755)).unwrap();
    let pc2 = dir.join("patch.pc2");
    let simulate = |extra: &[&str]| {
        let mut args = vec![
            "simulate",
            "--body",
            "samples/body.glb",
            "--garment",
            obj.to_str().unwrap(),
            "--config",
            fabric.to_str().unwrap(),
            "--motion",
            "samples/motions/131_01.bvh",
            "--fps",
            "30",
            "--frames",
            "4",
            "--settle",
            "0",
            "--blend",
            "0",
            "--threads",
            "1",
            "--cache",
            cache.to_str().unwrap(),
            "--out",
            pc2.to_str().unwrap(),
            "--json",
        ];
        args.extend_from_slice(extra);
        let report = garmentbake_json(&args);
        (report, std::fs::read(&pc2).unwrap())
    };
    let (first, frames) = simulate(&[]);
    assert_eq!(first["cached"], false);
    let (repeat, repeated) = simulate(&[]);
    assert_eq!(repeat["cached"], true, "the same request is read back");
    assert_eq!(repeat["cache_key"], first["cache_key"]);
    assert_eq!(repeated, frames);
    let (other, _) = simulate(&["--blender", next.to_str().unwrap()]);
    assert_eq!(other["cached"], false, "another Blender simulates again");
    assert_ne!(other["cache_key"], first["cache_key"]);
    let (other_repeat, _) = simulate(&["--blender", next.to_str().unwrap()]);
    assert_eq!(other_repeat["cached"], true);
}
