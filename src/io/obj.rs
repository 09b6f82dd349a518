//! Wavefront OBJ reader and writer for garment and body meshes.
//!
//! Reading keeps what the pipeline needs: positions (`v`), texture coordinates (`vt`) and faces
//! (`f`) in any of the `v`, `v/vt`, `v//vn`, `v/vt/vn` forms, with absolute or negative
//! (relative) indices. Polygons are fan-triangulated from their first corner (`n` corners give
//! triangles `(0, i, i+1)`), which is exact for the planar convex quads of garment and body
//! meshes. `g` and `o` name the group of the faces that follow. Normals (`vn`, and a corner's
//! normal index, which only has to be an integer), smoothing (`s`), materials (`usemtl`,
//! `mtllib`), lines, points and unknown statements are ignored; line continuation with `\` is
//! not supported. No unit or axis conversion happens here.
//!
//! UVs are all-or-nothing: a file whose faces all carry `vt` indices gives face-varying UVs, one
//! with none gives `uv: None`, and a file that mixes the two is rejected, since the dynamic model
//! works in the garment's UV space and silently dropping UVs would only fail later, far from the
//! cause.

use std::fmt;
use std::fs;
use std::io::{self, Write};
use std::ops::Range;
use std::path::Path;

use thiserror::Error;

use crate::geometry::mesh::{FaceVaryingUv, MeshError, TriMesh};

/// A parsed OBJ file.
#[derive(Clone, Debug, PartialEq)]
pub struct ObjMesh {
    pub mesh: TriMesh,
    /// Triangle ranges per group name, in file order. One entry per contiguous run, so a name that
    /// appears in several places has several entries. Faces before any `g`/`o` are in
    /// `"default"`; when `o` and `g` are both used, the latest statement names the group.
    pub groups: Vec<(String, Range<usize>)>,
}

/// Why an OBJ file could not be read; each message is one line naming the file.
#[derive(Debug, Error)]
pub enum ObjError {
    #[error("cannot read {file}: {}", exporters::atomic::io_message(.cause))]
    Read { file: String, cause: io::Error },
    #[error("{file}:{line}: {problem}")]
    Syntax {
        file: String,
        line: usize,
        problem: ObjProblem,
    },
    #[error("{file}: the file has no faces (no `f` lines)")]
    NoFaces { file: String },
    #[error("{file}: {problem}")]
    InvalidMesh { file: String, problem: MeshError },
}

/// What is wrong on one line of an OBJ file.
#[derive(Clone, Debug, PartialEq, Error)]
pub enum ObjProblem {
    #[error("bad number '{text}' in {statement}")]
    BadNumber {
        text: String,
        statement: &'static str,
    },
    #[error("{statement} needs at least {needed} numbers, found {found}")]
    TooFewNumbers {
        statement: &'static str,
        needed: usize,
        found: usize,
    },
    #[error("bad face corner '{0}' (expected v, v/vt, v//vn or v/vt/vn)")]
    BadCorner(String),
    #[error("{} 0 is invalid (OBJ indices start at 1)", .0.index_name())]
    ZeroIndex(Element),
    #[error("{} {index} out of range (file has {count} {})", .element.index_name(), .element.plural())]
    OutOfRange {
        element: Element,
        index: i64,
        count: usize,
    },
    #[error("relative {} {index} points before the first {} ({defined} defined so far)",
        .element.index_name(), .element.singular())]
    RelativeOutOfRange {
        element: Element,
        index: i64,
        defined: usize,
    },
    #[error("face has {0} vertices; a face needs at least 3")]
    TooFewCorners(usize),
    #[error("face repeats vertex {0} (degenerate face)")]
    RepeatedVertex(i64),
    #[error("face mixes corners with and without texture coordinates")]
    MixedCornerUv,
    #[error("face {} texture coordinates but the face on line {first_line} {} (UVs must be on all faces or none)",
        if *.has_uv { "has" } else { "has no" }, if *.has_uv { "has none" } else { "has them" })]
    InconsistentUv { has_uv: bool, first_line: usize },
}

/// The kinds of indexed OBJ elements a face refers to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Element {
    Vertex,
    TexCoord,
}

