//! glTF 2.0 writer: skinned meshes with morph targets and one animation per clip.
//!
//! Morph targets are applied before skinning in glTF, exactly like the baked models, so the file
//! replays `LBS(T + Σ w_k D_k)` without any runtime of ours. `.glb` packs everything in one file;
//! `.gltf` writes the JSON next to a `.bin`.

use crate::asset::{unit_quat, BakedAsset, Mesh, SkelAnimation, SHORT_STEPS};
use crate::atomic::write_atomic;
use gltf_json as json;
use json::validation::{Checked::Valid, USize64};
use std::path::Path;

#[derive(Debug, thiserror::Error)]
pub enum GltfError {
    #[error("{0}")]
    Io(#[from] std::io::Error),
    #[error("cannot write {path}: {reason}")]
    Invalid { path: String, reason: String },
}

/// Writes `asset` to `path`; `.glb` → binary container, anything else → `.gltf` + `.bin`.
pub fn write(asset: &BakedAsset, path: &Path) -> Result<(), GltfError> {
    asset.check().map_err(|reason| GltfError::Invalid {
        path: path.display().to_string(),
        reason,
    })?;
    let binary = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("glb"));
    if binary {
        let (root, bin) = build(asset, None);
        write_atomic(path, &glb_bytes(&root, &bin))?;
    } else {
        let bin_path = path.with_extension("bin");
        let bin_name = bin_path
            .file_name()
            .unwrap_or_default()
            .to_string_lossy()
            .into_owned();
        let (root, bin) = build(asset, Some(bin_name));
        write_atomic(&bin_path, &bin)?;
        let text = json::serialize::to_string_pretty(&root).expect("glTF JSON serialises");
        write_atomic(path, text.as_bytes())?;
    }
    Ok(())
}

/// The `.glb` bytes of `asset` (used by tests and benchmarks without touching the disk).
pub fn to_glb(asset: &BakedAsset) -> Vec<u8> {
    let (root, bin) = build(asset, None);
    glb_bytes(&root, &bin)
}

/// Accumulates the binary buffer and the JSON objects that point into it.
struct Builder {
    root: json::Root,
    bin: Vec<u8>,
}

#[derive(Clone, Copy)]
enum Target {
    None,
    Vertex,
    Index,
}

impl Builder {
    fn view(&mut self, bytes: &[u8], target: Target) -> json::Index<json::buffer::View> {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        let target = match target {
            Target::None => None,
            Target::Vertex => Some(Valid(json::buffer::Target::ArrayBuffer)),
            Target::Index => Some(Valid(json::buffer::Target::ElementArrayBuffer)),
        };
        self.root.push(json::buffer::View {
            buffer: json::Index::new(0),
            byte_length: USize64::from(bytes.len()),
            byte_offset: Some(USize64::from(offset)),
            byte_stride: None,
            name: None,
            target,
            extensions: None,
            extras: Default::default(),
        })
    }

    /// Float accessor over `comps`-wide elements, with min/max when asked (required for POSITION,
    /// morph POSITION deltas and animation inputs).
    fn floats(
        &mut self,
        data: &[f32],
        comps: usize,
        target: Target,
        bounds: bool,
    ) -> json::Index<json::Accessor> {
        let bytes: Vec<u8> = data.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.view(&bytes, target);
        let (min, max) = if bounds {
            min_max(data, comps)
        } else {
            (None, None)
        };
        self.accessor(
            view,
            data.len() / comps,
            json::accessor::ComponentType::F32,
            type_of(comps),
            min,
            max,
        )
    }

