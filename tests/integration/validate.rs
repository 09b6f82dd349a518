//! `garmentbake validate` against the Khronos glTF validator: a corpus of corruptions of a
//! correct bake, generated here, each judged by both; every file Khronos reports an error for
//! must fail ours, and every file Khronos accepts must pass ours. The confusion table (docs/validate.md) is printed by
//! `cargo test --test integration validate::khronos_corpus -- --nocapture`.

use crate::bake::bake;
use crate::common::*;
use garmentbake::validate::{check_gltf, Problems};
use serde_json::{json, Value};
use std::path::Path;

/// A GLB taken apart: its JSON and its BIN chunk, to corrupt either and put back together.
#[derive(Clone)]
struct Glb {
    json: Value,
    bin: Vec<u8>,
}

impl Glb {
    fn read(bytes: &[u8]) -> Glb {
        let len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
        let json = serde_json::from_slice(&bytes[20..20 + len]).unwrap();
        let bin_len = u32::from_le_bytes(bytes[20 + len..24 + len].try_into().unwrap()) as usize;
        let bin = bytes[28 + len..28 + len + bin_len].to_vec();
        Glb { json, bin }
    }

    fn bytes(&self) -> Vec<u8> {
        let mut text = serde_json::to_vec(&self.json).unwrap();
        while !text.len().is_multiple_of(4) {
            text.push(b' ');
        }
        let mut bin = self.bin.clone();
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        glb(&text, &bin)
    }

    /// Accessor index of the garment's attribute `name` (mesh 0, primitive 0).
    fn attribute(&self, name: &str) -> usize {
        self.json["meshes"][0]["primitives"][0]["attributes"][name]
            .as_u64()
            .unwrap() as usize
    }

    /// Sets `key` of the accessor of the garment's attribute `name`.
    fn set_attribute_key(&mut self, name: &str, key: &str, value: Value) {
        let a = self.attribute(name);
        self.json["accessors"][a][key] = value;
    }

    /// Byte offset in BIN of component `c` of element `e` of a tightly packed accessor.
    fn at(&self, accessor: usize, e: usize, c: usize) -> usize {
        let a = &self.json["accessors"][accessor];
        let view = &self.json["bufferViews"][a["bufferView"].as_u64().unwrap() as usize];
        let size = match a["componentType"].as_u64().unwrap() {
            5120 | 5121 => 1,
            5122 | 5123 => 2,
            _ => 4,
        };
        let comps = match a["type"].as_str().unwrap() {
            "SCALAR" => 1,
            "VEC2" => 2,
            "VEC3" => 3,
            "VEC4" => 4,
            _ => 16,
        };
        let base = view["byteOffset"].as_u64().unwrap_or(0) + a["byteOffset"].as_u64().unwrap_or(0);
        base as usize + (e * comps + c) * size
    }

    fn f32(&self, accessor: usize, e: usize, c: usize) -> f32 {
        let o = self.at(accessor, e, c);
        f32::from_le_bytes(self.bin[o..o + 4].try_into().unwrap())
    }

    fn set_f32(&mut self, accessor: usize, e: usize, c: usize, v: f32) {
        let o = self.at(accessor, e, c);
        self.bin[o..o + 4].copy_from_slice(&v.to_le_bytes());
    }

    fn set_u16(&mut self, accessor: usize, e: usize, c: usize, v: u16) {
        let o = self.at(accessor, e, c);
        self.bin[o..o + 2].copy_from_slice(&v.to_le_bytes());
    }

    /// Appends `bytes` to BIN as a new buffer view; returns its index.
    fn append_view(&mut self, bytes: &[u8]) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        self.json["buffers"][0]["byteLength"] = json!(self.bin.len());
        let views = self.json["bufferViews"].as_array_mut().unwrap();
        views.push(json!({"buffer": 0, "byteOffset": offset, "byteLength": bytes.len()}));
        views.len() - 1
    }

    /// The first animation sampler whose channel animates `path`.
    fn sampler(&self, path: &str) -> usize {
        let channels = self.json["animations"][0]["channels"].as_array().unwrap();
        let c = channels
            .iter()
            .find(|c| c["target"]["path"] == path)
            .unwrap();
        c["sampler"].as_u64().unwrap() as usize
    }

    fn sampler_accessor(&self, path: &str, which: &str) -> usize {
        let s = self.sampler(path);
        self.json["animations"][0]["samplers"][s][which]
            .as_u64()
            .unwrap() as usize
    }

    /// The first vertex with at least two non-zero weights.
    fn shared_vertex(&self) -> usize {
        let w = self.attribute("WEIGHTS_0");
        (0..).find(|&v| self.f32(w, v, 1) > 0.0).unwrap()
    }
}

