//! `train-dynamic --stage space` on a short simulation of the sample skirt: the untrained space
//! is the exact linear fit of its frames (unskinning inverts skinning), the networks learn what a
//! one-dimensional linear path leaves (the reconstruction error falls), the same seed gives the
//! same bytes, --resume continues the checkpoint's history, and bad inputs fail with one line and
//! write nothing.

use crate::common::*;
use std::path::{Path, PathBuf};

/// Six simulated frames of the skirt on 131_01 (shared cache: simulated once per checkout).
fn short_sim(dir: &Path) -> PathBuf {
    let out = dir.join("skirt_sim.pc2");
    let cache = root().join("target/test-out/sim-cache");
    let o = garmentbake_in_root(&[
        "simulate",
        "--body",
        "samples/body.glb",
        "--garment",
        "samples/garments/skirt.obj",
        "--motion",
        "samples/motions/131_01.bvh",
        "--fps",
        "30",
        "--frames",
        "6",
        "--settle",
        "0.1",
        "--blend",
        "0.2",
        "--cache",
        cache.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    out
}

fn train(sim: &Path, out: &Path, epochs: &str, extra: &[&str]) -> serde_json::Value {
    let mut args = vec![
        "train-dynamic",
        "--body",
        "samples/body.glb",
        "--garment",
        "samples/garments/skirt.obj",
        "--motion",
        "samples/motions/131_01.bvh",
        "--sim",
        sim.to_str().unwrap(),
        "--fps",
        "30",
        "--epochs",
        epochs,
        "--batch",
        "2",
        "--lr",
        "1e-3",
        "--threads",
        "1",
        "--out",
        out.to_str().unwrap(),
        "--json",
    ];
    args.extend_from_slice(extra);
    garmentbake_json(&args)
}

#[test]
fn the_space_learns_is_deterministic_and_resumes_exactly() {
    if blender_skipped() {
        return;
    }
    let dir = out_dir("dyn_space");
    let sim = short_sim(&dir);
    // Six frames span five directions around their mean: 64 principal components hold them
    // exactly, so the untrained space must give them back (unskinning undone by skinning).
    let exact = train(&sim, &dir.join("e0.safetensors"), "0", &[]);
    let exact_mm = exact["train"]["max_mm"].as_f64().unwrap();
    assert!(
        exact_mm < 0.05,
        "untrained 64-d space: {exact_mm:.3} mm off its own frames"
    );
    // One latent dimension leaves millimetres for the networks to learn.
    let one = ["--latent", "1"];
    let before = train(&sim, &dir.join("l0.safetensors"), "0", &one)["train"]["mean_mm"]
        .as_f64()
        .unwrap();
    let a = dir.join("a.safetensors");
    let trained = train(&sim, &a, "60", &one);
    let after = trained["train"]["mean_mm"].as_f64().unwrap();
    assert!(
        after < 0.85 * before,
        "reconstruction {before:.2} mm → {after:.2} mm after 60 epochs"
    );
    assert_eq!(trained["frames"], 6);
    let (b1, b2) = (dir.join("b1.safetensors"), dir.join("b2.safetensors"));
    train(&sim, &b1, "6", &one);
    train(&sim, &b2, "6", &one);
    assert!(
        std::fs::read(&b1).unwrap() == std::fs::read(&b2).unwrap(),
        "same seed, different bytes"
    );
    // Resume extends a run (the learning-rate schedule spans the new --epochs): the first 3
    // epochs are the checkpoint's, the history goes on to 6.
    let c = dir.join("c.safetensors");
    train(&sim, &c, "3", &one);
    let history = |p: &Path| {
        let o = garmentbake_in_root(&["inspect", p.to_str().unwrap(), "--json"]);
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        v["description"]["model"]["history"]
            .as_array()
            .unwrap()
            .clone()
    };
    let first = history(&c);
    train(&sim, &c, "6", &[&one[..], &["--resume"]].concat());
    let all = history(&c);
    assert_eq!((first.len(), all.len()), (3, 6));
    assert!(
        all[..3] == first[..],
        "resume rewrote the checkpoint's history"
    );
    let o = garmentbake_in_root(&["inspect", a.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("kind: dynamic") && text.contains("kernel_radius_mm"),
        "{text}"
    );
}

#[test]
fn bad_inputs_name_the_file_and_write_nothing() {
    if blender_skipped() {
        return;
    }
    let dir = out_dir("dyn_bad");
    let sim = short_sim(&dir);
    let out = dir.join("m.safetensors");
    let fails = |garment: &str, sim: &Path| {
        let o = garmentbake_in_root(&[
            "train-dynamic",
            "--body",
            "samples/body.glb",
            "--garment",
            garment,
            "--motion",
            "samples/motions/131_01.bvh",
            "--sim",
            sim.to_str().unwrap(),
            "--fps",
            "30",
            "--epochs",
            "1",
            "--out",
            out.to_str().unwrap(),
        ]);
        one_error_line(&o, &out)
    };
    let err = fails("samples/garments/shirt.obj", &sim);
    assert!(err.contains("shirt.obj has no UVs"), "{err}");
    let body_cache = dir.join("body.pc2");
    let o = garmentbake_in_root(&[
        "simulate",
        "--body",
        "samples/body.glb",
        "--garment",
        "samples/garments/skirt.obj",
        "--motion",
        "samples/motions/131_01.bvh",
        "--fps",
        "30",
        "--frames",
        "6",
        "--settle",
        "0.1",
        "--blend",
        "0.2",
        "--cache",
        root().join("target/test-out/sim-cache").to_str().unwrap(),
        "--out",
        dir.join("again.pc2").to_str().unwrap(),
        "--body-out",
        body_cache.to_str().unwrap(),
    ]);
    assert!(o.status.success());
    let err = fails("samples/garments/skirt.obj", &body_cache);
    assert!(
        err.contains("body.pc2") && err.contains("the garment has 2808 vertices"),
        "{err}"
    );
    let bytes = std::fs::read(&sim).unwrap();
    let cut = dir.join("cut.pc2");
    std::fs::write(&cut, &bytes[..bytes.len() - 100]).unwrap();
    let err = fails("samples/garments/skirt.obj", &cut);
    assert!(
        err.contains("cut.pc2") && err.contains("the header announces"),
        "{err}"
    );
}
