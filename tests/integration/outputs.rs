//! Commands that write several files (`simulate --out --body-out`, `eval --out --body-out
//! --view`, `rollout --out --lbs-out --body-out`, `bake --out --view`) check every output before
//! the work and write the set all or nothing; on a full disk (a 1 MB tmpfs, mounted here: the
//! tests run as root, as in CI) every command gives one error line and leaves no file and no
//! temporary file.

use crate::common::*;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The files and folders under `dir` (relative, sorted), hidden ones included.
fn tree(dir: &Path) -> Vec<String> {
    fn walk(base: &Path, dir: &Path, out: &mut Vec<String>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            out.push(p.strip_prefix(base).unwrap().display().to_string());
            if p.is_dir() {
                walk(base, &p, out);
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out);
    out.sort();
    out
}

fn run(args: &[&str]) -> std::process::Output {
    garmentbake_in_root(args)
}

/// The PBNS model the bake tests train once per run.
fn pbns_model() -> String {
    crate::bake::model().display().to_string()
}

#[test]
fn simulate_checks_body_out_before_simulating() {
    let dir = out_dir("outputs_simulate");
    let out = dir.join("skirt.pc2");
    let base = |body_out: &Path| {
        let mut args = skirt_simulation("6");
        args.extend(["--no-cache", "--out", out.to_str().unwrap()]);
        args.extend(["--body-out", body_out.to_str().unwrap()]);
        run(&args)
    };
    // Before: the simulation ran, --out was written, then --body-out failed.
    let err = one_error_line(&base(&dir.join("body.obj")), &out);
    assert!(err.contains("--body-out") && err.contains(".pc2"), "{err}");
    let err = one_error_line(&base(&dir.join("no-such-folder/body.pc2")), &out);
    assert!(
        err.contains("--body-out") && err.contains("no folder"),
        "{err}"
    );
    let err = one_error_line(&base(&out), &dir.join("never"));
    assert!(err.contains("--out writes that file too"), "{err}");
    assert!(tree(&dir).is_empty(), "{:?}", tree(&dir));
}

/// `eval --out A --body-out B --view C`: a bad B or C is refused before the model is run; a B
/// whose final move fails (a folder holds its name) leaves neither A nor C, and the old A.
#[test]
fn eval_writes_its_outputs_all_or_nothing() {
    let model = pbns_model();
    let dir = out_dir("outputs_eval");
    let (out, page) = (dir.join("skirt.pc2"), dir.join("skirt.html"));
    let eval = |body_out: &Path, page: &Path| {
        run(&[
            "eval",
            "--model",
            &model,
            "--motion",
            "samples/motions/131_01.bvh",
            "--fps",
            "1",
            "--threads",
            "1",
            "--out",
            out.to_str().unwrap(),
            "--body-out",
            body_out.to_str().unwrap(),
            "--view",
            page.to_str().unwrap(),
        ])
    };
    let err = one_error_line(&eval(&dir.join("none/body.pc2"), &page), &out);
    assert!(err.contains("--body-out") && err.contains("none"), "{err}");
    let err = one_error_line(&eval(&dir.join("body.pc2"), &dir.join("p.txt")), &out);
    assert!(err.contains("--view") && err.contains(".html"), "{err}");
    // The whole evaluation runs; the body cache cannot take its name at the end.
    std::fs::write(&out, b"old bytes").unwrap();
    let blocked = dir.join("body.pc2");
    std::fs::create_dir(&blocked).unwrap();
    let err = one_error_line(&eval(&blocked, &page), &page);
    assert!(err.contains(&*blocked.to_string_lossy()), "{err}");
    assert!(
        std::fs::read(&out).unwrap() == b"old bytes",
        "--out replaced"
    );
    assert_eq!(tree(&dir), ["body.pc2", "skirt.pc2"], "left behind");
}

/// `bake --out A --view B`: B's extension is checked before the bake, and a B that cannot be
/// put in place takes A with it.
#[test]
fn bake_with_a_page_writes_both_or_neither() {
    let model = pbns_model();
    let dir = out_dir("outputs_bake");
    let out = dir.join("skirt.glb");
    let bake = |page: &Path| {
        run(&[
            "bake",
            "--model",
            &model,
            "--motion",
            "samples/motions/131_01.bvh",
            "--fps",
            "1",
            "--max-targets",
            "4",
            "--out",
            out.to_str().unwrap(),
            "--view",
            page.to_str().unwrap(),
        ])
    };
    let err = one_error_line(&bake(&dir.join("skirt.png")), &out);
    assert!(err.contains("--view") && err.contains(".html"), "{err}");
    let (page, old) = occupied_target(&dir, "skirt.html");
    let err = one_error_line(&bake(&page), &out);
    assert!(err.contains(&*page.to_string_lossy()), "{err}");
    assert_left_untouched(&dir, &old);
    std::fs::remove_dir_all(&page).unwrap();
    let o = bake(&page);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(tree(&dir), ["skirt.glb", "skirt.html"]);
}

/// A 1 MB tmpfs mounted for one test, filled but for `free` bytes, unmounted when dropped (also
/// when the test fails). Mounting needs root, which CI has: a refusal fails the test.
struct FullDisk {
    dir: PathBuf,
}

/// What the filler leaves free: room for a small file (a batch plan, logs), not for an output.
const FREE: usize = 64 << 10;

impl FullDisk {
    fn mount(test: &str) -> FullDisk {
        let dir = out_dir(test).join("disk");
        std::fs::create_dir_all(&dir).unwrap();
        let o = Command::new("mount")
            .args(["-t", "tmpfs", "-o", "size=1m", "tmpfs"])
            .arg(&dir)
            .output()
            .expect("run mount");
        assert!(
            o.status.success(),
            "cannot mount a 1 MB tmpfs on {} (the tests run as root in CI): {}",
            dir.display(),
            String::from_utf8_lossy(&o.stderr)
        );
        let disk = FullDisk { dir };
        std::fs::write(disk.dir.join("filler"), vec![7u8; (1 << 20) - FREE]).unwrap();
        disk
    }

    /// Only the filler (and `also`) may be on the disk.
    fn assert_nothing_left(&self, also: &[&str]) {
        let left: Vec<String> = tree(&self.dir)
            .into_iter()
            .filter(|p| p != "filler" && !also.iter().any(|a| p.starts_with(a)))
            .collect();
        assert!(left.is_empty(), "left on the full disk: {left:?}");
    }
}

impl Drop for FullDisk {
    fn drop(&mut self) {
        let o = Command::new("umount").arg(&self.dir).output();
        if !o.is_ok_and(|o| o.status.success()) {
            let _ = Command::new("umount").arg("-l").arg(&self.dir).output();
        }
    }
}

/// `bake` and `eval` on a full disk: one line naming the file, nothing left. eval's --out goes
/// elsewhere (it fits), its --body-out to the full disk: the set fails as one.
#[test]
fn bake_and_eval_on_a_full_disk_leave_nothing() {
    let model = pbns_model();
    let disk = FullDisk::mount("outputs_full_bake_eval");
    let glb = disk.dir.join("skirt.glb");
    let o = run(&[
        "bake",
        "--model",
        &model,
        "--motion",
        "samples/motions/131_01.bvh",
        "--fps",
        "1",
        "--out",
        glb.to_str().unwrap(),
        "--view",
        disk.dir.join("skirt.html").to_str().unwrap(),
    ]);
    let err = one_error_line(&o, &glb);
    assert!(err.contains("No space left on device"), "{err}");
    assert!(err.contains(&*disk.dir.to_string_lossy()), "{err}");
    disk.assert_nothing_left(&[]);

    let elsewhere = disk.dir.parent().unwrap().join("skirt.pc2");
    let body = disk.dir.join("body.pc2");
    let o = run(&[
        "eval",
        "--model",
        &model,
        "--motion",
        "samples/motions/131_01.bvh",
        "--fps",
        "1",
        "--threads",
        "1",
        "--out",
        elsewhere.to_str().unwrap(),
        "--body-out",
        body.to_str().unwrap(),
    ]);
    let err = one_error_line(&o, &body);
    assert!(
        err.contains("No space left on device") && err.contains(&*body.to_string_lossy()),
        "{err}"
    );
    assert!(!elsewhere.exists(), "--out was left behind");
    disk.assert_nothing_left(&[]);
}

/// `rollout` of the dynamic test model: --lbs-out and --body-out checked before the roll-out,
/// and on a full disk (--out elsewhere, --lbs-out there) one line and no file.
#[test]
fn rollout_outputs_are_checked_first_and_fail_together_on_a_full_disk() {
    let (dir, sim, _space) = crate::dynamic::untrained_space("outputs_rollout");
    let (model, _) = crate::dynamic::motion_model(&dir, &sim, "motion.safetensors", &[]);
    let out = dir.join("roll.pc2");
    let rollout = |extra: &[&str]| {
        let mut args = vec![
            "rollout",
            "--model",
            model.to_str().unwrap(),
            "--motion",
            "samples/motions/131_01.bvh",
            "--frames",
            "6",
            "--threads",
            "1",
            "--no-collision-fix",
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        run(&args)
    };
    let bad = dir.join("lbs.obj");
    let err = one_error_line(&rollout(&["--lbs-out", bad.to_str().unwrap()]), &out);
    assert!(err.contains("--lbs-out") && err.contains(".pc2"), "{err}");
    let none = dir.join("none/body.pc2");
    let err = one_error_line(&rollout(&["--body-out", none.to_str().unwrap()]), &out);
    assert!(
        err.contains("--body-out") && err.contains("no folder"),
        "{err}"
    );

    let disk = FullDisk::mount("outputs_full_rollout");
    let lbs = disk.dir.join("lbs.pc2");
    let o = rollout(&["--lbs-out", lbs.to_str().unwrap()]);
    let err = one_error_line(&o, &lbs);
    assert!(
        err.contains("No space left on device") && err.contains(&*lbs.to_string_lossy()),
        "{err}"
    );
    assert!(!out.exists(), "--out was left behind");
    disk.assert_nothing_left(&[]);
}

/// `batch run` with its output folder on a full disk: its plan and logs fit, the training job's
/// files do not. The run stops with one error line naming the job and the file, exit code 2,
/// and takes back all it wrote: an output folder it created is gone, one that was there gets
/// its old plan back and keeps nothing else (no log, report, key or temporary file).
#[test]
fn batch_run_on_a_full_disk_is_one_error_and_leaves_nothing() {
    let dir = out_dir("outputs_full_batch");
    let manifest = dir.join("batch.toml");
    std::fs::write(
        &manifest,
        format!(
            r#"body = "{body}"
threads = 1

[[clips]]
path = "{clip}"
fps = 10

[[garments]]
name = "skirt"
mesh = "{skirt}"
seed = 3

[garments.static]
train = ["131_01"]
epochs = 1
args = ["--width", "16", "--coverage", "0"]
gltf = {{ max_targets = 4 }}
"#,
            body = sample("body.glb").display(),
            clip = sample("motions/131_01.bvh").display(),
            skirt = sample("garments/skirt.obj").display()
        ),
    )
    .unwrap();
    let disk = FullDisk::mount("outputs_full_batch_disk");
    let out = disk.dir.join("out");
    let batch = || {
        Command::new(env!("CARGO_BIN_EXE_garmentbake"))
            .args(["batch", "run"])
            .arg(&manifest)
            .arg("--out")
            .arg(&out)
            .arg("--json")
            .output()
            .unwrap()
    };
    let check = |o: &std::process::Output| {
        assert!(
            o.stdout.is_empty(),
            "{}",
            String::from_utf8_lossy(&o.stdout)
        );
        let err = one_error_line(o, &out.join("skirt"));
        assert!(
            err.contains("train:skirt")
                && err.contains("No space left on device")
                && err.contains(&*out.to_string_lossy()),
            "{err}"
        );
    };
    // A fresh output folder: the run created it, so it goes too.
    check(&batch());
    disk.assert_nothing_left(&[]);
    // A folder an earlier run left: its plan is put back, nothing of this run stays.
    std::fs::create_dir(&out).unwrap();
    std::fs::write(out.join("plan.json"), b"the earlier plan").unwrap();
    check(&batch());
    assert_eq!(tree(&disk.dir), ["filler", "out", "out/plan.json"]);
    assert_eq!(
        std::fs::read(out.join("plan.json")).unwrap(),
        b"the earlier plan"
    );
}

/// Every command that writes files, each output flag: a bad extension or a missing folder is one
/// `error:` line naming the flag, exit code 2, before any work (the inputs given do not exist,
/// so a command that read them first would name them instead), nothing written. The flags are
/// found through clap: an output flag added later without a row here fails the test.
#[test]
fn every_output_is_checked_before_any_work() {
    // (command words, output flag, an extension it writes ("" for any name), the other flags).
    let model = ["--model", "missing.safetensors"];
    let clip = ["--motion", "missing.bvh"];
    let body = ["--body", "missing.glb", "--garment", "missing.obj"];
    let cases: Vec<(&[&str], &str, &str, Vec<&str>)> = vec![
        (
            &["pose"],
            "out",
            "glb",
            [&clip[..], &["--body", "missing.glb"]].concat(),
        ),
        (&["bake"], "out", "usdc", [&model[..], &clip].concat()),
        (
            &["bake"],
            "view",
            "html",
            [&model[..], &clip, &["--out", "x.glb"]].concat(),
        ),
        (&["preview"], "out", "png", vec!["--body", "missing.glb"]),
        (
            &["interpolate"],
            "out",
            "pc2",
            [&model[..], &clip, &["--sim", "s.pc2", "--between", "0,1"]].concat(),
        ),
        (&["map", "suggest"], "out", "toml", vec!["missing.bvh"]),
        (
            &["upgrade"],
            "out",
            "safetensors",
            vec!["missing.safetensors"],
        ),
        (
            &["train"],
            "out",
            "safetensors",
            [&body[..], &clip].concat(),
        ),
        (
            &["train"],
            "log",
            "",
            [&body[..], &clip, &["--out", "m.safetensors"]].concat(),
        ),
        (
            &["train-swing"],
            "out",
            "safetensors",
            [&["--from", "missing.safetensors"][..], &clip].concat(),
        ),
        (
            &["train-swing"],
            "log",
            "",
            [
                &["--from", "missing.safetensors"][..],
                &clip,
                &["--out", "m.safetensors"],
            ]
            .concat(),
        ),
        (
            &["train-dynamic"],
            "out",
            "safetensors",
            [&body[..], &clip, &["--sim", "s.pc2", "--fps", "30"]].concat(),
        ),
        (
            &["train-dynamic"],
            "log",
            "",
            [
                &body[..],
                &clip,
                &["--sim", "s.pc2", "--fps", "30", "--out", "m.safetensors"],
            ]
            .concat(),
        ),
        (
            &["validate"],
            "png",
            "png",
            [&["missing.glb"][..], &model, &clip].concat(),
        ),
        (&["view"], "out", "html", vec!["missing.glb"]),
        (
            &["compare"],
            "plot-horizon",
            "png",
            [
                &body[..],
                &clip,
                &["--fps", "30", "--sim", "a.pc2", "--sim", "b.pc2"],
            ]
            .concat(),
        ),
        (
            &["compare"],
            "plot-hem",
            "png",
            [
                &body[..],
                &clip,
                &["--fps", "30", "--sim", "a.pc2", "--sim", "b.pc2"],
            ]
            .concat(),
        ),
        (
            &["simulate"],
            "out",
            "usdc",
            [&body[..], &clip, &["--fps", "30"]].concat(),
        ),
        (
            &["simulate"],
            "body-out",
            "pc2",
            [&body[..], &clip, &["--fps", "30", "--out", "s.pc2"]].concat(),
        ),
        (&["eval"], "out", "pc2", [&model[..], &clip].concat()),
        (
            &["eval"],
            "body-out",
            "pc2",
            [&model[..], &clip, &["--out", "e.pc2"]].concat(),
        ),
        (
            &["eval"],
            "view",
            "html",
            [&model[..], &clip, &["--out", "e.pc2"]].concat(),
        ),
        (&["rollout"], "out", "glb", [&model[..], &clip].concat()),
        (
            &["rollout"],
            "lbs-out",
            "pc2",
            [&model[..], &clip, &["--out", "r.pc2"]].concat(),
        ),
        (
            &["rollout"],
            "body-out",
            "pc2",
            [&model[..], &clip, &["--out", "r.pc2"]].concat(),
        ),
        (
            &["rollout"],
            "view",
            "html",
            [&model[..], &clip, &["--out", "r.pc2"]].concat(),
        ),
    ];
    // Every output flag clap knows, but for batch's --out (a folder, made if missing).
    const OUTPUT_FLAGS: [&str; 8] = [
        "out",
        "body-out",
        "lbs-out",
        "view",
        "png",
        "plot-horizon",
        "plot-hem",
        "log",
    ];
    fn walk(cmd: &clap::Command, words: &[String], out: &mut Vec<String>) {
        for arg in cmd.get_arguments() {
            if let Some(long) = arg.get_long().filter(|l| OUTPUT_FLAGS.contains(l)) {
                out.push(format!("{} --{long}", words.join(" ")));
            }
        }
        for sub in cmd.get_subcommands() {
            let mut w = words.to_vec();
            w.push(sub.get_name().to_string());
            walk(sub, &w, out);
        }
    }
    let mut flags = Vec::new();
    walk(&garmentbake::cli::command(), &[], &mut flags);
    let covered: Vec<String> = cases
        .iter()
        .map(|(words, flag, _, _)| format!("{} --{flag}", words.join(" ")))
        .collect();
    let missing: Vec<&String> = flags
        .iter()
        .filter(|f| !covered.contains(f) && !f.starts_with("batch "))
        .collect();
    assert!(missing.is_empty(), "output flags with no case: {missing:?}");

    let dir = out_dir("outputs_checked_first");
    let check = |(words, flag, ext, rest): &(&[&str], &str, &str, Vec<&str>)| {
        let bad_names = [
            (dir.join("out.bad"), "unknown extension"),
            (dir.join(format!("none/out.{ext}")), "no folder"),
        ];
        for (path, why) in &bad_names {
            if ext.is_empty() && *why == "unknown extension" {
                continue; // any name will do
            }
            let flag_arg = format!("--{flag}");
            let mut args: Vec<&str> = words.to_vec();
            args.extend(rest.iter().copied());
            args.extend([flag_arg.as_str(), path.to_str().unwrap()]);
            let err = one_error_line(&run(&args), path);
            assert!(
                err.starts_with(&format!("error: {flag_arg} {}", path.display()))
                    && err.contains(why),
                "{args:?}: {err}"
            );
        }
    };
    // Two at a time: each run is mostly the binary starting (libtorch loading).
    let (odd, even): (Vec<_>, Vec<_>) = cases.iter().enumerate().partition(|(i, _)| i % 2 == 1);
    std::thread::scope(|s| {
        let other = s.spawn(|| odd.iter().for_each(|(_, c)| check(c)));
        even.iter().for_each(|(_, c)| check(c));
        other.join().unwrap();
    });
    assert!(tree(&dir).is_empty(), "written: {:?}", tree(&dir));
}