    /// SHORT normalized accessor (KHR_mesh_quantization) over `comps`-wide elements in [-1, 1],
    /// each rounded to the nearest `k / SHORT_STEPS`; min/max in the stored integers, as the
    /// spec has bounds in the component type.
    fn shorts(
        &mut self,
        data: &[f32],
        comps: usize,
        target: Target,
    ) -> json::Index<json::Accessor> {
        let ints: Vec<i16> = data
            .iter()
            .map(|v| (v.clamp(-1.0, 1.0) * SHORT_STEPS).round() as i16)
            .collect();
        // Vertex attribute elements start on 4-byte boundaries: a SHORT VEC3 is padded to 8.
        let stride = (2 * comps).next_multiple_of(4);
        let bytes: Vec<u8> = ints
            .chunks_exact(comps)
            .flat_map(|e| {
                let mut element: Vec<u8> = e.iter().flat_map(|v| v.to_le_bytes()).collect();
                element.resize(stride, 0);
                element
            })
            .collect();
        let view = self.view(&bytes, target);
        if stride != 2 * comps {
            self.root.buffer_views[view.value()].byte_stride = Some(json::buffer::Stride(stride));
        }
        let as_f32: Vec<f32> = ints.iter().map(|&k| f32::from(k)).collect();
        let (min, max) = min_max(&as_f32, comps);
        let index = self.accessor(
            view,
            data.len() / comps,
            json::accessor::ComponentType::I16,
            type_of(comps),
            min,
            max,
        );
        self.root.accessors[index.value()].normalized = true;
        index
    }

    fn accessor(
        &mut self,
        view: json::Index<json::buffer::View>,
        count: usize,
        component: json::accessor::ComponentType,
        type_: json::accessor::Type,
        min: Option<json::Value>,
        max: Option<json::Value>,
    ) -> json::Index<json::Accessor> {
        self.root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64::from(count),
            component_type: Valid(json::accessor::GenericComponentType(component)),
            extensions: None,
            extras: Default::default(),
            type_: Valid(type_),
            min,
            max,
            name: None,
            normalized: false,
            sparse: None,
        })
    }
}

fn type_of(comps: usize) -> json::accessor::Type {
    match comps {
        1 => json::accessor::Type::Scalar,
        2 => json::accessor::Type::Vec2,
        3 => json::accessor::Type::Vec3,
        4 => json::accessor::Type::Vec4,
        _ => json::accessor::Type::Mat4,
    }
}

fn min_max(data: &[f32], comps: usize) -> (Option<json::Value>, Option<json::Value>) {
    let mut lo = vec![f32::INFINITY; comps];
    let mut hi = vec![f32::NEG_INFINITY; comps];
    for chunk in data.chunks_exact(comps) {
        for (c, &v) in chunk.iter().enumerate() {
            lo[c] = lo[c].min(v);
            hi[c] = hi[c].max(v);
        }
    }
    (Some(json::Value::from(lo)), Some(json::Value::from(hi)))
}

fn flat<const N: usize>(v: &[[f32; N]]) -> Vec<f32> {
    v.iter().flatten().copied().collect()
}

fn extras(value: serde_json::Value) -> json::Extras {
    Some(serde_json::value::to_raw_value(&value).expect("extras serialise"))
}

