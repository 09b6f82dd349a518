//! Joint-name maps: which rig joint each motion-capture joint drives, and what becomes of the rest.
//!
//! A map file is TOML:
//! ```toml
//! name = "cc_base"
//! fold = ["CC_Base_Pelvis"]          # optional: joints composed into their chain
//! skip = ["CC_Base_FacialBone", "CC_Base_*Twist01"]   # optional: joints dropped with their subtree
//! [map]
//! CC_Base_Hip = "Hips"               # ClipJoint = "RigJoint"
//! ```
//! A map names only the joints that matter. Every other clip joint is *folded* when a mapped joint
//! lies below it (its local rotation is composed into the chain: world rotations of the mapped
//! joints below it include it, so a twist bone or a helper between thigh and calf loses nothing) and
//! *dropped* otherwise (face, fingers, toes, twist leaves). `fold` and `skip` say so explicitly
//! (`*` and `?` globs allowed); skipping a joint that has a mapped joint below it is an error, as is
//! a literal `fold` entry with none. Each rig joint is the target of at most one clip joint; rig
//! joints no clip joint reaches keep their rest pose relative to their parent.
//!
//! [`resolve`] picks the map for a clip: the first user map (`--map`) that covers the clip's joints
//! or whose `[map]` joints all are clip joints; else a built-in map that *recognises* the clip (all
//! its `[map]` joints present and every clip joint named by its `[map]`, `fold` or `skip`: the CMU
//! maps list every joint, so they match their exact joint set, because those namings reuse each
//! other's names for different joints, see `cmu_3dsmax.map.toml`); else identity when every clip
//! joint already has a rig joint's name; else an error telling the user to pass `--map`. A user map
//! meant for the clip (half its joints or more are clip joints) that names joints the clip lacks is
//! an error naming them, not a silent fall back to a built-in.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::path::Path;

use serde::Deserialize;
use thiserror::Error;

pub use crate::rig::retarget::{JointFate, JointMapping};

/// A named clip-joint → rig-joint renaming, with what to do with the joints it leaves out.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct JointMap {
    pub name: String,
    /// (clip joint, rig joint), sorted by clip joint.
    pub pairs: Vec<(String, String)>,
    /// Clip joints (globs) composed into the chain of the mapped joints below them.
    pub fold: Vec<String>,
    /// Clip joints (globs) dropped with everything below them.
    pub skip: Vec<String>,
    /// Where the map came from, for error messages (a path, or the sample path for built-ins).
    pub source: String,
}

/// A clip's joint tree as resolving a map needs it: names and parents, parents first.
#[derive(Debug, Clone, Copy)]
pub struct ClipJoints<'a> {
    pub names: &'a [&'a str],
    pub parents: &'a [Option<usize>],
}

/// Why a joint map could not be read or applied. Every message is one line naming the file or clip.
#[derive(Debug, Error)]
pub enum JointMapError {
    #[error("{file}: cannot read: {err}")]
    Io { file: String, err: std::io::Error },
    #[error("{file}:{line}: bad joint map TOML: {detail}")]
    Toml {
        file: String,
        line: usize,
        detail: String,
    },
    #[error("{file}: the [map] table is empty; list each clip joint that matters as ClipJoint = \"RigJoint\"")]
    Empty { file: String },
    #[error("{file}: empty joint name in the entry for '{clip}'; every [map] entry must name a rig joint")]
    EmptyName { file: String, clip: String },
    #[error("{file}: rig joint '{rig}' is the target of both '{first}' and '{second}'; each rig joint may be mapped at most once")]
    DuplicateTarget {
        file: String,
        rig: String,
        first: String,
        second: String,
    },
    #[error("{file}: maps clip joint '{clip}' to '{rig}', which is not a joint of the rig{hint}")]
    UnknownRigJoint {
        file: String,
        clip: String,
        rig: String,
        hint: String,
    },
    #[error("{clip}: has two joints named '{joint}'; joint names must be unique to be mapped")]
    DuplicateClipJoint { clip: String, joint: String },
    #[error("{file}: names {joints}, which {clip} lacks; fix the names or leave them out (joints left out are folded or dropped)")]
    MissingClipJoints {
        file: String,
        clip: String,
        joints: String,
    },
    #[error("{file}: skips '{skipped}' of {clip}, but mapped joint '{mapped}' lies below it; fold it instead (leave it out of skip)")]
    SkipsMapped {
        file: String,
        clip: String,
        skipped: String,
        mapped: String,
    },
    #[error(
        "{file}: folds '{joint}' of {clip}, but no mapped joint lies below it; list it under skip"
    )]
    FoldsLeaf {
        file: String,
        clip: String,
        joint: String,
    },
    #[error("{clip}: cannot match its joints to the rig: {detail}; pass --map FILE.toml with a [map] table naming a rig joint for each clip joint that matters (`garmentbake map suggest` drafts one)")]
    NoMap { clip: String, detail: String },
}

