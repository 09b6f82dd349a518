//! `batch.toml`: the body, the clips, the garments with their recipes and the outputs wanted per
//! garment. Read strictly (an unknown key is an error naming it) and resolved: paths relative
//! to the manifest's folder, globs expanded in sorted order, every clip named by its file stem.

use anyhow::{bail, Context, Result};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// The manifest as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// Skinned body (glTF/glb).
    pub body: PathBuf,
    /// Output folder (`batch run --out` overrides it).
    pub out: Option<PathBuf>,
    /// CPU threads per job (torch and the nearest-neighbour queries).
    #[serde(default = "one")]
    pub threads: usize,
    /// Where training runs: cpu, cuda or cuda:N (a cuda job asks its engine for a GPU).
    #[serde(default = "cpu")]
    pub device: String,
    #[serde(default)]
    pub clips: Vec<ClipSpec>,
    #[serde(default)]
    pub garments: Vec<Garment>,
}

/// One clip, or many through a glob in the file name (`motions/*.bvh`).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClipSpec {
    pub path: PathBuf,
    /// Joint-name map (TOML) for these clips.
    pub map: Option<PathBuf>,
    /// Keep every n-th frame so the clip plays at this rate.
    pub fps: Option<f32>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Garment {
    pub name: String,
    /// OBJ or USD mesh in the body's rest pose (its NAME.toml sidecar is read too).
    pub mesh: PathBuf,
    /// A fabric preset (cotton, silk, denim, jersey) or a FABRIC.toml.
    #[serde(default = "cotton")]
    pub fabric: String,
    #[serde(default)]
    pub seed: u64,
    /// PBNS: pose-driven model, baked to blend shapes.
    #[serde(rename = "static")]
    pub pbns: Option<StaticRecipe>,
    /// Motion-driven model trained on Blender simulations, rolled out to point caches.
    pub dynamic: Option<DynamicRecipe>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StaticRecipe {
    /// Clips (names) the model is trained on; default: every clip.
    pub train: Option<Vec<String>>,
    pub epochs: usize,
    /// Further `garmentbake train` flags, passed as they are (`["--width", "32"]`).
    #[serde(default)]
    pub args: Vec<String>,
    /// Clips the outputs are made for; default: every clip.
    pub clips: Option<Vec<String>>,
    /// Point cache of the network per clip (`garmentbake eval`): pc2, mdd or usdc.
    pub cache: Option<String>,
    /// One glTF bake (.glb) per clip.
    pub gltf: Option<BakeSpec>,
    /// One UsdSkel bake (.usdc) per clip.
    pub usd: Option<BakeSpec>,
    /// Replay every bake against the network (`garmentbake validate --model`); default on.
    #[serde(default = "yes")]
    pub validate: bool,
}

/// `garmentbake bake` options of one output format.
#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct BakeSpec {
    pub max_targets: Option<usize>,
    pub tolerance_mm: Option<f32>,
    pub influences: Option<usize>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DynamicRecipe {
    /// Clips simulated and trained on (names).
    pub train: Vec<String>,
    /// Clips rolled out (each is simulated too, as the roll-out's reference).
    pub rollout: Vec<String>,
    /// Simulate and roll out only the first N frames of each clip.
    pub frames: Option<usize>,
    /// Frame rate of the dynamic jobs (default: each clip's); cloth wants 30 or more.
    pub fps: Option<f32>,
    #[serde(default = "cpu")]
    pub preset: String,
    /// Epochs of the generative space (stage 1).
    pub space_epochs: usize,
    /// Epochs of the motion encoder's networks (stage 2, `train-dynamic --stage dynamic
    /// --epochs`; 0 keeps its ridge fit). `dynamic_epochs` is its old name.
    #[serde(default, alias = "dynamic_epochs")]
    pub motion_epochs: usize,
    /// Epochs of the learnt dynamics (`train-dynamic --dynamics-epochs`; default: the
    /// command's, the recipe's 40). 0 for clips shorter than its 32-frame windows.
    pub dynamics_epochs: Option<usize>,
    /// Further `train-dynamic` flags for both stages.
    #[serde(default)]
    pub args: Vec<String>,
    /// Roll-out point cache: pc2, mdd or usdc.
    #[serde(default = "pc2")]
    pub cache: String,
}

fn one() -> usize {
    1
}
fn yes() -> bool {
    true
}
fn cpu() -> String {
    "cpu".into()
}
fn cotton() -> String {
    "cotton".into()
}
fn pc2() -> String {
    "pc2".into()
}

/// A clip after globs are expanded: its name (file stem), file, map and rate.
#[derive(Clone, Debug)]
pub struct Clip {
    pub name: String,
    pub path: PathBuf,
    pub map: Option<PathBuf>,
    pub fps: Option<f32>,
}

/// A manifest read and resolved against its folder.
pub struct Resolved {
    pub file: PathBuf,
    pub manifest: Manifest,
    pub clips: Vec<Clip>,
}

impl Resolved {
    pub fn clip(&self, name: &str) -> Result<&Clip> {
        self.clips.iter().find(|c| c.name == name).with_context(|| {
            let names: Vec<&str> = self.clips.iter().map(|c| c.name.as_str()).collect();
            format!(
                "{}: no clip named '{name}' (clips: {})",
                self.file.display(),
                names.join(", ")
            )
        })
    }

    /// The named clips, or every clip when `names` is absent.
    pub fn clips_named(&self, names: Option<&[String]>) -> Result<Vec<&Clip>> {
        match names {
            None => Ok(self.clips.iter().collect()),
            Some(names) => names.iter().map(|n| self.clip(n)).collect(),
        }
    }
}

/// Reads `file` and resolves its paths; every error names the manifest.
pub fn read(file: &Path) -> Result<Resolved> {
    let text =
        std::fs::read_to_string(file).with_context(|| format!("cannot read {}", file.display()))?;
    let mut manifest: Manifest = toml::from_str(&text)
        .with_context(|| format!("{} is not a batch manifest", file.display()))?;
    let file = &file
        .canonicalize()
        .with_context(|| format!("cannot read {}", file.display()))?;
    let dir = file.parent().map(Path::to_path_buf).unwrap_or_default();
    let at = |p: &Path| normal(&dir.join(p));
    manifest.body = at(&manifest.body);
    manifest.out = manifest.out.as_deref().map(at);
    let mut clips = Vec::new();
    for spec in &manifest.clips {
        for path in expand(&at(&spec.path))
            .with_context(|| format!("{}: clip {}", file.display(), spec.path.display()))?
        {
            let name = stem(&path);
            if clips.iter().any(|c: &Clip| c.name == name) {
                bail!(
                    "{}: two clips are named '{name}' (names are file stems)",
                    file.display()
                );
            }
            clips.push(Clip {
                name,
                path,
                map: spec.map.as_deref().map(at),
                fps: spec.fps,
            });
        }
    }
    for g in &mut manifest.garments {
        g.mesh = at(&g.mesh);
        if Path::new(&g.fabric).extension().is_some() {
            g.fabric = at(Path::new(&g.fabric)).to_string_lossy().into_owned();
        }
    }
    check(file, &manifest)?;
    Ok(Resolved {
        file: file.to_path_buf(),
        manifest,
        clips,
    })
}

fn check(file: &Path, m: &Manifest) -> Result<()> {
    if m.garments.is_empty() {
        bail!("{}: no [[garments]]", file.display());
    }
    if m.threads == 0 {
        bail!("{}: threads must be at least 1", file.display());
    }
    for (i, g) in m.garments.iter().enumerate() {
        let ok = !g.name.is_empty()
            && g.name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
        if !ok {
            bail!(
                "{}: garment name '{}' must be letters, digits, _ or - (it names folders)",
                file.display(),
                g.name
            );
        }
        if m.garments[..i].iter().any(|o| o.name == g.name) {
            bail!("{}: two garments are named '{}'", file.display(), g.name);
        }
        if g.pbns.is_none() && g.dynamic.is_none() {
            bail!(
                "{}: garment '{}' has neither a [garments.static] nor a [garments.dynamic] recipe",
                file.display(),
                g.name
            );
        }
    }
    Ok(())
}

/// `a/b/../c` → `a/c` without touching the disk (a path in the plan reads plainly).
fn normal(path: &Path) -> PathBuf {
    use std::path::Component;
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::ParentDir if out.file_name().is_some() => {
                out.pop();
            }
            Component::CurDir => {}
            c => out.push(c),
        }
    }
    out
}