fn build(asset: &BakedAsset, bin_uri: Option<String>) -> (json::Root, Vec<u8>) {
    let mut b = Builder {
        root: json::Root::default(),
        bin: Vec::new(),
    };
    b.root.asset.generator = Some(format!("garmentbake {}", env!("CARGO_PKG_VERSION")));
    if !asset.provenance.is_empty() {
        let map: serde_json::Map<_, _> = asset
            .provenance
            .iter()
            .map(|(k, v)| (k.clone(), serde_json::Value::from(v.clone())))
            .collect();
        b.root.asset.extras = extras(serde_json::Value::Object(map));
    }
    if asset
        .meshes
        .iter()
        .any(|m| m.quantized_blend_shapes && !m.blend_shapes.is_empty())
    {
        let name = String::from("KHR_mesh_quantization");
        b.root.extensions_used.push(name.clone());
        b.root.extensions_required.push(name);
    }
    let joint_nodes = add_joints(&mut b, asset);
    let skin = (!joint_nodes.is_empty()).then(|| add_skin(&mut b, asset, &joint_nodes));
    let mut mesh_nodes = Vec::new();
    for mesh in &asset.meshes {
        let m = add_mesh(&mut b, mesh);
        let node = b.root.push(json::Node {
            mesh: Some(m),
            name: Some(mesh.name.clone()),
            skin: mesh.skin.as_ref().and(skin),
            ..Default::default()
        });
        mesh_nodes.push(node);
    }
    for anim in &asset.animations {
        add_animation(&mut b, anim, &joint_nodes, &mesh_nodes);
    }
    let roots = joint_nodes
        .iter()
        .zip(&asset.skeleton.parents)
        .filter(|(_, p)| p.is_none())
        .map(|(n, _)| *n)
        .chain(mesh_nodes.iter().copied())
        .collect();
    let scene = b.root.push(json::Scene {
        nodes: roots,
        name: Some("garmentbake".into()),
        extensions: None,
        extras: None,
    });
    b.root.scene = Some(scene);
    while !b.bin.len().is_multiple_of(4) {
        b.bin.push(0);
    }
    b.root.push(json::Buffer {
        byte_length: USize64::from(b.bin.len()),
        name: None,
        uri: bin_uri,
        extensions: None,
        extras: None,
    });
    (b.root, b.bin)
}

/// One node per joint, in skeleton order, children linked to parents.
fn add_joints(b: &mut Builder, asset: &BakedAsset) -> Vec<json::Index<json::Node>> {
    let sk = &asset.skeleton;
    let nodes: Vec<_> = (0..sk.joint_count())
        .map(|j| {
            b.root.push(json::Node {
                name: Some(sk.joint_names[j].clone()),
                translation: Some(sk.rest_translations[j]),
                rotation: Some(json::scene::UnitQuaternion(sk.rest_rotations[j])),
                ..Default::default()
            })
        })
        .collect();
    for (j, parent) in sk.parents.iter().enumerate() {
        if let Some(p) = parent {
            let children = b.root.nodes[nodes[*p].value()]
                .children
                .get_or_insert_with(Vec::new);
            children.push(nodes[j]);
        }
    }
    nodes
}

fn add_skin(
    b: &mut Builder,
    asset: &BakedAsset,
    joints: &[json::Index<json::Node>],
) -> json::Index<json::Skin> {
    let ibm: Vec<f32> = asset
        .skeleton
        .inverse_bind_matrices
        .iter()
        .flatten()
        .copied()
        .collect();
    let acc = b.floats(&ibm, 16, Target::None, false);
    let root = asset
        .skeleton
        .parents
        .iter()
        .position(|p| p.is_none())
        .map(|r| joints[r]);
    b.root.push(json::Skin {
        extensions: None,
        extras: None,
        inverse_bind_matrices: Some(acc),
        joints: joints.to_vec(),
        name: Some("Skeleton".into()),
        skeleton: root,
    })
}