/// The file layout; unknown keys are rejected so typos do not silently drop a table.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MapFile {
    name: Option<String>,
    #[serde(default)]
    fold: Vec<String>,
    #[serde(default)]
    skip: Vec<String>,
    map: BTreeMap<String, String>,
}

const BUILTIN: [(&str, &str); 4] = [
    (
        "samples/motions/cmu_mb.map.toml (built in)",
        include_str!("../../samples/motions/cmu_mb.map.toml"),
    ),
    (
        "samples/motions/cmu_3dsmax.map.toml (built in)",
        include_str!("../../samples/motions/cmu_3dsmax.map.toml"),
    ),
    (
        "samples/motions/cc_base.map.toml (built in)",
        include_str!("../../samples/motions/cc_base.map.toml"),
    ),
    (
        "samples/motions/mixamo.map.toml (built in)",
        include_str!("../../samples/motions/mixamo.map.toml"),
    ),
];

/// The maps shipped with the tool: CMU MotionBuilder naming (`cmu_mb`), CMU 3dsMax naming
/// (`cmu_3dsmax`), Character Creator (`cc_base`) and Mixamo (`mixamo`).
pub fn builtin() -> Vec<JointMap> {
    // The embedded files are checked by tests; a broken one is skipped rather than panicking.
    BUILTIN
        .iter()
        .filter_map(|(source, text)| JointMap::parse(text, source).ok())
        .collect()
}