/// Rewrites the first morph target's POSITION as SHORT normalized (KHR_mesh_quantization's
/// format) in a new view of `stride` bytes per element (8: three SHORTs padded to 4-byte
/// alignment; 6: packed, unaligned), the extension declared when `declare`.
fn quantize_first_target(g: &mut Glb, stride: usize, declare: bool) {
    let a = g.json["meshes"][0]["primitives"][0]["targets"][0]["POSITION"]
        .as_u64()
        .unwrap() as usize;
    let count = g.json["accessors"][a]["count"].as_u64().unwrap() as usize;
    let floats: Vec<f32> = (0..count * 3).map(|i| g.f32(a, i / 3, i % 3)).collect();
    let scale = floats.iter().fold(0.0f32, |m, v| m.max(v.abs())).max(1e-9);
    let ints: Vec<i16> = floats
        .iter()
        .map(|v| (v / scale * 32767.0).round() as i16)
        .collect();
    let mut bytes = Vec::new();
    for e in ints.chunks_exact(3) {
        e.iter()
            .for_each(|v| bytes.extend_from_slice(&v.to_le_bytes()));
        bytes.resize(bytes.len() + stride - 6, 0);
    }
    let view = g.append_view(&bytes);
    if stride != 6 {
        g.json["bufferViews"][view]["byteStride"] = json!(stride);
    }
    g.json["bufferViews"][view]["target"] = json!(34962);
    let bound = |pick: fn(i16, i16) -> i16, c: usize| {
        ints.iter()
            .skip(c)
            .step_by(3)
            .copied()
            .reduce(pick)
            .unwrap()
    };
    let acc = g.json["accessors"][a].as_object_mut().unwrap();
    acc.remove("byteOffset");
    acc.insert("bufferView".into(), json!(view));
    acc.insert("componentType".into(), json!(5122));
    acc.insert("normalized".into(), json!(true));
    acc.insert(
        "min".into(),
        json!((0..3).map(|c| bound(i16::min, c)).collect::<Vec<_>>()),
    );
    acc.insert(
        "max".into(),
        json!((0..3).map(|c| bound(i16::max, c)).collect::<Vec<_>>()),
    );
    if declare {
        g.json["extensionsUsed"] = json!(["KHR_mesh_quantization"]);
        g.json["extensionsRequired"] = json!(["KHR_mesh_quantization"]);
    }
}