fn add_mesh(b: &mut Builder, mesh: &Mesh) -> json::Index<json::Mesh> {
    use json::mesh::Semantic;
    let mut attributes = std::collections::BTreeMap::new();
    let pos = b.floats(&flat(&mesh.points), 3, Target::Vertex, true);
    attributes.insert(Valid(Semantic::Positions), pos);
    if let Some(normals) = &mesh.normals {
        attributes.insert(
            Valid(Semantic::Normals),
            b.floats(&flat(normals), 3, Target::Vertex, false),
        );
    }
    for (set, uvs) in [&mesh.uvs, &mesh.uvs2].into_iter().enumerate() {
        if let Some(uvs) = uvs {
            attributes.insert(
                Valid(Semantic::TexCoords(set as u32)),
                b.floats(&flat(uvs), 2, Target::Vertex, false),
            );
        }
    }
    if let Some(skin) = &mesh.skin {
        for (set, (joints, weights)) in skin_sets(skin).into_iter().enumerate() {
            let view = b.view(&joints, Target::Vertex);
            let count = joints.len() / 8; // four u16 per vertex
            let acc = b.accessor(
                view,
                count,
                json::accessor::ComponentType::U16,
                json::accessor::Type::Vec4,
                None,
                None,
            );
            attributes.insert(Valid(Semantic::Joints(set as u32)), acc);
            attributes.insert(
                Valid(Semantic::Weights(set as u32)),
                b.floats(&weights, 4, Target::Vertex, false),
            );
        }
    }
    let indices = add_indices(b, &mesh.triangles, mesh.points.len());
    let targets = (!mesh.blend_shapes.is_empty()).then(|| {
        mesh.blend_shapes
            .iter()
            .map(|shape| json::mesh::MorphTarget {
                positions: Some(if mesh.quantized_blend_shapes {
                    b.shorts(&flat(&shape.offsets), 3, Target::Vertex)
                } else {
                    b.floats(&flat(&shape.offsets), 3, Target::Vertex, true)
                }),
                normals: shape
                    .normal_offsets
                    .as_ref()
                    .map(|n| b.floats(&flat(n), 3, Target::Vertex, false)),
                tangents: None,
            })
            .collect()
    });
    let material = add_material(b, mesh);
    let names: Vec<_> = mesh.blend_shapes.iter().map(|s| s.name.clone()).collect();
    b.root.push(json::Mesh {
        extensions: None,
        extras: mesh_extras(mesh, &names),
        name: Some(mesh.name.clone()),
        primitives: vec![json::mesh::Primitive {
            attributes,
            extensions: None,
            extras: None,
            indices: Some(indices),
            material: Some(material),
            mode: Valid(json::mesh::Mode::Triangles),
            targets,
        }],
        weights: (!names.is_empty()).then(|| match mesh.rest_weights.is_empty() {
            true => vec![0.0; names.len()],
            false => mesh.rest_weights.clone(),
        }),
    })
}

/// The mesh's extras: blend-shape names (three.js, Blender read `targetNames`) and, when the
/// vertices were split at UV seams, `sourceVertex`: each vertex's index in the source mesh, the
/// order point caches of the same garment keep (`garmentbake view` plays them on this mesh).
fn mesh_extras(mesh: &Mesh, names: &[String]) -> json::Extras {
    let mut map = serde_json::Map::new();
    if !names.is_empty() {
        map.insert("targetNames".into(), serde_json::json!(names));
    }
    let identity = mesh
        .source_vertex
        .iter()
        .enumerate()
        .all(|(i, &s)| i == s as usize);
    if !identity {
        map.insert("sourceVertex".into(), serde_json::json!(mesh.source_vertex));
    }
    (!map.is_empty())
        .then(|| extras(serde_json::Value::Object(map)))
        .flatten()
}

/// JOINTS_n / WEIGHTS_n sets of 4; empty slots point at joint 0 with weight 0.
fn skin_sets(skin: &crate::asset::SkinBinding) -> Vec<(Vec<u8>, Vec<f32>)> {
    let sets = skin.influences.div_ceil(4).max(1);
    let n = skin.joint_indices.len() / skin.influences.max(1);
    let mut out = vec![(Vec::with_capacity(n * 8), Vec::with_capacity(n * 4)); sets];
    for v in 0..n {
        for (s, (joints, weights)) in out.iter_mut().enumerate() {
            for slot in 0..4 {
                let k = s * 4 + slot;
                let (j, w) = if k < skin.influences {
                    let i = v * skin.influences + k;
                    (skin.joint_indices[i], skin.joint_weights[i])
                } else {
                    (0, 0.0)
                };
                let j = if w == 0.0 { 0 } else { j };
                joints.extend_from_slice(&j.to_le_bytes());
                weights.push(w);
            }
        }
    }
    out
}

