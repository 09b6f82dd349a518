//! BVH (Biovision hierarchy) motion-capture reader.
//!
//! Parses the HIERARCHY (joint tree, offsets, channel lists) and the MOTION block (one row of raw
//! channel values per frame) and evaluates poses: local joint transforms from the channels, in the
//! order the file lists them, and forward kinematics for world transforms.
//!
//! Units are left as in the file (CMU BVH: about 0.0548 m per unit) and axes as in the file (Y-up for
//! CMU); converting to metres is the caller's job. Every error is one line naming the file and, where
//! there is one, the line. No input makes the parser panic; the parser is iterative, so deeply nested
//! joints cannot overflow the stack.

use std::path::Path;

use crate::rig::capture::{CaptureClip, RootOffset};
use nalgebra::{UnitQuaternion, Vector3};
use thiserror::Error;

/// One animated degree of freedom of a joint, as named after `CHANNELS` in the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Channel {
    Xposition,
    Yposition,
    Zposition,
    Xrotation,
    Yrotation,
    Zrotation,
}

impl Channel {
    const ALL: [Channel; 6] = [
        Channel::Xposition,
        Channel::Yposition,
        Channel::Zposition,
        Channel::Xrotation,
        Channel::Yrotation,
        Channel::Zrotation,
    ];

    /// The name as written in BVH files.
    pub fn name(self) -> &'static str {
        match self {
            Channel::Xposition => "Xposition",
            Channel::Yposition => "Yposition",
            Channel::Zposition => "Zposition",
            Channel::Xrotation => "Xrotation",
            Channel::Yrotation => "Yrotation",
            Channel::Zrotation => "Zrotation",
        }
    }

    /// Case-insensitive: some exporters write `xrotation`.
    pub fn from_name(name: &str) -> Option<Channel> {
        Channel::ALL
            .into_iter()
            .find(|c| c.name().eq_ignore_ascii_case(name))
    }

    /// 0, 1 or 2 for X, Y, Z.
    pub fn axis(self) -> usize {
        match self {
            Channel::Xposition | Channel::Xrotation => 0,
            Channel::Yposition | Channel::Yrotation => 1,
            Channel::Zposition | Channel::Zrotation => 2,
        }
    }

    pub fn is_rotation(self) -> bool {
        matches!(
            self,
            Channel::Xrotation | Channel::Yrotation | Channel::Zrotation
        )
    }
}

/// One joint of the hierarchy. `offset` is the rest translation from the parent, in file units.
#[derive(Debug, Clone, PartialEq)]
pub struct BvhJoint {
    pub name: String,
    pub parent: Option<usize>,
    pub offset: [f64; 3],
    pub channels: Vec<Channel>,
    /// Offset of the `End Site` block, if the joint has one (the tip of a leaf bone).
    pub end_site: Option<[f64; 3]>,
}

/// A parsed BVH file.
#[derive(Debug, Clone, PartialEq)]
pub struct Bvh {
    /// In file order, so every parent comes before its children.
    pub joints: Vec<BvhJoint>,
    /// Seconds per frame.
    pub frame_time: f64,
    /// Raw channel values per frame, in file order (joint by joint, channel by channel; degrees for
    /// rotations).
    pub frames: Vec<Vec<f64>>,
    /// The file name used in error messages (the path as given to [`Bvh::read`]).
    pub source_name: String,
}

/// Why a BVH file could not be read. Every message is one line starting with `file:line:`.
#[derive(Debug, Error)]
pub enum BvhError {
    #[error("{file}: cannot read: {err}")]
    Io { file: String, err: std::io::Error },
    #[error("{file}:{line}: missing {section} section ({detail})")]
    MissingSection {
        file: String,
        line: usize,
        section: &'static str,
        detail: String,
    },
    #[error("{file}:{line}: unknown channel '{name}' (expected Xposition, Yposition, Zposition, Xrotation, Yrotation or Zrotation)")]
    UnknownChannel {
        file: String,
        line: usize,
        name: String,
    },
    /// `frame` counts from 1, as a person reads the file.
    #[error("{file}:{line}: frame {frame} has {found} values, expected {expected}")]
    WrongValueCount {
        file: String,
        line: usize,
        frame: usize,
        found: usize,
        expected: usize,
    },
    #[error("{file}:{line}: truncated file: found {found} complete frames, but 'Frames:' declares {declared}")]
    Truncated {
        file: String,
        line: usize,
        found: usize,
        declared: usize,
    },
    #[error("{file}:{line}: '{token}' is not a number ({context})")]
    NotANumber {
        file: String,
        line: usize,
        token: String,
        context: String,
    },
    #[error("{file}:{line}: unbalanced braces: {detail}")]
    UnbalancedBraces {
        file: String,
        line: usize,
        detail: String,
    },
    #[error("{file}:{line}: frame time must be a positive number of seconds, found {value}")]
    BadFrameTime {
        file: String,
        line: usize,
        value: String,
    },
    #[error("{file}:{line}: {detail}")]
    Syntax {
        file: String,
        line: usize,
        detail: String,
    },
}

