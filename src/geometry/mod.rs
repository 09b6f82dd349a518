//! Triangle-mesh geometry shared by the importers, the models and the exporters.
//!
//! Storage is plain `f32` arrays (`[f32; 3]` positions, `[u32; 3]` triangles) so buffers go to
//! tch tensors and glTF accessors without conversion; `nalgebra` is used for the arithmetic.
//! Functions that take a mesh assume it passed [`TriMesh::validate`] (the readers guarantee that):
//! bad *input* is rejected at the file boundary with an error, not deep inside the maths.

pub mod candidates;
pub mod edges;
pub mod frames;
pub mod laplacian;
pub mod mesh;
pub mod nearest;
pub mod normals;
pub mod sdf_grid;
pub mod strain_limit;
pub mod topology;
pub mod winding;

#[cfg(test)]
pub(crate) mod test_meshes;

pub use candidates::CandidateTree;
pub use frames::Frames;
pub use laplacian::Laplacian;
pub use mesh::{FaceVaryingUv, MeshError, TriMesh};
pub use nearest::{NearestError, PointIndex};
pub use normals::{face_normals, vertex_normals};
pub use strain_limit::StrainLimit;
pub use topology::{Hinge, Topology};
pub use winding::SurfaceIndex;

/// The vector type used for geometric arithmetic.
pub type Vec3 = nalgebra::Vector3<f32>;

/// Converts a stored position into a vector for arithmetic.
#[inline]
pub fn v3(p: [f32; 3]) -> Vec3 {
    Vec3::new(p[0], p[1], p[2])
}

/// Squared distance between two stored positions (no square root: for comparisons with a
/// squared radius).
#[inline]
pub fn distance2(a: [f32; 3], b: [f32; 3]) -> f32 {
    let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
}

/// Distance between two stored positions.
#[inline]
pub fn distance(a: [f32; 3], b: [f32; 3]) -> f32 {
    (v3(a) - v3(b)).norm()
}

/// Converts a vector back into stored form.
#[inline]
pub fn arr3(v: Vec3) -> [f32; 3] {
    [v.x, v.y, v.z]
}
