//! The job graph: a resolved manifest expanded into `garmentbake` command lines with their
//! inputs, outputs, dependencies, resources and a content-addressed key. The plan is plain data
//! (JSON, schema in docs/batch.md) so any engine can run it: the local runner, Ray, a farm.

use super::manifest::{BakeSpec, Clip, Garment, Resolved};
use crate::io::digest::{sha256_hex, to_hex};
use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

/// The plan's schema name; bumped when a field changes meaning.
pub const SCHEMA: &str = "garmentbake-batch-plan/1";

/// The package version, for people reading a plan; keys use the build id instead (it has been
/// 0.1.0 through every change of output).
pub const TOOL_VERSION: &str = env!("CARGO_PKG_VERSION");

/// The programs a job's output depends on besides its inputs and arguments: this build of
/// garmentbake (every job) and Blender (simulations).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Tools {
    /// [`crate::build_id::id`].
    pub build: String,
    /// `blender --version`'s first line, when the plan simulates (else none); "no Blender
    /// found" when there was none to ask, so installing one re-runs the simulations.
    pub blender: Option<String>,
}

impl Tools {
    /// This build, and the Blender `simulate` would run (`$GARMENTBAKE_BLENDER` or PATH) when
    /// `simulates`.
    pub fn here(simulates: bool) -> Tools {
        let blender = simulates.then(|| {
            crate::simulate::blender::find(None)
                .and_then(|b| crate::simulate::blender::version(&b))
                .unwrap_or_else(|_| "no Blender found".into())
        });
        Tools {
            build: crate::build_id::id().into(),
            blender,
        }
    }
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Plan {
    pub schema: String,
    pub tool_version: String,
    /// What the keys were made with (absent in plans written before it).
    #[serde(default)]
    pub tools: Option<Tools>,
    pub manifest: PathBuf,
    pub out: PathBuf,
    /// In dependency order: every job comes after the jobs it depends on.
    pub jobs: Vec<Job>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Job {
    /// Stable id: `kind:garment[:clip][:format]`.
    pub id: String,
    pub kind: String,
    pub garment: String,
    pub clip: Option<String>,
    /// Arguments of the `garmentbake` binary (absolute paths), ending with `--json`.
    pub args: Vec<String>,
    /// Files the job reads that no job of the plan writes.
    pub inputs: Vec<PathBuf>,
    /// Files the job writes (each gets `NAME.key` beside it).
    pub outputs: Vec<PathBuf>,
    /// The command's `--json` report, kept as an output too.
    pub report: PathBuf,
    /// The command's stderr.
    pub log: PathBuf,
    /// Ids of the jobs whose outputs this one reads.
    pub deps: Vec<String>,
    pub resources: Resources,
    /// Hex SHA-256 of the build id (and Blender's version for a simulation), the kind, the
    /// arguments with every input replaced by its bytes' hash (or by the key of the job writing
    /// it) and outputs relative to `out`.
    pub key: String,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Resources {
    pub cpus: usize,
    pub gpus: usize,
}

/// One argument while a command line is assembled.
enum Arg {
    Text(String),
    In(PathBuf),
    Out(PathBuf),
}

fn t(s: impl ToString) -> Arg {
    Arg::Text(s.to_string())
}

/// Expands a manifest into jobs keyed for this build (and the Blender on PATH when it simulates);
/// `out` is the output folder (absolute).
pub fn plan(resolved: &Resolved, out: &Path) -> Result<Plan> {
    let simulates = resolved
        .manifest
        .garments
        .iter()
        .any(|g| g.dynamic.is_some());
    plan_with(resolved, out, Tools::here(simulates))
}

/// [`plan`] with the keys made for `tools`.
pub fn plan_with(resolved: &Resolved, out: &Path, tools: Tools) -> Result<Plan> {
    let mut b = Builder {
        tools,
        out: out.to_path_buf(),
        cpus: resolved.manifest.threads,
        jobs: Vec::new(),
        hashes: HashMap::new(),
        producers: HashMap::new(),
        ids: HashSet::new(),
        manifest: resolved.file.clone(),
    };
    b.hash_all(&files(resolved));
    for g in &resolved.manifest.garments {
        if g.pbns.is_some() {
            static_jobs(&mut b, resolved, g)?;
        }
        if g.dynamic.is_some() {
            dynamic_jobs(&mut b, resolved, g)?;
        }
    }
    Ok(Plan {
        schema: SCHEMA.into(),
        tool_version: TOOL_VERSION.into(),
        tools: Some(b.tools),
        manifest: resolved.file.clone(),
        out: out.to_path_buf(),
        jobs: b.jobs,
    })
}

/// What a job is: its kind, garment, clip and format or stage (which make its id), and
/// whether it asks for a GPU.
struct Node<'a> {
    kind: &'static str,
    garment: &'a Garment,
    clip: Option<&'a Clip>,
    suffix: Option<&'a str>,
    gpus: usize,
}

/// A job of `kind` on `garment` (and `clip`) that needs no GPU.
fn node<'a>(kind: &'static str, garment: &'a Garment, clip: Option<&'a Clip>) -> Node<'a> {
    Node {
        kind,
        garment,
        clip,
        suffix: None,
        gpus: 0,
    }
}