impl Element {
    fn index_name(self) -> &'static str {
        match self {
            Element::Vertex => "face index",
            Element::TexCoord => "texture coordinate index",
        }
    }
    fn singular(self) -> &'static str {
        match self {
            Element::Vertex => "vertex",
            Element::TexCoord => "texture coordinate",
        }
    }
    fn plural(self) -> &'static str {
        match self {
            Element::Vertex => "vertices",
            Element::TexCoord => "texture coordinates",
        }
    }
}

impl fmt::Display for Element {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.singular())
    }
}

/// Reads and parses an OBJ file. Errors name the file as given in `path`.
pub fn read_obj(path: &Path) -> Result<ObjMesh, ObjError> {
    let name = path.display().to_string();
    let bytes = fs::read(path).map_err(|cause| ObjError::Read {
        file: name.clone(),
        cause,
    })?;
    // Lossy: non-UTF-8 bytes only ever appear in comments and names, never in the numbers.
    parse_obj(&String::from_utf8_lossy(&bytes), &name)
}

/// Parses OBJ text; `source_name` is the file name used in error messages.
pub fn parse_obj(text: &str, source_name: &str) -> Result<ObjMesh, ObjError> {
    let totals = count_elements(text);
    let mut parser = Parser::new(totals);
    for (i, line) in text.lines().enumerate() {
        parser
            .statement(i + 1, line)
            .map_err(|problem| ObjError::Syntax {
                file: source_name.to_string(),
                line: i + 1,
                problem,
            })?;
    }
    parser.finish(source_name)
}

/// Writes `mesh` as OBJ (`v`, `vt`, `f v/vt`), each `comment` line as a `#` line first.
/// Numbers use Rust's shortest round-trip formatting, so reading the file back gives the same
/// `f32` values. Written atomically ([`exporters::atomic`]): `path` is never half-written, and
/// an error keeps its `io::ErrorKind` and names the file: `cannot write PATH: …`.
pub fn write_obj(path: &Path, mesh: &TriMesh, comment: &str) -> io::Result<()> {
    exporters::atomic::write_atomic_with(path, |w| write_lines(w, mesh, comment))
}

fn write_lines(w: &mut impl Write, mesh: &TriMesh, comment: &str) -> io::Result<()> {
    for line in comment.lines() {
        writeln!(w, "# {line}")?;
    }
    for [x, y, z] in &mesh.positions {
        writeln!(w, "v {x} {y} {z}")?;
    }
    match &mesh.uv {
        Some(uv) => {
            for [u, v] in &uv.coords {
                writeln!(w, "vt {u} {v}")?;
            }
            for (t, ut) in mesh.triangles.iter().zip(&uv.triangles) {
                let [a, b, c] = t.map(|i| i as u64 + 1);
                let [ta, tb, tc] = ut.map(|i| i as u64 + 1);
                writeln!(w, "f {a}/{ta} {b}/{tb} {c}/{tc}")?;
            }
        }
        None => {
            for t in &mesh.triangles {
                let [a, b, c] = t.map(|i| i as u64 + 1);
                writeln!(w, "f {a} {b} {c}")?;
            }
        }
    }
    Ok(())
}

/// The statement keyword and its arguments, with any `#` comment removed.
fn split_statement(line: &str) -> Option<(&str, &str)> {
    let line = line.split('#').next().unwrap_or("").trim();
    if line.is_empty() {
        return None;
    }
    Some(match line.split_once(char::is_whitespace) {
        Some((keyword, rest)) => (keyword, rest.trim()),
        None => (line, ""),
    })
}

/// Number of `v` and `vt` statements, so absolute indices can be checked as faces are read
/// (forward references are allowed) and errors can say how many the file has.
#[derive(Clone, Copy, Default)]
struct Counts {
    v: usize,
    vt: usize,
}

impl Counts {
    fn of(&self, element: Element) -> usize {
        match element {
            Element::Vertex => self.v,
            Element::TexCoord => self.vt,
        }
    }
}

fn count_elements(text: &str) -> Counts {
    let mut c = Counts::default();
    for line in text.lines() {
        match split_statement(line) {
            Some(("v", _)) => c.v += 1,
            Some(("vt", _)) => c.vt += 1,
            _ => {}
        }
    }
    c
}