fn stem(path: &Path) -> String {
    path.file_stem()
        .map_or_else(String::new, |s| s.to_string_lossy().into_owned())
}

/// The files a path names: itself, or with `*` / `?` in its file name the matching files of
/// its folder in sorted order (folders in the path are taken literally).
fn expand(path: &Path) -> Result<Vec<PathBuf>> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    if !name.contains(['*', '?']) {
        if !path.is_file() {
            bail!("no such file {}", path.display());
        }
        return Ok(vec![path.to_path_buf()]);
    }
    let dir = path.parent().unwrap_or(Path::new("."));
    let mut found: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("cannot read folder {}", dir.display()))?
        .filter_map(|e| e.ok())
        .filter(|e| matches(&name, &e.file_name().to_string_lossy()) && e.path().is_file())
        .map(|e| e.path())
        .collect();
    found.sort();
    if found.is_empty() {
        bail!("no file matches {}", path.display());
    }
    Ok(found)
}

/// Shell-style match of `*` (any run) and `?` (one character).
fn matches(pattern: &str, name: &str) -> bool {
    let (p, n): (Vec<char>, Vec<char>) = (pattern.chars().collect(), name.chars().collect());
    let (mut i, mut j, mut star, mut mark) = (0, 0, None, 0);
    while j < n.len() {
        if i < p.len() && (p[i] == '?' || p[i] == n[j]) {
            i += 1;
            j += 1;
        } else if i < p.len() && p[i] == '*' {
            star = Some(i);
            mark = j;
            i += 1;
        } else if let Some(s) = star {
            i = s + 1;
            mark += 1;
            j = mark;
        } else {
            return false;
        }
    }
    p[i..].iter().all(|&c| c == '*')
}

#[cfg(test)]
mod tests {
    use super::{matches, DynamicRecipe};

    #[test]
    fn the_motion_stage_epochs_keep_their_old_name() {
        let recipe = |key: &str| -> DynamicRecipe {
            toml::from_str(&format!(
                "train = [\"a\"]\nrollout = [\"b\"]\nspace_epochs = 1\n{key} = 7\n"
            ))
            .unwrap()
        };
        assert_eq!(recipe("motion_epochs").motion_epochs, 7);
        assert_eq!(recipe("dynamic_epochs").motion_epochs, 7);
        assert_eq!(recipe("dynamics_epochs").motion_epochs, 0);
    }

    #[test]
    fn globs_match_like_a_shell() {
        assert!(matches("*.bvh", "131_01.bvh"));
        assert!(matches("131_0?.bvh", "131_02.bvh"));
        assert!(!matches("*.bvh", "map.toml"));
        assert!(!matches("13?_01.bvh", "01_01.bvh"));
        assert!(matches("*_*", "a_b"));
    }
}
