//! glTF 2.0 structural rules, checked on the typed document and the accessor data: the
//! schema's references (gltf-json), then the rules the Khronos validator reports as errors —
//! buffer views inside buffers, accessor layouts and bounds, the attribute formats of each
//! semantic, skins (weights normalised and non-negative, joints unique and inside the skin),
//! morph targets consistent across primitives, animation samplers, and an acyclic node tree.
//! Numeric tolerances are Khronos' own, so a file they accept we accept too.

use super::accessor::{component_size, format_name, read, Values};
use super::container::Document;
use super::Problems;
use gltf::json;
use json::accessor::{ComponentType as C, Type as T};
use json::validation::Checked::Valid;
use json::validation::Validate;

/// |length − 1| allowed for unit vectors (normals) and node rotations (Khronos' thresholds).
const UNIT_VEC3: f64 = 0.00769;
const UNIT_QUAT: f64 = 0.00769;
/// Per non-zero weight, the f32 rounding a weight sum may carry (Khronos' threshold).
const WEIGHT_SUM_PER_WEIGHT: f32 = 2e-7;

/// Every accessor read once: `Ok` values or the reason it could not be read.
pub type Accessors = Vec<Result<Values, String>>;

/// Runs every rule; returns the accessors' data for later checks (replay) when the references
/// themselves are sound.
/// A component type and whether it is normalized.
type Format = (C, bool);

/// Extensions beyond gltf-json's own whose rules these checks know: KHR_mesh_quantization's
/// integer morph-target deltas.
const CHECKED_EXTENSIONS: [&str; 1] = ["KHR_mesh_quantization"];

pub fn check(doc: &Document, p: &mut Problems) -> Option<Accessors> {
    let root = &doc.root;
    if let Some(problem) = crate::io::gltf_body::dangling_position(root) {
        let (at, message) = problem.split_once(": ").unwrap_or(("/", &problem));
        p.error(at, message);
        return None;
    }
    let before = p.errors.len();
    // gltf-json reports every required extension it does not implement; the ones whose rules
    // are checked here are not unsupported.
    let mut plain = root.clone();
    plain
        .extensions_required
        .retain(|e| !CHECKED_EXTENSIONS.contains(&e.as_str()));
    plain.validate(&plain, json::Path::new, &mut |path, error| {
        p.error(pointer(&path().to_string()), format!("{error:?} value"));
    });
    if root.asset.version.split('.').next() != Some("2") {
        p.error(
            "/asset/version",
            format!("'{}', expected 2.x", root.asset.version),
        );
    }
    if p.errors.len() > before {
        return None; // broken references: the rules below would only repeat them
    }
    buffer_views(root, p);
    let accessors: Accessors = (0..root.accessors.len())
        .map(|i| read(root, &doc.buffers, json::Index::new(i as u32)))
        .collect();
    for (i, a) in accessors.iter().enumerate() {
        match a {
            Ok(values) => accessor_values(root, i, values, p),
            Err(e) => p.error(format!("/accessors/{i}"), e.clone()),
        }
    }
    let rules = Rules {
        root,
        accessors: &accessors,
        quantized: root
            .extensions_used
            .iter()
            .any(|e| e == CHECKED_EXTENSIONS[0]),
    };
    rules.meshes(p);
    rules.nodes(p);
    rules.skins(p);
    rules.animations(p);
    Some(accessors)
}

/// gltf-json's paths (`meshes[0].primitives[1]`) as JSON pointers (`/meshes/0/primitives/1`).
fn pointer(path: &str) -> String {
    let mut out = String::from("/");
    out.push_str(
        &path
            .replace("][", "/")
            .replace(['[', '.'], "/")
            .replace(']', ""),
    );
    out
}

fn buffer_views(root: &json::Root, p: &mut Problems) {
    for (i, view) in root.buffer_views.iter().enumerate() {
        let at = format!("/bufferViews/{i}");
        if let Some(stride) = view.byte_stride {
            if !(4..=252).contains(&stride.0) || stride.0 % 4 != 0 {
                p.error(
                    &at,
                    format!("byteStride {} must be a multiple of 4 in 4..252", stride.0),
                );
            }
        }
        if view.byte_length.0 == 0 {
            p.error(&at, "byteLength must be at least 1");
        }
        if let Some(buffer) = root.get(view.buffer) {
            let end = view.byte_offset.map_or(0, |o| o.0) + view.byte_length.0;
            if end > buffer.byte_length.0 {
                p.error(
                    &at,
                    format!(
                        "ends at byte {end}, past buffer {} ({} bytes)",
                        view.buffer.value(),
                        buffer.byte_length.0
                    ),
                );
            }
        }
    }
}