/// One face corner: position index and optional texture-coordinate index (0-based).
type Corner = (u32, Option<u32>);

struct Parser {
    totals: Counts,
    defined: Counts,
    positions: Vec<[f32; 3]>,
    uv_coords: Vec<[f32; 2]>,
    triangles: Vec<[u32; 3]>,
    uv_triangles: Vec<[u32; 3]>,
    /// Whether faces carry UVs, and the line of the first face (which decided it).
    uv_mode: Option<(bool, usize)>,
    groups: Vec<(String, Range<usize>)>,
    group_name: String,
    group_start: usize,
}

impl Parser {
    fn new(totals: Counts) -> Parser {
        Parser {
            totals,
            defined: Counts::default(),
            positions: Vec::with_capacity(totals.v),
            uv_coords: Vec::with_capacity(totals.vt),
            triangles: Vec::new(),
            uv_triangles: Vec::new(),
            uv_mode: None,
            groups: Vec::new(),
            group_name: "default".to_string(),
            group_start: 0,
        }
    }

    fn statement(&mut self, line_no: usize, line: &str) -> Result<(), ObjProblem> {
        let Some((keyword, args)) = split_statement(line) else {
            return Ok(());
        };
        match keyword {
            "v" => {
                let [x, y, z] = parse_numbers::<3>(args, 3, "vertex")?;
                self.positions.push([x, y, z]);
                self.defined.v += 1;
            }
            "vt" => {
                let [u, v] = parse_numbers::<2>(args, 1, "texture coordinate")?;
                self.uv_coords.push([u, v]);
                self.defined.vt += 1;
            }
            "f" => self.face(line_no, args)?,
            "g" | "o" => self.start_group(args),
            _ => {} // s, usemtl, mtllib, l, p and anything unknown: not needed for cloth.
        }
        Ok(())
    }

    fn face(&mut self, line_no: usize, args: &str) -> Result<(), ObjProblem> {
        let corners = args
            .split_whitespace()
            .map(|token| self.corner(token))
            .collect::<Result<Vec<Corner>, _>>()?;
        if corners.len() < 3 {
            return Err(ObjProblem::TooFewCorners(corners.len()));
        }
        let has_uv = corners[0].1.is_some();
        if corners.iter().any(|c| c.1.is_some() != has_uv) {
            return Err(ObjProblem::MixedCornerUv);
        }
        match self.uv_mode {
            None => self.uv_mode = Some((has_uv, line_no)),
            Some((mode, first_line)) if mode != has_uv => {
                return Err(ObjProblem::InconsistentUv { has_uv, first_line });
            }
            Some(_) => {}
        }
        let corners = drop_repeated_neighbours(corners);
        if corners.len() < 3 {
            // Collapsed corners left a line or a point.
            let v = corners.first().map_or(0, |c| c.0);
            return Err(ObjProblem::RepeatedVertex(v as i64 + 1));
        }
        for i in 1..corners.len() - 1 {
            let tri = [corners[0], corners[i], corners[i + 1]];
            let [a, b, c] = tri.map(|c| c.0);
            if a == b || a == c {
                return Err(ObjProblem::RepeatedVertex(a as i64 + 1));
            }
            if b == c {
                return Err(ObjProblem::RepeatedVertex(b as i64 + 1));
            }
            self.triangles.push([a, b, c]);
            if has_uv {
                self.uv_triangles.push(tri.map(|c| c.1.unwrap_or(0)));
            }
        }
        Ok(())
    }

    /// Parses `v`, `v/vt`, `v//vn` or `v/vt/vn`.
    fn corner(&self, token: &str) -> Result<Corner, ObjProblem> {
        let parts: Vec<&str> = token.split('/').collect();
        let bad = || ObjProblem::BadCorner(token.to_string());
        let (v, vt, vn) = match parts.as_slice() {
            [v] => (*v, None, None),
            [v, vt] => (*v, Some(*vt), None),
            [v, vt, vn] => (*v, Some(*vt).filter(|s| !s.is_empty()), Some(*vn)),
            _ => return Err(bad()),
        };
        if v.is_empty() || vt == Some("") || vn == Some("") {
            return Err(bad());
        }
        let position = self.resolve(v, Element::Vertex).ok_or_else(bad)??;
        let uv = match vt {
            Some(t) => Some(self.resolve(t, Element::TexCoord).ok_or_else(bad)??),
            None => None,
        };
        // Normals are ignored; their index only has to be an integer.
        if vn.is_some_and(|n| n.parse::<i64>().is_err()) {
            return Err(bad());
        }
        Ok((position, uv))
    }