impl Bvh {
    /// Reads and parses a BVH file; errors name the path as given.
    pub fn read(path: &Path) -> Result<Bvh, BvhError> {
        let file = path.display().to_string();
        let bytes = std::fs::read(path).map_err(|err| BvhError::Io {
            file: file.clone(),
            err,
        })?;
        let text = String::from_utf8(bytes).map_err(|e| BvhError::Io {
            file: file.clone(),
            err: std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!(
                    "not a text file (invalid UTF-8 at byte {})",
                    e.utf8_error().valid_up_to()
                ),
            ),
        })?;
        Bvh::parse(&text, &file)
    }

    /// Parses BVH text; `source_name` is only used in error messages and kept in the result.
    pub fn parse(text: &str, source_name: &str) -> Result<Bvh, BvhError> {
        // Some Windows tools write a byte-order mark, which is not whitespace.
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let mut p = Parser {
            tokens: Tokens::new(text),
            file: source_name,
        };
        p.expect_section("HIERARCHY")?;
        let joints = p.hierarchy()?;
        let width = joints.iter().map(|j| j.channels.len()).sum();
        let (declared, frame_time) = p.motion_header()?;
        let frames = p.frames(declared, width)?;
        Ok(Bvh {
            joints,
            frame_time,
            frames,
            source_name: source_name.to_string(),
        })
    }

    pub fn frame_count(&self) -> usize {
        self.frames.len()
    }

    /// Frames per second, `1 / frame_time` unrounded (CMU's `.0083333` gives 120.0005).
    pub fn fps(&self) -> f64 {
        1.0 / self.frame_time
    }

    /// Time of the last frame, frame 0 being at t = 0: `(frame_count - 1) * frame_time`, the end
    /// of a keyframed animation track (0 for an empty or single-frame clip).
    pub fn duration(&self) -> f64 {
        self.frame_count().saturating_sub(1) as f64 * self.frame_time
    }

    /// Index of the joint with exactly this name.
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    /// Where `joint`'s values start in a frame row: the channel counts of the joints before it.
    pub fn channel_offset(&self, joint: usize) -> usize {
        self.joints[..joint.min(self.joints.len())]
            .iter()
            .map(|j| j.channels.len())
            .sum()
    }

    /// Local transform of `joint` at `frame`: translation (file units) and rotation relative to the
    /// parent. Channels apply in the order listed: `Zrotation Yrotation Xrotation` gives
    /// R = Rz·Ry·Rx (intrinsic, degrees). A position channel replaces the offset component it names;
    /// components without one keep the offset. A root whose channels are relative to its OFFSET
    /// ([`Bvh::root_offset`]) adds them to it.
    ///
    /// Panics if `frame` or `joint` is out of range, like slice indexing.
    pub fn local_pose(&self, frame: usize, joint: usize) -> (Vector3<f64>, UnitQuaternion<f64>) {
        let row = &self.frames[frame];
        let j = &self.joints[joint];
        let start = self.channel_offset(joint);
        let add = j.parent.is_none() && self.root_offset() == RootOffset::Added;
        local_from_channels(j, &row[start..start + j.channels.len()], add)
    }

    /// How the root's OFFSET relates to its position channels. Exporters disagree: iClone and
    /// Character Creator write channels relative to the OFFSET (the hip at OFFSET + channels),
    /// others write the position itself and repeat it as the OFFSET. Channels that stay near the
    /// OFFSET over the take hold the position; channels far from it are relative to it.
    pub fn root_offset(&self) -> RootOffset {
        let Some(root) = self.joints.first() else {
            return RootOffset::Zero;
        };
        let offset = Vector3::from(root.offset);
        if offset.norm() < 1e-9 {
            return RootOffset::Zero;
        }
        // Compare on the axes the channels set; the others keep the OFFSET either way.
        let (mut mean, mut on) = (Vector3::zeros(), Vector3::zeros());
        let mut any = false;
        for (i, ch) in root.channels.iter().enumerate() {
            if !ch.is_rotation() {
                any = true;
                let n = self.frames.len().max(1) as f64;
                mean[ch.axis()] = self.frames.iter().map(|f| f[i]).sum::<f64>() / n;
                on[ch.axis()] = offset[ch.axis()];
            }
        }
        if !any || (mean - on).norm() > 0.5 * on.norm() {
            RootOffset::Added
        } else {
            RootOffset::Replaced
        }
    }

    /// World positions of the joints in the rest pose (frame-independent): sums of offsets.
    pub fn world_rest_positions(&self) -> Vec<Vector3<f64>> {
        let mut out: Vec<Vector3<f64>> = Vec::with_capacity(self.joints.len());
        for j in &self.joints {
            let parent = j.parent.and_then(|p| out.get(p)).copied();
            out.push(parent.unwrap_or_else(Vector3::zeros) + Vector3::from(j.offset));
        }
        out
    }

    /// Forward kinematics: world position and world rotation of every joint at `frame`.
    ///
    /// Panics if `frame` is out of range.
    pub fn world_pose(&self, frame: usize) -> Vec<(Vector3<f64>, UnitQuaternion<f64>)> {
        self.world_pose_with(frame, self.root_offset() == RootOffset::Added)
    }

    fn world_pose_with(
        &self,
        frame: usize,
        add_root_offset: bool,
    ) -> Vec<(Vector3<f64>, UnitQuaternion<f64>)> {
        let row = &self.frames[frame];
        let mut out: Vec<(Vector3<f64>, UnitQuaternion<f64>)> =
            Vec::with_capacity(self.joints.len());
        let mut start = 0;
        for j in &self.joints {
            let end = start + j.channels.len();
            let (t, r) =
                local_from_channels(j, &row[start..end], add_root_offset && j.parent.is_none());
            start = end;
            // Parents precede children (parser guarantee); a hand-built Bvh that breaks this gets the
            // joint treated as a root rather than a panic.
            let world = match j.parent.and_then(|p| out.get(p)) {
                Some((pp, pr)) => (pp + pr * t, pr * r),
                None => (t, r),
            };
            out.push(world);
        }
        out
    }

    /// The clip in the format-neutral form retargeting takes.
    pub fn capture(&self) -> CaptureClip {
        let root_offset = self.root_offset();
        let add = root_offset == RootOffset::Added;
        CaptureClip {
            zero_pose: self.world_rest_positions(),
            zero_pose_rotation: UnitQuaternion::identity(),
            frames: (0..self.frame_count())
                .map(|f| self.world_pose_with(f, add))
                .collect(),
            frame_time: self.frame_time,
            root_offset,
        }
    }
}

