//! Reads a skinned body from glTF: the first skinned mesh node, its skin's joints as a Skeleton,
//! JOINTS/WEIGHTS as a Skin. All triangle primitives of that mesh are merged.

use crate::body::Body;
use crate::geometry::mesh::{FaceVaryingUv, TriMesh};
use crate::rig::skeleton::topological_order;
use crate::rig::{JointTransform, Skeleton, Skin};
use gltf::accessor::{DataType, Dimensions};
use nalgebra::{Matrix4, Quaternion, UnitQuaternion, Vector3};
use std::path::Path;

#[derive(Debug, thiserror::Error)]
#[error("{path}: {reason}")]
pub struct BodyError {
    pub path: String,
    pub reason: String,
}

pub fn read_body(path: &Path) -> Result<Body, BodyError> {
    let bytes = std::fs::read(path).map_err(|e| body_error(path, format!("cannot read ({e})")))?;
    let base = path.parent().unwrap_or(Path::new("."));
    import(&bytes, Some(base))
        .and_then(|(doc, buffers)| body_of(&doc, &buffers))
        .map_err(|reason| body_error(path, reason))
}

/// The body in a GLB (or a self-contained glTF) held in memory; `source` names it in errors.
pub fn parse_body(bytes: &[u8], source: &Path) -> Result<Body, BodyError> {
    import(bytes, None)
        .and_then(|(doc, buffers)| body_of(&doc, &buffers))
        .map_err(|reason| body_error(source, reason))
}

/// The document and its buffers (external ones beside `base`; none without it). Images are not
/// loaded: a body needs none.
fn import(
    bytes: &[u8],
    base: Option<&Path>,
) -> Result<(gltf::Document, Vec<gltf::buffer::Data>), String> {
    let unreadable = |e: gltf::Error| format!("not a readable glTF file ({e})");
    // gltf's GLB reader subtracts the 12-byte header from the declared length unchecked (an
    // overflow panic in checked builds, found by fuzzing).
    let declared = bytes
        .get(8..12)
        .map(|l| u32::from_le_bytes([l[0], l[1], l[2], l[3]]));
    if bytes.starts_with(b"glTF") && declared.is_none_or(|length| length < 12) {
        return Err(
            "not a readable glTF file (GLB: the declared length is under the 12-byte header)"
                .into(),
        );
    }
    let gltf::Gltf { document, blob } =
        gltf::Gltf::from_slice_without_validation(bytes).map_err(unreadable)?;
    let json = document.into_json();
    if let Some(problem) = dangling_position(&json) {
        return Err(format!("not a readable glTF file ({problem})"));
    }
    let document = gltf::Document::from_json(json).map_err(unreadable)?;
    let buffers = gltf::import_buffers(&document, base, blob).map_err(unreadable)?;
    Ok((document, buffers))
}

/// A primitive whose POSITION names no accessor. gltf-json's own validation looks that accessor
/// up before checking the index (and panics, found by fuzzing): check it first.
pub fn dangling_position(root: &gltf::json::Root) -> Option<String> {
    let position = gltf::json::validation::Checked::Valid(gltf::Semantic::Positions);
    root.meshes.iter().enumerate().find_map(|(m, mesh)| {
        mesh.primitives.iter().enumerate().find_map(|(p, prim)| {
            let a = prim.attributes.get(&position)?.value();
            (a >= root.accessors.len()).then(|| {
                format!(
                    "/meshes/{m}/primitives/{p}/attributes/POSITION: accessor {a} does not exist ({} accessors)",
                    root.accessors.len()
                )
            })
        })
    })
}

fn body_error(path: &Path, reason: String) -> BodyError {
    BodyError {
        path: path.display().to_string(),
        reason,
    }
}

/// The first skinned mesh node of an imported document, as a Body.
fn body_of(doc: &gltf::Document, buffers: &[gltf::buffer::Data]) -> Result<Body, String> {
    let node = doc
        .nodes()
        .find(|n| n.mesh().is_some() && n.skin().is_some())
        .ok_or_else(|| {
            format!(
                "no skinned mesh ({} meshes, {} skins); export the body with its armature",
                doc.meshes().len(),
                doc.skins().len()
            )
        })?;
    let (mesh, skin) = (node.mesh().expect("checked"), node.skin().expect("checked"));
    let (skeleton, remap) = read_skeleton(doc, &skin, buffers)?;
    let (tri, normals, skin) = read_mesh(&mesh, buffers, &remap)?;
    let name = node.name().or(mesh.name()).unwrap_or("body").to_string();
    Ok(Body::new(name, tri, normals, skeleton, skin))
}

