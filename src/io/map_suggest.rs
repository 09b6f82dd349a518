//! A draft joint map for an unknown clip, from joint names and the hierarchy (`garmentbake map
//! suggest`).
//!
//! Names alone mislead (CMU's 3dsMax naming calls the upper arm `LeftShoulder`), so names only find
//! the chain ends, the feet, hands and head, and their side; the hierarchy does the rest: walking up
//! from a foot gives the shin, then the thigh, then (if it still has a side) a hip joint; walking up
//! from a hand gives the forearm, the upper arm and (if it has a side) the clavicle. The hips are
//! the joint the legs and the head have in common. Helper bones (twist, share, roll, end) are never
//! looked for as a chain end or a toe or finger. What it cannot place it reports; the draft names only the joints that matter, so
//! every other joint is folded or dropped by the map rules.

use std::fmt::Write as _;

use thiserror::Error;

/// A suggested map: `(clip joint, rig joint)` pairs in rig order, and the rig joints left unplaced.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct Suggestion {
    pub name: String,
    pub pairs: Vec<(String, String)>,
    pub unplaced: Vec<String>,
}

#[derive(Debug, Error)]
pub enum SuggestError {
    #[error("{clip}: no recognisable legs (no joints named like a foot or an ankle on both sides, below a common hip); write the map by hand (see samples/motions/cc_base.map.toml)")]
    NoLegs { clip: String },
}

/// Which side of the body a joint name says it is on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Side {
    Left,
    Right,
}

fn side_of(name: &str) -> Option<Side> {
    let base = name.rsplit(':').next().unwrap_or(name);
    let lower = base.to_ascii_lowercase();
    if lower.contains("left") {
        return Some(Side::Left);
    }
    if lower.contains("right") {
        return Some(Side::Right);
    }
    // Separated letters (`CC_Base_L_Thigh`, `thigh_l`, `Hand.R`) or a capital before a capital
    // (`LHipJoint`, `RThumb`).
    let tokens: Vec<&str> = base.split(['_', '.', ' ', '-']).collect();
    for t in &tokens {
        match *t {
            "L" | "l" => return Some(Side::Left),
            "R" | "r" => return Some(Side::Right),
            _ => {}
        }
    }
    let b = base.as_bytes();
    if b.len() > 1 && b[1].is_ascii_uppercase() {
        match b[0] {
            b'L' => return Some(Side::Left),
            b'R' => return Some(Side::Right),
            _ => {}
        }
    }
    None
}

fn lower(name: &str) -> String {
    name.rsplit(':').next().unwrap_or(name).to_ascii_lowercase()
}

/// Twist bones, helpers and tips: never a chain joint.
fn is_helper(name: &str) -> bool {
    let n = lower(name);
    ["twist", "share", "roll", "helper", "_end", "nub"]
        .iter()
        .any(|k| n.contains(k))
}

fn has(name: &str, keys: &[&str]) -> bool {
    let n = lower(name);
    keys.iter().any(|k| n.contains(k))
}

struct Tree<'a> {
    names: &'a [&'a str],
    parents: &'a [Option<usize>],
}

impl Tree<'_> {
    fn ancestors(&self, j: usize) -> Vec<usize> {
        let mut out = Vec::new();
        let mut at = self.parents[j];
        while let Some(p) = at {
            out.push(p);
            at = self.parents[p];
        }
        out
    }

    /// The joints above `j`. Helpers hang beside a chain, not in it (a thigh's twist bone is its
    /// child, not the shin's parent), so they are not filtered here: a Character Creator neck is
    /// `NeckTwist01` / `NeckTwist02`.
    fn chain_up(&self, j: usize) -> Vec<usize> {
        self.ancestors(j)
    }

    fn children(&self, j: usize) -> impl Iterator<Item = usize> + '_ {
        (0..self.names.len()).filter(move |&c| self.parents[c] == Some(j))
    }

    fn depth(&self, j: usize) -> usize {
        self.ancestors(j).len()
    }

    /// The shallowest joint on `side` whose name has one of `keys` (and none of `not`).
    fn find(&self, side: Option<Side>, keys: &[&str], not: &[&str]) -> Option<usize> {
        (0..self.names.len())
            .filter(|&j| {
                let n = self.names[j];
                side_of(n) == side && has(n, keys) && !has(n, not) && !is_helper(n)
            })
            .min_by_key(|&j| self.depth(j))
    }

    fn common_ancestor(&self, joints: &[usize]) -> Option<usize> {
        let first = joints.first()?;
        let mut line = vec![*first];
        line.extend(self.ancestors(*first));
        line.into_iter().find(|&a| {
            joints
                .iter()
                .all(|&j| j == a || self.ancestors(j).contains(&a))
        })
    }
}