impl Node<'_> {
    /// `kind:garment[:clip][:format or stage]`.
    fn id(&self) -> String {
        let parts = [
            Some(self.kind),
            Some(self.garment.name.as_str()),
            self.clip.map(|c| c.name.as_str()),
            self.suffix,
        ];
        parts
            .iter()
            .flatten()
            .copied()
            .collect::<Vec<_>>()
            .join(":")
    }
}

struct Builder {
    tools: Tools,
    out: PathBuf,
    /// CPU threads of every job (the manifest's `threads`).
    cpus: usize,
    jobs: Vec<Job>,
    /// Content hashes of input files, each file read once per plan.
    hashes: HashMap<PathBuf, String>,
    ids: HashSet<String>,
    /// Output path → index of the job writing it.
    producers: HashMap<PathBuf, usize>,
    manifest: PathBuf,
}

impl Builder {
    fn add(&mut self, node: Node, args: Vec<Arg>, hidden: &[PathBuf]) -> Result<PathBuf> {
        let id = node.id();
        if !self.ids.insert(id.clone()) {
            bail!("{}: two jobs would be '{id}'", self.manifest.display());
        }
        let kind = node.kind;
        let mut h = Sha256::new();
        let mut part = |s: &str| {
            h.update((s.len() as u64).to_le_bytes());
            h.update(s.as_bytes());
        };
        part(&self.tools.build);
        if kind == "simulate" {
            part(self.tools.blender.as_deref().unwrap_or("no Blender found"));
        }
        part(kind);
        let (mut inputs, mut outputs, mut deps, mut text) = (vec![], vec![], vec![], vec![]);
        let mut record_input = |b: &mut Self, p: &Path, part: &mut dyn FnMut(&str)| -> Result<()> {
            match b.producers.get(p) {
                Some(&i) => {
                    let dep = &b.jobs[i];
                    part(&format!("job {} {}", dep.key, rel(&b.out, p)));
                    if !deps.contains(&dep.id) {
                        deps.push(dep.id.clone());
                    }
                }
                None => {
                    part(&format!("file {}", b.hash(p, &id)?));
                    if !inputs.iter().any(|q: &PathBuf| q == p) {
                        inputs.push(p.to_path_buf());
                    }
                }
            }
            Ok(())
        };
        for a in args {
            match a {
                Arg::Text(s) => {
                    part(&s);
                    text.push(s);
                }
                Arg::In(p) => {
                    record_input(self, &p, &mut part)?;
                    text.push(p.to_string_lossy().into_owned());
                }
                Arg::Out(p) => {
                    part(&format!("out {}", rel(&self.out, &p)));
                    text.push(p.to_string_lossy().into_owned());
                    outputs.push(p);
                }
            }
        }
        for p in hidden {
            record_input(self, p, &mut part)?;
        }
        text.push("--json".into());
        let key = to_hex(&h.finalize());
        let file = id.replace(':', ".");
        for o in &outputs {
            self.producers.insert(o.clone(), self.jobs.len());
        }
        let first = outputs.first().cloned().unwrap_or_default();
        self.jobs.push(Job {
            kind: kind.into(),
            garment: node.garment.name.clone(),
            clip: node.clip.map(|c| c.name.clone()),
            args: text,
            inputs,
            outputs,
            report: self.out.join("reports").join(format!("{file}.json")),
            log: self.out.join("logs").join(format!("{file}.log")),
            deps,
            resources: Resources {
                cpus: self.cpus,
                gpus: node.gpus,
            },
            key,
            id,
        });
        Ok(first)
    }