impl JointMap {
    /// Reads a map file; errors name the path as given.
    pub fn read(path: &Path) -> Result<JointMap, JointMapError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|err| JointMapError::Io {
            file: file.clone(),
            err,
        })?;
        JointMap::parse(&text, &file)
    }

    /// Parses map TOML. `name` defaults to the file stem of `source_name`.
    pub fn parse(text: &str, source_name: &str) -> Result<JointMap, JointMapError> {
        let raw: MapFile = toml::from_str(text).map_err(|e| toml_error(text, source_name, &e))?;
        let file = || source_name.to_string();
        if raw.map.is_empty() {
            return Err(JointMapError::Empty { file: file() });
        }
        let mut first_source_of: HashMap<&str, &str> = HashMap::new();
        for (clip, rig) in &raw.map {
            if clip.trim().is_empty() || rig.trim().is_empty() {
                return Err(JointMapError::EmptyName {
                    file: file(),
                    clip: clip.clone(),
                });
            }
            if let Some(first) = first_source_of.insert(rig, clip) {
                return Err(JointMapError::DuplicateTarget {
                    file: file(),
                    rig: rig.clone(),
                    first: first.to_string(),
                    second: clip.clone(),
                });
            }
        }
        let name = raw
            .name
            .filter(|n| !n.trim().is_empty())
            .unwrap_or_else(|| default_name(source_name));
        Ok(JointMap {
            name,
            pairs: raw.map.into_iter().collect(),
            fold: raw.fold,
            skip: raw.skip,
            source: file(),
        })
    }

    /// True when the map names every clip joint: as a `[map]` key, by `fold` / `skip`, or below a
    /// skipped joint (extra keys are allowed).
    pub fn covers(&self, joints: ClipJoints) -> bool {
        self.unnamed(joints).is_empty()
    }

    /// The rig joint a clip joint maps to.
    pub fn target(&self, clip_joint: &str) -> Option<&str> {
        self.pairs
            .iter()
            .find(|(c, _)| c == clip_joint)
            .map(|(_, r)| r.as_str())
    }

    fn keys(&self) -> HashSet<&str> {
        self.pairs.iter().map(|(c, _)| c.as_str()).collect()
    }

    /// Named by a `fold` or `skip` pattern.
    fn listed(&self, joint: &str) -> bool {
        self.fold.iter().chain(&self.skip).any(|p| glob(p, joint))
    }

    /// How a built-in map is chosen: all its `[map]` joints are clip joints and it names every clip
    /// joint (for maps without fold / skip: the exact joint set).
    fn recognises(&self, joints: ClipJoints) -> bool {
        self.missing(joints.names).is_empty() && self.covers(joints)
    }

    /// `[map]` joints the clip lacks, sorted.
    fn missing(&self, clip_joint_names: &[&str]) -> Vec<&str> {
        let clip: HashSet<&str> = clip_joint_names.iter().copied().collect();
        self.pairs
            .iter()
            .map(|(c, _)| c.as_str())
            .filter(|c| !clip.contains(c))
            .collect()
    }

    /// Clip joints this map does not name at all (nor skips an ancestor of), in clip order.
    fn unnamed<'c>(&self, joints: ClipJoints<'c>) -> Vec<&'c str> {
        let keys = self.keys();
        let mut skipped = vec![false; joints.names.len()];
        let mut out = Vec::new();
        for (k, &name) in joints.names.iter().enumerate() {
            let under_skip = joints.parents[k].is_some_and(|p| skipped[p]);
            let skip = self.skip.iter().any(|p| glob(p, name)) && !keys.contains(name);
            skipped[k] = under_skip || skip;
            if !keys.contains(name) && !self.listed(name) && !under_skip {
                out.push(name);
            }
        }
        out
    }

    /// A user map meant for this clip: half its `[map]` joints or more are clip joints.
    fn meant_for(&self, clip_joint_names: &[&str]) -> bool {
        2 * self.missing(clip_joint_names).len() <= self.pairs.len()
    }

    fn apply(
        &self,
        clip: &str,
        joints: ClipJoints,
        rig_joint_names: &[&str],
    ) -> Result<JointMapping, JointMapError> {
        let lookup: HashMap<&str, &str> = self
            .pairs
            .iter()
            .map(|(c, r)| (c.as_str(), r.as_str()))
            .collect();
        let rig = rig_index(rig_joint_names);
        let mut targets = Vec::with_capacity(joints.names.len());
        for &name in joints.names {
            // Joints the map leaves out are folded or dropped (see `fates`).
            let Some(&target) = lookup.get(name) else {
                targets.push(None);
                continue;
            };
            let Some(&i) = rig.get(target) else {
                return Err(JointMapError::UnknownRigJoint {
                    file: self.source.clone(),
                    clip: name.to_string(),
                    rig: target.to_string(),
                    hint: did_you_mean(target, rig_joint_names),
                });
            };
            targets.push(Some(i));
        }
        check_unique(clip, joints.names, &targets)?;
        let fates = self.fates(clip, joints, &targets)?;
        Ok(JointMapping {
            map_name: self.name.clone(),
            fates,
        })
    }

    /// The fate of every clip joint given the mapped ones.
    fn fates(
        &self,
        clip: &str,
        joints: ClipJoints,
        targets: &[Option<usize>],
    ) -> Result<Vec<JointFate>, JointMapError> {
        let n = joints.names.len();
        // The first mapped joint below each joint (clip order puts parents first).
        let mut mapped_below: Vec<Option<usize>> = vec![None; n];
        for k in (0..n).rev() {
            if let Some(p) = joints.parents[k] {
                let below = if targets[k].is_some() {
                    Some(k)
                } else {
                    mapped_below[k]
                };
                if mapped_below[p].is_none() {
                    mapped_below[p] = below;
                }
            }
        }
        let mut fates: Vec<JointFate> = Vec::with_capacity(n);
        for k in 0..n {
            let name = joints.names[k];
            let parent_fate = joints.parents[k].map(|p| &fates[p]);
            if targets[k].is_none()
                && mapped_below[k].is_none()
                && self.fold.iter().any(|p| p == name)
            {
                return Err(JointMapError::FoldsLeaf {
                    file: self.source.clone(),
                    clip: clip.to_string(),
                    joint: name.to_string(),
                });
            }
            let fate = if let Some(rig) = targets[k] {
                JointFate::Mapped { rig }
            } else if let Some(JointFate::Dropped { .. }) = parent_fate {
                JointFate::Dropped { explicit: false }
            } else if self.skip.iter().any(|p| glob(p, name)) {
                if let Some(m) = mapped_below[k] {
                    return Err(JointMapError::SkipsMapped {
                        file: self.source.clone(),
                        clip: clip.to_string(),
                        skipped: name.to_string(),
                        mapped: joints.names[m].to_string(),
                    });
                }
                JointFate::Dropped { explicit: true }
            } else {
                let explicit = self.fold.iter().any(|p| glob(p, name));
                match mapped_below[k] {
                    Some(_) => JointFate::Folded {
                        into: nearest_mapped_ancestor(k, joints.parents, &fates),
                        explicit,
                    },
                    None => JointFate::Dropped { explicit: false },
                }
            };
            fates.push(fate);
        }
        Ok(fates)
    }
}

fn nearest_mapped_ancestor(
    k: usize,
    parents: &[Option<usize>],
    fates: &[JointFate],
) -> Option<usize> {
    let mut at = parents[k];
    while let Some(p) = at {
        if matches!(fates[p], JointFate::Mapped { .. }) {
            return Some(p);
        }
        at = parents[p];
    }
    None
}

