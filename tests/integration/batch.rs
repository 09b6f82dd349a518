//! `garmentbake batch`: a tiny manifest (the skirt, two clips at 10 fps, one epoch, 4-target glTF
//! bakes, each replayed by `validate`) run end to end, incrementally, killed and resumed, with a
//! corrupt clip, and on a local Ray cluster: the outputs are compared byte for byte.

use crate::common::*;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

/// The artifacts of the tiny manifest (what a run must reproduce byte for byte).
const ARTIFACTS: [&str; 3] = [
    "skirt/skirt.safetensors",
    "skirt/131_01.glb",
    "skirt/131_02.glb",
];

/// A folder with its own copies of the two clips (so a test can edit them) and the manifest:
/// train on 131_01, bake and validate both clips. Five jobs.
fn tiny(test: &str) -> PathBuf {
    let dir = out_dir(test);
    std::fs::create_dir_all(dir.join("clips")).unwrap();
    for clip in ["131_01", "131_02"] {
        std::fs::copy(
            sample(&format!("motions/{clip}.bvh")),
            dir.join(format!("clips/{clip}.bvh")),
        )
        .unwrap();
    }
    let manifest = format!(
        r#"# The test's demo recipe: one epoch of a narrow model, enough to exercise every job.
body = "{body}"
out = "out"
threads = 1

[[clips]]
path = "clips/*.bvh"
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
        skirt = sample("garments/skirt.obj").display()
    );
    std::fs::write(dir.join("batch.toml"), manifest).unwrap();
    dir
}

fn batch(args: &[&str], dir: &Path) -> (Output, Value) {
    let out = Command::new(env!("CARGO_BIN_EXE_garmentbake"))
        .arg("batch")
        .args(args)
        .arg(dir.join("batch.toml"))
        .arg("--json")
        .output()
        .expect("run garmentbake batch");
    let report = serde_json::from_slice(&out.stdout).unwrap_or(Value::Null);
    (out, report)
}

/// `batch run` that must succeed; its report.
fn run_ok(dir: &Path) -> Value {
    let (out, report) = batch(&["run"], dir);
    assert!(
        out.status.success(),
        "batch run failed: {}\n{report:#}",
        String::from_utf8_lossy(&out.stderr)
    );
    report
}

fn job<'a>(report: &'a Value, id: &str) -> &'a Value {
    report["jobs"]
        .as_array()
        .unwrap()
        .iter()
        .find(|j| j["id"] == id)
        .unwrap_or_else(|| panic!("no job {id} in {report:#}"))
}

fn count(report: &Value, what: &str) -> u64 {
    report[what]
        .as_u64()
        .unwrap_or_else(|| panic!("no {what} in {report:#}"))
}

fn artifacts(dir: &Path) -> Vec<Vec<u8>> {
    ARTIFACTS
        .iter()
        .map(|a| std::fs::read(dir.join("out").join(a)).unwrap_or_default())
        .collect()
}

/// One uninterrupted run of the tiny manifest, shared by the tests that compare bytes with it.
fn whole() -> &'static PathBuf {
    static WHOLE: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    WHOLE.get_or_init(|| {
        let dir = tiny("batch_whole");
        run_ok(&dir);
        dir
    })
}