/// The body rig's joint for each role, in the sample body's (MakeHuman `cmu_mb`) naming.
const LEG: [&str; 5] = ["HipJoint", "UpLeg", "Leg", "Foot", "ToeBase"];

/// Drafts a map for a clip's joint tree onto the sample body's rig.
pub fn suggest(
    clip: &str,
    names: &[&str],
    parents: &[Option<usize>],
) -> Result<Suggestion, SuggestError> {
    let tree = Tree { names, parents };
    let mut pairs: Vec<(usize, String)> = Vec::new();
    let no_legs = || SuggestError::NoLegs {
        clip: clip.to_string(),
    };
    let foot_keys = ["foot", "ankle"];
    let feet: Vec<usize> = [Side::Left, Side::Right]
        .iter()
        .map(|&s| tree.find(Some(s), &foot_keys, &["toe", "ball"]))
        .collect::<Option<_>>()
        .ok_or_else(no_legs)?;
    let head = tree.find(None, &["head"], &["top"]);
    let mut ends = feet.clone();
    ends.extend(head);
    let hips = tree.common_ancestor(&ends).ok_or_else(no_legs)?;
    // Per leg: foot, shin, thigh, and a hip joint while the chain still has a side.
    for (&foot, side) in feet.iter().zip(["Left", "Right"]) {
        let up: Vec<usize> = tree
            .chain_up(foot)
            .into_iter()
            .take_while(|&a| a != hips)
            .collect();
        if up.len() < 2 {
            return Err(no_legs());
        }
        let short = if side == "Left" { "L" } else { "R" };
        pairs.push((foot, format!("{side}Foot")));
        pairs.push((up[0], format!("{side}Leg")));
        pairs.push((up[1], format!("{side}UpLeg")));
        if let Some(&hj) = up.get(2) {
            if side_of(names[hj]).is_some() {
                pairs.push((hj, format!("{short}HipJoint")));
            }
        }
        let toe = tree
            .children(foot)
            .filter(|&c| has(names[c], &["toe", "ball"]) && !is_helper(names[c]))
            .max_by_key(|&c| tree.children(c).count());
        if let Some(t) = toe {
            pairs.push((t, format!("{side}ToeBase")));
        }
    }
    pairs.push((hips, "Hips".to_string()));
    // Spine: the joints from the hips to the head; the neck ones by name.
    let mut spine_top = None;
    if let Some(h) = head {
        pairs.push((h, "Head".to_string()));
        let mut chain: Vec<usize> = tree
            .chain_up(h)
            .into_iter()
            .take_while(|&a| a != hips)
            .collect();
        chain.reverse(); // hips side first
        let (necks, spine): (Vec<usize>, Vec<usize>) =
            chain.iter().partition(|&&j| has(names[j], &["neck"]));
        match necks.as_slice() {
            [] => {}
            [one] => pairs.push((*one, "Neck".to_string())),
            [.., a, b] => {
                pairs.push((*a, "Neck".to_string()));
                pairs.push((*b, "Neck1".to_string()));
            }
        }
        let roles = ["LowerBack", "Spine", "Spine1"];
        match spine.as_slice() {
            [] => {}
            [one] => pairs.push((*one, "Spine1".to_string())),
            [a, b] => {
                pairs.push((*a, "Spine".to_string()));
                pairs.push((*b, "Spine1".to_string()));
            }
            many => {
                let last = many.len() - 1;
                pairs.push((many[0], roles[0].to_string()));
                pairs.push((many[last / 2], roles[1].to_string()));
                pairs.push((many[last], roles[2].to_string()));
            }
        }
        spine_top = spine.last().copied();
    }
    // Arms: hand, forearm, upper arm, and a clavicle while the chain still has a side.
    for (side, s) in [("Left", Side::Left), ("Right", Side::Right)] {
        let Some(hand) = tree.find(
            Some(s),
            &["hand", "wrist"],
            &["finger", "thumb", "index", "middle", "ring", "pinky"],
        ) else {
            continue;
        };
        let up = tree.chain_up(hand);
        pairs.push((hand, format!("{side}Hand")));
        if let Some(&fa) = up.first() {
            pairs.push((fa, format!("{side}ForeArm")));
        }
        if let Some(&ua) = up.get(1) {
            pairs.push((ua, format!("{side}Arm")));
        }
        if let Some(&cl) = up.get(2) {
            if side_of(names[cl]).is_some() && Some(cl) != spine_top {
                pairs.push((cl, format!("{side}Shoulder")));
            }
        }
        let short = if side == "Left" { "L" } else { "R" };
        let kids: Vec<usize> = tree
            .children(hand)
            .filter(|&c| !is_helper(names[c]))
            .collect();
        if let Some(&t) = kids.iter().find(|&&c| has(names[c], &["thumb"])) {
            pairs.push((t, format!("{short}Thumb")));
        }
        let finger = kids
            .iter()
            .copied()
            .find(|&c| has(names[c], &["mid"]))
            .or_else(|| kids.iter().copied().find(|&c| !has(names[c], &["thumb"])));
        if let Some(f) = finger {
            pairs.push((f, format!("{side}FingerBase")));
            if let Some(tip) = tree.children(f).find(|&c| !is_helper(names[c])) {
                pairs.push((tip, format!("{side}HandFinger1")));
            }
        }
    }
    let rig_order = rig_roles();
    pairs.sort_by_key(|(_, r)| rig_order.iter().position(|x| x == r));
    pairs.dedup_by(|a, b| a.0 == b.0);
    let unplaced = rig_order
        .iter()
        .filter(|r| !pairs.iter().any(|(_, p)| p == *r))
        .cloned()
        .collect();
    Ok(Suggestion {
        name: format!("{}_suggested", stem(clip)),
        pairs: pairs
            .into_iter()
            .map(|(j, r)| (names[j].to_string(), r))
            .collect(),
        unplaced,
    })
}