/// `*` any run of characters, `?` one character; everything else literal.
fn glob(pattern: &str, name: &str) -> bool {
    let p: Vec<char> = pattern.chars().collect();
    let s: Vec<char> = name.chars().collect();
    // Classic two-pointer match with backtracking to the last `*`.
    let (mut i, mut j) = (0, 0);
    let mut star: Option<(usize, usize)> = None;
    while j < s.len() {
        if i < p.len() && (p[i] == '?' || p[i] == s[j]) {
            i += 1;
            j += 1;
        } else if i < p.len() && p[i] == '*' {
            star = Some((i, j));
            i += 1;
        } else if let Some((si, sj)) = star {
            i = si + 1;
            j = sj + 1;
            star = Some((si, sj + 1));
        } else {
            return false;
        }
    }
    p[i..].iter().all(|&c| c == '*')
}

/// Chooses and applies the joint map for one clip (`clip` names it in errors): the first user map
/// that covers the clip's joints or whose `[map]` joints are all clip joints, else a built-in map
/// that recognises the clip, else identity if every clip joint is named like a rig joint, else an
/// error.
pub fn resolve(
    clip: &str,
    joints: ClipJoints,
    rig_joint_names: &[&str],
    user_maps: &[JointMap],
) -> Result<JointMapping, JointMapError> {
    let names = joints.names;
    if let Some(m) = user_maps
        .iter()
        .find(|m| m.covers(joints) || m.missing(names).is_empty())
    {
        return m.apply(clip, joints, rig_joint_names);
    }
    if let Some(m) = user_maps.iter().find(|m| m.meant_for(names)) {
        return Err(JointMapError::MissingClipJoints {
            file: m.source.clone(),
            clip: clip.to_string(),
            joints: list(&m.missing(names)),
        });
    }
    let builtins = builtin();
    if let Some(m) = builtins.iter().find(|m| m.recognises(joints)) {
        return m.apply(clip, joints, rig_joint_names);
    }
    let rig = rig_index(rig_joint_names);
    if names.iter().all(|n| rig.contains_key(n)) {
        let targets: Vec<Option<usize>> = names.iter().map(|n| rig.get(n).copied()).collect();
        check_unique(clip, names, &targets)?;
        return Ok(JointMapping {
            map_name: "identity".to_string(),
            fates: targets
                .into_iter()
                .map(|t| JointFate::Mapped {
                    rig: t.expect("every name is a rig joint"),
                })
                .collect(),
        });
    }
    Err(JointMapError::NoMap {
        clip: clip.to_string(),
        detail: no_map_detail(joints, &rig, user_maps, &builtins),
    })
}

/// First index of each rig joint name.
fn rig_index<'r>(rig_joint_names: &[&'r str]) -> HashMap<&'r str, usize> {
    let mut index = HashMap::new();
    for (i, &n) in rig_joint_names.iter().enumerate() {
        index.entry(n).or_insert(i);
    }
    index
}

/// Two clip joints landing on one rig joint can only come from duplicate clip names (map targets
/// are unique by construction).
fn check_unique(
    clip: &str,
    clip_joint_names: &[&str],
    clip_to_rig: &[Option<usize>],
) -> Result<(), JointMapError> {
    let mut seen = HashSet::new();
    for (name, target) in clip_joint_names.iter().zip(clip_to_rig) {
        if let Some(t) = target {
            if !seen.insert(*t) {
                return Err(JointMapError::DuplicateClipJoint {
                    clip: clip.to_string(),
                    joint: name.to_string(),
                });
            }
        }
    }
    Ok(())
}

/// Explains the failure through the closest map when that narrows it down, else lists the clip
/// joints the rig does not know.
fn no_map_detail(
    joints: ClipJoints,
    rig: &HashMap<&str, usize>,
    user_maps: &[JointMap],
    builtins: &[JointMap],
) -> String {
    let clip_joint_names = joints.names;
    let unknown: Vec<&str> = clip_joint_names
        .iter()
        .copied()
        .filter(|n| !rig.contains_key(n))
        .collect();
    let closest = user_maps
        .iter()
        .chain(builtins)
        .map(|m| (m, m.unnamed(joints)))
        .min_by_key(|(_, unnamed)| unnamed.len());
    match closest {
        Some((m, unnamed)) if unnamed.is_empty() => {
            // Only a built-in can get here: it names every clip joint but expects more.
            format!(
                "the built-in map '{}' ({}) also expects joints the clip lacks ({}), and built-in maps apply only to clips with all their joints",
                m.name,
                m.source,
                list(&m.missing(clip_joint_names))
            )
        }
        Some((m, unnamed)) if unnamed.len() < unknown.len() => format!(
            "closest map '{}' ({}) has no entry for {}",
            m.name,
            m.source,
            list(&unnamed)
        ),
        _ => format!("joints {} are not rig joints", list(&unknown)),
    }
}