    /// Hashes `paths` on every core up front (500 clips are hundreds of MB); a file that cannot
    /// be read is left for [`Builder::hash`] to report with the job that needs it.
    fn hash_all(&mut self, paths: &[PathBuf]) {
        use rayon::prelude::*;
        let hashed: Vec<(PathBuf, String)> = paths
            .par_iter()
            .filter_map(|p| Some((p.clone(), sha256_hex(&std::fs::read(p).ok()?))))
            .collect();
        self.hashes.extend(hashed);
    }

    /// Hex SHA-256 of a file's bytes (once per file).
    fn hash(&mut self, path: &Path, job: &str) -> Result<String> {
        if let Some(h) = self.hashes.get(path) {
            return Ok(h.clone());
        }
        let bytes = std::fs::read(path).with_context(|| {
            format!(
                "{}: job {job}: cannot read {}",
                self.manifest.display(),
                path.display()
            )
        })?;
        let h = sha256_hex(&bytes);
        self.hashes.insert(path.to_path_buf(), h.clone());
        Ok(h)
    }
}

/// Every file the manifest names (body, meshes and their sidecars, fabric files, clips, maps).
fn files(r: &Resolved) -> Vec<PathBuf> {
    let m = &r.manifest;
    let mut files = vec![m.body.clone()];
    for g in &m.garments {
        files.push(g.mesh.clone());
        files.extend(sidecar(g));
        files.push(PathBuf::from(&g.fabric));
    }
    for c in &r.clips {
        files.push(c.path.clone());
        files.extend(c.map.clone());
    }
    files.sort();
    files.dedup();
    files.retain(|f| f.is_file());
    files
}

fn rel(out: &Path, p: &Path) -> String {
    p.strip_prefix(out)
        .unwrap_or(p)
        .to_string_lossy()
        .into_owned()
}

