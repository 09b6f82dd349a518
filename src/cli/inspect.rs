//! `garmentbake inspect`: what a file holds, as text or JSON.

use super::Execute;
use crate::geometry::topology::Topology;
use crate::io::bvh::Bvh;
use crate::io::obj::read_obj;
use crate::models::file::{KindInfo, MotionInfo};
use anyhow::{bail, Context, Result};
use exporters::FileKind;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// Describe a glTF/glb (nodes, skins, joints, meshes, morph targets, animations), a BVH clip
/// (joints, frames, fps, duration), an OBJ mesh (vertices, faces, boundary loops) or a trained
/// model (.safetensors: its description and tensors; --json prints the whole description,
/// faces and UVs included).
#[derive(clap::Args)]
pub struct Args {
    /// File to describe (.glb, .gltf, .bvh, .obj, .safetensors).
    pub file: PathBuf,
    /// BVH: also read the clip onto this body (.glb) and print what each clip joint became (the
    /// rig joint it drives, folded, dropped), the map, up axis, units and rest pose.
    #[arg(long, help_heading = "Inputs")]
    pub body: Option<PathBuf>,
    /// BVH with --body: joint map(s) to try first (see `garmentbake map suggest`).
    #[arg(long = "map", requires = "body", help_heading = "Inputs")]
    pub maps: Vec<PathBuf>,
    /// BVH with --body: the clip's up axis (detected when left out).
    #[arg(long, requires = "body", value_parser = super::args::parse_up, help_heading = "Inputs")]
    pub up: Option<crate::rig::capture::UpAxis>,
    /// BVH with --body: the clip's length unit (detected when left out).
    #[arg(long, requires = "body", value_parser = super::args::parse_units, help_heading = "Inputs")]
    pub units: Option<crate::rig::capture::Units>,
    /// Print JSON instead of text.
    #[arg(long, help_heading = "Outputs")]
    pub json: bool,
}

impl Execute for Args {
    type Report = Value;

    fn execute(&self, _say: &dyn Fn(&str)) -> Result<Value> {
        let path = &self.file;
        match FileKind::of(path) {
            Some(FileKind::Gltf) => gltf_report(path),
            Some(FileKind::Bvh) => bvh_report(path, self),
            Some(FileKind::Obj) => obj_report(path),
            Some(FileKind::Model) => model_report(path, self.json),
            _ => bail!(
                "{}: unknown file type (expected {})",
                path.display(),
                FileKind::extension_list(
                    &[
                        FileKind::Gltf,
                        FileKind::Bvh,
                        FileKind::Obj,
                        FileKind::Model
                    ],
                    false
                )
            ),
        }
    }

    fn print(report: &Value) {
        print_text(report, 0);
    }
}

fn gltf_report(path: &Path) -> Result<Value> {
    let (doc, _, _) = gltf::import(path)
        .with_context(|| format!("{}: not a readable glTF file", path.display()))?;
    let name = |n: Option<&str>, i: usize| n.map_or_else(|| format!("#{i}"), str::to_string);
    let meshes: Vec<Value> = doc
        .meshes()
        .map(|m| {
            let prim = m.primitives().next();
            let vertices = prim.as_ref().and_then(|p| p.get(&gltf::Semantic::Positions)).map_or(0, |a| a.count());
            let targets = prim.as_ref().map_or(0, |p| p.morph_targets().count());
            json!({ "name": name(m.name(), m.index()), "primitives": m.primitives().count(), "vertices": vertices, "morph_targets": targets })
        })
        .collect();
    let skins: Vec<Value> = doc
        .skins()
        .map(|s| json!({ "name": name(s.name(), s.index()), "joints": s.joints().map(|j| name(j.name(), j.index())).collect::<Vec<_>>() }))
        .collect();
    let animations: Vec<Value> = doc
        .animations()
        .map(|a| {
            let duration = a.samplers().filter_map(|s| s.input().max()).filter_map(|v| v.as_array()?.first()?.as_f64()).fold(0.0, f64::max);
            let frames = a.samplers().map(|s| s.input().count()).max().unwrap_or(0);
            json!({ "name": name(a.name(), a.index()), "channels": a.channels().count(), "keyframes": frames, "duration_s": duration })
        })
        .collect();
    Ok(
        json!({ "file": path.display().to_string(), "nodes": doc.nodes().count(), "meshes": meshes, "skins": skins, "animations": animations }),
    )
}

fn bvh_report(path: &Path, args: &Args) -> Result<Value> {
    let bvh = Bvh::read(path)?;
    let mut report = json!({
        "file": path.display().to_string(),
        "joints": bvh.joints.iter().map(|j| j.name.clone()).collect::<Vec<_>>(),
        "frames": bvh.frame_count(), "fps": bvh.fps(), "duration_s": bvh.duration(),
    });
    if let Some(body) = &args.body {
        let body = crate::io::gltf_body::read_body(body)?;
        let reader =
            crate::motion::read_maps(&args.maps)?.with_axes(crate::rig::capture::ClipAxes {
                up: args.up,
                units: args.units,
            });
        let (clip, fates) = crate::motion::clip_joint_fates(path, &reader, &body)?;
        report["map"] = json!(clip.reading.describe(&clip.map_name));
        report["reading"] = json!(clip.reading);
        report["joints"] = json!(fates
            .iter()
            .map(|f| format!("{} -> {}", f.joint, f.became))
            .collect::<Vec<_>>());
    }
    Ok(report)
}