/// Local (translation, rotation) of one joint from its slice of a frame row; `add_offset`: position
/// channels are relative to the OFFSET.
fn local_from_channels(
    joint: &BvhJoint,
    values: &[f64],
    add_offset: bool,
) -> (Vector3<f64>, UnitQuaternion<f64>) {
    let mut t = Vector3::from(joint.offset);
    let mut r = UnitQuaternion::identity();
    for (&ch, &v) in joint.channels.iter().zip(values) {
        if ch.is_rotation() {
            // Right-multiplying composes intrinsic rotations in channel order.
            r *= axis_rotation(ch.axis(), v.to_radians());
        } else if add_offset {
            t[ch.axis()] = joint.offset[ch.axis()] + v;
        } else {
            t[ch.axis()] = v;
        }
    }
    (t, r)
}

fn axis_rotation(axis: usize, radians: f64) -> UnitQuaternion<f64> {
    let a = match axis {
        0 => Vector3::x_axis(),
        1 => Vector3::y_axis(),
        _ => Vector3::z_axis(),
    };
    UnitQuaternion::from_axis_angle(&a, radians)
}

/// Whitespace-separated tokens with 1-based line numbers. The frame reader takes over the remaining
/// lines once the MOTION header is read, because frames are line-structured.
struct Tokens<'a> {
    lines: std::iter::Enumerate<std::str::Lines<'a>>,
    current: std::str::SplitWhitespace<'a>,
    line: usize,
}

impl<'a> Tokens<'a> {
    fn new(text: &'a str) -> Self {
        Tokens {
            lines: text.lines().enumerate(),
            current: "".split_whitespace(),
            line: 0,
        }
    }

    fn next(&mut self) -> Option<(usize, &'a str)> {
        loop {
            if let Some(t) = self.current.next() {
                return Some((self.line, t));
            }
            let (i, l) = self.lines.next()?;
            self.line = i + 1;
            self.current = l.split_whitespace();
        }
    }

    /// The tokens left on the line of the last token returned.
    fn rest_of_line(&mut self) -> Vec<&'a str> {
        self.current.by_ref().collect()
    }
}

/// Open `{` blocks of the hierarchy.
enum Open {
    Joint(usize),
    EndSite(usize),
}

struct Parser<'a> {
    tokens: Tokens<'a>,
    file: &'a str,
}

impl<'a> Parser<'a> {
    fn syntax(&self, line: usize, detail: impl Into<String>) -> BvhError {
        BvhError::Syntax {
            file: self.file.to_string(),
            line,
            detail: detail.into(),
        }
    }

    fn unbalanced(&self, line: usize, detail: impl Into<String>) -> BvhError {
        BvhError::UnbalancedBraces {
            file: self.file.to_string(),
            line,
            detail: detail.into(),
        }
    }

    fn not_a_number(&self, line: usize, token: &str, context: impl Into<String>) -> BvhError {
        BvhError::NotANumber {
            file: self.file.to_string(),
            line,
            token: shorten(token),
            context: context.into(),
        }
    }

    fn missing(&self, section: &'static str, found: Option<(usize, &str)>) -> BvhError {
        let (line, detail) = match found {
            Some((line, t)) => (line, format!("found '{}'", shorten(t))),
            None => (self.tokens.line, "file ends".to_string()),
        };
        BvhError::MissingSection {
            file: self.file.to_string(),
            line: line.max(1),
            section,
            detail,
        }
    }

    fn expect_section(&mut self, section: &'static str) -> Result<(), BvhError> {
        match self.tokens.next() {
            Some((_, t)) if t == section => Ok(()),
            other => Err(self.missing(section, other)),
        }
    }

    /// Next token, which must exist; `what` says what the file ended inside of.
    fn need(&mut self, what: &str) -> Result<(usize, &'a str), BvhError> {
        self.tokens
            .next()
            .ok_or_else(|| self.syntax(self.tokens.line.max(1), format!("file ends inside {what}")))
    }

    fn number(&mut self, context: &str) -> Result<f64, BvhError> {
        let (line, t) = self.need(context)?;
        parse_f64(t).ok_or_else(|| self.not_a_number(line, t, context))
    }

    fn vec3(&mut self, context: &str) -> Result<[f64; 3], BvhError> {
        Ok([
            self.number(context)?,
            self.number(context)?,
            self.number(context)?,
        ])
    }

