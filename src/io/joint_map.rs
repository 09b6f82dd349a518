//! Joint-name maps: rename a motion clip's joints onto the body rig's joints.
//!
//! A map file is TOML:
//! ```toml
//! name = "cmu_3dsmax"
//! [map]
//! LeftCollar = "LeftShoulder"   # ClipJoint = "RigJoint"
//! ```
//! Maps are strict: every clip joint must map to an existing rig joint and each rig joint is the
//! target of at most one clip joint. Rig joints no clip joint reaches keep their rest pose.
//!
//! [`resolve`] picks the map for a clip: a user map (`--map`) that covers all the clip's joints, else a
//! built-in map whose joints are exactly the clip's, else identity when every clip joint already has a
//! rig joint's name, else an error telling the user to pass `--map`. Built-ins must match exactly
//! because namings reuse each other's names for different joints (see `cmu_3dsmax.map.toml`).

use std::collections::{BTreeMap, HashMap, HashSet};
use std::path::Path;

use serde::Deserialize;
use thiserror::Error;

/// A named clip-joint → rig-joint renaming.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct JointMap {
    pub name: String,
    /// (clip joint, rig joint), sorted by clip joint.
    pub pairs: Vec<(String, String)>,
    /// Where the map came from, for error messages (a path, or the sample path for built-ins).
    pub source: String,
}

use crate::rig::retarget::JointMapping;

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
    #[error("{file}: the [map] table is empty; list each clip joint as ClipJoint = \"RigJoint\"")]
    Empty { file: String },
    #[error("{file}: empty joint name in the entry for '{clip}'; every clip joint must map to a rig joint")]
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
    #[error("{clip}: cannot match its joints to the rig: {detail}; pass --map FILE.toml with a [map] table naming a rig joint for each clip joint")]
    NoMap { clip: String, detail: String },
}

/// The file layout; unknown keys are rejected so typos do not silently drop a table.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MapFile {
    name: Option<String>,
    map: BTreeMap<String, String>,
}

const BUILTIN: [(&str, &str); 2] = [
    (
        "samples/motions/cmu_mb.map.toml (built in)",
        include_str!("../../samples/motions/cmu_mb.map.toml"),
    ),
    (
        "samples/motions/cmu_3dsmax.map.toml (built in)",
        include_str!("../../samples/motions/cmu_3dsmax.map.toml"),
    ),
];

/// The maps shipped with the tool: CMU MotionBuilder naming (`cmu_mb`) and 3dsMax naming
/// (`cmu_3dsmax`).
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
            source: file(),
        })
    }

    /// True when every clip joint is a key of the map (extra keys are allowed).
    pub fn covers(&self, clip_joint_names: &[&str]) -> bool {
        let keys = self.keys();
        clip_joint_names.iter().all(|n| keys.contains(n))
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

    /// Same joint set as the clip: how a built-in map is chosen.
    fn matches_exactly(&self, clip_joint_names: &[&str]) -> bool {
        let clip: HashSet<&str> = clip_joint_names.iter().copied().collect();
        self.keys() == clip
    }

    /// Clip joints this map has no entry for, in clip order.
    fn missing<'c>(&self, clip_joint_names: &[&'c str]) -> Vec<&'c str> {
        let keys = self.keys();
        clip_joint_names
            .iter()
            .copied()
            .filter(|n| !keys.contains(n))
            .collect()
    }

    fn apply(
        &self,
        clip: &str,
        clip_joint_names: &[&str],
        rig_joint_names: &[&str],
    ) -> Result<JointMapping, JointMapError> {
        let targets = self.pairs.iter().map(|(c, r)| (c.as_str(), r.as_str()));
        let lookup: HashMap<&str, &str> = targets.collect();
        let rig = rig_index(rig_joint_names);
        let mut clip_to_rig = Vec::with_capacity(clip_joint_names.len());
        for &name in clip_joint_names {
            let target = lookup.get(name).copied().unwrap_or(name);
            let Some(&i) = rig.get(target) else {
                return Err(JointMapError::UnknownRigJoint {
                    file: self.source.clone(),
                    clip: name.to_string(),
                    rig: target.to_string(),
                    hint: did_you_mean(target, rig_joint_names),
                });
            };
            clip_to_rig.push(Some(i));
        }
        check_unique(clip, clip_joint_names, &clip_to_rig)?;
        Ok(JointMapping {
            map_name: self.name.clone(),
            clip_to_rig,
        })
    }
}