fn obj_report(path: &Path) -> Result<Value> {
    let obj = read_obj(path)?;
    let topo = Topology::new(&obj.mesh);
    let loops = topo.boundary_loops();
    let (lo, hi) = obj.mesh.bounds();
    Ok(json!({
        "file": path.display().to_string(), "vertices": obj.mesh.vertex_count(), "faces": obj.mesh.triangle_count(),
        "edges": topo.edges.len(), "boundary_loops": loops.iter().map(Vec::len).collect::<Vec<_>>(),
        "non_manifold_edges": topo.non_manifold_edges.len(), "has_uvs": obj.mesh.uv.is_some(), "bounds_min": lo, "bounds_max": hi,
    }))
}

fn model_report(path: &Path, full: bool) -> Result<Value> {
    let (info, tensors) = crate::models::file::read_info(path)?;
    let tensors: Vec<Value> = tensors
        .iter()
        .map(|(n, shape, dtype)| json!({ "name": n, "shape": shape, "dtype": dtype }))
        .collect();
    if full {
        return Ok(
            json!({ "file": path.display().to_string(), "description": info, "tensors": tensors }),
        );
    }
    let names = &info.skeleton.joint_names;
    let g = &info.garment;
    let (model, training, history) = match &info.model {
        KindInfo::Pbns(p) => (
            json!({
                "kind": info.model.kind(),
                "mlp": format!("{} inputs → {} × {} ReLU → {} PSD blend shapes", p.shape.features, p.shape.layers, p.shape.width, p.shape.width),
                "influences": p.shape.influences,
                "feature_joints": p.feature_joints.iter().map(|&j| names[j].clone()).collect::<Vec<_>>(),
            }),
            json!(p.training),
            json!({ "epochs": p.history.len(), "last": p.history.last() }),
        ),
        KindInfo::Dynamic(d) => (
            with_motion(
                json!({
                    "kind": info.model.kind(),
                    "stages": d.training.stages,
                    "space": format!("{}² UV map, {} seeds → latent {} → ξ {} ch → R {} × {}", d.shape.map, d.shape.anchors, d.shape.latent, d.shape.xi, d.shape.mlp_layers, d.shape.mlp),
                    "preset": d.shape.preset,
                    "fps": d.fps,
                    "kernel_radius_mm": d.parts.iter().zip(&d.radii).map(|(p, r)| format!("{p} {:.1}", r * 1e3)).collect::<Vec<_>>(),
                }),
                d.motion.as_ref(),
            ),
            json!(d.training),
            json!({ "epochs": d.history.len(), "last": d.history.last() }),
        ),
    };
    Ok(json!({
        "file": path.display().to_string(),
        "format": format!("{} v{}", info.format, info.version),
        "model": model,
        "skeleton": { "joints": names.len(), "names": names },
        "garment": { "name": g.name, "vertices": g.vertices, "faces": g.faces.len(), "uvs": g.uv.is_some(),
                     "pinned": g.pinned.len(), "rest_hash": g.rest_hash },
        "body": { "name": info.body.name, "vertices": info.body.vertices, "rest_hash": info.body.rest_hash },
        "fabric": info.fabric,
        "training": training,
        "history": history,
        "tensors": tensors,
    }))
}

/// `model` with a `motion` line when the model has its motion stage.
fn with_motion(mut model: Value, motion: Option<&MotionInfo>) -> Value {
    if let Some(m) = motion {
        model["motion"] = motion_summary(m).into();
    }
    model
}

/// The motion stage's integrator in one line: how it was fitted and settled.
fn motion_summary(m: &MotionInfo) -> String {
    let settle = m.settle.map_or("not settled".to_string(), |s| s.summary());
    format!(
        "integrator ridge {}, {} roll-out round(s), body drive on {} joint(s), {settle}",
        m.ridge,
        m.rollout_rounds.len(),
        m.shape.drive_joints.len()
    )
}

/// Indented `key: value` lines; short arrays stay on one line.
fn print_text(v: &Value, indent: usize) {
    let pad = " ".repeat(indent);
    match v {
        Value::Object(map) => {
            for (k, v) in map {
                match v {
                    Value::Object(_) => {
                        println!("{pad}{k}:");
                        print_text(v, indent + 2);
                    }
                    Value::Array(items) if items.iter().any(Value::is_object) => {
                        println!("{pad}{k}: {}", items.len());
                        for item in items {
                            print_text(item, indent + 2);
                            println!();
                        }
                    }
                    _ => println!("{pad}{k}: {}", compact(v)),
                }
            }
        }
        other => println!("{pad}{}", compact(other)),
    }
}

fn compact(v: &Value) -> String {
    match v {
        Value::String(s) => s.clone(),
        Value::Array(a) => a.iter().map(compact).collect::<Vec<_>>().join(", "),
        other => other.to_string(),
    }
}