/// The sample body's 31 joints in rig order.
fn rig_roles() -> Vec<String> {
    let mut out = vec!["Hips".to_string()];
    for (side, short) in [("Left", "L"), ("Right", "R")] {
        for part in LEG {
            out.push(if part == "HipJoint" {
                format!("{short}{part}")
            } else {
                format!("{side}{part}")
            });
        }
    }
    for j in ["LowerBack", "Spine", "Spine1", "Neck", "Neck1", "Head"] {
        out.push(j.to_string());
    }
    for (side, short) in [("Left", "L"), ("Right", "R")] {
        for part in [
            "Shoulder",
            "Arm",
            "ForeArm",
            "Hand",
            "FingerBase",
            "HandFinger1",
        ] {
            out.push(format!("{side}{part}"));
        }
        out.push(format!("{short}Thumb"));
    }
    out
}

fn stem(clip: &str) -> String {
    std::path::Path::new(clip)
        .file_stem()
        .map_or_else(|| "clip".to_string(), |s| s.to_string_lossy().into_owned())
}

impl Suggestion {
    /// The map as TOML, with what was left unplaced in a comment.
    pub fn to_toml(&self, clip: &str) -> String {
        let mut out = String::new();
        let _ = writeln!(
            out,
            "# Joint map drafted by `garmentbake map suggest {clip}`: check it with\n# `garmentbake inspect {clip} --body BODY.glb --map THIS.toml`."
        );
        if !self.unplaced.is_empty() {
            let _ = writeln!(
                out,
                "# Rig joints not placed (they keep their rest pose): {}",
                self.unplaced.join(", ")
            );
        }
        let _ = writeln!(
            out,
            "# Clip joints not named here are folded (a mapped joint lies below them) or dropped.\n"
        );
        let _ = writeln!(out, "name = {}\n\n[map]", toml_string(&self.name));
        for (clip_joint, rig) in &self.pairs {
            let _ = writeln!(out, "{} = {}", toml_key(clip_joint), toml_string(rig));
        }
        out
    }
}