/// Rules on one accessor's own data: finite floats, declared bounds equal to the actual ones.
fn accessor_values(root: &json::Root, i: usize, v: &Values, p: &mut Problems) {
    let at = format!("/accessors/{i}");
    if let Some(e) = v.data.iter().position(|x| !x.is_finite()) {
        p.error(
            &at,
            format!(
                "element {} is {} (floats must be finite)",
                e / v.comps,
                v.data[e]
            ),
        );
        return;
    }
    let acc = &root.accessors[i];
    for (name, declared, pick) in [
        ("min", &acc.min, f64::min as fn(f64, f64) -> f64),
        ("max", &acc.max, f64::max),
    ] {
        let Some(declared) = declared else { continue };
        let Some(declared) = declared.as_array() else {
            p.error(&at, format!("{name} must be an array"));
            continue;
        };
        if declared.len() != v.comps {
            p.error(
                &at,
                format!(
                    "{name} has {} values, the type has {}",
                    declared.len(),
                    v.comps
                ),
            );
            continue;
        }
        for (c, d) in declared.iter().enumerate() {
            let actual = (0..v.count())
                .map(|e| v.data[e * v.comps + c])
                .reduce(pick)
                .unwrap_or(0.0);
            let d = d.as_f64().unwrap_or(f64::NAN);
            // Compared in the component's own precision (f32 for floats), as Khronos does.
            let same = match v.component {
                C::F32 => d as f32 == actual as f32,
                _ => d == actual,
            };
            if !same {
                p.error(
                    &at,
                    format!("declared {name} {d} of component {c} but the data's is {actual}"),
                );
            }
        }
    }
}

struct Rules<'a> {
    root: &'a json::Root,
    accessors: &'a Accessors,
    /// KHR_mesh_quantization is used: integer morph-target deltas are allowed.
    quantized: bool,
}