    /// Reads joints up to and including the `MOTION` keyword.
    fn hierarchy(&mut self) -> Result<Vec<BvhJoint>, BvhError> {
        let mut joints: Vec<BvhJoint> = Vec::new();
        let mut stack: Vec<Open> = Vec::new();
        loop {
            let Some((line, tok)) = self.tokens.next() else {
                return Err(self.hierarchy_eof(&joints, &stack));
            };
            match tok {
                "ROOT" | "JOINT" => {
                    let parent = self.parent_for(tok, line, &joints, &stack)?;
                    let name = self.joint_name(tok, line)?;
                    joints.push(BvhJoint {
                        name,
                        parent,
                        offset: [0.0; 3],
                        channels: Vec::new(),
                        end_site: None,
                    });
                    stack.push(Open::Joint(joints.len() - 1));
                }
                "End" => {
                    let j = self.end_site_owner(line, &joints, &stack)?;
                    stack.push(Open::EndSite(j));
                }
                "OFFSET" => self.offset(line, &mut joints, &stack)?,
                "CHANNELS" => self.channels(line, &mut joints, &stack)?,
                "}" => {
                    if stack.pop().is_none() {
                        return Err(self.unbalanced(line, "'}' without a matching '{'"));
                    }
                }
                "MOTION" => return self.end_hierarchy(line, joints, &stack),
                "{" => return Err(self.unbalanced(line, "'{' not after ROOT, JOINT or End Site")),
                other => {
                    return Err(self.syntax(
                        line,
                        format!(
                            "unexpected '{}' in HIERARCHY (expected ROOT, JOINT, End Site, OFFSET, CHANNELS, '}}' or MOTION)",
                            shorten(other)
                        ),
                    ))
                }
            }
        }
    }

    fn hierarchy_eof(&self, joints: &[BvhJoint], stack: &[Open]) -> BvhError {
        match stack.last() {
            Some(open) => self.unbalanced(
                self.tokens.line.max(1),
                format!(
                    "file ends with {} block(s) still open (innermost: {})",
                    stack.len(),
                    describe(open, joints)
                ),
            ),
            None => self.missing("MOTION", None),
        }
    }

    fn end_hierarchy(
        &self,
        line: usize,
        joints: Vec<BvhJoint>,
        stack: &[Open],
    ) -> Result<Vec<BvhJoint>, BvhError> {
        if let Some(open) = stack.last() {
            return Err(self.unbalanced(
                line,
                format!(
                    "MOTION reached with {} block(s) still open (innermost: {})",
                    stack.len(),
                    describe(open, &joints)
                ),
            ));
        }
        if joints.is_empty() {
            return Err(self.syntax(line, "HIERARCHY has no ROOT joint"));
        }
        Ok(joints)
    }

    /// ROOT only at top level (several roots are allowed); JOINT only inside a joint.
    fn parent_for(
        &self,
        keyword: &str,
        line: usize,
        joints: &[BvhJoint],
        stack: &[Open],
    ) -> Result<Option<usize>, BvhError> {
        match (keyword, stack.last()) {
            ("ROOT", None) => Ok(None),
            ("JOINT", Some(Open::Joint(p))) => Ok(Some(*p)),
            ("JOINT", None) => Err(self.syntax(line, "JOINT outside any ROOT")),
            (_, Some(open)) => {
                Err(self.syntax(line, format!("{keyword} inside {}", describe(open, joints))))
            }
            _ => Err(self.syntax(line, format!("unexpected {keyword}"))),
        }
    }

    /// The rest of the line is the name (names with spaces exist); an optional trailing `{` opens
    /// the block, otherwise the next token must.
    fn joint_name(&mut self, keyword: &str, line: usize) -> Result<String, BvhError> {
        let mut words = self.tokens.rest_of_line();
        let brace_on_line = words.last() == Some(&"{");
        if brace_on_line {
            words.pop();
        }
        if words.is_empty() {
            return Err(self.syntax(line, format!("{keyword} without a name")));
        }
        let name = words.join(" ");
        if !brace_on_line {
            self.open_brace(&format!("{keyword} {name}"))?;
        }
        Ok(name)
    }

    fn open_brace(&mut self, after: &str) -> Result<(), BvhError> {
        let (line, t) = self.need(after)?;
        if t == "{" {
            Ok(())
        } else {
            Err(self.unbalanced(
                line,
                format!("expected '{{' after {after}, found '{}'", shorten(t)),
            ))
        }
    }

    fn end_site_owner(
        &mut self,
        line: usize,
        joints: &[BvhJoint],
        stack: &[Open],
    ) -> Result<usize, BvhError> {
        let (l, t) = self.need("End Site")?;
        if t != "Site" {
            return Err(self.syntax(
                l,
                format!("expected 'End Site', found 'End {}'", shorten(t)),
            ));
        }
        let j = match stack.last() {
            Some(Open::Joint(j)) => *j,
            Some(open) => {
                return Err(self.syntax(line, format!("End Site inside {}", describe(open, joints))))
            }
            None => return Err(self.syntax(line, "End Site outside any joint")),
        };
        self.open_brace("End Site")?;
        Ok(j)
    }

    fn offset(
        &mut self,
        line: usize,
        joints: &mut [BvhJoint],
        stack: &[Open],
    ) -> Result<(), BvhError> {
        match stack.last() {
            Some(Open::Joint(j)) => {
                let ctx = format!("OFFSET of joint '{}'", joints[*j].name);
                joints[*j].offset = self.vec3(&ctx)?;
            }
            Some(Open::EndSite(j)) => {
                let ctx = format!("End Site OFFSET of joint '{}'", joints[*j].name);
                joints[*j].end_site = Some(self.vec3(&ctx)?);
            }
            None => return Err(self.syntax(line, "OFFSET outside any joint")),
        }
        Ok(())
    }

