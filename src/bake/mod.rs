//! Turns rig data and model output into the exporter-neutral baked asset (`exporters::asset`).

pub mod compress;
pub mod normals;
pub mod pbns;
pub mod replay;
pub mod sequence;

use crate::geometry::mesh::TriMesh;
use crate::geometry::normals::vertex_normals;
use crate::rig::{SkelAnimation, Skeleton, Skin};
use exporters::asset;

pub fn skeleton_asset(skeleton: &Skeleton) -> asset::Skeleton {
    skeleton.to_plain()
}

pub fn animation_asset(anim: &SkelAnimation) -> asset::SkelAnimation {
    asset::SkelAnimation {
        name: anim.name.clone(),
        fps: anim.fps,
        frame_count: anim.frame_count(),
        translations: anim
            .translations
            .iter()
            .flatten()
            .map(|t| (*t).into())
            .collect(),
        rotations: anim
            .rotations
            .iter()
            .flatten()
            .map(|r| r.coords.into())
            .collect(),
        blend_shape_weights: Vec::new(),
    }
}

/// `mesh` with each vertex moved by `offsets` (rest space): the base a bake whose blend-shape
/// weights start at 0 plays its targets on.
pub fn moved_by(mesh: &TriMesh, offsets: &[[f32; 3]]) -> TriMesh {
    let mut moved = mesh.clone();
    for (p, d) in moved.positions.iter_mut().zip(offsets) {
        (0..3).for_each(|a| p[a] += d[a]);
    }
    moved
}

/// A skinned mesh, split at UV seams (glTF needs one UV per vertex); normals from the welded mesh
/// so seams stay invisible.
/// `normals`: per-vertex normals to keep (e.g. read from a file), else computed.
pub fn skinned_mesh_asset(
    name: &str,
    mesh: &TriMesh,
    normals: Option<&[[f32; 3]]>,
    skin: &Skin,
    color: [f32; 3],
) -> asset::Mesh {
    let normals = normals.map_or_else(
        || vertex_normals(&mesh.positions, &mesh.triangles),
        <[_]>::to_vec,
    );
    let (source_vertex, uvs, triangles) = match &mesh.uv {
        // Already one UV per vertex: keep the vertex order untouched.
        Some(uv) if uv.triangles == mesh.triangles && uv.coords.len() == mesh.vertex_count() => (
            (0..mesh.vertex_count() as u32).collect(),
            Some(uv.coords.clone()),
            mesh.triangles.clone(),
        ),
        Some(_) => {
            let (remap, uvs, tris) = mesh.split_by_uv();
            (remap, Some(uvs), tris)
        }
        None => (
            (0..mesh.vertex_count() as u32).collect(),
            None,
            mesh.triangles.clone(),
        ),
    };
    let pick = |v: &[[f32; 3]]| {
        source_vertex
            .iter()
            .map(|&s| v[s as usize])
            .collect::<Vec<_>>()
    };
    let skin = skin.subset(&source_vertex);
    asset::Mesh {
        name: name.to_string(),
        points: pick(&mesh.positions),
        normals: Some(pick(&normals)),
        uvs,
        uvs2: None,
        triangles,
        skin: Some(asset::SkinBinding {
            influences: skin.influences,
            joint_indices: skin.joint_indices,
            joint_weights: skin.joint_weights,
        }),
        blend_shapes: Vec::new(),
        source_vertex,
        color,
        quantized_blend_shapes: false,
        rest_weights: Vec::new(),
    }
}

/// Colour of the body in every viewer: a neutral grey.
pub const BODY_COLOR: [f32; 3] = [0.6, 0.6, 0.6];