/// Skeleton from the skin's joints, sorted parents-first; `remap[old skin slot] = new joint index`.
fn read_skeleton(
    doc: &gltf::Document,
    skin: &gltf::Skin,
    buffers: &[gltf::buffer::Data],
) -> Result<(Skeleton, Vec<usize>), String> {
    let joints: Vec<gltf::Node> = skin.joints().collect();
    let mut node_parent = vec![None; doc.nodes().len()];
    for n in doc.nodes() {
        for c in n.children() {
            node_parent[c.index()] = Some(n.index());
        }
    }
    let slot_of = |node: usize| joints.iter().position(|j| j.index() == node);
    let parents: Vec<Option<usize>> = joints
        .iter()
        .map(|j| {
            let mut p = node_parent[j.index()];
            while let Some(n) = p {
                if let Some(s) = slot_of(n) {
                    return Some(s);
                }
                p = node_parent[n];
            }
            None
        })
        .collect();
    if let Some(a) = skin.inverse_bind_matrices() {
        expect_format(
            &a,
            "inverseBindMatrices",
            &[DataType::F32],
            Dimensions::Mat4,
        )?;
    }
    let ibm: Vec<Matrix4<f32>> = match skin
        .reader(|b| Some(&buffers[b.index()]))
        .read_inverse_bind_matrices()
    {
        Some(it) => it.map(|m| Matrix4::from_fn(|r, c| m[c][r])).collect(),
        None => vec![Matrix4::identity(); joints.len()],
    };
    if ibm.len() != joints.len() {
        return Err(format!(
            "{} inverse bind matrices for the skin's {} joints",
            ibm.len(),
            joints.len()
        ));
    }
    let order = topological_order(&parents).ok_or("the skin's joint hierarchy has a cycle")?;
    let mut remap = vec![0; joints.len()];
    for (new, &old) in order.iter().enumerate() {
        remap[old] = new;
    }
    let rest = order.iter().map(|&o| node_rest(&joints[o])).collect();
    let skeleton = Skeleton::new(
        order
            .iter()
            .map(|&o| {
                joints[o]
                    .name()
                    .map_or_else(|| format!("joint{o}"), str::to_string)
            })
            .collect(),
        order
            .iter()
            .map(|&o| parents[o].map(|p| remap[p]))
            .collect(),
        rest,
        order.iter().map(|&o| ibm[o]).collect(),
    )
    .map_err(|e| e.to_string())?;
    Ok((skeleton, remap))
}

fn node_rest(node: &gltf::Node) -> JointTransform {
    let (t, r, s) = node.transform().decomposed();
    JointTransform {
        translation: Vector3::from(t),
        rotation: UnitQuaternion::from_quaternion(Quaternion::new(r[3], r[0], r[1], r[2])),
        scale: Vector3::from(s),
    }
}

type MeshParts = (TriMesh, Vec<[f32; 3]>, Skin);