    fn channels(
        &mut self,
        line: usize,
        joints: &mut [BvhJoint],
        stack: &[Open],
    ) -> Result<(), BvhError> {
        let j = match stack.last() {
            Some(Open::Joint(j)) => *j,
            Some(open) => {
                return Err(self.syntax(line, format!("CHANNELS inside {}", describe(open, joints))))
            }
            None => return Err(self.syntax(line, "CHANNELS outside any joint")),
        };
        if !joints[j].channels.is_empty() {
            return Err(self.syntax(
                line,
                format!("joint '{}' has a second CHANNELS line", joints[j].name),
            ));
        }
        let ctx = format!("CHANNELS of joint '{}'", joints[j].name);
        let (l, t) = self.need(&ctx)?;
        let count: usize = t.parse().map_err(|_| {
            self.not_a_number(l, t, format!("channel count of joint '{}'", joints[j].name))
        })?;
        // Pushing one by one: a bogus huge count fails at the first non-channel token, no big
        // allocation up front.
        for _ in 0..count {
            let (l, t) = self.need(&ctx)?;
            let ch = Channel::from_name(t).ok_or_else(|| BvhError::UnknownChannel {
                file: self.file.to_string(),
                line: l,
                name: shorten(t),
            })?;
            joints[j].channels.push(ch);
        }
        Ok(())
    }

    /// `Frames: N` and `Frame Time: T`; returns (declared frame count, frame time).
    fn motion_header(&mut self) -> Result<(usize, f64), BvhError> {
        let (l, t) = self.need("MOTION header")?;
        if t != "Frames:" {
            return Err(self.syntax(
                l,
                format!("expected 'Frames:' after MOTION, found '{}'", shorten(t)),
            ));
        }
        let (l, t) = self.need("MOTION header")?;
        let declared: usize = t
            .parse()
            .map_err(|_| self.not_a_number(l, t, "frame count after 'Frames:'"))?;
        let (l, t1) = self.need("MOTION header")?;
        let (_, t2) = self.need("MOTION header")?;
        if t1 != "Frame" || t2 != "Time:" {
            return Err(self.syntax(
                l,
                format!(
                    "expected 'Frame Time:', found '{} {}'",
                    shorten(t1),
                    shorten(t2)
                ),
            ));
        }
        let (l, t) = self.need("MOTION header")?;
        let frame_time = match parse_f64(t) {
            Some(v) if v > 0.0 => v,
            _ => {
                return Err(BvhError::BadFrameTime {
                    file: self.file.to_string(),
                    line: l,
                    value: shorten(t),
                })
            }
        };
        if let Some(extra) = self.tokens.rest_of_line().first() {
            return Err(self.syntax(
                l,
                format!("unexpected '{}' after the frame time", shorten(extra)),
            ));
        }
        Ok((declared, frame_time))
    }

    /// One frame per non-blank line, each with exactly `width` values.
    fn frames(&mut self, declared: usize, width: usize) -> Result<Vec<Vec<f64>>, BvhError> {
        // Capped: the declared count is untrusted.
        let mut frames = Vec::with_capacity(declared.min(1 << 16));
        let mut last_line = self.tokens.line;
        // Take the remaining lines out of the tokenizer so `self` stays free for error helpers.
        let rest = std::mem::replace(&mut self.tokens.lines, "".lines().enumerate());
        let mut lines = rest.filter(|(_, l)| !l.trim().is_empty()).peekable();
        while let Some((i, text)) = lines.next() {
            let line = i + 1;
            last_line = line;
            let frame = frames.len() + 1;
            if frames.len() == declared {
                return Err(self.syntax(
                    line,
                    format!("more frame lines than the {declared} declared by 'Frames:'"),
                ));
            }
            let found = text.split_whitespace().count();
            if found != width {
                // A short last line of a file with missing frames is a cut-off file, not a bad frame.
                if found < width && lines.peek().is_none() {
                    break;
                }
                return Err(BvhError::WrongValueCount {
                    file: self.file.to_string(),
                    line,
                    frame,
                    found,
                    expected: width,
                });
            }
            frames.push(self.frame_row(line, frame, text)?);
        }
        if frames.len() < declared {
            return Err(BvhError::Truncated {
                file: self.file.to_string(),
                line: last_line.max(1),
                found: frames.len(),
                declared,
            });
        }
        Ok(frames)
    }

    fn frame_row(&self, line: usize, frame: usize, text: &str) -> Result<Vec<f64>, BvhError> {
        text.split_whitespace()
            .enumerate()
            .map(|(k, t)| {
                parse_f64(t).ok_or_else(|| {
                    self.not_a_number(line, t, format!("frame {frame}, value {}", k + 1))
                })
            })
            .collect()
    }
}

/// Finite numbers only: NaN or infinite channel values would poison every pose downstream.
fn parse_f64(t: &str) -> Option<f64> {
    t.parse::<f64>().ok().filter(|v| v.is_finite())
}

fn describe(open: &Open, joints: &[BvhJoint]) -> String {
    let name = |j: &usize| joints.get(*j).map_or("?", |j| j.name.as_str());
    match open {
        Open::Joint(j) => format!("joint '{}'", name(j)),
        Open::EndSite(j) => format!("the End Site of joint '{}'", name(j)),
    }
}