    /// 1-based or negative (relative to what is defined so far) index → 0-based; `None` when
    /// `text` is not an integer (the caller reports the whole corner).
    fn resolve(&self, text: &str, element: Element) -> Option<Result<u32, ObjProblem>> {
        let index: i64 = text.parse().ok()?;
        Some(self.resolve_index(index, element))
    }

    fn resolve_index(&self, index: i64, element: Element) -> Result<u32, ObjProblem> {
        let resolved = match index {
            0 => return Err(ObjProblem::ZeroIndex(element)),
            i if i > 0 => {
                let count = self.totals.of(element);
                if i as u64 > count as u64 {
                    return Err(ObjProblem::OutOfRange {
                        element,
                        index,
                        count,
                    });
                }
                i - 1
            }
            i => {
                let defined = self.defined.of(element);
                let r = defined as i64 + i;
                if r < 0 {
                    return Err(ObjProblem::RelativeOutOfRange {
                        element,
                        index,
                        defined,
                    });
                }
                r
            }
        };
        u32::try_from(resolved).map_err(|_| ObjProblem::OutOfRange {
            element,
            index,
            count: self.totals.of(element),
        })
    }

    fn start_group(&mut self, args: &str) {
        let name = args.split_whitespace().collect::<Vec<_>>().join(" ");
        let name = if name.is_empty() {
            "default".to_string()
        } else {
            name
        };
        if name != self.group_name {
            self.close_group();
            self.group_name = name;
            self.group_start = self.triangles.len();
        }
    }

    /// Records the current run of triangles, merging it into the previous entry when that has
    /// the same name and ends where this one starts (an empty group came in between).
    fn close_group(&mut self) {
        let range = self.group_start..self.triangles.len();
        if range.is_empty() {
            return;
        }
        if let Some((name, last)) = self.groups.last_mut() {
            if *name == self.group_name && last.end == range.start {
                last.end = range.end;
                return;
            }
        }
        self.groups.push((self.group_name.clone(), range));
    }

    fn finish(mut self, source_name: &str) -> Result<ObjMesh, ObjError> {
        if self.triangles.is_empty() {
            return Err(ObjError::NoFaces {
                file: source_name.to_string(),
            });
        }
        self.close_group();
        let uv = match self.uv_mode {
            Some((true, _)) => Some(FaceVaryingUv {
                coords: self.uv_coords,
                triangles: self.uv_triangles,
            }),
            _ => None,
        };
        let mesh = TriMesh {
            positions: self.positions,
            triangles: self.triangles,
            uv,
        };
        mesh.validate().map_err(|problem| ObjError::InvalidMesh {
            file: source_name.to_string(),
            problem,
        })?;
        Ok(ObjMesh {
            mesh,
            groups: self.groups,
        })
    }
}

/// Parses the first `N` numbers of a statement (at least `needed`; missing ones are 0).
fn parse_numbers<const N: usize>(
    args: &str,
    needed: usize,
    statement: &'static str,
) -> Result<[f32; N], ObjProblem> {
    let mut out = [0.0f32; N];
    let mut found = 0;
    for (slot, text) in out.iter_mut().zip(args.split_whitespace()) {
        *slot = text
            .parse::<f32>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| ObjProblem::BadNumber {
                text: text.to_string(),
                statement,
            })?;
        found += 1;
    }
    if found < needed {
        return Err(ObjProblem::TooFewNumbers {
            statement,
            needed,
            found,
        });
    }
    Ok(out)
}

