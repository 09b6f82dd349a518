//! MakeHuman / MPFB2 assets (CC0): `base.obj` (decimetres, Y-up, A-pose), vertex groups, a rig whose
//! joint heads are the centres of small "joint cube" helpers, and per-bone skin weights.
//! Converted to metres with the feet on y = 0.

use crate::body::Body;
use crate::geometry::mesh::TriMesh;
use crate::io::obj::read_obj;
use crate::rig::{Skeleton, Skin};
use anyhow::{anyhow, bail, Context, Result};
use nalgebra::Vector3;
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::Path;

/// The skin surface of base.obj; everything above is helper geometry.
pub const BODY_VERTICES: std::ops::RangeInclusive<u32> = 0..=13379;

pub struct MakeHuman {
    /// The whole base mesh, already in metres with the body's feet on y = 0.
    pub mesh: TriMesh,
    groups: BTreeMap<String, Vec<[u32; 2]>>,
    rig: serde_json::Map<String, Value>,
    weights: serde_json::Map<String, Value>,
}

impl MakeHuman {
    /// Reads `base.obj`, `basemesh_vertex_groups.json`, `rig.<name>.json`, `weights.<name>.json`.
    pub fn load(dir: &Path, rig_name: &str) -> Result<Self> {
        let obj = read_obj(&dir.join("base.obj"))?;
        let groups: BTreeMap<String, Vec<[u32; 2]>> =
            serde_json::from_value(read_json(&dir.join("basemesh_vertex_groups.json"))?)
                .context("basemesh_vertex_groups.json: expected {group: [[first, last], ...]}")?;
        let rig = read_json(&dir.join(format!("rig.{rig_name}.json")))?;
        let weights = read_json(&dir.join(format!("weights.{rig_name}.json")))?;
        let rig = rig
            .as_object()
            .cloned()
            .ok_or_else(|| anyhow!("rig.{rig_name}.json: expected an object of bones"))?;
        let weights = weights
            .get("weights")
            .and_then(Value::as_object)
            .cloned()
            .ok_or_else(|| anyhow!("weights.{rig_name}.json: no \"weights\" object"))?;
        let mut mesh = obj.mesh;
        let floor = BODY_VERTICES
            .map(|v| mesh.positions[v as usize][1])
            .fold(f32::INFINITY, f32::min);
        // Decimetres → metres, feet on the floor.
        mesh = mesh.transformed(|p| [p[0] * 0.1, (p[1] - floor) * 0.1, p[2] * 0.1]);
        Ok(MakeHuman {
            mesh,
            groups,
            rig,
            weights,
        })
    }

    /// Vertex indices of a named group (inclusive ranges in the JSON).
    pub fn group(&self, name: &str) -> Result<Vec<u32>> {
        let ranges = self
            .groups
            .get(name)
            .ok_or_else(|| anyhow!("MakeHuman vertex group '{name}' not found"))?;
        Ok(ranges.iter().flat_map(|[a, b]| *a..=*b).collect())
    }

    /// Triangles whose vertices all lie in `group`, re-indexed; also returns new → base.obj vertex.
    pub fn group_mesh(&self, name: &str) -> Result<(TriMesh, Vec<u32>)> {
        let keep: std::collections::HashSet<u32> = self.group(name)?.into_iter().collect();
        Ok(self.mesh.submesh(|v| keep.contains(&v)))
    }

    /// The rigged body: skin vertices only, skeleton from the joint cubes, top-4 weights.
    pub fn body(&self) -> Result<Body> {
        let (mesh, source) = self.mesh.submesh(|v| BODY_VERTICES.contains(&v));
        let skeleton = self.skeleton()?;
        let skin = self.skin(&skeleton, &source, 4)?;
        let normals = crate::geometry::normals::vertex_normals(&mesh.positions, &mesh.triangles);
        Ok(Body::new("body".into(), mesh, normals, skeleton, skin))
    }

    /// Joints at the centres of their head markers, world-aligned frames (identity rest rotations).
    pub fn skeleton(&self) -> Result<Skeleton> {
        let names: Vec<String> = self.rig.keys().cloned().collect();
        let parents = names
            .iter()
            .map(|n| {
                match self.rig[n]
                    .get("parent")
                    .and_then(Value::as_str)
                    .unwrap_or("")
                {
                    "" => Ok(None),
                    p => names
                        .iter()
                        .position(|x| x == p)
                        .map(Some)
                        .ok_or_else(|| anyhow!("bone '{n}' has unknown parent '{p}'")),
                }
            })
            .collect::<Result<Vec<_>>>()?;
        let heads = names
            .iter()
            .map(|n| {
                self.marker(&self.rig[n]["head"])
                    .with_context(|| format!("bone '{n}' head"))
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Skeleton::from_world_positions(&names, &parents, &heads)?)
    }

    fn marker(&self, spec: &Value) -> Result<Vector3<f32>> {
        let vertices = match spec.get("strategy").and_then(Value::as_str) {
            Some("CUBE") => self.group(spec["cube_name"].as_str().unwrap_or_default())?,
            Some("MEAN") | Some("VERTEX") => spec["vertex_indices"]
                .as_array()
                .map(|a| {
                    a.iter()
                        .filter_map(|v| v.as_u64().map(|v| v as u32))
                        .collect()
                })
                .unwrap_or_default(),
            other => bail!("unsupported joint placement strategy {other:?}"),
        };
        if vertices.is_empty() {
            bail!("joint marker has no vertices");
        }
        let sum: Vector3<f32> = vertices
            .iter()
            .map(|&v| Vector3::from(self.mesh.positions[v as usize]))
            .sum();
        Ok(sum / vertices.len() as f32)
    }

    /// Skin weights for the base.obj vertices `source` (one entry per output vertex).
    pub fn skin(&self, skeleton: &Skeleton, source: &[u32], influences: usize) -> Result<Skin> {
        let mut position = std::collections::HashMap::new();
        for (i, &s) in source.iter().enumerate() {
            position.insert(s, i);
        }
        let mut per_vertex = vec![Vec::new(); source.len()];
        for (bone, list) in &self.weights {
            let j = skeleton
                .joint_index(bone)
                .ok_or_else(|| anyhow!("weights name bone '{bone}' that the rig does not have"))?;
            for pair in list.as_array().into_iter().flatten() {
                let (Some(v), Some(w)) = (pair[0].as_u64(), pair[1].as_f64()) else {
                    bail!("bone '{bone}': bad weight entry {pair}")
                };
                if let Some(&i) = position.get(&(v as u32)) {
                    per_vertex[i].push((j as u16, w as f32));
                }
            }
        }
        Ok(Skin::from_sparse(&per_vertex, influences, 0))
    }
}

fn read_json(path: &Path) -> Result<Value> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("{}: invalid JSON", path.display()))
}