fn glb(text: &[u8], bin: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&((28 + text.len() + bin.len()) as u32).to_le_bytes());
    out.extend_from_slice(&(text.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(text);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(bin);
    out
}

enum Edit {
    /// A change to the document or the data, repacked as a well-formed GLB.
    Doc(fn(&mut Glb)),
    /// A change to the container's bytes.
    Bytes(fn(Vec<u8>) -> Vec<u8>),
}

/// The corruptions, each named for the rule it breaks (plus two harmless edits and one
/// SHOULD-level one, so the table has both kinds of row).
fn corpus() -> Vec<(&'static str, Edit)> {
    use Edit::*;
    vec![
        (
            "harmless_rename",
            Doc(|g| g.json["nodes"][0]["name"] = json!("renamed")),
        ),
        (
            "harmless_extra_weights_key",
            Doc(|g| g.json["asset"]["extras"] = json!({"note": 1})),
        ),
        (
            "zero_weight_nonzero_joint",
            Doc(|g| {
                let (j, w) = (g.attribute("JOINTS_0"), g.attribute("WEIGHTS_0"));
                let v = (0..).find(|&v| g.f32(w, v, 3) == 0.0).unwrap();
                g.set_u16(j, v, 3, 5);
            }),
        ),
        (
            "bad_json",
            Bytes(|b| {
                let g = Glb::read(&b);
                glb(b"{\"asset\": {\"version\": \"2.0\"},   ", &g.bin)
            }),
        ),
        (
            "json_schema_type",
            Doc(|g| g.json["accessors"][0]["count"] = json!("many")),
        ),
        (
            "missing_asset",
            Doc(|g| {
                g.json.as_object_mut().unwrap().remove("asset");
            }),
        ),
        (
            "asset_version_1",
            Doc(|g| g.json["asset"]["version"] = json!("1.0")),
        ),
        (
            "bad_magic",
            Bytes(|mut b| {
                b[3] = b'X';
                b
            }),
        ),
        (
            "glb_version_1",
            Bytes(|mut b| {
                b[4] = 1;
                b
            }),
        ),
        (
            "glb_length_mismatch",
            Bytes(|mut b| {
                b.extend_from_slice(&[0; 8]);
                b
            }),
        ),
        (
            "truncated_file",
            Bytes(|mut b| {
                b.truncate(b.len() - 1000);
                b
            }),
        ),
        (
            "truncated_bin_chunk",
            Bytes(|b| {
                let g = Glb::read(&b);
                let text = serde_json::to_vec(&g.json).unwrap();
                let mut text = text;
                while !text.len().is_multiple_of(4) {
                    text.push(b' ');
                }
                glb(&text, &g.bin[..g.bin.len() - 4096])
            }),
        ),
        (
            "unaligned_json_chunk",
            Bytes(|b| {
                let g = Glb::read(&b);
                let mut text = serde_json::to_vec(&g.json).unwrap();
                if text.len().is_multiple_of(4) {
                    text.push(b' ');
                }
                glb(&text, &g.bin)
            }),
        ),
        (
            "bin_chunk_first",
            Bytes(|b| {
                let g = Glb::read(&b);
                let mut out = b"glTF".to_vec();
                out.extend_from_slice(&2u32.to_le_bytes());
                out.extend_from_slice(&((12 + 8 + g.bin.len()) as u32).to_le_bytes());
                out.extend_from_slice(&(g.bin.len() as u32).to_le_bytes());
                out.extend_from_slice(b"BIN\0");
                out.extend_from_slice(&g.bin);
                out
            }),
        ),
        (
            "buffer_view_past_buffer",
            Doc(|g| {
                let len = g.json["buffers"][0]["byteLength"].as_u64().unwrap();
                g.json["bufferViews"][1]["byteOffset"] = json!(len - 8);
            }),
        ),
        (
            "buffer_view_length_huge",
            Doc(|g| g.json["bufferViews"][2]["byteLength"] = json!(1u64 << 40)),
        ),
        (
            "byte_stride_3",
            Doc(|g| {
                let view = g.json["accessors"][g.attribute("NORMAL")]["bufferView"].clone();
                g.json["bufferViews"][view.as_u64().unwrap() as usize]["byteStride"] = json!(3);
            }),
        ),
        (
            "accessor_count_past_view",
            Doc(|g| {
                let a = g.attribute("POSITION");
                let n = g.json["accessors"][a]["count"].as_u64().unwrap();
                g.json["accessors"][a]["count"] = json!(n + 1000);
            }),
        ),
        (
            "attribute_counts_differ",
            Doc(|g| {
                let a = g.attribute("NORMAL");
                let n = g.json["accessors"][a]["count"].as_u64().unwrap();
                g.json["accessors"][a]["count"] = json!(n - 1);
            }),
        ),
        (
            "accessor_offset_misaligned",
            Doc(|g| g.set_attribute_key("TEXCOORD_0", "byteOffset", json!(2))),
        ),
        (
            "position_type_vec2",
            Doc(|g| g.set_attribute_key("POSITION", "type", json!("VEC2"))),
        ),
        (
            "position_component_ushort",
            Doc(|g| g.set_attribute_key("POSITION", "componentType", json!(5123))),
        ),
        (
            "texcoord_type_scalar",
            Doc(|g| g.set_attribute_key("TEXCOORD_0", "type", json!("SCALAR"))),
        ),
        (
            "joints_as_float",
            Doc(|g| {
                let a = g.attribute("JOINTS_0");
                g.json["accessors"][a]["componentType"] = json!(5126);
                let n = g.json["accessors"][a]["count"].as_u64().unwrap();
                g.json["accessors"][a]["count"] = json!(n / 2);
            }),
        ),
        (
            "position_nan",
            Doc(|g| {
                let a = g.attribute("POSITION");
                g.set_f32(a, 7, 1, f32::NAN);
            }),
        ),
        (
            "position_max_wrong",
            Doc(|g| {
                let a = g.attribute("POSITION");
                g.json["accessors"][a]["max"][1] = json!(9.0);
            }),
        ),
        (
            "position_without_bounds",
            Doc(|g| {
                let a = g.attribute("POSITION");
                let acc = g.json["accessors"][a].as_object_mut().unwrap();
                acc.remove("min");
                acc.remove("max");
            }),
        ),
        (
            "normal_not_unit",
            Doc(|g| {
                let a = g.attribute("NORMAL");
                for c in 0..3 {
                    let v = g.f32(a, 3, c);
                    g.set_f32(a, 3, c, 2.0 * v);
                }
            }),
        ),
        (
            "index_past_vertices",
            Doc(|g| {
                let prim = &g.json["meshes"][0]["primitives"][0];
                let a = prim["indices"].as_u64().unwrap() as usize;
                let n = g.json["accessors"][g.attribute("POSITION")]["count"]
                    .as_u64()
                    .unwrap();
                g.set_u16(a, 4, 0, n as u16);
            }),
        ),
        (
            "joint_index_past_skin",
            Doc(|g| {
                let a = g.attribute("JOINTS_0");
                g.set_u16(a, 0, 0, 200);
            }),
        ),
        (
            "joint_index_duplicate",
            Doc(|g| {
                let (j, v) = (g.attribute("JOINTS_0"), g.shared_vertex());
                let first =
                    u16::from_le_bytes(g.bin[g.at(j, v, 0)..g.at(j, v, 0) + 2].try_into().unwrap());
                g.set_u16(j, v, 1, first);
            }),
        ),
        (
            "weights_unnormalised",
            Doc(|g| {
                let w = g.attribute("WEIGHTS_0");
                for c in 0..4 {
                    let x = g.f32(w, 10, c);
                    g.set_f32(w, 10, c, 1.5 * x);
                }
            }),
        ),
        (
            "weight_negative",
            Doc(|g| {
                let (w, v) = (g.attribute("WEIGHTS_0"), g.shared_vertex());
                let (a, b) = (g.f32(w, v, 0), g.f32(w, v, 1));
                g.set_f32(w, v, 0, a + 2.0 * b);
                g.set_f32(w, v, 1, -b);
            }),
        ),
        (
            "skin_removed_joints_attribute",
            Doc(|g| {
                let attrs = g.json["meshes"][0]["primitives"][0]["attributes"]
                    .as_object_mut()
                    .unwrap();
                attrs.remove("JOINTS_0");
                attrs.remove("WEIGHTS_0");
            }),
        ),
        (
            "morph_target_tangent_without_base",
            Doc(|g| {
                let n = g.attribute("NORMAL");
                g.json["meshes"][0]["primitives"][0]["targets"][0]["TANGENT"] = json!(n);
            }),
        ),
        (
            "harmless_quantized_morph_target",
            Doc(|g| quantize_first_target(g, 8, true)),
        ),
        (
            "quantized_morph_target_without_extension",
            Doc(|g| quantize_first_target(g, 8, false)),
        ),
        (
            "quantized_morph_target_unaligned",
            Doc(|g| quantize_first_target(g, 6, true)),
        ),
        (
            "morph_target_wrong_count",
            Doc(|g| {
                let a = g.json["meshes"][0]["primitives"][0]["targets"][1]["POSITION"]
                    .as_u64()
                    .unwrap() as usize;
                let n = g.json["accessors"][a]["count"].as_u64().unwrap();
                g.json["accessors"][a]["count"] = json!(n / 2);
                let acc = g.json["accessors"][a].as_object_mut().unwrap();
                acc.remove("min");
                acc.remove("max");
                acc.insert("min".into(), json!([-1.0, -1.0, -1.0]));
                acc.insert("max".into(), json!([1.0, 1.0, 1.0]));
            }),
        ),
        (
            "primitives_unequal_targets",
            Doc(|g| {
                let mut second = g.json["meshes"][0]["primitives"][0].clone();
                second["targets"].as_array_mut().unwrap().truncate(3);
                g.json["meshes"][0]["primitives"]
                    .as_array_mut()
                    .unwrap()
                    .push(second);
            }),
        ),
        (
            "mesh_weights_length",
            Doc(|g| {
                g.json["meshes"][0]["weights"]
                    .as_array_mut()
                    .unwrap()
                    .push(json!(0.0))
            }),
        ),
        (
            "sparse_index_past_count",
            Doc(|g| {
                let a = g.attribute("POSITION");
                let n = g.json["accessors"][a]["count"].as_u64().unwrap() as u16;
                let iv = g.append_view(&(n + 5).to_le_bytes());
                let vv = g.append_view(&[0u8; 12]);
                g.json["accessors"][a]["sparse"] = json!({"count": 1, "indices": {"bufferView": iv, "componentType": 5123}, "values": {"bufferView": vv}});
            }),
        ),
        (
            "sparse_indices_decreasing",
            Doc(|g| {
                let a = g.attribute("POSITION");
                let idx: Vec<u8> = [9u16, 4].iter().flat_map(|i| i.to_le_bytes()).collect();
                let iv = g.append_view(&idx);
                let values: Vec<u8> = (0..6)
                    .flat_map(|k| {
                        let (e, c) = (if k < 3 { 9 } else { 4 }, k % 3);
                        g.f32(a, e, c).to_le_bytes()
                    })
                    .collect();
                let vv = g.append_view(&values);
                g.json["accessors"][a]["sparse"] = json!({"count": 2, "indices": {"bufferView": iv, "componentType": 5123}, "values": {"bufferView": vv}});
            }),
        ),
        (
            "node_loop",
            Doc(|g| g.json["nodes"][3]["children"] = json!([0])),
        ),
        (
            "node_two_parents",
            Doc(|g| {
                let child = g.json["nodes"][2]["children"][0].clone();
                let children = &mut g.json["nodes"][5]["children"];
                match children.as_array_mut() {
                    Some(c) => c.push(child),
                    None => *children = json!([child]),
                }
            }),
        ),
        (
            "scene_lists_child_node",
            Doc(|g| {
                g.json["scenes"][0]["nodes"]
                    .as_array_mut()
                    .unwrap()
                    .push(json!(1))
            }),
        ),
        (
            "node_rotation_not_unit",
            Doc(|g| g.json["nodes"][1]["rotation"] = json!([0.0, 0.0, 0.0, 2.0])),
        ),
        (
            "node_matrix_and_trs",
            Doc(|g| {
                g.json["nodes"][1]["matrix"] = json!([
                    1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0
                ])
            }),
        ),
        (
            "skin_joint_missing_node",
            Doc(|g| g.json["skins"][0]["joints"][3] = json!(9999)),
        ),
        (
            "skin_joint_listed_twice",
            Doc(|g| g.json["skins"][0]["joints"][3] = json!(2)),
        ),
        (
            "skin_ibm_too_few",
            Doc(|g| {
                let a = g.json["skins"][0]["inverseBindMatrices"].as_u64().unwrap() as usize;
                let n = g.json["accessors"][a]["count"].as_u64().unwrap();
                g.json["accessors"][a]["count"] = json!(n - 2);
            }),
        ),
        (
            "skin_skeleton_not_root",
            Doc(|g| g.json["skins"][0]["skeleton"] = json!(5)),
        ),
        (
            "sampler_input_not_increasing",
            Doc(|g| {
                let a = g.sampler_accessor("rotation", "input");
                let (t4, t5) = (g.f32(a, 4, 0), g.f32(a, 5, 0));
                g.set_f32(a, 4, 0, t5);
                g.set_f32(a, 5, 0, t4);
            }),
        ),
        (
            "sampler_input_negative",
            Doc(|g| {
                let a = g.sampler_accessor("rotation", "input");
                g.set_f32(a, 0, 0, -0.5);
                g.json["accessors"][a]["min"] = json!([-0.5]);
            }),
        ),
        (
            "sampler_input_without_bounds",
            Doc(|g| {
                let a = g.sampler_accessor("rotation", "input");
                g.json["accessors"][a]
                    .as_object_mut()
                    .unwrap()
                    .remove("max");
            }),
        ),
        (
            "sampler_output_count",
            Doc(|g| {
                let a = g.sampler_accessor("rotation", "output");
                let n = g.json["accessors"][a]["count"].as_u64().unwrap();
                g.json["accessors"][a]["count"] = json!(n - 1);
            }),
        ),
        (
            "sampler_cubic_without_tangents",
            Doc(|g| {
                let s = g.sampler("rotation");
                g.json["animations"][0]["samplers"][s]["interpolation"] = json!("CUBICSPLINE");
            }),
        ),
        (
            "rotation_output_vec3",
            Doc(|g| {
                let a = g.sampler_accessor("rotation", "output");
                g.json["accessors"][a]["type"] = json!("VEC3");
            }),
        ),
        (
            "rotation_key_not_unit",
            Doc(|g| {
                let a = g.sampler_accessor("rotation", "output");
                g.set_f32(a, 2, 3, 3.0);
            }),
        ),
        (
            "weights_output_count",
            Doc(|g| {
                let a = g.sampler_accessor("weights", "output");
                let n = g.json["accessors"][a]["count"].as_u64().unwrap();
                g.json["accessors"][a]["count"] = json!(n - 32);
            }),
        ),
        (
            "channel_duplicate_target",
            Doc(|g| {
                let c = g.json["animations"][0]["channels"][1].clone();
                g.json["animations"][0]["channels"]
                    .as_array_mut()
                    .unwrap()
                    .push(c);
            }),
        ),
        (
            "channel_node_missing",
            Doc(|g| g.json["animations"][0]["channels"][0]["target"]["node"] = json!(4000)),
        ),
        (
            "channel_weights_on_joint",
            Doc(|g| {
                let channels = g.json["animations"][0]["channels"].as_array_mut().unwrap();
                let c = channels
                    .iter_mut()
                    .find(|c| c["target"]["path"] == "weights")
                    .unwrap();
                c["target"]["node"] = json!(3);
            }),
        ),
        (
            "channel_sampler_missing",
            Doc(|g| g.json["animations"][0]["channels"][0]["sampler"] = json!(777)),
        ),
    ]
}

/// One line per corpus file from tools/node/validate.mjs --each.
fn khronos_each(files: &[std::path::PathBuf]) -> Vec<Value> {
    let out = run_ok(
        std::process::Command::new("node")
            .arg(root().join("tools/node/validate.mjs"))
            .arg("--each")
            .args(files),
    );
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

fn ours(path: &Path) -> Problems {
    ours_bytes(path, &std::fs::read(path).unwrap())
}

#[test]
fn khronos_corpus() {
    let dir = out_dir("validate_corpus");
    let base_path = bake(&dir, "base.glb", &[]);
    let base = std::fs::read(&base_path).unwrap();
    let corpus = corpus();
    let mut files = vec![base_path.clone()];
    for (i, (name, edit)) in corpus.iter().enumerate() {
        let bytes = match edit {
            Edit::Doc(f) => {
                let mut g = Glb::read(&base);
                f(&mut g);
                g.bytes()
            }
            Edit::Bytes(f) => f(base.clone()),
        };
        let path = dir.join(format!("{i:02}_{name}.glb"));
        std::fs::write(&path, bytes).unwrap();
        files.push(path);
    }
    // A file another tool quantized (gltfpack's defaults: integer positions, byte normals,
    // byte/short morph deltas, the dequantization folded into the skin): both must pass it.
    let packed = dir.join(format!("{:02}_harmless_gltfpack.glb", corpus.len()));
    run_ok(
        std::process::Command::new(root().join("tools/node/node_modules/.bin/gltfpack"))
            .arg("-i")
            .arg(&base_path)
            .arg("-o")
            .arg(&packed),
    );
    files.push(packed);
    let khronos = khronos_each(&files);
    let mut rows = String::from(
        "| file | Khronos errors | Khronos codes | ours | our first error |\n|---|---|---|---|---|\n",
    );
    let mut cells = [[0usize; 2]; 2]; // [khronos error][ours fail]
    let (mut missed, mut ours_alone) = (Vec::new(), Vec::new());
    for (path, k) in files.iter().zip(&khronos) {
        let p = ours(path);
        let k_err = k["errors"].as_u64().unwrap() > 0;
        let fail = !p.passed();
        let name = path.file_name().unwrap().to_string_lossy();
        if name.contains("_harmless") {
            assert!(!k_err && !fail, "{name}: Khronos {k}, ours {:?}", p.errors);
        }
        cells[k_err as usize][fail as usize] += 1;
        if k_err && !fail {
            missed.push(path.file_name().unwrap().to_string_lossy().into_owned());
        }
        if fail && !k_err {
            ours_alone.push(path.file_name().unwrap().to_string_lossy().into_owned());
        }
        let codes: Vec<&str> = k["codes"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c.as_str().unwrap())
            .collect();
        let first = p
            .errors
            .first()
            .map(|e| format!("`{}` {}", e.at, e.message))
            .unwrap_or_else(|| {
                p.warnings
                    .first()
                    .map(|w| format!("(warning) {}", w.message))
                    .unwrap_or_default()
            });
        rows.push_str(&format!(
            "| {} | {} | {} | {} | {} |\n",
            path.file_name().unwrap().to_string_lossy(),
            k["errors"],
            codes.join(" "),
            if fail { "fail" } else { "pass" },
            first.replace('|', "\\|")
        ));
    }
    let table = format!(
        "|  | ours: fail | ours: pass |\n|---|---|---|\n| Khronos: error | {} | {} |\n| Khronos: no error | {} | {} |\n\n{rows}",
        cells[1][1], cells[1][0], cells[0][1], cells[0][0]
    );
    std::fs::write(dir.join("table.md"), &table).unwrap();
    println!("{table}");
    assert!(corpus.len() >= 30);
    assert!(ours(&base_path).passed(), "the correct bake must pass");
    assert_eq!(khronos[0]["errors"], 0, "the correct bake passes Khronos");
    assert!(
        missed.is_empty(),
        "Khronos reports errors our validate passes: {missed:?}"
    );
    // And the other way (docs/validate.md: "no file is rejected by us alone"), for every file,
    // not only the harmless ones.
    assert!(
        ours_alone.is_empty(),
        "our validate rejects files Khronos accepts: {ours_alone:?}"
    );
    assert!(
        cells[1][1] >= 30,
        "at least 30 corruptions Khronos rejects: {cells:?}"
    );
    // The command: exit 0 on the correct bake, 1 (with the problem, as JSON) on a corrupt one,
    // 2 on a file it cannot read at all.
    assert!(garmentbake(&["validate", base_path.to_str().unwrap()])
        .status
        .success());
    let nan = dir.join("24_position_nan.glb");
    let out = garmentbake(&["validate", nan.to_str().unwrap(), "--json"]);
    assert_eq!(out.status.code(), Some(1));
    let report: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(report["passed"], false);
    assert!(
        report["errors"][0]["message"]
            .as_str()
            .unwrap()
            .contains("NaN"),
        "{report}"
    );
    let missing = dir.join("missing.glb");
    let err = one_error_line(
        &garmentbake(&["validate", missing.to_str().unwrap()]),
        &missing,
    );
    assert!(err.contains("missing.glb"), "{err}");
}

/// The bake's morph offsets (every target's POSITION) multiplied by `scale`, bounds updated so
/// the file stays structurally valid.
fn scale_morphs(base: &[u8], scale: f32) -> Vec<u8> {
    let mut g = Glb::read(base);
    let targets = g.json["meshes"][0]["primitives"][0]["targets"].clone();
    for t in targets.as_array().unwrap() {
        let a = t["POSITION"].as_u64().unwrap() as usize;
        let n = g.json["accessors"][a]["count"].as_u64().unwrap() as usize;
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for e in 0..n {
            for c in 0..3 {
                let v = g.f32(a, e, c) * scale;
                g.set_f32(a, e, c, v);
                (lo[c], hi[c]) = (lo[c].min(v), hi[c].max(v));
            }
        }
        g.json["accessors"][a]["min"] = json!(lo);
        g.json["accessors"][a]["max"] = json!(hi);
    }
    g.bytes()
}

fn validate_against_model(file: &Path, fps: &str, extra: &[&str]) -> (Option<i32>, Value) {
    let mut args = vec![
        "validate",
        file.to_str().unwrap(),
        "--model",
        crate::bake::model().to_str().unwrap(),
        "--motion",
        crate::bake::s("motions/131_02.bvh"),
        "--fps",
        fps,
        "--threads",
        "1",
        "--json",
    ];
    args.extend_from_slice(extra);
    let out = garmentbake(&args);
    let report = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!("{e}: {}", String::from_utf8_lossy(&out.stderr));
    });
    (out.status.code(), report)
}