/// `'A', 'B', 'C' and 4 more`: keeps the message one readable line.
fn list(names: &[&str]) -> String {
    const SHOWN: usize = 5;
    let quoted: Vec<String> = names.iter().take(SHOWN).map(|n| format!("'{n}'")).collect();
    let more = names.len().saturating_sub(SHOWN);
    if more > 0 {
        format!("{} and {more} more", quoted.join(", "))
    } else {
        quoted.join(", ")
    }
}

fn did_you_mean(target: &str, rig_joint_names: &[&str]) -> String {
    rig_joint_names
        .iter()
        .find(|r| r.eq_ignore_ascii_case(target))
        .map_or_else(String::new, |r| format!(" (did you mean '{r}'?)"))
}

fn default_name(source_name: &str) -> String {
    let file = Path::new(source_name)
        .file_name()
        .map_or(source_name.to_string(), |f| {
            f.to_string_lossy().into_owned()
        });
    file.strip_suffix(".map.toml")
        .or_else(|| file.strip_suffix(".toml"))
        .unwrap_or(&file)
        .to_string()
}

/// toml's own Display spans several lines (with a source excerpt); keep one line with a line number.
fn toml_error(text: &str, file: &str, e: &toml::de::Error) -> JointMapError {
    let line = e.span().map_or(1, |s| {
        text.get(..s.start)
            .map_or(1, |before| before.matches('\n').count() + 1)
    });
    JointMapError::Toml {
        file: file.to_string(),
        line,
        detail: e.message().trim().replace('\n', "; "),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::bvh::Bvh;

    /// The body rig (shared/data/makehuman/rig.cmu_mb.json): (joint, parent).
    const RIG: [(&str, &str); 31] = [
        ("Hips", ""),
        ("LHipJoint", "Hips"),
        ("LeftUpLeg", "LHipJoint"),
        ("LeftLeg", "LeftUpLeg"),
        ("LeftFoot", "LeftLeg"),
        ("LeftToeBase", "LeftFoot"),
        ("RHipJoint", "Hips"),
        ("RightUpLeg", "RHipJoint"),
        ("RightLeg", "RightUpLeg"),
        ("RightFoot", "RightLeg"),
        ("RightToeBase", "RightFoot"),
        ("LowerBack", "Hips"),
        ("Spine", "LowerBack"),
        ("Spine1", "Spine"),
        ("Neck", "Spine1"),
        ("Neck1", "Neck"),
        ("Head", "Neck1"),
        ("LeftShoulder", "Spine1"),
        ("LeftArm", "LeftShoulder"),
        ("LeftForeArm", "LeftArm"),
        ("LeftHand", "LeftForeArm"),
        ("LeftFingerBase", "LeftHand"),
        ("LeftHandFinger1", "LeftFingerBase"),
        ("LThumb", "LeftHand"),
        ("RightShoulder", "Spine1"),
        ("RightArm", "RightShoulder"),
        ("RightForeArm", "RightArm"),
        ("RightHand", "RightForeArm"),
        ("RightFingerBase", "RightHand"),
        ("RightHandFinger1", "RightFingerBase"),
        ("RThumb", "RightHand"),
    ];

    fn rig_names() -> Vec<&'static str> {
        RIG.iter().map(|(n, _)| *n).collect()
    }

    fn clip(name: &str) -> Bvh {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../shared/data/mocap")
            .join(name);
        Bvh::read(&path).unwrap_or_else(|e| panic!("{e}"))
    }

    fn names(b: &Bvh) -> Vec<&str> {
        b.joints.iter().map(|j| j.name.as_str()).collect()
    }

    fn parents(b: &Bvh) -> Vec<Option<usize>> {
        b.joints.iter().map(|j| j.parent).collect()
    }

    /// Resolves a real clip.
    fn resolve_bvh(file: &str, b: &Bvh, users: &[JointMap]) -> Result<JointMapping, JointMapError> {
        let (n, p) = (names(b), parents(b));
        resolve(
            file,
            ClipJoints {
                names: &n,
                parents: &p,
            },
            &rig_names(),
            users,
        )
    }

    /// Resolves a flat list of root joints (no hierarchy).
    fn resolve_flat(
        clip: &str,
        joints: &[&str],
        users: &[JointMap],
    ) -> Result<JointMapping, JointMapError> {
        let p = vec![None; joints.len()];
        resolve(
            clip,
            ClipJoints {
                names: joints,
                parents: &p,
            },
            &rig_names(),
            users,
        )
    }

    /// Under the resolved map every clip joint's parent must land on the rig joint's parent: this
    /// is what catches a swapped LeftShoulder/LeftArm or Neck/Neck1.
    fn assert_hierarchy_preserved(b: &Bvh, r: &JointMapping) {
        let rig = rig_names();
        let to = r.clip_to_rig();
        assert_eq!(to.len(), b.joints.len());
        for (i, j) in b.joints.iter().enumerate() {
            let target = to[i].expect("every joint mapped");
            let rig_parent = RIG[target].1;
            let mapped_parent = j.parent.map_or("", |p| rig[to[p].unwrap()]);
            assert_eq!(mapped_parent, rig_parent, "{} -> {}", j.name, rig[target]);
        }
    }

    #[test]
    fn builtins_parse() {
        let b = builtin();
        let names: Vec<&str> = b.iter().map(|m| m.name.as_str()).collect();
        assert_eq!(names, ["cmu_mb", "cmu_3dsmax", "cc_base", "mixamo"]);
        for m in &b {
            // The CMU maps list every joint; the others only those that matter.
            let mapped = match m.name.as_str() {
                "cc_base" => 29,
                "mixamo" => 28,
                _ => 31,
            };
            assert_eq!(m.pairs.len(), mapped, "{}", m.name);
            let rig = rig_names();
            assert!(m.pairs.iter().all(|(_, r)| rig.contains(&r.as_str())));
        }
    }

    #[test]
    fn clips_131_resolve_through_3dsmax_map() {
        for file in ["131_01.bvh", "131_02.bvh"] {
            let b = clip(file);
            let r = resolve_bvh(file, &b, &[]).unwrap();
            assert_eq!(r.map_name, "cmu_3dsmax");
            assert_hierarchy_preserved(&b, &r);
            let rig = rig_names();
            let to = |n: &str| rig[r.clip_to_rig()[b.joint_index(n).unwrap()].unwrap()];
            assert_eq!(to("LeftShoulder"), "LeftArm");
            assert_eq!(to("LeftCollar"), "LeftShoulder");
            assert_eq!(to("Neck"), "Neck1");
            assert_eq!(to("lowerneck"), "Neck");
        }
    }

    #[test]
    fn clip_01_resolves_through_mb_map() {
        let b = clip("01_01.bvh");
        let r = resolve_bvh("01_01.bvh", &b, &[]).unwrap();
        assert_eq!(r.map_name, "cmu_mb");
        assert_hierarchy_preserved(&b, &r);
        let rig = rig_names();
        let i = b.joint_index("RFingers").unwrap();
        assert_eq!(rig[r.clip_to_rig()[i].unwrap()], "RightHandFinger1");
    }

    #[test]
    fn unknown_joint_is_named() {
        let b = clip("01_01.bvh");
        let mut n = names(&b);
        n.push("Tail");
        let e = resolve_flat("tail.bvh", &n, &[]).unwrap_err().to_string();
        assert!(e.starts_with("tail.bvh: cannot match"), "{e}");
        assert!(
            e.contains("'cmu_mb'") && e.contains("no entry for 'Tail'"),
            "{e}"
        );
        assert!(e.contains("--map FILE.toml") && !e.contains('\n'), "{e}");

        // A user map that covers everything but points at a joint the rig lacks.
        let user = JointMap::parse("[map]\nHips = \"Pelvis\"\n", "my.map.toml").unwrap();
        let e = resolve_flat("c.bvh", &["Hips"], &[user]).unwrap_err();
        assert_eq!(
            e.to_string(),
            "my.map.toml: maps clip joint 'Hips' to 'Pelvis', which is not a joint of the rig"
        );

        // Unknown names and no map at all.
        let e = resolve_flat("x.bvh", &["Hips", "A", "B"], &[]).unwrap_err();
        assert!(
            e.to_string().contains("joints 'A', 'B' are not rig joints"),
            "{e}"
        );
    }

    #[test]
    fn partial_builtin_is_not_used() {
        // Joints common to both namings but with different meanings: no built-in may guess.
        let e = resolve_flat("p.bvh", &["Hips", "LeftShoulder", "LeftCollar"], &[])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("'cmu_3dsmax'") && e.contains("clips with all their joints"),
            "{e}"
        );
        // Exactly the rig's names: identity.
        let r = resolve_flat("i.bvh", &["Hips", "LeftShoulder"], &[]).unwrap();
        assert_eq!(r.map_name, "identity");
        assert_eq!(r.clip_to_rig(), [Some(0), Some(17)]);
    }

    #[test]
    fn user_map_applies_only_to_clips_it_covers() {
        let user = JointMap::parse(
            "name = \"mine\"\n[map]\nPelvis = \"Hips\"\nThigh = \"LeftUpLeg\"\n",
            "mine.toml",
        )
        .unwrap();
        let users = [user];
        let r = resolve_flat("a.bvh", &["Pelvis", "Thigh"], &users).unwrap();
        assert_eq!(r.map_name, "mine");
        assert_eq!(r.clip_to_rig(), [Some(0), Some(2)]);
        let b = clip("131_01.bvh");
        let r = resolve_bvh("131_01.bvh", &b, &users).unwrap();
        assert_eq!(r.map_name, "cmu_3dsmax");
        // The user map may cover a subset of its keys.
        let r = resolve_flat("b.bvh", &["Pelvis"], &users).unwrap();
        assert_eq!(r.clip_to_rig(), [Some(0)]);
    }

    #[test]
    fn parse_errors_are_one_line_and_name_the_file() {
        let e = JointMap::parse(
            "name = \"x\"\n[map]\nA = \"Hips\"\nB = \"Hips\"\n",
            "d.toml",
        )
        .unwrap_err()
        .to_string();
        assert_eq!(e, "d.toml: rig joint 'Hips' is the target of both 'A' and 'B'; each rig joint may be mapped at most once");
        let e = JointMap::parse("name = \"x\"\n[map]\n", "e.toml").unwrap_err();
        assert!(matches!(e, JointMapError::Empty { .. }), "{e}");
        let e = JointMap::parse("[map]\nA = \n", "t.toml")
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("t.toml:2: bad joint map TOML:") && !e.contains('\n'),
            "{e}"
        );
        let e = JointMap::parse("[map]\nA = 3\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("t.toml:2: bad joint map TOML:"), "{e}");
        let e = JointMap::parse("[mapp]\nA = \"B\"\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("t.toml:") && !e.contains('\n'), "{e}");
        let e = JointMap::parse("[map]\nA = \"\"\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("empty joint name in the entry for 'A'"), "{e}");
        let e = JointMap::read(Path::new("/nonexistent/m.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("/nonexistent/m.toml: cannot read:") && !e.contains('\n'));
        // Name defaults to the file stem.
        let m = JointMap::parse("[map]\nA = \"Hips\"\n", "dir/rokoko.map.toml").unwrap();
        assert_eq!(m.name, "rokoko");
        assert_eq!(m.target("A"), Some("Hips"));
        let flat = |n: &'static [&'static str]| ClipJoints {
            names: n,
            parents: &[None, None][..n.len()],
        };
        assert!(m.covers(flat(&["A"])) && !m.covers(flat(&["A", "B"])));
    }

    #[test]
    fn duplicate_clip_joint_names_rejected() {
        let e = resolve_flat("d.bvh", &["Hips", "Hips"], &[]).unwrap_err();
        assert!(matches!(e, JointMapError::DuplicateClipJoint { .. }), "{e}");
    }

    fn cc(name: &str) -> Bvh {
        clip(&format!("cc_base/{name}"))
    }

    fn fate_of(b: &Bvh, r: &JointMapping, joint: &str) -> JointFate {
        r.fates[b.joint_index(joint).unwrap_or_else(|| panic!("no {joint}"))]
    }

    #[test]
    fn every_cc_base_take_is_recognised_and_folds_what_lies_between() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/mocap/cc_base");
        let mut takes: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "bvh"))
            .collect();
        takes.sort();
        assert_eq!(takes.len(), 56);
        let rig = rig_names();
        for path in &takes {
            let b = Bvh::read(path).unwrap();
            let file = path.file_name().unwrap().to_string_lossy();
            let r = resolve_bvh(&file, &b, &[]).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(r.map_name, "cc_base", "{file}");
            let (mapped, folded, dropped) = r.counts();
            assert_eq!(mapped, 29, "{file}");
            let hip = b.joint_index("CC_Base_Hip").unwrap();
            assert_eq!(
                fate_of(&b, &r, "CC_Base_Pelvis"),
                JointFate::Folded {
                    into: Some(hip),
                    explicit: true
                },
                "{file}"
            );
            assert_eq!(
                fate_of(&b, &r, "CC_Base_L_ThighTwist02"),
                JointFate::Dropped { explicit: false },
                "{file}: below a skipped twist bone"
            );
            assert_eq!(
                fate_of(&b, &r, "CC_Base_L_CalfTwist01"),
                JointFate::Dropped { explicit: true }
            );
            let extra_root = b.joint_index("RL_BoneRoot").is_some();
            if extra_root {
                assert_eq!(
                    fate_of(&b, &r, "RL_BoneRoot"),
                    JointFate::Folded {
                        into: None,
                        explicit: true
                    }
                );
            }
            assert_eq!(folded, 1 + extra_root as usize, "{file}");
            assert_eq!(mapped + folded + dropped, b.joints.len());
            let knee = fate_of(&b, &r, "CC_Base_L_Calf");
            assert_eq!(knee, JointFate::Mapped { rig: 3 });
            assert_eq!(rig[3], "LeftLeg");
        }
    }

    #[test]
    fn a_partial_user_map_folds_and_drops_the_rest() {
        let b = cc("005_02.bvh");
        // Hips, the legs and the spine: everything else folded or dropped by the rule.
        let user = JointMap::parse(
            "[map]\nCC_Base_Hip = \"Hips\"\nCC_Base_L_Thigh = \"LeftUpLeg\"\nCC_Base_L_Foot = \"LeftFoot\"\nCC_Base_R_Thigh = \"RightUpLeg\"\nCC_Base_R_Foot = \"RightFoot\"\nCC_Base_Head = \"Head\"\n",
            "mine.toml",
        )
        .unwrap();
        let r = resolve_bvh("005_02.bvh", &b, &[user]).unwrap();
        assert_eq!(r.map_name, "mine");
        let thigh = b.joint_index("CC_Base_L_Thigh").unwrap();
        // Between thigh and foot: folded into the thigh.
        assert_eq!(
            fate_of(&b, &r, "CC_Base_L_Calf"),
            JointFate::Folded {
                into: Some(thigh),
                explicit: false
            }
        );
        assert_eq!(
            fate_of(&b, &r, "CC_Base_NeckTwist02"),
            JointFate::Folded {
                into: Some(b.joint_index("CC_Base_Hip").unwrap()),
                explicit: false
            }
        );
        assert_eq!(
            fate_of(&b, &r, "CC_Base_L_Hand"),
            JointFate::Dropped { explicit: false }
        );
        assert_eq!(r.counts().0, 6);
    }

    #[test]
    fn bad_maps_for_a_production_rig_are_one_line_errors() {
        let b = cc("005_02.bvh");
        let one_line = |e: JointMapError| {
            let e = e.to_string();
            assert!(!e.contains('\n'), "{e}");
            e
        };
        // A joint the clip lacks.
        let user = JointMap::parse(
            "[map]\nCC_Base_Hip = \"Hips\"\nCC_Base_L_Thig = \"LeftUpLeg\"\n",
            "typo.toml",
        )
        .unwrap();
        let e = one_line(resolve_bvh("005_02.bvh", &b, &[user]).unwrap_err());
        assert_eq!(e, "typo.toml: names 'CC_Base_L_Thig', which 005_02.bvh lacks; fix the names or leave them out (joints left out are folded or dropped)");
        // Skipping a joint with a mapped joint below it.
        let user = JointMap::parse(
            "skip = [\"CC_Base_Pelvis\"]\n[map]\nCC_Base_Hip = \"Hips\"\nCC_Base_L_Thigh = \"LeftUpLeg\"\n",
            "skip.toml",
        )
        .unwrap();
        let e = one_line(resolve_bvh("005_02.bvh", &b, &[user]).unwrap_err());
        assert!(
            e.contains("skips 'CC_Base_Pelvis'") && e.contains("'CC_Base_L_Thigh'"),
            "{e}"
        );
        // Folding a leaf.
        let user = JointMap::parse(
            "fold = [\"CC_Base_L_Eye\"]\n[map]\nCC_Base_Hip = \"Hips\"\n",
            "fold.toml",
        )
        .unwrap();
        let e = one_line(resolve_bvh("005_02.bvh", &b, &[user]).unwrap_err());
        assert!(
            e.contains("folds 'CC_Base_L_Eye'") && e.contains("skip"),
            "{e}"
        );
    }

    #[test]
    fn globs() {
        assert!(glob("CC_Base_*Twist0?", "CC_Base_L_ThighTwist01"));
        assert!(!glob("CC_Base_*Twist0?", "CC_Base_L_ThighTwist1"));
        assert!(glob("*", ""));
        assert!(glob("a*b*c", "aXXbYc"));
        assert!(!glob("a*b*c", "aXXbYd"));
        assert!(glob("mixamorig:*Toe_End", "mixamorig:LeftToe_End"));
        assert!(!glob("abc", "abcd"));
    }
}
