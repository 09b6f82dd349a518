//! The exporter-neutral baked asset: a skeleton, skinned meshes with blend shapes, and animations.
//! Names follow UsdSkel (Skeleton, SkelAnimation, BlendShape, jointIndices / jointWeights).
//! Units metres, Y-up; quaternions are `[x, y, z, w]`; matrices column-major.

/// The joint hierarchy, parents before children.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Skeleton {
    pub joint_names: Vec<String>,
    pub parents: Vec<Option<usize>>,
    /// Rest pose, local to the parent joint.
    pub rest_translations: Vec<[f32; 3]>,
    pub rest_rotations: Vec<[f32; 4]>,
    /// World → joint at bind time (column-major 4×4).
    pub inverse_bind_matrices: Vec<[f32; 16]>,
}

impl Skeleton {
    pub fn joint_count(&self) -> usize {
        self.joint_names.len()
    }
}

/// Per-vertex skin binding, `influences` entries per vertex, vertex-major.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SkinBinding {
    pub influences: usize,
    pub joint_indices: Vec<u16>,
    pub joint_weights: Vec<f32>,
}

/// A morph target: offsets added to the rest points before skinning.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BlendShape {
    pub name: String,
    pub offsets: Vec<[f32; 3]>,
    /// Optional normal offsets (same length as `offsets`).
    pub normal_offsets: Option<Vec<[f32; 3]>>,
}

/// One mesh with per-vertex attributes (vertices already split at UV seams).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    pub name: String,
    pub points: Vec<[f32; 3]>,
    pub normals: Option<Vec<[f32; 3]>>,
    pub uvs: Option<Vec<[f32; 2]>>,
    pub triangles: Vec<[u32; 3]>,
    pub skin: Option<SkinBinding>,
    pub blend_shapes: Vec<BlendShape>,
    /// For each vertex, the vertex of the source mesh it came from (seam splits duplicate vertices).
    pub source_vertex: Vec<u32>,
    /// RGB base colour used by viewers (linear, 0..1).
    pub color: [f32; 3],
}

/// A clip: joint local transforms and blend-shape weights sampled at a fixed rate.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SkelAnimation {
    pub name: String,
    pub fps: f32,
    pub frame_count: usize,
    /// `[frame * joints + joint]`, local to the parent joint.
    pub translations: Vec<[f32; 3]>,
    pub rotations: Vec<[f32; 4]>,
    /// Per animated mesh: mesh index and weights `[frame * targets + target]`.
    pub blend_shape_weights: Vec<(usize, Vec<f32>)>,
}

impl SkelAnimation {
    pub fn duration(&self) -> f32 {
        self.frame_count.saturating_sub(1) as f32 / self.fps
    }
    pub fn time(&self, frame: usize) -> f32 {
        frame as f32 / self.fps
    }
}

/// Everything one output file holds.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BakedAsset {
    pub skeleton: Skeleton,
    pub meshes: Vec<Mesh>,
    pub animations: Vec<SkelAnimation>,
    /// Free-form provenance written into the file's metadata (generator, model, clips).
    pub provenance: Vec<(String, String)>,
}