#[test]
fn replay_against_the_model() {
    let dir = out_dir("validate_replay");
    // bake --validate runs the same checks on what it wrote (exit 0 when they pass).
    let base_path = bake(&dir, "base.glb", &["--validate"]);
    let base = std::fs::read(&base_path).unwrap();
    let (code, good) = validate_against_model(&base_path, "30", &[]);
    assert_eq!(code, Some(0), "{good}");
    let r = &good["replay"];
    assert_eq!(r["frames"], 312);
    // Measured 0.0020 mm (f32 noise of the full-basis bake against the network's forward pass).
    assert!(r["max_mm"].as_f64().unwrap() < 0.02, "{r}");

    // Offsets ×1.5: structurally valid (Khronos and ours agree), but the replay is off by half
    // the morph displacement and fails the default 1 mm tolerance, with the error in mm. (The
    // weights run from 0 since stop 34, the rest of each target's offset sits in the base mesh:
    // ×1.05 now moves this test model's garment only 0.23 mm.)
    let scaled = dir.join("morphs_x1.5.glb");
    std::fs::write(&scaled, scale_morphs(&base, 1.5)).unwrap();
    let (ok, summary) = khronos_validate(&scaled);
    assert!(ok, "{summary}");
    let png = dir.join("worst.png");
    let (code, bad) = validate_against_model(&scaled, "30", &["--png", png.to_str().unwrap()]);
    assert_eq!(code, Some(1), "{bad}");
    let e50 = bad["replay"]["max_mm"].as_f64().unwrap();
    assert!(e50 > 1.0, "{bad}");
    let message = bad["errors"][0]["message"].as_str().unwrap();
    assert!(message.contains(&format!("{e50:.3} mm")), "{message}");
    assert!(image::open(&png).is_ok(), "the worst frame picture");

    // The error is linear in the scale: ×2 (the whole displacement again) is twice ×1.5's.
    let doubled = dir.join("morphs_x2.glb");
    std::fs::write(&doubled, scale_morphs(&base, 2.0)).unwrap();
    let (_, twice) = validate_against_model(&doubled, "30", &[]);
    let e100 = twice["replay"]["max_mm"].as_f64().unwrap();
    assert!(
        (e100 / e50 - 2.0).abs() < 0.02,
        "x2: {e100} mm, x1.5: {e50} mm"
    );
}