/// Chooses and applies the joint map for one clip (`clip` names it in errors):
/// the first user map that covers the clip's joints, else a built-in map with exactly the clip's
/// joints, else identity if every clip joint is named like a rig joint, else an error.
pub fn resolve(
    clip: &str,
    clip_joint_names: &[&str],
    rig_joint_names: &[&str],
    user_maps: &[JointMap],
) -> Result<JointMapping, JointMapError> {
    if let Some(m) = user_maps.iter().find(|m| m.covers(clip_joint_names)) {
        return m.apply(clip, clip_joint_names, rig_joint_names);
    }
    let builtins = builtin();
    if let Some(m) = builtins
        .iter()
        .find(|m| m.matches_exactly(clip_joint_names))
    {
        return m.apply(clip, clip_joint_names, rig_joint_names);
    }
    let rig = rig_index(rig_joint_names);
    if clip_joint_names.iter().all(|n| rig.contains_key(n)) {
        let clip_to_rig: Vec<Option<usize>> = clip_joint_names
            .iter()
            .map(|n| rig.get(n).copied())
            .collect();
        check_unique(clip, clip_joint_names, &clip_to_rig)?;
        return Ok(JointMapping {
            map_name: "identity".to_string(),
            clip_to_rig,
        });
    }
    Err(JointMapError::NoMap {
        clip: clip.to_string(),
        detail: no_map_detail(clip_joint_names, &rig, user_maps, &builtins),
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
    clip_joint_names: &[&str],
    rig: &HashMap<&str, usize>,
    user_maps: &[JointMap],
    builtins: &[JointMap],
) -> String {
    let unknown: Vec<&str> = clip_joint_names
        .iter()
        .copied()
        .filter(|n| !rig.contains_key(n))
        .collect();
    let closest = user_maps
        .iter()
        .chain(builtins)
        .map(|m| (m, m.missing(clip_joint_names)))
        .min_by_key(|(_, missing)| missing.len());
    match closest {
        Some((m, missing)) if missing.is_empty() => {
            // Only a built-in can get here: it knows every clip joint but has more.
            let clip: HashSet<&str> = clip_joint_names.iter().copied().collect();
            let extra: Vec<&str> = m
                .pairs
                .iter()
                .map(|(c, _)| c.as_str())
                .filter(|c| !clip.contains(c))
                .collect();
            format!(
                "the built-in map '{}' ({}) also expects joints the clip lacks ({}), and built-in maps apply only to their exact joint set",
                m.name,
                m.source,
                list(&extra)
            )
        }
        Some((m, missing)) if missing.len() < unknown.len() => format!(
            "closest map '{}' ({}) has no entry for {}",
            m.name,
            m.source,
            list(&missing)
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

    /// Under the resolved map every clip joint's parent must land on the rig joint's parent: this
    /// is what catches a swapped LeftShoulder/LeftArm or Neck/Neck1.
    fn assert_hierarchy_preserved(b: &Bvh, r: &JointMapping) {
        let rig = rig_names();
        assert_eq!(r.clip_to_rig.len(), b.joints.len());
        for (i, j) in b.joints.iter().enumerate() {
            let target = r.clip_to_rig[i].expect("every joint mapped");
            let rig_parent = RIG[target].1;
            let mapped_parent = j.parent.map_or("", |p| rig[r.clip_to_rig[p].unwrap()]);
            assert_eq!(mapped_parent, rig_parent, "{} -> {}", j.name, rig[target]);
        }
    }

    #[test]
    fn builtins_parse() {
        let b = builtin();
        let names: Vec<&str> = b.iter().map(|m| m.name.as_str()).collect();
        assert_eq!(names, ["cmu_mb", "cmu_3dsmax"]);
        for m in &b {
            assert_eq!(m.pairs.len(), 31, "{}", m.name);
            let rig = rig_names();
            assert!(m.pairs.iter().all(|(_, r)| rig.contains(&r.as_str())));
        }
    }

    #[test]
    fn clips_131_resolve_through_3dsmax_map() {
        for file in ["131_01.bvh", "131_02.bvh"] {
            let b = clip(file);
            let r = resolve(file, &names(&b), &rig_names(), &[]).unwrap();
            assert_eq!(r.map_name, "cmu_3dsmax");
            assert_hierarchy_preserved(&b, &r);
            let rig = rig_names();
            let to = |n: &str| rig[r.clip_to_rig[b.joint_index(n).unwrap()].unwrap()];
            assert_eq!(to("LeftShoulder"), "LeftArm");
            assert_eq!(to("LeftCollar"), "LeftShoulder");
            assert_eq!(to("Neck"), "Neck1");
            assert_eq!(to("lowerneck"), "Neck");
        }
    }

    #[test]
    fn clip_01_resolves_through_mb_map() {
        let b = clip("01_01.bvh");
        let r = resolve("01_01.bvh", &names(&b), &rig_names(), &[]).unwrap();
        assert_eq!(r.map_name, "cmu_mb");
        assert_hierarchy_preserved(&b, &r);
        let rig = rig_names();
        let i = b.joint_index("RFingers").unwrap();
        assert_eq!(rig[r.clip_to_rig[i].unwrap()], "RightHandFinger1");
    }

    #[test]
    fn unknown_joint_is_named() {
        let b = clip("01_01.bvh");
        let mut n = names(&b);
        n.push("Tail");
        let e = resolve("tail.bvh", &n, &rig_names(), &[])
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("tail.bvh: cannot match"), "{e}");
        assert!(
            e.contains("'cmu_mb'") && e.contains("no entry for 'Tail'"),
            "{e}"
        );
        assert!(e.contains("--map FILE.toml") && !e.contains('\n'), "{e}");

        // A user map that covers everything but points at a joint the rig lacks.
        let user = JointMap::parse("[map]\nHips = \"Pelvis\"\n", "my.map.toml").unwrap();
        let e = resolve("c.bvh", &["Hips"], &rig_names(), &[user]).unwrap_err();
        assert_eq!(
            e.to_string(),
            "my.map.toml: maps clip joint 'Hips' to 'Pelvis', which is not a joint of the rig"
        );

        // Unknown names and no map at all.
        let e = resolve("x.bvh", &["Hips", "A", "B"], &rig_names(), &[]).unwrap_err();
        assert!(
            e.to_string().contains("joints 'A', 'B' are not rig joints"),
            "{e}"
        );
    }

    #[test]
    fn partial_builtin_is_not_used() {
        // Joints common to both namings but with different meanings: no built-in may guess.
        let e = resolve(
            "p.bvh",
            &["Hips", "LeftShoulder", "LeftCollar"],
            &rig_names(),
            &[],
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("'cmu_3dsmax'") && e.contains("exact joint set"),
            "{e}"
        );
        // Exactly the rig's names: identity.
        let r = resolve("i.bvh", &["Hips", "LeftShoulder"], &rig_names(), &[]).unwrap();
        assert_eq!(r.map_name, "identity");
        assert_eq!(r.clip_to_rig, [Some(0), Some(17)]);
    }

    #[test]
    fn user_map_applies_only_to_clips_it_covers() {
        let user = JointMap::parse(
            "name = \"mine\"\n[map]\nPelvis = \"Hips\"\nThigh = \"LeftUpLeg\"\n",
            "mine.toml",
        )
        .unwrap();
        let users = [user];
        let r = resolve("a.bvh", &["Pelvis", "Thigh"], &rig_names(), &users).unwrap();
        assert_eq!(r.map_name, "mine");
        assert_eq!(r.clip_to_rig, [Some(0), Some(2)]);
        let b = clip("131_01.bvh");
        let r = resolve("131_01.bvh", &names(&b), &rig_names(), &users).unwrap();
        assert_eq!(r.map_name, "cmu_3dsmax");
        // The user map may cover a subset of its keys.
        let r = resolve("b.bvh", &["Pelvis"], &rig_names(), &users).unwrap();
        assert_eq!(r.clip_to_rig, [Some(0)]);
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
        assert!(m.covers(&["A"]) && !m.covers(&["A", "B"]));
    }

    #[test]
    fn duplicate_clip_joint_names_rejected() {
        let e = resolve("d.bvh", &["Hips", "Hips"], &rig_names(), &[]).unwrap_err();
        assert!(matches!(e, JointMapError::DuplicateClipJoint { .. }), "{e}");
    }
}