/// `--motion` (and `--sim`) of each clip, their maps once each, and their common `--fps`.
fn clip_args(clips: &[&Clip], sims: Option<&[PathBuf]>, manifest: &Path) -> Result<Vec<Arg>> {
    let mut args = vec![];
    for (i, c) in clips.iter().enumerate() {
        args.extend([t("--motion"), Arg::In(c.path.clone())]);
        if let Some(sims) = sims {
            args.extend([t("--sim"), Arg::In(sims[i].clone())]);
        }
    }
    let mut maps: Vec<&PathBuf> = clips.iter().filter_map(|c| c.map.as_ref()).collect();
    maps.dedup();
    for m in maps {
        args.extend([t("--map"), Arg::In(m.clone())]);
    }
    let fps = clips.first().and_then(|c| c.fps);
    if clips.iter().any(|c| c.fps != fps) {
        bail!(
            "{}: clips {} read together need one fps",
            manifest.display(),
            clips
                .iter()
                .map(|c| c.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    if let Some(f) = fps {
        args.extend([t("--fps"), t(f)]);
    }
    Ok(args)
}

/// The fabric as an argument: a preset name is text, a file is an input.
fn fabric(g: &Garment) -> Arg {
    if Path::new(&g.fabric).is_file() {
        Arg::In(PathBuf::from(&g.fabric))
    } else {
        t(&g.fabric)
    }
}

/// The garment's pinning sidecar (read by every command that reads the mesh), when present.
fn sidecar(g: &Garment) -> Vec<PathBuf> {
    let s = g.mesh.with_extension("toml");
    if s.is_file() {
        vec![s]
    } else {
        vec![]
    }
}

fn static_jobs(b: &mut Builder, r: &Resolved, g: &Garment) -> Result<()> {
    let m = &r.manifest;
    let s = g.pbns.as_ref().expect("a static recipe");
    let dir = b.out.join(&g.name);
    let threads = m.threads.to_string();
    let gpus = usize::from(m.device.starts_with("cuda"));
    let train_clips = r.clips_named(s.train.as_deref())?;
    let mut args = vec![
        t("train"),
        t("--body"),
        Arg::In(m.body.clone()),
        t("--garment"),
        Arg::In(g.mesh.clone()),
    ];
    args.extend(clip_args(&train_clips, None, &r.file)?);
    args.extend([
        t("--config"),
        fabric(g),
        t("--seed"),
        t(g.seed),
        t("--epochs"),
        t(s.epochs),
    ]);
    args.extend([t("--threads"), t(&threads), t("--device"), t(&m.device)]);
    args.extend(s.args.iter().map(t));
    args.extend([
        t("--out"),
        Arg::Out(dir.join(format!("{}.safetensors", g.name))),
    ]);
    let model = b.add(
        Node {
            gpus,
            ..node("train", g, None)
        },
        args,
        &sidecar(g),
    )?;
    for c in r.clips_named(s.clips.as_deref())? {
        let common = |args: &mut Vec<Arg>| {
            args.extend([t("--threads"), t(&threads)]);
        };
        if let Some(ext) = &s.cache {
            let mut args = vec![t("eval"), t("--model"), Arg::In(model.clone())];
            args.extend(clip_args(&[c], None, &r.file)?);
            common(&mut args);
            args.extend([t("--out"), Arg::Out(dir.join(format!("{}.{ext}", c.name)))]);
            b.add(node("eval", g, Some(c)), args, &[])?;
        }
        for (spec, ext) in [(&s.gltf, "glb"), (&s.usd, "usdc")] {
            let Some(spec) = spec else { continue };
            let mut args = vec![t("bake"), t("--model"), Arg::In(model.clone())];
            args.extend(clip_args(&[c], None, &r.file)?);
            args.extend(bake_flags(spec));
            common(&mut args);
            args.extend([t("--out"), Arg::Out(dir.join(format!("{}.{ext}", c.name)))]);
            let baked = b.add(
                Node {
                    suffix: Some(ext),
                    ..node("bake", g, Some(c))
                },
                args,
                &[],
            )?;
            if s.validate {
                let mut args = vec![
                    t("validate"),
                    Arg::In(baked),
                    t("--model"),
                    Arg::In(model.clone()),
                ];
                args.extend(clip_args(&[c], None, &r.file)?);
                args.extend([t("--tolerance-mm"), t(spec.tolerance_mm.unwrap_or(1.0))]);
                common(&mut args);
                b.add(
                    Node {
                        suffix: Some(ext),
                        ..node("validate", g, Some(c))
                    },
                    args,
                    &[],
                )?;
            }
        }
    }
    Ok(())
}

fn bake_flags(spec: &BakeSpec) -> Vec<Arg> {
    let mut args = vec![];
    if let Some(k) = spec.max_targets {
        args.extend([t("--max-targets"), t(k)]);
    }
    if let Some(mm) = spec.tolerance_mm {
        args.extend([t("--tolerance-mm"), t(mm)]);
    }
    if let Some(n) = spec.influences {
        args.extend([t("--influences"), t(n)]);
    }
    args
}

fn dynamic_jobs(b: &mut Builder, r: &Resolved, g: &Garment) -> Result<()> {
    let m = &r.manifest;
    let d = g.dynamic.as_ref().expect("a dynamic recipe");
    let dir = b.out.join(&g.name).join("dynamic");
    let threads = m.threads.to_string();
    let gpus = usize::from(m.device.starts_with("cuda"));
    // The recipe's rate, when it has one, replaces the clips' own.
    let at_rate = |names: &[String]| -> Result<Vec<Clip>> {
        Ok(r.clips_named(Some(names))?
            .into_iter()
            .map(|c| Clip {
                fps: d.fps.or(c.fps),
                ..c.clone()
            })
            .collect())
    };
    let train = at_rate(&d.train)?;
    let rollout = at_rate(&d.rollout)?;
    let mut simulated: Vec<&Clip> = train.iter().collect();
    for c in &rollout {
        if !simulated.iter().any(|s| s.name == c.name) {
            simulated.push(c);
        }
    }
    let mut sims = HashMap::new();
    for c in &simulated {
        let mut args = vec![
            t("simulate"),
            t("--body"),
            Arg::In(m.body.clone()),
            t("--garment"),
            Arg::In(g.mesh.clone()),
        ];
        args.extend(clip_args(&[c], None, &r.file)?);
        args.extend([t("--config"), fabric(g)]);
        if let Some(n) = d.frames {
            args.extend([t("--frames"), t(n)]);
        }
        args.extend([t("--no-cache"), t("--threads"), t(&threads)]);
        args.extend([
            t("--out"),
            Arg::Out(dir.join(format!("sim_{}.pc2", c.name))),
        ]);
        let sim = b.add(node("simulate", g, Some(c)), args, &sidecar(g))?;
        sims.insert(c.name.clone(), sim);
    }
    let train: Vec<&Clip> = train.iter().collect();
    let train_sims: Vec<PathBuf> = train.iter().map(|c| sims[&c.name].clone()).collect();
    let train_args = |stage: &str, epochs: usize| -> Result<Vec<Arg>> {
        let mut args = vec![t("train-dynamic"), t("--stage"), t(stage)];
        args.extend(clip_args(&train, Some(&train_sims), &r.file)?);
        args.extend([t("--epochs"), t(epochs), t("--seed"), t(g.seed)]);
        args.extend([t("--threads"), t(&threads), t("--device"), t(&m.device)]);
        args.extend(d.args.iter().map(t));
        Ok(args)
    };
    let mut args = train_args("space", d.space_epochs)?;
    args.extend([
        t("--body"),
        Arg::In(m.body.clone()),
        t("--garment"),
        Arg::In(g.mesh.clone()),
    ]);
    args.extend([t("--preset"), t(&d.preset), t("--config"), fabric(g)]);
    args.extend([t("--out"), Arg::Out(dir.join("space.safetensors"))]);
    let space = b.add(
        Node {
            suffix: Some("space"),
            gpus,
            ..node("train-dynamic", g, None)
        },
        args,
        &sidecar(g),
    )?;
    let mut args = train_args("dynamic", d.motion_epochs)?;
    if let Some(n) = d.dynamics_epochs {
        args.extend([t("--dynamics-epochs"), t(n)]);
    }
    args.extend([
        t("--from"),
        Arg::In(space),
        t("--out"),
        Arg::Out(dir.join("dynamic.safetensors")),
    ]);
    let model = b.add(
        Node {
            suffix: Some("dynamic"),
            gpus,
            ..node("train-dynamic", g, None)
        },
        args,
        &[],
    )?;
    for c in &rollout {
        let mut args = vec![
            t("rollout"),
            t("--model"),
            Arg::In(model.clone()),
            t("--motion"),
            Arg::In(c.path.clone()),
        ];
        if let Some(map) = &c.map {
            args.extend([t("--map"), Arg::In(map.clone())]);
        }
        if let Some(n) = d.frames {
            args.extend([t("--frames"), t(n)]);
        }
        args.extend([
            t("--reference"),
            Arg::In(sims[&c.name].clone()),
            t("--threads"),
            t(&threads),
        ]);
        args.extend([
            t("--out"),
            Arg::Out(dir.join(format!("{}.{}", c.name, d.cache))),
        ]);
        b.add(node("rollout", g, Some(c)), args, &[])?;
    }
    Ok(())
}

impl Plan {
    /// How many jobs of each kind, kinds in the order they first come.
    pub fn kinds(&self) -> Vec<(&str, usize)> {
        let mut kinds: Vec<(&str, usize)> = vec![];
        for j in &self.jobs {
            match kinds.iter_mut().find(|(k, _)| *k == j.kind) {
                Some((_, n)) => *n += 1,
                None => kinds.push((&j.kind, 1)),
            }
        }
        kinds
    }
}

/// The plan of the manifest at `manifest`, its outputs in `out` (default: the manifest's
/// `out`), which is created if missing (noted in `ledger`).
pub fn from_manifest(
    manifest: &Path,
    out: Option<&Path>,
    ledger: &super::ledger::Ledger,
) -> Result<Plan> {
    let resolved = super::manifest::read(manifest)?;
    let out = match (out, &resolved.manifest.out) {
        (Some(o), _) => o.to_path_buf(),
        (None, Some(o)) => o.clone(),
        (None, None) => bail!("{}: no `out` folder; give --out", manifest.display()),
    };
    ledger
        .create_dir_all(&out)
        .with_context(|| format!("cannot create {}", out.display()))?;
    let out = out
        .canonicalize()
        .with_context(|| format!("cannot read {}", out.display()))?;
    plan(&resolved, &out)
}

/// Job `id` of the plan saved at `path` (by `batch plan --json` or `batch run`).
pub fn saved_job(path: &Path, id: &str) -> Result<Job> {
    let text = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let plan: Plan = serde_json::from_slice(&text)
        .with_context(|| format!("{} is not a batch plan", path.display()))?;
    plan.jobs
        .into_iter()
        .find(|x| x.id == id)
        .with_context(|| format!("{}: no job '{id}'", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn keys(tools: Tools) -> Vec<(String, String)> {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let resolved = super::super::manifest::read(&root.join("samples/batch.toml")).unwrap();
        let plan = plan_with(&resolved, &root.join("target/test-out/plan-keys"), tools).unwrap();
        plan.jobs.into_iter().map(|j| (j.id, j.key)).collect()
    }

    fn tools(build: &str, blender: &str) -> Tools {
        Tools {
            build: build.into(),
            blender: Some(blender.into()),
        }
    }

    /// Another build re-runs every job; another Blender exactly the simulations and what reads
    /// them (the sample manifest: 37 jobs, 2 simulations, 2 dynamic trainings, 1 roll-out).
    #[test]
    fn keys_change_with_the_build_and_simulations_with_blender() {
        let base = keys(tools("1935e54", "Blender 3.4.1"));
        assert_eq!(base, keys(tools("1935e54", "Blender 3.4.1")));
        let rebuilt = keys(tools("7f7d33d", "Blender 3.4.1"));
        assert!(base
            .iter()
            .zip(&rebuilt)
            .all(|(a, b)| a.0 == b.0 && a.1 != b.1));
        let upgraded = keys(tools("1935e54", "Blender 4.2.0"));
        let changed: Vec<&str> = base
            .iter()
            .zip(&upgraded)
            .filter(|(a, b)| a.1 != b.1)
            .map(|(a, _)| a.0.as_str())
            .collect();
        assert_eq!(
            changed,
            [
                "simulate:skirt:131_01",
                "simulate:skirt:131_02",
                "train-dynamic:skirt:space",
                "train-dynamic:skirt:dynamic",
                "rollout:skirt:131_02",
            ],
            "of {} jobs",
            base.len()
        );
    }
}