/// Keeps error messages one short line whatever garbage the file holds.
fn shorten(token: &str) -> String {
    const MAX: usize = 40;
    let mut s: String = token
        .chars()
        .take(MAX)
        .flat_map(char::escape_debug)
        .collect();
    if token.chars().nth(MAX).is_some() {
        s.push('…');
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    /// shared/ lies beside the repository (locally and in CI).
    fn mocap(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../shared/data/mocap")
            .join(name)
    }

    fn load(name: &str) -> Bvh {
        Bvh::read(&mocap(name)).unwrap_or_else(|e| panic!("{e}"))
    }

    fn text(name: &str) -> String {
        std::fs::read_to_string(mocap(name)).unwrap()
    }

    fn err(text: &str) -> String {
        let e = Bvh::parse(text, "t.bvh").expect_err("should fail");
        let msg = e.to_string();
        assert!(!msg.contains('\n'), "multi-line message: {msg}");
        msg
    }

    /// q and -q are the same rotation.
    fn same_rotation(a: UnitQuaternion<f64>, b: UnitQuaternion<f64>) -> bool {
        let d = (a.coords - b.coords)
            .norm()
            .min((a.coords + b.coords).norm());
        d < 1e-9
    }

    fn deg(v: f64) -> f64 {
        v.to_radians()
    }

    fn q_axis(axis: Vector3<f64>, degrees: f64) -> UnitQuaternion<f64> {
        UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(axis), deg(degrees))
    }

    /// One root with the given channels and one frame of values.
    fn one_joint(channels: &str, values: &str) -> Bvh {
        let n = channels.split_whitespace().count();
        let src = format!(
            "HIERARCHY\nROOT R\n{{\n OFFSET 1 2 3\n CHANNELS {n} {channels}\n End Site\n {{\n  OFFSET 0 1 0\n }}\n}}\nMOTION\nFrames: 1\nFrame Time: 0.5\n{values}\n"
        );
        Bvh::parse(&src, "hand.bvh").unwrap_or_else(|e| panic!("{e}"))
    }

    #[test]
    fn real_files_counts_and_rate() {
        for (name, frames) in [
            ("01_01.bvh", 2752),
            ("131_01.bvh", 994),
            ("131_02.bvh", 1247),
        ] {
            let b = load(name);
            assert_eq!(b.joints.len(), 31, "{name}");
            assert_eq!(b.frame_count(), frames, "{name}");
            assert!((b.fps() - 120.0).abs() < 0.01, "{name}: {}", b.fps());
            assert!((b.duration() - (frames - 1) as f64 * 0.0083333).abs() < 1e-9);
            assert!(b.frames.iter().all(|f| f.len() == 96), "{name}");
            assert_eq!(b.joints[0].channels.len(), 6);
            assert_eq!(b.channel_offset(1), 6);
            assert_eq!(b.channel_offset(31), 96);
            assert_eq!(b.joint_index("Hips"), Some(0));
            assert_eq!(
                b.joint_index("LThumb").map(|i| b.joints[i].parent),
                Some(b.joint_index(if name == "01_01.bvh" {
                    "LeftHand"
                } else {
                    "LeftWrist"
                }))
            );
            assert!(b
                .joints
                .iter()
                .enumerate()
                .all(|(i, j)| j.parent.is_none_or(|p| p < i)));
        }
    }

    #[test]
    fn mixed_channel_orders_and_line_endings_of_131() {
        // 131_* arm joints were edited by hand: LF-only lines, no indentation, ZXY order.
        let b = load("131_01.bvh");
        let arm = &b.joints[b.joint_index("LeftShoulder").unwrap()];
        use Channel::*;
        assert_eq!(arm.channels, vec![Zrotation, Xrotation, Yrotation]);
        assert_eq!(arm.offset, [3.05381, 1.47088, -0.01697]);
        let collar = &b.joints[b.joint_index("LeftCollar").unwrap()];
        assert_eq!(collar.channels, vec![Zrotation, Yrotation, Xrotation]);
        let tip = b.joints[b.joint_index("LFingers").unwrap()].end_site;
        assert_eq!(tip, Some([0.0, -0.53034, 0.0]));
    }

    #[test]
    fn root_world_position_is_its_position_channels() {
        for name in ["01_01.bvh", "131_01.bvh", "131_02.bvh"] {
            let b = load(name);
            let (p, _) = b.world_pose(0)[0];
            let f = &b.frames[0];
            assert_eq!(p, Vector3::new(f[0], f[1], f[2]), "{name}");
        }
    }

    #[test]
    fn forward_kinematics_composes_parent_rotation_and_offset() {
        let b = load("131_01.bvh");
        for frame in [0, 500, 993] {
            let world = b.world_pose(frame);
            for (i, j) in b.joints.iter().enumerate().skip(1) {
                let p = j.parent.unwrap();
                let (pp, pr) = world[p];
                let expect_pos = pp + pr * Vector3::from(j.offset);
                assert!(
                    (world[i].0 - expect_pos).norm() < 1e-9,
                    "{} at {frame}",
                    j.name
                );
                let (_, lr) = b.local_pose(frame, i);
                assert!(same_rotation(world[i].1, pr * lr));
            }
        }
    }

    #[test]
    fn rest_positions_sum_offsets() {
        let b = load("01_01.bvh");
        let rest = b.world_rest_positions();
        let i = b.joint_index("LeftForeArm").unwrap();
        // The rest (T-pose) position is the sum of the offsets up the chain to the root.
        let mut expect = Vector3::zeros();
        let mut k = Some(i);
        while let Some(j) = k {
            expect += Vector3::from(b.joints[j].offset);
            k = b.joints[j].parent;
        }
        assert!((rest[i] - expect).norm() < 1e-12);
    }

    #[test]
    fn xyz_order_90_degrees_matches_hand_computed_quaternion() {
        // R = Rx(90)·Ry(90)·Rz(90). By hand, q = (w, x, y, z), s = √½:
        //   qx·qy = (s,s,0,0)(s,0,s,0) = (½, ½, ½, ½)
        //   (½,½,½,½)·(s,0,0,s) = (0, s, 0, s): 180° about (X+Z)/√2.
        // Check of its action, applying Rz first: X→Y→Y→Z, Y→-X→Z→-Y.
        // (The reverse, extrinsic reading Rz·Ry·Rx, would give (s, 0, s, 0) instead.)
        use Channel::*;
        let b = one_joint("Xrotation Yrotation Zrotation", "90 90 90");
        assert_eq!(b.joints[0].channels, vec![Xrotation, Yrotation, Zrotation]);
        let (t, r) = b.local_pose(0, 0);
        assert_eq!(t, Vector3::new(1.0, 2.0, 3.0));
        let s = 0.5f64.sqrt();
        let expect = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(0.0, s, 0.0, s));
        assert!(same_rotation(r, expect), "{r:?}");
        assert!((r * Vector3::x() - Vector3::z()).norm() < 1e-12);
        assert!((r * Vector3::y() + Vector3::y()).norm() < 1e-12);
    }

    #[test]
    fn channel_order_is_respected_and_independent_of_layout() {
        // The same rotation Rz(30)·Rx(-50)·Ry(70), written with the channels in ZXY order and as a
        // 6-channel root with positions interleaved: same rotation either way. Positions far from
        // the root's OFFSET (1, 2, 3) are relative to it.
        let a = one_joint("Zrotation Xrotation Yrotation", "30 -50 70");
        let b = one_joint(
            "Zrotation Xposition Xrotation Yposition Yrotation Zposition",
            "30 7 -50 8 70 9",
        );
        let expect =
            q_axis(Vector3::z(), 30.0) * q_axis(Vector3::x(), -50.0) * q_axis(Vector3::y(), 70.0);
        let (ta, ra) = a.local_pose(0, 0);
        let (tb, rb) = b.local_pose(0, 0);
        assert!(same_rotation(ra, expect));
        assert!(same_rotation(rb, expect));
        assert_eq!(ta, Vector3::new(1.0, 2.0, 3.0));
        assert_eq!(b.root_offset(), RootOffset::Added);
        assert_eq!(tb, Vector3::new(8.0, 10.0, 12.0));
        // Positions near the OFFSET hold the position itself (exporters that repeat it).
        let c = one_joint("Xposition Yposition Zposition", "1.1 2.2 2.9");
        assert_eq!(c.root_offset(), RootOffset::Replaced);
        assert_eq!(c.local_pose(0, 0).0, Vector3::new(1.1, 2.2, 2.9));
    }

    #[test]
    fn same_pose_with_two_channel_orders() {
        // Express one rotation R as ZYX Euler angles and as XYZ Euler angles; both files must give R.
        let r = q_axis(Vector3::new(0.3, -1.0, 0.5), 63.0);
        let (x, y, z) = r.euler_angles(); // nalgebra: R = Rz(z)·Ry(y)·Rx(x)
        let zyx = one_joint(
            "Zrotation Yrotation Xrotation",
            &format!("{} {} {}", z.to_degrees(), y.to_degrees(), x.to_degrees()),
        );
        // XYZ order: R = Rx(a)·Ry(b)·Rz(c) ⇔ Rᵀ = Rz(-c)·Ry(-b)·Rx(-a).
        let (ia, ib, ic) = r.inverse().euler_angles();
        let xyz = one_joint(
            "Xrotation Yrotation Zrotation",
            &format!(
                "{} {} {}",
                -ia.to_degrees(),
                -ib.to_degrees(),
                -ic.to_degrees()
            ),
        );
        assert!(same_rotation(zyx.local_pose(0, 0).1, r));
        assert!(same_rotation(xyz.local_pose(0, 0).1, r));
    }

    #[test]
    fn subset_of_channels() {
        // Only Yposition and Yrotation: X and Z keep the offset; Y (5, far from the OFFSET's 2)
        // is relative to it.
        let b = one_joint("Yposition Yrotation", "5 90");
        let (t, r) = b.local_pose(0, 0);
        assert_eq!(t, Vector3::new(1.0, 7.0, 3.0));
        assert!(same_rotation(r, q_axis(Vector3::y(), 90.0)));
    }

    #[test]
    fn truncated_mid_motion_says_how_many_frames() {
        let full = text("01_01.bvh");
        let lines: Vec<&str> = full.lines().collect();
        // Header is 187 lines; keep 1000 whole frames.
        let cut = lines[..187 + 1000].join("\n");
        let msg = err(&cut);
        assert!(
            msg.contains("found 1000 complete frames") && msg.contains("2752"),
            "{msg}"
        );
        // Cut in the middle of frame 1001's line: still a truncation, not a bad frame.
        let mid = format!("{cut}\n{}", &lines[187 + 1000][..100]);
        let msg = err(&mid);
        assert!(
            msg.contains("truncated") && msg.contains("found 1000 complete frames"),
            "{msg}"
        );
    }

    #[test]
    fn truncated_prefixes_never_panic() {
        let full = text("131_01.bvh");
        let bytes = full.as_bytes();
        // Densely through the hierarchy, MOTION header and first frames; sparsely after.
        let mut cuts: Vec<usize> = (0..8000).step_by(5).collect();
        cuts.extend((0..bytes.len()).step_by(bytes.len() / 40));
        for cut in cuts {
            if !full.is_char_boundary(cut) {
                continue;
            }
            let prefix = &full[..cut];
            // catch_unwind only to report which cut panicked.
            match std::panic::catch_unwind(|| Bvh::parse(prefix, "cut.bvh")) {
                Ok(Ok(_)) => {}
                Ok(Err(e)) => assert!(!e.to_string().contains('\n'), "cut {cut}: {e}"),
                Err(_) => panic!("parser panicked on a prefix of {cut} bytes"),
            }
        }
    }

    #[test]
    fn error_messages() {
        let good = "HIERARCHY\nROOT A\n{\n OFFSET 0 0 0\n CHANNELS 3 Xposition Yposition Zposition\n}\nMOTION\nFrames: 2\nFrame Time: 0.1\n1 2 3\n4 5 6\n";
        assert_eq!(Bvh::parse(good, "t.bvh").unwrap().frame_count(), 2);

        let m = err(&good.replace("Zposition", "Wrotation"));
        assert!(m.starts_with("t.bvh:5: unknown channel 'Wrotation'"), "{m}");
        let m = err(&good.replace("4 5 6", "4 5 6 7"));
        assert_eq!(m, "t.bvh:11: frame 2 has 4 values, expected 3");
        let m = err(&good.replace("1 2 3", "1 2"));
        assert_eq!(m, "t.bvh:10: frame 1 has 2 values, expected 3");
        let m = err(&good.replace("4 5 6", "4 x5 6"));
        assert_eq!(m, "t.bvh:11: 'x5' is not a number (frame 2, value 2)");
        let m = err(&good.replace("4 5 6", "4 nan 6"));
        assert!(m.contains("'nan' is not a number"), "{m}");
        let m = err(&good.replace("OFFSET 0 0 0", "OFFSET 0 zero 0"));
        assert!(
            m.starts_with("t.bvh:4: 'zero' is not a number (OFFSET of joint 'A')"),
            "{m}"
        );
        let m = err(&good.replace("0.1", "0"));
        assert!(
            m.starts_with("t.bvh:9: frame time must be a positive"),
            "{m}"
        );
        let m = err(&good.replace("0.1", "-0.1"));
        assert!(m.contains("frame time"), "{m}");
        let m = err(&good.replace("HIERARCHY", "HIERARCHIE"));
        assert_eq!(m, "t.bvh:1: missing HIERARCHY section (found 'HIERARCHIE')");
        let m = err(good.split("MOTION").next().unwrap());
        assert!(
            m.starts_with("t.bvh:6: missing MOTION section (file ends)"),
            "{m}"
        );
        let m = err(&good.replace("}\nMOTION", "MOTION"));
        assert!(m.starts_with("t.bvh:6: unbalanced braces: MOTION reached with 1 block(s) still open (innermost: joint 'A')"), "{m}");
        let m = err(&good.replace("}\nMOTION", "}\n}\nMOTION"));
        assert!(m.starts_with("t.bvh:7: unbalanced braces"), "{m}");
        let m = err(&good.replace("Frames: 2", "Frames: 3"));
        assert!(
            m.contains("found 2 complete frames, but 'Frames:' declares 3"),
            "{m}"
        );
        let m = err(&good.replace("Frames: 2", "Frames: 1"));
        assert!(
            m.starts_with("t.bvh:11: more frame lines than the 1 declared"),
            "{m}"
        );
        let bom = format!("\u{feff}{good}");
        assert_eq!(Bvh::parse(&bom, "t.bvh").unwrap().frame_count(), 2);
        let m = err("");
        assert!(
            m.starts_with("t.bvh:1: missing HIERARCHY section (file ends)"),
            "{m}"
        );
        let m = err(&good.replace("ROOT A", "ROOT A\n{\n{"));
        assert!(m.contains("unbalanced braces"), "{m}");
        let long = "y".repeat(5000);
        let m = err(&good.replace("4 5 6", &format!("4 {long} 6")));
        assert!(m.len() < 200, "{m}");
    }

    #[test]
    fn unreadable_file() {
        let e = Bvh::read(Path::new("/nonexistent/x.bvh")).unwrap_err();
        let m = e.to_string();
        assert!(m.starts_with("/nonexistent/x.bvh: cannot read:"), "{m}");
        assert!(!m.contains('\n'));
    }

    #[test]
    fn braces_on_the_name_line_and_deep_nesting() {
        let src = "HIERARCHY\nROOT A {\n OFFSET 0 0 0\n CHANNELS 1 Xrotation\n JOINT Left Arm {\n  OFFSET 1 0 0\n  CHANNELS 1 Zrotation\n }\n}\nMOTION\nFrames: 1\nFrame Time: 1\n0 90\n";
        let b = Bvh::parse(src, "t.bvh").unwrap();
        assert_eq!(b.joints[1].name, "Left Arm");
        let w = b.world_pose(0);
        assert!((w[1].0 - Vector3::new(1.0, 0.0, 0.0)).norm() < 1e-12);
        // 100k nested joints: iterative parser, no stack overflow.
        let deep = "JOINT j\n{\n".repeat(100_000);
        let src = format!("HIERARCHY\nROOT r\n{{\n{deep}");
        assert!(err(&src).contains("unbalanced braces"));
    }
}