fn toml_string(s: &str) -> String {
    format!("\"{}\"", s.replace('\\', "\\\\").replace('"', "\\\""))
}

fn toml_key(s: &str) -> String {
    if !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
    {
        s.to_string()
    } else {
        toml_string(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::bvh::Bvh;
    use crate::io::joint_map::builtin;
    use std::path::Path;

    fn draft(rel: &str) -> Result<Suggestion, SuggestError> {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../shared/data/mocap")
            .join(rel);
        let b = Bvh::read(&path).unwrap();
        let names: Vec<&str> = b.joints.iter().map(|j| j.name.as_str()).collect();
        let parents: Vec<Option<usize>> = b.joints.iter().map(|j| j.parent).collect();
        suggest(rel, &names, &parents)
    }

    /// The draft for each shipped naming equals the hand-written built-in map, joint for joint
    /// (the CMU 3dsMax naming calls the upper arm `LeftShoulder`: only the hierarchy gets it right).
    #[test]
    fn drafts_equal_the_hand_written_maps() {
        let maps = builtin();
        for (clip, map) in [
            ("01_01.bvh", "cmu_mb"),
            ("131_01.bvh", "cmu_3dsmax"),
            ("cc_base/005_02.bvh", "cc_base"),
            ("cc_base/002_01.bvh", "cc_base"),
        ] {
            let s = draft(clip).unwrap();
            let m = maps.iter().find(|m| m.name == map).unwrap();
            let mut want = m.pairs.clone();
            want.sort();
            let mut got = s.pairs.clone();
            got.sort();
            assert_eq!(got, want, "{clip} vs {map}");
            let mapped: Vec<&str> = want.iter().map(|(_, r)| r.as_str()).collect();
            let roles = rig_roles();
            let unplaced: Vec<&str> = roles
                .iter()
                .map(String::as_str)
                .filter(|r| !mapped.contains(r))
                .collect::<Vec<_>>();
            assert_eq!(s.unplaced, unplaced, "{clip}");
            // The TOML parses back into the same map.
            let parsed = crate::io::joint_map::JointMap::parse(&s.to_toml(clip), "draft").unwrap();
            assert_eq!(parsed.pairs, {
                let mut p = s.pairs.clone();
                p.sort();
                p
            });
        }
    }

    #[test]
    fn a_clip_without_legs_is_one_error_line() {
        let names = ["Root", "Spine", "Head", "LeftArm", "LeftHand"];
        let parents = [None, Some(0), Some(1), Some(1), Some(3)];
        let e = suggest("arms.bvh", &names, &parents)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("arms.bvh: no recognisable legs"), "{e}");
        assert!(!e.contains('\n'));
    }

    #[test]
    fn sides_from_names() {
        for (n, s) in [
            ("LeftUpLeg", Some(Side::Left)),
            ("CC_Base_R_Thigh", Some(Side::Right)),
            ("thigh_l", Some(Side::Left)),
            ("Hand.R", Some(Side::Right)),
            ("LHipJoint", Some(Side::Left)),
            ("RThumb", Some(Side::Right)),
            ("mixamorig:LeftHand", Some(Side::Left)),
            ("LowerBack", None),
            ("CC_Base_Hip", None),
        ] {
            assert_eq!(side_of(n), s, "{n}");
        }
    }
}