/// Runs `validate FILE --json [extra]`: (exit code, report).
fn validate_json(file: &Path, extra: &[&str]) -> (Option<i32>, Value) {
    let mut args = vec!["validate", file.to_str().unwrap(), "--json"];
    args.extend_from_slice(extra);
    let out = garmentbake(&args);
    let report = serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&out.stderr)));
    (out.status.code(), report)
}

/// The first error message of a failed report.
fn first_error(code: Option<i32>, report: &Value) -> String {
    assert_eq!(code, Some(1), "{report}");
    report["errors"][0]["message"].as_str().unwrap().to_string()
}

/// 131_02 at 4 fps.
const FRAMES: usize = 42;

#[test]
fn point_caches() {
    let dir = out_dir("validate_caches");
    // 131_02 at 4 fps (42 frames): eval's metrics are the slow part, the checks need few frames.
    // The caches are the ones the cache tests share (engine::, bake::): read, never written.
    let [pc2, mdd, usdc] =
        ["walk.pc2", "walk.mdd", "walk.usdc"].map(crate::bake::shared_eval_131_02_at_4);
    // eval's caches pass and replay the network (the USD one read back by usd-core): measured
    // 0.0003 mm for all three against the network's forward pass, an evaluation independent of
    // eval's sparse skinning (a fault there used to be on both sides: 0 mm whatever it was).
    for file in [&pc2, &mdd, &usdc] {
        let (code, report) = validate_against_model(file, "4", &[]);
        assert_eq!(code, Some(0), "{report}");
        assert_eq!(report["replay"]["frames"], FRAMES);
        assert!(
            report["replay"]["max_mm"].as_f64().unwrap() < 1e-3,
            "{report}"
        );
    }
    let bytes = std::fs::read(&mdd).unwrap();
    let frames = FRAMES;
    let points = (bytes.len() - 8 - 4 * frames) / (12 * frames);
    let broken = |name: &str, data: Vec<u8>| {
        let path = dir.join(name);
        std::fs::write(&path, data).unwrap();
        path
    };
    // A cut-off PC2.
    let mut cut = std::fs::read(&pc2).unwrap();
    cut.truncate(cut.len() - 1000);
    let (code, report) = validate_json(&broken("cut.pc2", cut), &[]);
    let e = first_error(code, &report);
    assert!(e.contains("truncated") && e.contains("42 samples"), "{e}");
    // An MDD whose header announces one frame more than it holds.
    let mut wrong = bytes.clone();
    wrong[..4].copy_from_slice(&(frames as i32 + 1).to_be_bytes());
    let (code, report) = validate_json(&broken("frames.mdd", wrong), &[]);
    let e = first_error(code, &report);
    assert!(e.contains("frame count is 43"), "{e}");
    // A NaN point.
    let mut nan = bytes.clone();
    let at = 8 + 4 * frames + 12 * (points * 7 + 3);
    nan[at..at + 4].copy_from_slice(&f32::NAN.to_be_bytes());
    let (code, report) = validate_json(&broken("nan.mdd", nan), &[]);
    assert!(
        first_error(code, &report).contains("point 3 is not finite"),
        "{report}"
    );
    // A cache against a reference cache (how a dynamic model's roll-out is checked): eval's MDD
    // plays its PC2 exactly; one point moved by 2 mm is found, in mm, at its frame and vertex.
    let reference = ["--reference", pc2.to_str().unwrap()];
    let (code, report) = validate_json(&mdd, &reference);
    assert_eq!(code, Some(0), "{report}");
    assert_eq!(report["replay"]["frames"], FRAMES);
    assert_eq!(report["replay"]["max_mm"], 0.0, "{report}");
    let mut moved = bytes.clone();
    let at = 8 + 4 * frames + 12 * (points * 9 + 11);
    let x = f32::from_be_bytes(moved[at..at + 4].try_into().unwrap()) + 0.002;
    moved[at..at + 4].copy_from_slice(&x.to_be_bytes());
    let (code, report) = validate_json(&broken("moved.mdd", moved), &reference);
    let e = first_error(code, &report);
    assert!(e.contains("(frame 9, vertex 11)"), "{e}");
    let max = report["replay"]["max_mm"].as_f64().unwrap();
    assert!((max - 2.0).abs() < 1e-3, "{report}");
    // Consistent files that do not play the clip: one frame short, and times at 25 fps.
    let mut short = bytes.clone();
    short[..4].copy_from_slice(&(frames as i32 - 1).to_be_bytes());
    short.drain(8 + 4 * (frames - 1)..8 + 4 * frames);
    short.truncate(short.len() - 12 * points);
    let (code, report) = validate_json(&broken("short.mdd", short.clone()), &[]);
    assert_eq!(code, Some(0), "structurally sound: {report}");
    let (code, report) = validate_json(&dir.join("short.mdd"), &reference);
    assert!(
        first_error(code, &report).contains("41 frames, the reference has 42"),
        "{report}"
    );
    let (code, report) = validate_against_model(&dir.join("short.mdd"), "4", &[]);
    assert!(first_error(code, &report).contains("41 frames, the clip at 4 fps has 42"));
    let mut slow = bytes.clone();
    for f in 0..frames {
        slow[8 + 4 * f..12 + 4 * f].copy_from_slice(&(f as f32 / 5.0).to_be_bytes());
    }
    let (code, report) = validate_against_model(&broken("rate.mdd", slow), "4", &[]);
    assert!(
        first_error(code, &report).contains("give 5.0000 fps"),
        "{report}"
    );

    // Blender's Mesh Cache modifier plays our MDD as we wrote it.
    let json = dir.join("blender_mdd.json");
    run_ok(
        std::process::Command::new("blender")
            .args(["-b", "--factory-startup", "--python"])
            .arg(root().join("tools/blender/eval_pc2.py"))
            .arg("--")
            .arg(sample("garments/skirt.obj"))
            .arg(&mdd)
            .args(["--frames", "0,5,40", "--out"])
            .arg(&json),
    );
    let r: Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(r["header"]["num_samples"], FRAMES);
    for f in r["frames"].as_array().unwrap() {
        let frame = f["frame"].as_f64().unwrap() as usize;
        let start = 8 + 4 * frames + 12 * points * frame;
        let want: Vec<f32> = bytes[start..start + 12 * points]
            .chunks_exact(4)
            .map(|b| f32::from_be_bytes(b.try_into().unwrap()))
            .collect();
        let got = f["positions"].as_array().unwrap();
        assert_eq!(got.len(), want.len());
        let worst = got
            .iter()
            .zip(&want)
            .map(|(a, &b)| (a.as_f64().unwrap() - b as f64).abs())
            .fold(0.0, f64::max);
        // Measured 0.000044 to 0.000056 mm (f32 through Blender's Mesh Cache).
        assert!(worst < 5e-7, "frame {frame}: Blender differs by {worst} m");
    }
}

