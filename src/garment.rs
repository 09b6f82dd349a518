//! A garment: its rest mesh (aligned with the body's rest pose), the pinned vertices and the
//! fitting step that pushes vertices out of the body before training or simulation.
//!
//! Read from OBJ or USD (one Mesh prim; usd-core converts units and up axis). Sidecar next to
//! `NAME.obj` (or `NAME.usd*`): `NAME.toml` with `pinned = [...]` (vertex indices) and an optional
//! `layer` (0 = innermost, for outfits).

use crate::body::{body_offsets, Body};
use crate::geometry::{arr3, v3, Laplacian, PointIndex, Topology, TriMesh};
use crate::io::obj::{read_obj, write_obj};
use crate::io::usd_mesh::{is_usd, read_usd_mesh};
use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct GarmentSidecar {
    /// Vertices held at their skinned rest position (e.g. a skirt's waist band).
    #[serde(default)]
    pub pinned: Vec<u32>,
    /// Layer order in an outfit, inner first.
    #[serde(default)]
    pub layer: u32,
    /// Where the mesh came from (free text).
    #[serde(default)]
    pub source: String,
}

#[derive(Clone, Debug)]
pub struct Garment {
    pub name: String,
    pub mesh: TriMesh,
    pub sidecar: GarmentSidecar,
}

pub fn sidecar_path(obj: &Path) -> PathBuf {
    obj.with_extension("toml")
}

impl Garment {
    /// Reads `NAME.obj` (or a USD file with one Mesh prim) and, when present, `NAME.toml`;
    /// pinned indices are checked.
    pub fn read(path: &Path) -> Result<Garment> {
        let mesh = if is_usd(path) {
            read_usd_mesh(path)?
        } else {
            read_obj(path)?.mesh
        };
        let side = sidecar_path(path);
        let sidecar = if side.exists() {
            let text = std::fs::read_to_string(&side)
                .with_context(|| format!("cannot read {}", side.display()))?;
            toml::from_str(&text)
                .with_context(|| format!("{}: invalid garment sidecar", side.display()))?
        } else {
            GarmentSidecar::default()
        };
        let n = mesh.vertex_count();
        if let Some(bad) = sidecar.pinned.iter().find(|&&v| v as usize >= n) {
            bail!(
                "{}: pinned vertex {bad} out of range ({} has {n} vertices)",
                side.display(),
                path.display()
            );
        }
        let name = path
            .file_stem()
            .map_or("garment".into(), |s| s.to_string_lossy().into_owned());
        Ok(Garment {
            name,
            mesh,
            sidecar,
        })
    }

    /// What would spoil training or simulation, one line each: vertices inside the body at rest
    /// (more than 5 %), non-manifold edges, degenerate faces. Empty when the garment is fit.
    pub fn fit_problems(&self, body: &Body) -> Result<Vec<String>> {
        let mesh = &self.mesh;
        let n = mesh.vertex_count();
        let mut problems = Vec::new();
        let inside = count_inside(&mesh.positions, &body.mesh().positions, &body.normals)?;
        if inside * 20 > n {
            problems.push(format!(
                "{inside} of {n} vertices ({:.1} %) are inside the body at rest (more than 5 %): fit the garment first (push it out of the body)",
                100.0 * inside as f64 / n as f64
            ));
        }
        let topo = Topology::new(mesh);
        if let Some(&[a, b]) = topo.non_manifold_edges.first() {
            problems.push(format!(
                "{} non-manifold edges (3 or more faces; first: vertices {a}-{b}): they get no bending term",
                topo.non_manifold_edges.len()
            ));
        }
        let degenerate = mesh.degenerate_faces(1e-12);
        if let Some(first) = degenerate.first() {
            problems.push(format!(
                "{} degenerate (zero-area) faces (first: face {first}): their normals are undefined",
                degenerate.len()
            ));
        }
        Ok(problems)
    }

    /// Writes the OBJ and its sidecar (both atomically).
    pub fn write(&self, path: &Path) -> Result<()> {
        write_obj(
            path,
            &self.mesh,
            &format!("garmentbake garment '{}'", self.name),
        )?;
        let text = toml::to_string(&self.sidecar)?;
        exporters::atomic::write_atomic(&sidecar_path(path), text.as_bytes())?;
        Ok(())
    }
}

/// Vertices of `points` inside the body (offset < 0).
pub fn count_inside(
    points: &[[f32; 3]],
    body_points: &[[f32; 3]],
    body_normals: &[[f32; 3]],
) -> Result<usize> {
    let index = PointIndex::new(body_points)?;
    Ok(body_offsets(points, body_points, body_normals, &index)
        .iter()
        .filter(|&&d| d < 0.0)
        .count())
}

/// Push-out fitting: moves vertices closer than `margin` to the body (or inside it) out along the
/// body normal, relaxing the result with a little Laplacian smoothing so no spikes remain; a final
/// push guarantees the margin. Returns how many vertices were inside before.
pub fn push_out(
    mesh: &mut TriMesh,
    body_points: &[[f32; 3]],
    body_normals: &[[f32; 3]],
    margin: f32,
) -> Result<usize> {
    let index = PointIndex::new(body_points)?;
    let inside = body_offsets(&mesh.positions, body_points, body_normals, &index)
        .iter()
        .filter(|&&d| d < 0.0)
        .count();
    let laplacian = Laplacian::uniform(mesh);
    for round in 0..6 {
        push_once(
            &mut mesh.positions,
            body_points,
            body_normals,
            &index,
            margin,
        );
        if round < 5 {
            mesh.positions = laplacian.smooth(&mesh.positions, 0.3, 1);
        }
    }
    Ok(inside)
}

fn push_once(
    points: &mut [[f32; 3]],
    body_points: &[[f32; 3]],
    body_normals: &[[f32; 3]],
    index: &PointIndex,
    margin: f32,
) {
    let offsets = body_offsets(points, body_points, body_normals, index);
    for (p, d) in points.iter_mut().zip(offsets) {
        if d < margin {
            let (b, _) = index.nearest(*p);
            *p = arr3(v3(*p) + v3(body_normals[b as usize]) * (margin - d));
        }
    }
}