#[test]
fn plan_names_every_job_with_its_dependencies() {
    let dir = tiny("batch_plan");
    let (out, plan) = batch(&["plan"], &dir);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let ids: Vec<&str> = plan["jobs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|j| j["id"].as_str().unwrap())
        .collect();
    assert_eq!(
        ids,
        [
            "train:skirt",
            "bake:skirt:131_01:glb",
            "validate:skirt:131_01:glb",
            "bake:skirt:131_02:glb",
            "validate:skirt:131_02:glb"
        ]
    );
    assert_eq!(
        job(&plan, "validate:skirt:131_02:glb")["deps"],
        serde_json::json!(["bake:skirt:131_02:glb", "train:skirt"])
    );
    // Keys are stable: the same inputs plan to the same keys.
    let (_, again) = batch(&["plan"], &dir);
    assert_eq!(plan["jobs"], again["jobs"]);
}

#[test]
fn a_changed_clip_reruns_only_the_jobs_that_read_it() {
    let dir = tiny("batch_incremental");
    let first = run_ok(&dir);
    assert_eq!(
        (count(&first, "ran"), count(&first, "up_to_date")),
        (5, 0),
        "{first:#}"
    );
    for clip in ["131_01", "131_02"] {
        let v = job(&first, &format!("validate:skirt:{clip}:glb"));
        assert!(v["metrics"]["replay_mm"].as_f64().unwrap() < 1.0, "{v:#}");
    }
    let report: Value = serde_json::from_slice(
        &std::fs::read(dir.join("out/reports/validate.skirt.131_02.glb.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(report["passed"], true, "{report:#}");
    let second = run_ok(&dir);
    assert_eq!(
        (count(&second, "ran"), count(&second, "up_to_date")),
        (0, 5),
        "{second:#}"
    );
    // Only the bytes count: a new modification time alone re-runs nothing, one more byte does.
    let clip = dir.join("clips/131_02.bvh");
    let mut bytes = std::fs::read(&clip).unwrap();
    std::fs::write(&clip, &bytes).unwrap();
    assert_eq!(count(&run_ok(&dir), "ran"), 0);
    bytes.push(b'\n');
    std::fs::write(&clip, &bytes).unwrap();
    let third = run_ok(&dir);
    let ran: Vec<&str> = third["jobs"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|j| j["status"] == "ran")
        .map(|j| j["id"].as_str().unwrap())
        .collect();
    assert_eq!(
        ran,
        ["bake:skirt:131_02:glb", "validate:skirt:131_02:glb"],
        "{third:#}"
    );
    assert_eq!(count(&third, "up_to_date"), 3);
}

#[test]
fn a_killed_run_resumes_to_the_same_bytes() {
    let whole = whole();
    let dir = tiny("batch_killed");
    // Its own process group, so the kill takes the runner and the job it is running.
    let mut child = std::os::unix::process::CommandExt::process_group(
        Command::new(env!("CARGO_BIN_EXE_garmentbake"))
            .args(["batch", "run", "--json"])
            .arg(dir.join("batch.toml")),
        0,
    )
    .stdout(std::process::Stdio::null())
    .spawn()
    .unwrap();
    let first_done = dir.join("out/reports/train.skirt.json.key");
    let start = Instant::now();
    while !first_done.exists() {
        assert!(
            start.elapsed() < Duration::from_secs(300),
            "the first job never finished"
        );
        assert!(
            child.try_wait().unwrap().is_none(),
            "the run ended before it could be killed"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let pid = child.id() as i32;
    assert_eq!(unsafe { libc::kill(-pid, libc::SIGKILL) }, 0);
    child.wait().unwrap();
    // Whatever is under a final name is whole: the same bytes as the uninterrupted run's.
    for (name, (got, want)) in ARTIFACTS
        .iter()
        .zip(artifacts(&dir).iter().zip(artifacts(whole)))
    {
        assert!(
            got.is_empty() || *got == want,
            "{name} was left partial by the kill"
        );
    }
    let resumed = run_ok(&dir);
    assert!(
        count(&resumed, "up_to_date") >= 1,
        "the finished training ran again: {resumed:#}"
    );
    assert_eq!(job(&resumed, "train:skirt")["status"], "up-to-date");
    assert_eq!(count(&resumed, "ran") + count(&resumed, "up_to_date"), 5);
    assert!(
        artifacts(&dir) == artifacts(whole),
        "a resumed run wrote other bytes than an uninterrupted one"
    );
}

#[test]
fn a_corrupt_clip_fails_its_jobs_and_the_rest_finish() {
    let dir = tiny("batch_corrupt");
    let clip = dir.join("clips/131_02.bvh");
    std::fs::write(&clip, b"HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0\n").unwrap();
    let (out, report) = batch(&["run"], &dir);
    assert_eq!(out.status.code(), Some(1), "{report:#}");
    let bake = job(&report, "bake:skirt:131_02:glb");
    assert_eq!(bake["status"], "failed");
    let error = bake["error"].as_str().unwrap();
    assert!(
        error.contains(&*clip.to_string_lossy()),
        "the error does not name the clip: {error}"
    );
    assert_eq!(
        job(&report, "validate:skirt:131_02:glb")["status"],
        "skipped"
    );
    for done in [
        "train:skirt",
        "bake:skirt:131_01:glb",
        "validate:skirt:131_01:glb",
    ] {
        assert_eq!(job(&report, done)["status"], "ran", "{report:#}");
    }
    assert_eq!(
        (count(&report, "failed"), count(&report, "skipped")),
        (1, 1)
    );
    // The person reading the summary sees the file and the error too.
    let text = Command::new(env!("CARGO_BIN_EXE_garmentbake"))
        .args(["batch", "run"])
        .arg(dir.join("batch.toml"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&text.stdout);
    assert!(
        stdout.contains("FAILED") && stdout.contains("131_02.bvh"),
        "{stdout}"
    );
}

#[test]
fn a_bad_manifest_is_one_error_line_naming_it() {
    let dir = tiny("batch_bad_manifest");
    let manifest = dir.join("batch.toml");
    let text = std::fs::read_to_string(&manifest)
        .unwrap()
        .replace("epochs = 1", "epochs = 1\nepoch = 2");
    std::fs::write(&manifest, text).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_garmentbake"))
        .args(["batch", "plan"])
        .arg(&manifest)
        .output()
        .unwrap();
    let err = one_error_line(&out, &dir.join("out/plan.json"));
    assert!(err.contains("batch.toml") && err.contains("epoch"), "{err}");
}

/// Stops the Ray cluster the test started and removes its temp folder, also when the test fails.
struct RayCluster {
    ray: PathBuf,
    temp: PathBuf,
}

impl Drop for RayCluster {
    fn drop(&mut self) {
        let _ = Command::new(&self.ray).args(["stop", "--force"]).output();
        let _ = std::fs::remove_dir_all(&self.temp);
    }
}

#[test]
fn ray_runs_the_same_bytes_as_the_local_runner() {
    let local = whole();
    let dir = tiny("batch_ray");
    let ray = root().join(".venv/bin/ray");
    let temp = std::env::temp_dir().join(format!("gb-ray-{}", std::process::id()));
    let port = "6391";
    let started = Command::new(&ray)
        .args([
            "start",
            "--head",
            "--num-cpus",
            "2",
            "--node-ip-address",
            "127.0.0.1",
            "--port",
            port,
        ])
        .args([
            "--include-dashboard",
            "false",
            "--disable-usage-stats",
            "--temp-dir",
        ])
        .arg(&temp)
        .output()
        .expect("ray is installed in .venv by scripts/setup.sh");
    let _cluster = RayCluster {
        ray: ray.clone(),
        temp: temp.clone(),
    };
    assert!(
        started.status.success(),
        "ray start failed: {}",
        String::from_utf8_lossy(&started.stderr)
    );
    let (out, report) = batch(&["run", "--ray", &format!("127.0.0.1:{port}")], &dir);
    assert!(
        out.status.success(),
        "{}\n{report:#}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        (report["engine"].as_str(), count(&report, "ran")),
        (Some("ray"), 5),
        "{report:#}"
    );
    assert!(
        artifacts(&dir) == artifacts(local),
        "Ray wrote other bytes than the local runner"
    );
    assert!(artifacts(&dir).iter().all(|a| !a.is_empty()));
}

/// The figure names of `job`'s metrics.
fn figures(job: &Value) -> Vec<String> {
    assert_eq!(job["error"], Value::Null, "{job:#}");
    let mut names: Vec<String> = job["metrics"]
        .as_object()
        .unwrap_or_else(|| panic!("{job:#}"))
        .keys()
        .cloned()
        .collect();
    names.sort();
    names
}

/// Every figure docs/batch.md lists for the static jobs comes out of the tiny manifest's run.
#[test]
fn static_jobs_report_their_figures() {
    let dir = whole();
    let (_, report) = batch(&["run"], dir);
    for (id, want) in [
        ("train:skirt", &["collided_pct", "edge_mm"][..]),
        ("bake:skirt:131_02:glb", &["replay_mm", "targets"]),
        ("validate:skirt:131_02:glb", &["replay_mm"]),
    ] {
        assert_eq!(figures(job(&report, id)), want, "{id}");
    }
}

/// The dynamic jobs (simulate → train-dynamic space → dynamic → rollout) run one by one by
/// `batch job` from a plan written here (six simulated frames, no epochs): each outcome carries
/// the figures docs/batch.md lists, read through the commands' own report types. Before, the
/// roll-out's `inside_pct` was looked up at `/summary/inside_pct`, a path its report never had
/// (it is `summary.inside.inside_pct`), and was silently missing from every summary.
#[test]
fn dynamic_jobs_report_their_figures() {
    use garmentbake::batch::plan::{Job, Plan, Resources};
    let dir = out_dir("batch_dynamic_figures");
    let s = |p: PathBuf| p.to_string_lossy().into_owned();
    let (body, skirt) = (s(sample("body.glb")), s(sample("garments/skirt.obj")));
    let clip = s(sample("motions/131_01.bvh"));
    let (sim, space, model, roll) = (
        s(dir.join("sim.pc2")),
        s(dir.join("space.safetensors")),
        s(dir.join("dynamic.safetensors")),
        s(dir.join("roll.pc2")),
    );
    // The dynamic tests' six frames and cache (simulated once per build).
    let cache = s(root().join("target/test-out/sim-cache"));
    let steps: [(&str, &str, Vec<&str>); 4] = [
        (
            "simulate",
            "simulate:skirt:131_01",
            vec![
                "simulate",
                "--body",
                &body,
                "--garment",
                &skirt,
                "--motion",
                &clip,
                "--fps",
                "30",
                "--frames",
                "6",
                "--settle",
                "0.1",
                "--blend",
                "0.2",
                "--cache",
                &cache,
                "--out",
                &sim,
            ],
        ),
        (
            "train-dynamic",
            "train-dynamic:skirt:space",
            vec![
                "train-dynamic",
                "--body",
                &body,
                "--garment",
                &skirt,
                "--motion",
                &clip,
                "--sim",
                &sim,
                "--fps",
                "30",
                "--epochs",
                "0",
                "--batch",
                "2",
                "--threads",
                "1",
                "--out",
                &space,
            ],
        ),
        (
            "train-dynamic",
            "train-dynamic:skirt:dynamic",
            vec![
                "train-dynamic",
                "--stage",
                "dynamic",
                "--from",
                &space,
                "--motion",
                &clip,
                "--sim",
                &sim,
                "--fps",
                "30",
                "--epochs",
                "0",
                "--dynamics-epochs",
                "0",
                "--threads",
                "1",
                "--out",
                &model,
            ],
        ),
        (
            "rollout",
            "rollout:skirt:131_01",
            vec![
                "rollout",
                "--model",
                &model,
                "--motion",
                &clip,
                "--init",
                &sim,
                "--reference",
                &sim,
                "--frames",
                "6",
                "--threads",
                "1",
                "--out",
                &roll,
            ],
        ),
    ];
    let jobs: Vec<Job> = steps
        .iter()
        .map(|(kind, id, args)| {
            let file = id.replace(':', ".");
            Job {
                id: id.to_string(),
                kind: kind.to_string(),
                garment: "skirt".into(),
                clip: None,
                args: args
                    .iter()
                    .map(|a| a.to_string())
                    .chain(["--json".into()])
                    .collect(),
                inputs: vec![],
                outputs: vec![],
                report: dir.join(format!("reports/{file}.json")),
                log: dir.join(format!("logs/{file}.log")),
                deps: vec![],
                resources: Resources { cpus: 1, gpus: 0 },
                key: format!("test {id}"),
            }
        })
        .collect();
    let plan = Plan {
        schema: garmentbake::batch::plan::SCHEMA.into(),
        tool_version: garmentbake::batch::plan::TOOL_VERSION.into(),
        tools: None,
        manifest: dir.join("none.toml"),
        out: dir.clone(),
        jobs,
    };
    let saved = dir.join("plan.json");
    std::fs::write(&saved, serde_json::to_vec_pretty(&plan).unwrap()).unwrap();
    let mut seen = Vec::new();
    for (_, id, _) in &steps {
        let out = garmentbake(&["batch", "job", "--plan", &s(saved.clone()), "--id", id]);
        let outcome: Value = serde_json::from_slice(&out.stdout).unwrap_or(Value::Null);
        assert_eq!(outcome["status"], "ran", "{id}: {outcome:#}");
        seen.push(figures(&outcome));
    }
    assert_eq!(
        seen,
        [
            vec!["s_per_frame"],
            vec!["train_mm"],
            vec!["train_mm"],
            vec!["inside_pct", "vs_sim_mm"],
        ]
    );
}

/// A plan asks the Blender its simulations will run (`$GARMENTBAKE_BLENDER`, else PATH) for its
/// version and keys them on it: another Blender (a wrapper reporting another version) changes
/// the keys of the simulation and of the jobs that read it, no other; the plan records both
/// tools. (Before, no key held Blender's version: an upgraded Blender's run found every
/// simulation up to date.)
#[test]
fn simulation_keys_follow_the_blender_that_will_run_them() {
    let dir = tiny("batch_blender");
    let manifest = std::fs::read_to_string(dir.join("batch.toml")).unwrap();
    let dynamic = "\n[garments.dynamic]\ntrain = [\"131_01\"]\nrollout = [\"131_01\"]\nfps = 30\nframes = 6\nspace_epochs = 0\ndynamic_epochs = 0\n";
    std::fs::write(dir.join("batch.toml"), manifest + dynamic).unwrap();
    let next = dir.join("blender-next");
    std::fs::write(
        &next,
        "#!/bin/sh\nif [ \"$1\" = --version ]; then echo 'Blender 99.0.0 (test wrapper)'; exit 0; fi\nexec blender \"$@\"\n",
    )
    .unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&next, std::fs::Permissions::from_mode(0o755)).unwrap();
    let plan = |blender: Option<&Path>| -> Value {
        let mut c = Command::new(env!("CARGO_BIN_EXE_garmentbake"));
        c.args(["batch", "plan"])
            .arg(dir.join("batch.toml"))
            .arg("--json");
        if let Some(b) = blender {
            c.env("GARMENTBAKE_BLENDER", b);
        }
        serde_json::from_slice(&crate::common::run_ok(&mut c).stdout).unwrap()
    };
    let (installed, wrapped) = (plan(None), plan(Some(&next)));
    assert!(
        installed["tools"]["blender"]
            .as_str()
            .unwrap()
            .starts_with("Blender "),
        "{}",
        installed["tools"]
    );
    assert_eq!(wrapped["tools"]["blender"], "Blender 99.0.0 (test wrapper)");
    assert_eq!(installed["tools"]["build"], wrapped["tools"]["build"]);
    let changed: Vec<&str> = installed["jobs"]
        .as_array()
        .unwrap()
        .iter()
        .zip(wrapped["jobs"].as_array().unwrap())
        .filter(|(a, b)| a["key"] != b["key"])
        .map(|(a, _)| a["id"].as_str().unwrap())
        .collect();
    assert_eq!(
        changed,
        [
            "simulate:skirt:131_01",
            "train-dynamic:skirt:space",
            "train-dynamic:skirt:dynamic",
            "rollout:skirt:131_01"
        ]
    );
}