#[test]
fn usd_files() {
    let dir = out_dir("validate_usd");
    let baked = bake(&dir, "skirt.usda", &["--max-targets", "8", "--validate"]);
    let (posed, posed_glb) = (dir.join("pose.usdc"), dir.join("pose.glb"));
    for out in [&posed, &posed_glb] {
        garmentbake_ok(&[
            "pose",
            "--body",
            sample("body.glb").to_str().unwrap(),
            "--motion",
            sample("motions/131_01.bvh").to_str().unwrap(),
            "--fps",
            "10",
            "--out",
            out.to_str().unwrap(),
        ]);
    }
    for file in [&baked, &posed, &posed_glb] {
        let (code, report) = validate_json(file, &[]);
        assert_eq!(code, Some(0), "{report}");
    }
    // Replayed through UsdSkel (usd-core's blend shape and skinning queries) at every frame.
    let (code, good) = validate_against_model(&baked, "30", &[]);
    assert_eq!(code, Some(0), "{good}");
    let r = &good["replay"];
    assert_eq!(r["frames"], 312);
    // Measured 0.0109 mm (8 of the 32 targets: compression, docs/validate.md's table).
    assert!(r["max_mm"].as_f64().unwrap() < 0.02, "{r}");
    // Every blend shape's offsets ×1.5, rewritten by usd-core: still a sound file, but off the
    // network by half the morph displacement (weights from 0: see `replay_against_the_model`).
    let scaled = dir.join("shapes_x1.5.usda");
    run_ok(
        std::process::Command::new(root().join(".venv/bin/python"))
            .args(["-c", SCALE_BLEND_SHAPES])
            .args([&baked, &scaled])
            .arg("1.5"),
    );
    let (code, report) = validate_json(&scaled, &[]);
    assert_eq!(code, Some(0), "structurally sound: {report}");
    let (code, bad) = validate_against_model(&scaled, "30", &[]);
    let e = first_error(code, &bad);
    let max = bad["replay"]["max_mm"].as_f64().unwrap();
    assert!(max > 1.0, "{bad}");
    assert!(e.contains(&format!("{max:.3} mm")), "{e}");
    // Played at another rate, the file does not match the clip's frames.
    let (code, wrong) = validate_against_model(&baked, "10", &[]);
    assert!(
        first_error(code, &wrong).contains("312 time samples, the clip 104 frames"),
        "{wrong}"
    );
    let text = std::fs::read_to_string(&baked).unwrap();
    let garbled = dir.join("garbled.usda");
    std::fs::write(&garbled, &text[..text.len() / 3]).unwrap();
    let (code, report) = validate_json(&garbled, &[]);
    assert!(first_error(code, &report).contains("cannot open the USD stage"));
    let past = dir.join("joints.usda");
    let needle = "primvars:skel:jointIndices = [";
    let at = text.find(needle).unwrap() + needle.len();
    let end = at + text[at..].find(',').unwrap();
    std::fs::write(&past, format!("{}40{}", &text[..at], &text[end..])).unwrap();
    let (code, report) = validate_json(&past, &[]);
    let e = first_error(code, &report);
    assert!(
        e.contains("jointIndices hold 40") && e.contains("31 joints"),
        "{e}"
    );
}