/// Removes corners equal to the one before them (cyclically): exporters write triangles as quads
/// with a repeated last vertex.
fn drop_repeated_neighbours(mut corners: Vec<Corner>) -> Vec<Corner> {
    corners.dedup_by_key(|c| c.0);
    while corners.len() > 1 && corners.first().map(|c| c.0) == corners.last().map(|c| c.0) {
        corners.pop();
    }
    corners
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::test_meshes::assert_split_roundtrip;
    use crate::geometry::topology::Topology;
    use std::path::PathBuf;

    fn parse(text: &str) -> Result<ObjMesh, ObjError> {
        parse_obj(text, "skirt.obj")
    }

    fn err(text: &str) -> String {
        parse(text).unwrap_err().to_string()
    }

    #[test]
    fn all_corner_forms_negative_indices_and_quads() {
        let text = "# test\nmtllib x.mtl\no thing\nv 0 0 0\nv 1 0 0\nv 1 1 0 1.0\nv 0 1 0\n\
                    vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\ns off\nusemtl cloth\n\
                    f 1/1/1 2/2/1 3/3/1 4/4/1\ng back\nf -4/-4 -2/-2 -1/-1\n";
        let obj = parse(text).unwrap();
        let m = &obj.mesh;
        assert_eq!(m.vertex_count(), 4);
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3], [0, 2, 3]]);
        assert_eq!(m.uv.as_ref().unwrap().triangles, m.triangles);
        assert_eq!(
            obj.groups,
            vec![("thing".to_string(), 0..2), ("back".to_string(), 2..3)]
        );

        let plain = parse("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1//1 2//1 3//1\nf 3 1 2\n").unwrap();
        assert_eq!(plain.mesh.uv, None);
        assert_eq!(plain.mesh.triangles, vec![[0, 1, 2], [2, 0, 1]]);
        assert_eq!(plain.groups, vec![("default".to_string(), 0..2)]);
    }

    #[test]
    fn forward_references_crlf_and_repeated_quad_corner() {
        let text = "f 1 2 3 3\r\nv 0 0 0\r\nv 1 0 0 # inline comment\r\nv 0 1 0\r\n";
        let obj = parse(text).unwrap();
        assert_eq!(obj.mesh.triangles, vec![[0, 1, 2]]);
    }

    #[test]
    fn groups_merge_across_empty_groups_and_repeat_per_run() {
        let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\ng a\nf 1 2 3\ng b\ng a\nf 1 2 3\n\
                    g b\nf 1 2 3\ng a\nf 1 2 3\n";
        let groups = parse(text).unwrap().groups;
        let names: Vec<_> = groups
            .iter()
            .map(|(n, r)| (n.as_str(), r.clone()))
            .collect();
        assert_eq!(names, vec![("a", 0..2), ("b", 2..3), ("a", 3..4)]);
    }

    #[test]
    fn error_messages_name_file_line_and_problem() {
        let v3 = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
        assert_eq!(
            err(&format!("{v3}f 1 2 9001\n")),
            "skirt.obj:4: face index 9001 out of range (file has 3 vertices)"
        );
        assert_eq!(
            err(&format!("{v3}f 1 2 -4\n")),
            "skirt.obj:4: relative face index -4 points before the first vertex (3 defined so far)"
        );
        assert_eq!(
            err(&format!("{v3}f 1 2 0\n")),
            "skirt.obj:4: face index 0 is invalid (OBJ indices start at 1)"
        );
        assert_eq!(
            err(&format!("{v3}vt 0 0\nf 1/1 2/2 3/1\n")),
            "skirt.obj:5: texture coordinate index 2 out of range (file has 1 texture coordinates)"
        );
        // A file cut off in the middle of a line.
        assert_eq!(
            err("v 0 0 0\nv 1 0"),
            "skirt.obj:2: vertex needs at least 3 numbers, found 2"
        );
        assert_eq!(
            err(&format!("{v3}f 1 2\n")),
            "skirt.obj:4: face has 2 vertices; a face needs at least 3"
        );
        assert_eq!(
            err("v 0 0 0\nv 1 O 0\n"),
            "skirt.obj:2: bad number 'O' in vertex"
        );
        assert_eq!(
            err("v 0 0 nan\n"),
            "skirt.obj:1: bad number 'nan' in vertex"
        );
        assert_eq!(
            err(&format!("{v3}f 1/ 2 3\n")),
            "skirt.obj:4: bad face corner '1/' (expected v, v/vt, v//vn or v/vt/vn)"
        );
        assert_eq!(
            err(&format!("{v3}f 1 2 x\n")),
            "skirt.obj:4: bad face corner 'x' (expected v, v/vt, v//vn or v/vt/vn)"
        );
        assert_eq!(
            err(&format!("{v3}f 1 2 1\n")),
            "skirt.obj:4: face repeats vertex 1 (degenerate face)"
        );
        assert_eq!(
            err(&format!("{v3}vt 0 0\nf 1/1 2 3\n")),
            "skirt.obj:5: face mixes corners with and without texture coordinates"
        );
        assert_eq!(
            err(&format!("{v3}vt 0 0\nf 1/1 2/1 3/1\nf 1 2 3\n")),
            "skirt.obj:6: face has no texture coordinates but the face on line 5 has them \
             (UVs must be on all faces or none)"
        );
        assert_eq!(err(v3), "skirt.obj: the file has no faces (no `f` lines)");
        for message in [err("v 0 0 0\nv 1 0"), err(v3)] {
            assert!(!message.contains('\n'));
        }
    }

    #[test]
    fn missing_file_error_is_one_clean_line() {
        let e = read_obj(Path::new("/nonexistent/skirt.obj")).unwrap_err();
        assert_eq!(
            e.to_string(),
            "cannot read /nonexistent/skirt.obj: No such file or directory"
        );
    }

    fn scratch_dir(name: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("garmentbake-obj-{}-{name}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn write_then_read_is_exact() {
        let dir = scratch_dir("roundtrip");
        let path = dir.join("out.obj");
        let mut mesh = crate::geometry::test_meshes::seamed_quad();
        mesh.positions[1] = [0.1, -1.0e-7, 123456.79];
        mesh.uv.as_mut().unwrap().coords[2] = [1.0 / 3.0, 0.7];
        write_obj(&path, &mesh, "garmentbake test\nsecond line").unwrap();
        assert!(!dir.join("out.obj.tmp").exists());
        let text = fs::read_to_string(&path).unwrap();
        assert!(text.starts_with("# garmentbake test\n# second line\nv "));
        let back = read_obj(&path).unwrap();
        assert_eq!(back.mesh, mesh);

        let plain = crate::geometry::test_meshes::grid(2, 1, 0.1);
        write_obj(&path, &plain, "").unwrap();
        assert_eq!(read_obj(&path).unwrap().mesh, plain);
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn failed_write_leaves_nothing_behind() {
        let dir = scratch_dir("fail");
        let target = dir.join("is_a_dir.obj");
        fs::create_dir_all(&target).unwrap(); // rename onto a directory fails
        let mesh = crate::geometry::test_meshes::grid(1, 1, 1.0);
        let e = write_obj(&target, &mesh, "").unwrap_err();
        assert_eq!(
            e.to_string(),
            format!("cannot write {}: Is a directory", target.display())
        );
        assert!(!dir.join("is_a_dir.obj.tmp").exists());
        fs::remove_dir_all(&dir).unwrap();
    }

    // ---- The MakeHuman base mesh (CC0), the project's real body and skirt template. ----

    fn base_obj_path() -> PathBuf {
        std::env::var_os("GARMENTBAKE_BASE_OBJ")
            .map(PathBuf::from)
            .unwrap_or_else(|| {
                PathBuf::from(concat!(
                    env!("CARGO_MANIFEST_DIR"),
                    "/../shared/data/makehuman/base.obj"
                ))
            })
    }

    fn base_obj() -> ObjMesh {
        let path = base_obj_path();
        read_obj(&path).unwrap_or_else(|e| panic!("{e} (set GARMENTBAKE_BASE_OBJ)"))
    }

    /// 0-based vertex range of `helper-skirt` in base.obj.
    const SKIRT: std::ops::RangeInclusive<u32> = 18002..=18721;

    #[test]
    fn base_obj_counts_and_groups() {
        let obj = base_obj();
        let m = &obj.mesh;
        assert_eq!(m.vertex_count(), 19158);
        assert_eq!(m.triangle_count(), 2 * 18486); // all quads
        let uv = m.uv.as_ref().unwrap();
        assert_eq!(uv.coords.len(), 21334);
        assert_eq!(obj.groups[0], ("body".to_string(), 0..2 * 13378));
        let skirt: Vec<_> = obj
            .groups
            .iter()
            .filter(|g| g.0 == "helper-skirt")
            .collect();
        assert_eq!(skirt.len(), 1);
        assert_eq!(skirt[0].1.len(), 2 * 684);
        // Every skirt triangle uses only skirt vertices.
        for t in skirt[0].1.clone() {
            assert!(m.triangles[t].iter().all(|v| SKIRT.contains(v)));
        }
        // Decimetres: the body is about 17 units tall.
        let (lo, hi) = m.bounds();
        assert!((15.0..20.0).contains(&(hi[1] - lo[1])), "{lo:?} {hi:?}");
    }

    #[test]
    fn base_obj_skirt_is_an_open_tube() {
        let obj = base_obj();
        let (skirt, map) = obj.mesh.submesh(|v| SKIRT.contains(&v));
        assert_eq!(skirt.vertex_count(), 720);
        assert_eq!(map.first(), Some(&18002));
        assert_eq!(skirt.triangle_count(), 2 * 684);
        assert_eq!(skirt.validate(), Ok(()));
        let topo = Topology::new(&skirt);
        assert!(topo.is_manifold());
        let loops = topo.boundary_loops();
        assert_eq!(loops.len(), 2, "waist and hem");
        assert!(loops.iter().all(|l| l.len() == 36));
        // An annulus: V - E + F = 0.
        let euler = 720 - topo.edges.len() as i64 + skirt.triangle_count() as i64;
        assert_eq!(euler, 0);
        // Raw decimetres: the waist ring is at y ≈ 1.7, the hem at y ≈ -7.1.
        let mean_y = |l: &Vec<u32>| {
            l.iter()
                .map(|&v| skirt.positions[v as usize][1])
                .sum::<f32>()
                / l.len() as f32
        };
        let (waist, hem) = (mean_y(&loops[0]), mean_y(&loops[1]));
        assert!(
            (waist - 1.70).abs() < 0.01 && (hem + 7.11).abs() < 0.01,
            "{waist} {hem}"
        );

        let sub = skirt.subdivide_midpoint();
        assert_eq!(sub.vertex_count(), 720 + topo.edges.len());
        assert_eq!(sub.triangle_count(), 4 * skirt.triangle_count());
        assert_eq!(sub.validate(), Ok(()));
        assert_eq!(Topology::new(&sub).boundary_loops().len(), 2);

        // Splitting at UV seams then mapping back reproduces every corner's position and UV.
        let split = skirt.split_by_uv();
        assert_split_roundtrip(&skirt, &split);
        // One vertical UV seam from waist to hem: 19 edges, so 20 vertices are doubled.
        assert_eq!(split.0.len(), 740);
    }

    #[test]
    fn base_obj_body_is_closed() {
        // The skin (vertices 0..=13379; the rest are helpers) is a watertight genus-0 surface,
        // consistently oriented: what the collision term's inside/outside test relies on.
        let obj = base_obj();
        let (body, _) = obj.mesh.submesh(|v| v <= 13379);
        let topo = Topology::new(&body);
        assert!(topo.boundary_edges.is_empty() && topo.is_manifold());
        let euler =
            body.vertex_count() as i64 - topo.edges.len() as i64 + body.triangle_count() as i64;
        assert_eq!(euler, 2);
        let consistent = topo.hinges.iter().all(|h| {
            let forward = |f: u32| {
                let t = body.triangles[f as usize];
                (0..3).any(|k| t[k] == h.edge[0] && t[(k + 1) % 3] == h.edge[1])
            };
            forward(h.faces[0]) != forward(h.faces[1])
        });
        assert!(consistent);
        // Outward: the vertex normals of the top of the head point up.
        let normals = crate::geometry::vertex_normals(&body.positions, &body.triangles);
        let top = (0..body.vertex_count())
            .max_by(|&a, &b| body.positions[a][1].total_cmp(&body.positions[b][1]))
            .unwrap();
        assert!(normals[top][1] > 0.9, "{:?}", normals[top]);
    }
}