impl Rules<'_> {
    fn values(&self, index: json::Index<json::Accessor>) -> Option<&Values> {
        self.accessors.get(index.value())?.as_ref().ok()
    }

    /// Checks an accessor's format against the allowed `(component, normalized, type)` list.
    fn format(
        &self,
        at: &str,
        what: &str,
        index: json::Index<json::Accessor>,
        allowed: &[(C, bool, T)],
        p: &mut Problems,
    ) -> Option<&Values> {
        let v = self.values(index)?;
        if !allowed
            .iter()
            .any(|&(c, n, t)| c == v.component && n == v.normalized && t == v.type_)
        {
            let list: Vec<String> = allowed
                .iter()
                .map(|&(c, n, t)| format_name(c, t, n))
                .collect();
            p.error(
                at,
                format!(
                    "{what} accessor {} is {}, must be {}",
                    index.value(),
                    v.format(),
                    list.join(" or ")
                ),
            );
            return None;
        }
        Some(v)
    }

    fn has_bounds(&self, index: json::Index<json::Accessor>) -> bool {
        self.root
            .get(index)
            .is_some_and(|a| a.min.is_some() && a.max.is_some())
    }

    /// The formats a vertex attribute (`morph`: a morph target's) may take: core glTF's, widened
    /// by KHR_mesh_quantization's tables when the file uses it (integer positions and texture
    /// coordinates, normalized byte/short normals and tangents, byte/short deltas).
    fn formats(&self, name: &str, morph: bool) -> Vec<(C, bool, T)> {
        let all_ints = [
            (C::I8, false),
            (C::I8, true),
            (C::U8, false),
            (C::U8, true),
            (C::I16, false),
            (C::I16, true),
            (C::U16, false),
            (C::U16, true),
        ];
        let signed_ints = [
            (C::I8, false),
            (C::I8, true),
            (C::I16, false),
            (C::I16, true),
        ];
        let signed_normalized = [(C::I8, true), (C::I16, true)];
        let (type_, core, quantized): (T, &[Format], &[Format]) = match (name, morph) {
            ("POSITION", false) => (T::Vec3, &[], &all_ints),
            ("POSITION", true) => (T::Vec3, &[], &signed_ints),
            ("TANGENT", false) => (T::Vec4, &[], &signed_normalized),
            ("NORMAL" | "TANGENT", _) => (T::Vec3, &[], &signed_normalized),
            // TEXCOORD: normalized unsigned bytes and shorts are core glTF.
            _ => (T::Vec2, &[(C::U8, true), (C::U16, true)], &all_ints),
        };
        let extra = if self.quantized { quantized } else { &[] };
        std::iter::once((C::F32, false))
            .chain(core.iter().copied())
            .chain(extra.iter().copied().filter(|f| !core.contains(f)))
            .map(|(c, n)| (c, n, type_))
            .collect()
    }

    /// glTF 2.0 §3.6.2.4: every vertex attribute element starts on a 4-byte boundary (its
    /// offset and its stride multiples of 4), e.g. a SHORT VEC3 needs a stride of 8.
    fn vertex_aligned(&self, at: &str, index: json::Index<json::Accessor>, p: &mut Problems) {
        let Some(acc) = self.root.get(index) else {
            return;
        };
        let (Valid(c), Valid(t)) = (&acc.component_type, &acc.type_) else {
            return;
        };
        let element = component_size(c.0) * t.multiplicity();
        let stride = self.stride(index).unwrap_or(element);
        let view_offset = acc
            .buffer_view
            .and_then(|v| self.root.get(v))
            .and_then(|v| v.byte_offset)
            .map_or(0, |o| o.0 as usize);
        let offset = view_offset + acc.byte_offset.map_or(0, |o| o.0 as usize);
        if !stride.is_multiple_of(4) || !offset.is_multiple_of(4) {
            p.error(
                at,
                format!(
                    "vertex attribute data must be aligned to 4 bytes (offset {offset}, stride {stride})"
                ),
            );
        }
    }

    fn stride(&self, index: json::Index<json::Accessor>) -> Option<usize> {
        let view = self.root.get(index)?.buffer_view?;
        Some(self.root.get(view)?.byte_stride?.0)
    }

    fn meshes(&self, p: &mut Problems) {
        for (m, mesh) in self.root.meshes.iter().enumerate() {
            let counts: Vec<usize> = mesh
                .primitives
                .iter()
                .map(|prim| prim.targets.as_ref().map_or(0, Vec::len))
                .collect();
            if counts.windows(2).any(|w| w[0] != w[1]) {
                p.error(
                    format!("/meshes/{m}"),
                    format!("primitives have different numbers of morph targets: {counts:?}"),
                );
            }
            let targets = counts.first().copied().unwrap_or(0);
            if let Some(w) = &mesh.weights {
                if w.len() != targets {
                    p.error(
                        format!("/meshes/{m}/weights"),
                        format!("{} weights for {targets} morph targets", w.len()),
                    );
                }
            }
            for (i, prim) in mesh.primitives.iter().enumerate() {
                self.primitive(&format!("/meshes/{m}/primitives/{i}"), prim, p);
            }
        }
    }

    fn primitive(&self, at: &str, prim: &json::mesh::Primitive, p: &mut Problems) {
        use json::mesh::Semantic as S;
        let mut count = None;
        let mut sets = (0, 0);
        for (semantic, &index) in &prim.attributes {
            let Valid(semantic) = semantic else { continue };
            let here = format!("{at}/attributes/{semantic:?}");
            self.vertex_aligned(&here, index, p);
            let v = match semantic {
                S::Positions => {
                    if !self.has_bounds(index) {
                        p.error(&here, "POSITION accessor needs min and max");
                    }
                    self.format(
                        &here,
                        "POSITION",
                        index,
                        &self.formats("POSITION", false),
                        p,
                    )
                }
                S::Normals => {
                    let v = self.format(&here, "NORMAL", index, &self.formats("NORMAL", false), p);
                    // Quantized normals are not unit length by construction (the extension
                    // leaves normalising to the reader), as Khronos does not check them.
                    if let Some(v) = v.filter(|v| v.component == C::F32) {
                        unit_vectors(&here, v, p);
                    }
                    v
                }
                S::Tangents => {
                    self.format(&here, "TANGENT", index, &self.formats("TANGENT", false), p)
                }
                S::TexCoords(_) => self.format(
                    &here,
                    "TEXCOORD",
                    index,
                    &self.formats("TEXCOORD", false),
                    p,
                ),
                S::Colors(_) => self.format(
                    &here,
                    "COLOR",
                    index,
                    &[
                        (C::F32, false, T::Vec3),
                        (C::F32, false, T::Vec4),
                        (C::U8, true, T::Vec3),
                        (C::U8, true, T::Vec4),
                        (C::U16, true, T::Vec3),
                        (C::U16, true, T::Vec4),
                    ],
                    p,
                ),
                S::Joints(_) => {
                    sets.0 += 1;
                    self.format(
                        &here,
                        "JOINTS",
                        index,
                        &[(C::U8, false, T::Vec4), (C::U16, false, T::Vec4)],
                        p,
                    )
                }
                S::Weights(_) => {
                    sets.1 += 1;
                    self.format(
                        &here,
                        "WEIGHTS",
                        index,
                        &[
                            (C::F32, false, T::Vec4),
                            (C::U8, true, T::Vec4),
                            (C::U16, true, T::Vec4),
                        ],
                        p,
                    )
                }
                #[allow(unreachable_patterns)]
                _ => self.values(index),
            };
            if let Some(v) = v {
                if count.is_some_and(|c| c != v.count()) {
                    p.error(
                        &here,
                        format!(
                            "{} elements, the other attributes have {}",
                            v.count(),
                            count.unwrap_or(0)
                        ),
                    );
                }
                count.get_or_insert(v.count());
            }
        }
        if sets.0 != sets.1 {
            p.error(
                at,
                format!("{} JOINTS sets but {} WEIGHTS sets", sets.0, sets.1),
            );
        } else if sets.0 > 0 {
            self.weights(at, prim, sets.0, p);
        }
        let vertices = count.unwrap_or(0);
        if let Some(indices) = prim.indices {
            self.indices(&format!("{at}/indices"), indices, vertices, p);
        }
        for (t, target) in prim.targets.iter().flatten().enumerate() {
            let here = format!("{at}/targets/{t}");
            for (name, semantic, index) in [
                ("POSITION", S::Positions, target.positions),
                ("NORMAL", S::Normals, target.normals),
                ("TANGENT", S::Tangents, target.tangents),
            ] {
                let Some(index) = index else { continue };
                self.vertex_aligned(&here, index, p);
                if !prim.attributes.contains_key(&Valid(semantic)) {
                    p.error(
                        &here,
                        format!("morph target has {name} but the primitive does not"),
                    );
                }
                if name == "POSITION" && !self.has_bounds(index) {
                    p.error(&here, "morph target POSITION accessor needs min and max");
                }
                let allowed = self.formats(name, true);
                if let Some(v) = self.format(&here, name, index, &allowed, p) {
                    if v.count() != vertices {
                        p.error(
                            &here,
                            format!(
                                "{name} has {} elements, the primitive {vertices} vertices",
                                v.count()
                            ),
                        );
                    }
                }
            }
        }
    }

    /// Weights non-negative and summing to 1 per vertex; joint indices of non-zero weights
    /// unique; unused slots should point at joint 0 (a warning, as the spec says SHOULD).
    fn weights(&self, at: &str, prim: &json::mesh::Primitive, sets: usize, p: &mut Problems) {
        use json::mesh::Semantic as S;
        let get = |s: S| prim.attributes.get(&Valid(s)).and_then(|&i| self.values(i));
        let pairs: Option<Vec<(&Values, &Values)>> = (0..sets as u32)
            .map(|s| Some((get(S::Joints(s))?, get(S::Weights(s))?)))
            .collect();
        let Some(pairs) = pairs else { return };
        let vertices = pairs[0].0.count();
        // Unequal counts and formats other than VEC4 are reported by the format rules (and a
        // VEC2 here once indexed past its element: found by fuzzing).
        let vec4 =
            |v: &Values| v.count() == vertices && (0..vertices).all(|e| v.element(e).len() == 4);
        if !pairs.iter().all(|(j, w)| vec4(j) && vec4(w)) {
            return;
        }
        for v in 0..vertices {
            let mut sum = 0f32;
            let mut used = Vec::with_capacity(4 * sets);
            for (s, (joints, weights)) in pairs.iter().enumerate() {
                for k in 0..4 {
                    let j = joints.element(v)[k];
                    let w = weights.real(weights.element(v)[k]);
                    if w < 0.0 {
                        p.error(
                            format!("{at}/attributes/WEIGHTS_{s}"),
                            format!("vertex {v}: negative weight {w}"),
                        );
                        return;
                    }
                    if w == 0.0 {
                        if j != 0.0 {
                            p.warning(
                                format!("{at}/attributes/JOINTS_{s}"),
                                format!("vertex {v}: joint {j} has zero weight (should be 0)"),
                            );
                        }
                        continue;
                    }
                    if used.contains(&j) {
                        p.error(
                            format!("{at}/attributes/JOINTS_{s}"),
                            format!("vertex {v}: joint {j} appears twice"),
                        );
                        return;
                    }
                    used.push(j);
                    sum += w as f32;
                }
            }
            if (sum - 1.0).abs() > WEIGHT_SUM_PER_WEIGHT * used.len() as f32 {
                p.error(
                    format!("{at}/attributes/WEIGHTS_0"),
                    format!("vertex {v}: weights sum to {sum}, not 1"),
                );
                return;
            }
        }
    }

    fn indices(
        &self,
        at: &str,
        index: json::Index<json::Accessor>,
        vertices: usize,
        p: &mut Problems,
    ) {
        let allowed = [
            (C::U8, false, T::Scalar),
            (C::U16, false, T::Scalar),
            (C::U32, false, T::Scalar),
        ];
        if self.stride(index).is_some() {
            p.error(at, "the indices' bufferView must not have a byteStride");
        }
        let Some(v) = self.format(at, "indices", index, &allowed, p) else {
            return;
        };
        let restart = match v.component {
            C::U8 => 255.0,
            C::U16 => 65535.0,
            _ => 4294967295.0,
        };
        if let Some(i) = v.data.iter().position(|&x| x == restart) {
            p.error(
                at,
                format!("index {i} is the primitive restart value {restart}"),
            );
        } else if let Some(i) = v.data.iter().position(|&x| x >= vertices as f64) {
            p.error(
                at,
                format!("index {i} is {}, past the {vertices} vertices", v.data[i]),
            );
        }
    }

    fn nodes(&self, p: &mut Problems) {
        let nodes = &self.root.nodes;
        let mut parent: Vec<Option<usize>> = vec![None; nodes.len()];
        for (n, node) in nodes.iter().enumerate() {
            let at = format!("/nodes/{n}");
            for child in node.children.iter().flatten() {
                let c = child.value();
                if parent[c].is_some() {
                    p.error(&at, format!("node {c} already has a parent"));
                }
                parent[c] = Some(n);
            }
            if node.matrix.is_some()
                && (node.translation.is_some() || node.rotation.is_some() || node.scale.is_some())
            {
                p.error(&at, "has both a matrix and translation/rotation/scale");
            }
            if let Some(q) = node.rotation {
                let len = q.0.iter().map(|&c| (c as f64).powi(2)).sum::<f64>();
                if (1.0 - len).abs() > UNIT_QUAT {
                    p.error(&at, format!("rotation {:?} is not a unit quaternion", q.0));
                }
            }
            self.node_mesh(&at, node, p);
        }
        // Following parents from every node must reach a root within `len` steps.
        for start in 0..nodes.len() {
            let mut at = start;
            for _ in 0..=nodes.len() {
                match parent[at] {
                    Some(up) if up == start => {
                        p.error(format!("/nodes/{start}"), "is part of a node loop");
                        break;
                    }
                    Some(up) => at = up,
                    None => break,
                }
            }
        }
        for (s, scene) in self.root.scenes.iter().enumerate() {
            for n in &scene.nodes {
                if parent.get(n.value()).copied().flatten().is_some() {
                    p.error(
                        format!("/scenes/{s}"),
                        format!("node {} is not a root node", n.value()),
                    );
                }
            }
        }
    }

    fn node_mesh(&self, at: &str, node: &json::Node, p: &mut Problems) {
        let Some(mesh) = node.mesh.and_then(|m| self.root.get(m)) else {
            if node.skin.is_some() {
                p.error(at, "has a skin but no mesh");
            }
            return;
        };
        let skinned = mesh.primitives.iter().any(|prim| {
            prim.attributes
                .contains_key(&Valid(json::mesh::Semantic::Joints(0)))
        });
        match (node.skin.and_then(|s| self.root.get(s)), skinned) {
            (Some(_), false) => p.error(at, "has a skin, but its mesh has no JOINTS_0"),
            (None, true) => p.warning(at, "its mesh is skinned but the node has no skin"),
            (Some(skin), true) => self.joints_in_skin(at, mesh, skin.joints.len(), p),
            (None, false) => {}
        }
        let targets = mesh
            .primitives
            .first()
            .and_then(|x| x.targets.as_ref())
            .map_or(0, Vec::len);
        if let Some(w) = &node.weights {
            if w.len() != targets {
                p.error(
                    at,
                    format!("{} weights for {targets} morph targets", w.len()),
                );
            }
        }
    }

    /// Every JOINTS value must index the skin's joint list.
    fn joints_in_skin(&self, at: &str, mesh: &json::Mesh, joints: usize, p: &mut Problems) {
        for prim in &mesh.primitives {
            for (semantic, &index) in &prim.attributes {
                let Valid(json::mesh::Semantic::Joints(s)) = semantic else {
                    continue;
                };
                let Some(v) = self.values(index) else {
                    continue;
                };
                if let Some(i) = v.data.iter().position(|&j| j >= joints as f64) {
                    p.error(
                        at,
                        format!(
                            "JOINTS_{s} of vertex {} is {}, past the skin's {joints} joints",
                            i / 4,
                            v.data[i]
                        ),
                    );
                    return;
                }
            }
        }
    }

    fn skins(&self, p: &mut Problems) {
        let parents = self.parents();
        for (s, skin) in self.root.skins.iter().enumerate() {
            let at = format!("/skins/{s}");
            if skin.joints.is_empty() {
                p.error(&at, "has no joints");
                continue;
            }
            let mut seen = std::collections::HashSet::new();
            if let Some(j) = skin.joints.iter().find(|j| !seen.insert(j.value())) {
                p.error(&at, format!("joint node {} is listed twice", j.value()));
            }
            if let Some(root) = skin.skeleton {
                let above = |mut n: usize| loop {
                    if n == root.value() {
                        break true;
                    }
                    match parents[n] {
                        Some(up) => n = up,
                        None => break false,
                    }
                };
                if let Some(j) = skin.joints.iter().find(|j| !above(j.value())) {
                    p.error(
                        &at,
                        format!(
                            "skeleton node {} is not an ancestor of joint node {}",
                            root.value(),
                            j.value()
                        ),
                    );
                }
            }
            let Some(ibm) = skin.inverse_bind_matrices else {
                continue;
            };
            if self.stride(ibm).is_some() {
                p.error(
                    &at,
                    "the inverse bind matrices' bufferView must not have a byteStride",
                );
            }
            let Some(v) = self.format(
                &at,
                "inverseBindMatrices",
                ibm,
                &[(C::F32, false, T::Mat4)],
                p,
            ) else {
                continue;
            };
            if v.count() < skin.joints.len() {
                p.error(
                    &at,
                    format!(
                        "{} inverse bind matrices for {} joints",
                        v.count(),
                        skin.joints.len()
                    ),
                );
            }
            // Column-major: the last row (elements 3, 7, 11, 15) of an affine matrix is 0 0 0 1.
            if let Some(m) = (0..v.count()).find(|&m| {
                let e = v.element(m);
                [e[3], e[7], e[11], e[15]] != [0.0, 0.0, 0.0, 1.0]
            }) {
                p.error(
                    &at,
                    format!("inverse bind matrix {m} is not affine (last row not 0 0 0 1)"),
                );
            }
        }
    }

    fn parents(&self) -> Vec<Option<usize>> {
        let mut parent = vec![None; self.root.nodes.len()];
        for (n, node) in self.root.nodes.iter().enumerate() {
            for c in node.children.iter().flatten() {
                parent[c.value()].get_or_insert(n);
            }
        }
        parent
    }

    fn animations(&self, p: &mut Problems) {
        use json::animation::{Interpolation, Property};
        for (a, anim) in self.root.animations.iter().enumerate() {
            let mut targets = std::collections::HashSet::new();
            for (c, channel) in anim.channels.iter().enumerate() {
                let at = format!("/animations/{a}/channels/{c}");
                let (node, Valid(path)) = (channel.target.node, &channel.target.path) else {
                    continue;
                };
                if !targets.insert((node.value(), format!("{path:?}"))) {
                    p.error(
                        &at,
                        format!("a second channel targets node {} {path:?}", node.value()),
                    );
                }
                let Some(sampler) = anim.samplers.get(channel.sampler.value()) else {
                    continue;
                };
                let Some(target) = self.root.get(node) else {
                    p.error(
                        &at,
                        format!("targets node {}, which does not exist", node.value()),
                    );
                    continue;
                };
                let morphs = target
                    .mesh
                    .and_then(|m| self.root.get(m))
                    .and_then(|m| m.primitives.first())
                    .and_then(|prim| prim.targets.as_ref())
                    .map_or(0, Vec::len);
                if *path == Property::MorphTargetWeights && morphs == 0 {
                    p.error(
                        &at,
                        "animates weights of a node whose mesh has no morph targets",
                    );
                }
                if *path != Property::MorphTargetWeights && target.matrix.is_some() {
                    p.error(&at, "animates TRS of a node that has a matrix");
                }
                let here = format!("/animations/{a}/samplers/{}", channel.sampler.value());
                let cubic = sampler.interpolation == Valid(Interpolation::CubicSpline);
                let Some(input) = self.input(&here, sampler.input, cubic, p) else {
                    continue;
                };
                let float = |t| (C::F32, false, t);
                let allowed: Vec<(C, bool, T)> = match path {
                    Property::Translation | Property::Scale => vec![float(T::Vec3)],
                    Property::Rotation => vec![
                        float(T::Vec4),
                        (C::I8, true, T::Vec4),
                        (C::U8, true, T::Vec4),
                        (C::I16, true, T::Vec4),
                        (C::U16, true, T::Vec4),
                    ],
                    Property::MorphTargetWeights => vec![
                        float(T::Scalar),
                        (C::I8, true, T::Scalar),
                        (C::U8, true, T::Scalar),
                        (C::I16, true, T::Scalar),
                        (C::U16, true, T::Scalar),
                    ],
                };
                if self.stride(sampler.output).is_some() {
                    p.error(&here, "the output's bufferView must not have a byteStride");
                }
                let Some(output) = self.format(&here, "output", sampler.output, &allowed, p) else {
                    continue;
                };
                let per_key = if *path == Property::MorphTargetWeights {
                    morphs
                } else {
                    1
                };
                let want = input * per_key * if cubic { 3 } else { 1 };
                if output.count() != want {
                    p.error(
                        &here,
                        format!(
                            "output has {} elements, {input} keys need {want}",
                            output.count()
                        ),
                    );
                } else if *path == Property::Rotation && !cubic {
                    unit_quaternions(&here, output, p);
                }
            }
        }
    }

    /// A sampler input: float scalars with bounds, non-negative, strictly increasing. Returns
    /// the key count.
    fn input(
        &self,
        at: &str,
        index: json::Index<json::Accessor>,
        cubic: bool,
        p: &mut Problems,
    ) -> Option<usize> {
        if !self.has_bounds(index) {
            p.error(at, "input accessor needs min and max");
        }
        if self.stride(index).is_some() {
            p.error(at, "the input's bufferView must not have a byteStride");
        }
        let v = self.format(at, "input", index, &[(C::F32, false, T::Scalar)], p)?;
        if let Some(i) = v.data.iter().position(|&t| t < 0.0) {
            p.error(at, format!("input time {i} is negative: {}", v.data[i]));
        }
        if let Some(i) = v.data.windows(2).position(|w| w[1] <= w[0]) {
            p.error(
                at,
                format!(
                    "input times are not strictly increasing: key {} ({}) after {}",
                    i + 1,
                    v.data[i + 1],
                    v.data[i]
                ),
            );
        }
        if cubic && v.count() < 2 {
            p.error(at, "cubic-spline interpolation needs at least 2 keys");
        }
        Some(v.count())
    }
}

fn unit_vectors(at: &str, v: &Values, p: &mut Problems) {
    if let Some(e) = (0..v.count()).find(|&e| {
        let len = v.element(e).iter().map(|c| c * c).sum::<f64>().sqrt();
        (len - 1.0).abs() > UNIT_VEC3
    }) {
        p.error(
            at,
            format!("normal {e} is not of unit length: {:?}", v.element(e)),
        );
    }
}

fn unit_quaternions(at: &str, v: &Values, p: &mut Problems) {
    if let Some(e) = (0..v.count()).find(|&e| {
        let len = v
            .element(e)
            .iter()
            .map(|&c| v.real(c).powi(2))
            .sum::<f64>()
            .sqrt();
        (len - 1.0).abs() > UNIT_QUAT
    }) {
        p.error(
            at,
            format!(
                "rotation key {e} is not a unit quaternion: {:?}",
                v.element(e)
            ),
        );
    }
}