/// usd-core rewrites a USD with every BlendShape's offsets scaled: argv = SRC DST SCALE.
const SCALE_BLEND_SHAPES: &str = "
import sys
from pxr import Usd, UsdSkel, Vt
stage = Usd.Stage.Open(sys.argv[1])
for prim in stage.Traverse():
    if prim.IsA(UsdSkel.BlendShape):
        attr = UsdSkel.BlendShape(prim).GetOffsetsAttr()
        attr.Set(Vt.Vec3fArray([v * float(sys.argv[3]) for v in attr.Get()]))
stage.GetRootLayer().Export(sys.argv[2])
";

/// Inputs that once made a reader panic under `cargo fuzz` (fuzz/; tests/fuzz_crashers/TARGET-what):
/// each goes through the readers its fuzz target drives, which must now return an error.
#[test]
fn fuzz_crashers_are_errors() {
    let dir = root().join("tests/fuzz_crashers");
    let mut seen = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        let bytes = std::fs::read(&path).unwrap();
        let text = String::from_utf8_lossy(&bytes);
        match name.split_once('-').map(|(target, _)| target) {
            Some("obj") => assert!(garmentbake::io::obj::parse_obj(&text, &name).is_err()),
            Some("bvh") => assert!(garmentbake::io::bvh::Bvh::parse(&text, &name).is_err()),
            Some("point_cache") => {
                let (pc2, mdd) = (exporters::pc2::read(&bytes), exporters::mdd::read(&bytes));
                assert!(pc2.is_err() || mdd.is_err(), "{name}");
            }
            Some("gltf_body") => {
                let read = garmentbake::io::gltf_body::parse_body(&bytes, &path);
                assert!(read.is_err(), "{name}");
            }
            Some("validate") => {
                for file in ["x.glb", "x.gltf"] {
                    assert!(!ours_bytes(&dir.join(file), &bytes).passed(), "{name}");
                }
                let mut p = Problems::default();
                garmentbake::validate::cache::check_pc2(&bytes, &mut p);
                garmentbake::validate::cache::check_mdd(&bytes, &mut p);
                assert!(!p.passed(), "{name}");
            }
            _ => panic!("{name}: name it TARGET-what after the fuzz target that found it"),
        }
        seen += 1;
    }
    assert!(seen >= 2, "{seen} crashers in {}", dir.display());
}

fn ours_bytes(path: &Path, bytes: &[u8]) -> Problems {
    let mut p = Problems::default();
    check_gltf(path, bytes, &mut p);
    p
}