fn add_indices(
    b: &mut Builder,
    triangles: &[[u32; 3]],
    vertex_count: usize,
) -> json::Index<json::Accessor> {
    let count = triangles.len() * 3;
    let indices = triangles.iter().flatten();
    // Small meshes get 16-bit indices (half the bytes, and what every client reads fastest).
    let (bytes, component): (Vec<u8>, _) = if vertex_count <= u16::MAX as usize {
        let bytes = indices.flat_map(|&i| (i as u16).to_le_bytes()).collect();
        (bytes, json::accessor::ComponentType::U16)
    } else {
        let bytes = indices.flat_map(|&i| i.to_le_bytes()).collect();
        (bytes, json::accessor::ComponentType::U32)
    };
    let view = b.view(&bytes, Target::Index);
    b.accessor(
        view,
        count,
        component,
        json::accessor::Type::Scalar,
        None,
        None,
    )
}

fn add_material(b: &mut Builder, mesh: &Mesh) -> json::Index<json::Material> {
    let [r, g, bl] = mesh.color;
    let mut material = json::Material {
        name: Some(format!("{}_material", mesh.name)),
        // Garments are open surfaces: both sides must render.
        double_sided: true,
        ..Default::default()
    };
    material.pbr_metallic_roughness.base_color_factor =
        json::material::PbrBaseColorFactor([r, g, bl, 1.0]);
    material.pbr_metallic_roughness.metallic_factor = json::material::StrengthFactor(0.0);
    material.pbr_metallic_roughness.roughness_factor = json::material::StrengthFactor(0.9);
    b.root.push(material)
}

fn add_animation(
    b: &mut Builder,
    anim: &SkelAnimation,
    joint_nodes: &[json::Index<json::Node>],
    mesh_nodes: &[json::Index<json::Node>],
) {
    use json::animation::{Channel, Interpolation, Property, Sampler, Target as ATarget};
    let times: Vec<f32> = (0..anim.frame_count).map(|f| anim.time(f)).collect();
    let input = b.floats(&times, 1, Target::None, true);
    let joints = joint_nodes.len();
    let mut samplers = Vec::new();
    let mut channels = Vec::new();
    let mut push = |b: &mut Builder, node, path, data: Vec<f32>, comps| {
        let output = b.floats(&data, comps, Target::None, false);
        let sampler = json::Index::push(
            &mut samplers,
            Sampler {
                extensions: None,
                extras: None,
                input,
                interpolation: Valid(Interpolation::Linear),
                output,
            },
        );
        channels.push(Channel {
            sampler,
            target: ATarget {
                extensions: None,
                extras: None,
                node,
                path: Valid(path),
            },
            extensions: None,
            extras: None,
        });
    };
    for (j, &node) in joint_nodes.iter().enumerate() {
        let track = |f: usize| f * joints + j;
        let moves =
            (1..anim.frame_count).any(|f| anim.translations[track(f)] != anim.translations[j]);
        if moves {
            let data = (0..anim.frame_count)
                .flat_map(|f| anim.translations[track(f)])
                .collect();
            push(b, node, Property::Translation, data, 3);
        }
        let data = (0..anim.frame_count)
            .flat_map(|f| unit_quat(anim.rotations[track(f)]))
            .collect();
        push(b, node, Property::Rotation, data, 4);
    }
    for (mesh, weights) in &anim.blend_shape_weights {
        push(
            b,
            mesh_nodes[*mesh],
            Property::MorphTargetWeights,
            weights.clone(),
            1,
        );
    }
    b.root.push(json::Animation {
        extensions: None,
        extras: None,
        channels,
        name: Some(anim.name.clone()),
        samplers,
    });
}

fn glb_bytes(root: &json::Root, bin: &[u8]) -> Vec<u8> {
    let mut text = json::serialize::to_vec(root).expect("glTF JSON serialises");
    while !text.len().is_multiple_of(4) {
        text.push(b' ');
    }
    let total = 12 + 8 + text.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(text.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&text);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(bin);
    out
}