fn read_mesh(
    mesh: &gltf::Mesh,
    buffers: &[gltf::buffer::Data],
    remap: &[usize],
) -> Result<MeshParts, String> {
    let mut positions = Vec::new();
    let mut normals = Vec::new();
    let mut uvs = Vec::new();
    let mut triangles = Vec::new();
    let mut influences: Vec<Vec<(u16, f32)>> = Vec::new();
    for prim in mesh
        .primitives()
        .filter(|p| p.mode() == gltf::mesh::Mode::Triangles)
    {
        check_formats(&prim)?;
        let reader = prim.reader(|b| Some(&buffers[b.index()]));
        let base = positions.len() as u32;
        let pos: Vec<[f32; 3]> = reader
            .read_positions()
            .ok_or("a primitive has no POSITION")?
            .collect();
        let n = pos.len();
        positions.extend(pos);
        let nrm: Option<Vec<[f32; 3]>> = reader.read_normals().map(|it| it.collect());
        normals.extend(same_count(nrm, n, "NORMAL")?.unwrap_or_else(|| vec![[0.0; 3]; n]));
        let uv: Option<Vec<[f32; 2]>> = reader.read_tex_coords(0).map(|t| t.into_f32().collect());
        uvs.extend(same_count(uv, n, "TEXCOORD_0")?.unwrap_or_else(|| vec![[0.0; 2]; n]));
        match reader.read_indices() {
            Some(idx) => {
                let idx: Vec<u32> = idx.into_u32().collect();
                if let Some(i) = idx.iter().find(|&&i| i as usize >= n) {
                    return Err(format!("index {i} past the primitive's {n} vertices"));
                }
                triangles.extend(
                    idx.chunks_exact(3)
                        .map(|t| [t[0] + base, t[1] + base, t[2] + base]),
                );
            }
            None => triangles.extend(
                (0..n as u32 / 3).map(|t| [base + 3 * t, base + 3 * t + 1, base + 3 * t + 2]),
            ),
        }
        let mut vertex_influences = vec![Vec::new(); n];
        for set in 0..2 {
            let (Some(j), Some(w)) = (reader.read_joints(set), reader.read_weights(set)) else {
                break;
            };
            for (v, (j, w)) in j.into_u16().zip(w.into_f32()).enumerate() {
                let Some(influences) = vertex_influences.get_mut(v) else {
                    return Err(format!(
                        "JOINTS_{set} has more elements than POSITION ({n})"
                    ));
                };
                for k in 0..4 {
                    let slot = j[k] as usize;
                    if w[k] > 0.0 {
                        let joint = *remap.get(slot).ok_or(format!(
                            "JOINTS_{set} refers to joint {slot}, the skin has {}",
                            remap.len()
                        ))?;
                        influences.push((joint as u16, w[k]));
                    }
                }
            }
        }
        influences.extend(vertex_influences);
    }
    if triangles.is_empty() {
        return Err("the skinned mesh has no triangles".into());
    }
    let most = influences.iter().map(Vec::len).max().unwrap_or(0);
    if most == 0 {
        return Err("the skinned mesh has no JOINTS_0/WEIGHTS_0".into());
    }
    let skin = Skin::from_sparse(&influences, if most > 4 { 8 } else { 4 }, 0);
    let uv = Some(FaceVaryingUv {
        coords: uvs,
        triangles: triangles.clone(),
    });
    Ok((
        TriMesh {
            positions,
            triangles,
            uv,
        },
        normals,
        skin,
    ))
}

/// The formats the gltf crate's typed readers take (they panic on any other): each attribute
/// this reader uses, and the indices, are checked before reading.
fn check_formats(prim: &gltf::Primitive) -> Result<(), String> {
    use gltf::Semantic;
    use DataType::{F32, U16, U32, U8};
    for (semantic, accessor) in prim.attributes() {
        let (name, types, dimensions): (_, &[DataType], _) = match semantic {
            Semantic::Positions => ("POSITION", &[F32], Dimensions::Vec3),
            Semantic::Normals => ("NORMAL", &[F32], Dimensions::Vec3),
            Semantic::TexCoords(_) => ("TEXCOORD", &[F32, U8, U16], Dimensions::Vec2),
            Semantic::Joints(_) => ("JOINTS", &[U8, U16], Dimensions::Vec4),
            Semantic::Weights(_) => ("WEIGHTS", &[F32, U8, U16], Dimensions::Vec4),
            _ => continue,
        };
        expect_format(&accessor, name, types, dimensions)?;
    }
    match prim.indices() {
        Some(a) => expect_format(&a, "indices", &[U8, U16, U32], Dimensions::Scalar),
        None => Ok(()),
    }
}

fn expect_format(
    accessor: &gltf::Accessor,
    what: &str,
    types: &[DataType],
    dimensions: Dimensions,
) -> Result<(), String> {
    if types.contains(&accessor.data_type()) && accessor.dimensions() == dimensions {
        return Ok(());
    }
    Err(format!(
        "{what} accessor {} is {:?} {:?}, expected {dimensions:?} of {types:?}",
        accessor.index(),
        accessor.data_type(),
        accessor.dimensions()
    ))
}

/// An optional per-vertex attribute, which must have one element per vertex.
fn same_count<T>(values: Option<Vec<T>>, n: usize, what: &str) -> Result<Option<Vec<T>>, String> {
    match values {
        Some(v) if v.len() != n => Err(format!("{what} has {} elements, POSITION {n}", v.len())),
        v => Ok(v),
    }
}
