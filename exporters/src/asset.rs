//! The exporter-neutral baked asset: a skeleton, skinned meshes with blend shapes, and animations.
//! Names follow UsdSkel (Skeleton, SkelAnimation, BlendShape, jointIndices / jointWeights).
//! Units metres, Y-up; quaternions are `[x, y, z, w]`; matrices column-major.

/// The joint hierarchy, parents before children (also the plain form of the core's skeleton in
/// model files).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
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

/// Steps of a SHORT normalized value on each side of zero: the stored integer `k` means
/// `k / SHORT_STEPS` (glTF 2.0 §3.11).
pub const SHORT_STEPS: f32 = 32767.0;

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
    /// A second UV set (glTF `TEXCOORD_1`; needs `uvs`): a VAT's texel column per vertex.
    pub uvs2: Option<Vec<[f32; 2]>>,
    pub triangles: Vec<[u32; 3]>,
    pub skin: Option<SkinBinding>,
    pub blend_shapes: Vec<BlendShape>,
    /// For each vertex, the vertex of the source mesh it came from (seam splits duplicate vertices).
    pub source_vertex: Vec<u32>,
    /// RGB base colour used by viewers (linear, 0..1).
    pub color: [f32; 3],
    /// The blend shapes' offsets lie in [-1, 1] on the grid of SHORT normalized values
    /// (`k / SHORT_STEPS`): glTF stores them as 16-bit integers under KHR_mesh_quantization,
    /// half the bytes of floats and exact. Readers without the extension refuse such a file.
    pub quantized_blend_shapes: bool,
    /// The blend-shape weights a reader shows when no animation plays (glTF `mesh.weights`):
    /// the bakes' weights start at 0 at each target's lowest point, so all-0 would show a
    /// distorted garment. Empty: all 0.
    pub rest_weights: Vec<f32>,
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

impl BakedAsset {
    /// Structural checks the formats cannot express: sizes that must agree. Every writer runs
    /// them first so a bad asset is refused with a reason instead of producing a broken file.
    pub fn check(&self) -> Result<(), String> {
        let sk = &self.skeleton;
        let joints = sk.joint_count();
        if sk.parents.len() != joints
            || sk.rest_translations.len() != joints
            || sk.rest_rotations.len() != joints
            || sk.inverse_bind_matrices.len() != joints
        {
            return Err(format!(
                "skeleton: per-joint arrays do not match {joints} joints"
            ));
        }
        if let Some((j, _)) = sk
            .parents
            .iter()
            .enumerate()
            .find(|(j, p)| p.is_some_and(|p| p >= *j))
        {
            return Err(format!(
                "skeleton: joint '{}' comes before its parent",
                sk.joint_names[j]
            ));
        }
        for mesh in &self.meshes {
            let n = mesh.points.len();
            if let Some(skin) = &mesh.skin {
                if skin.influences == 0
                    || skin.joint_indices.len() != n * skin.influences
                    || skin.joint_weights.len() != n * skin.influences
                {
                    return Err(format!(
                        "mesh '{}': skin arrays do not match {n} vertices",
                        mesh.name
                    ));
                }
                if let Some(j) = skin.joint_indices.iter().find(|&&j| j as usize >= joints) {
                    return Err(format!(
                        "mesh '{}': joint index {j} but the skeleton has {joints} joints",
                        mesh.name
                    ));
                }
            }
            if let Some(t) = mesh.triangles.iter().flatten().find(|&&i| i as usize >= n) {
                return Err(format!(
                    "mesh '{}': triangle index {t} out of range ({n} vertices)",
                    mesh.name
                ));
            }
            let per_vertex = |len: Option<usize>| len.is_none_or(|l| l == n);
            if !per_vertex(mesh.normals.as_ref().map(Vec::len))
                || !per_vertex(mesh.uvs.as_ref().map(Vec::len))
                || !per_vertex(mesh.uvs2.as_ref().map(Vec::len))
                || (mesh.uvs2.is_some() && mesh.uvs.is_none())
            {
                return Err(format!(
                    "mesh '{}': normals or UVs do not match {n} vertices",
                    mesh.name
                ));
            }
            if !mesh.rest_weights.is_empty() && mesh.rest_weights.len() != mesh.blend_shapes.len() {
                return Err(format!(
                    "mesh '{}': {} rest weights for {} blend shapes",
                    mesh.name,
                    mesh.rest_weights.len(),
                    mesh.blend_shapes.len()
                ));
            }
            if mesh.blend_shapes.iter().any(|b| {
                b.offsets.len() != n || !per_vertex(b.normal_offsets.as_ref().map(Vec::len))
            }) {
                return Err(format!(
                    "mesh '{}': a blend shape does not have {n} offsets",
                    mesh.name
                ));
            }
        }
        for anim in &self.animations {
            if anim.rotations.len() != anim.frame_count * joints
                || anim.translations.len() != anim.frame_count * joints
            {
                return Err(format!(
                    "animation '{}': joint samples do not match {} frames",
                    anim.name, anim.frame_count
                ));
            }
            if anim.frame_count < 2 || !positive_rate(anim.fps) {
                return Err(format!(
                    "animation '{}': needs at least 2 frames and a positive rate",
                    anim.name
                ));
            }
            for (m, weights) in &anim.blend_shape_weights {
                let Some(mesh) = self.meshes.get(*m) else {
                    return Err(format!(
                        "animation '{}': blend-shape weights for mesh {m}, which does not exist",
                        anim.name
                    ));
                };
                if weights.len() != anim.frame_count * mesh.blend_shapes.len() {
                    return Err(format!(
                        "animation '{}': blend-shape weights of mesh '{}' do not match {} frames x {} shapes",
                        anim.name,
                        mesh.name,
                        anim.frame_count,
                        mesh.blend_shapes.len()
                    ));
                }
            }
        }
        Ok(())
    }
}

/// Renormalised in f64 then rounded to f32, so validators (and skinning, which assumes unit
/// quaternions) see unit length.
pub fn unit_quat(q: [f32; 4]) -> [f32; 4] {
    let n = q.iter().map(|c| (*c as f64).powi(2)).sum::<f64>().sqrt();
    q.map(|c| (c as f64 / n) as f32)
}

/// A per-frame point cache: the same topology at every frame, only the points move (the baked
/// form of motion-driven garments whose skinning changes every frame). Format-neutral: the USD
/// writer makes time-sampled `points`, the PC2/MDD writers their own frames.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointCache {
    pub name: String,
    pub fps: f32,
    /// The clip frame of the first sample (0 unless the cache is a span of a longer clip):
    /// PC2's start frame, MDD's first time, USD's first time code, Alembic's start time.
    pub start: usize,
    pub triangles: Vec<[u32; 3]>,
    /// The mesh's UVs, when it has them: face-varying (a seam vertex has one UV per side).
    pub uvs: Option<CacheUvs>,
    pub point_count: usize,
    /// Frame-major: `points[frame * point_count + vertex]` (one flat buffer, so a writer hands
    /// whole frames to its format without copying vertex by vertex).
    pub points: Vec<[f32; 3]>,
}

/// Face-varying UVs of a point cache: the coordinates, and per triangle (in the cache's
/// triangle order) the coordinate each corner takes. Writers store them indexed, as DCCs do
/// (Alembic's indexed face-varying `uv`, USD's indexed `faceVarying` `primvars:st`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CacheUvs {
    pub coords: Vec<[f32; 2]>,
    pub triangles: Vec<[u32; 3]>,
}

impl PointCache {
    /// Caches written into one file (a USD stage, an Alembic archive) share its rate and frame
    /// range.
    pub fn same_timeline(caches: &[PointCache]) -> Result<(), String> {
        let first = caches.first().ok_or("no point cache to write")?;
        match caches
            .iter()
            .find(|c| c.fps != first.fps || c.start != first.start || c.frame_count() != first.frame_count())
        {
            Some(c) => Err(format!(
                "point caches '{}' ({} frames from frame {} at {} fps) and '{}' ({} from {} at {}) do not share a timeline",
                first.name,
                first.frame_count(),
                first.start,
                first.fps,
                c.name,
                c.frame_count(),
                c.start,
                c.fps
            )),
            None => Ok(()),
        }
    }

    pub fn frame_count(&self) -> usize {
        self.points.len().checked_div(self.point_count).unwrap_or(0)
    }

    pub fn frame(&self, f: usize) -> &[[f32; 3]] {
        &self.points[f * self.point_count..(f + 1) * self.point_count]
    }

    pub fn check(&self) -> Result<(), String> {
        let n = self.point_count;
        if n == 0 || self.points.is_empty() || !self.points.len().is_multiple_of(n) {
            return Err(format!(
                "point cache '{}': {} points are not whole frames of {n} points",
                self.name,
                self.points.len()
            ));
        }
        if !positive_rate(self.fps) {
            return Err(format!(
                "point cache '{}': the rate must be positive",
                self.name
            ));
        }
        if let Some(t) = self.triangles.iter().flatten().find(|&&i| i as usize >= n) {
            return Err(format!(
                "point cache '{}': triangle index {t} out of range ({n} points)",
                self.name
            ));
        }
        if let Some(uv) = &self.uvs {
            if uv.triangles.len() != self.triangles.len() {
                return Err(format!(
                    "point cache '{}': {} UV triangles for {} triangles",
                    self.name,
                    uv.triangles.len(),
                    self.triangles.len()
                ));
            }
            if let Some(i) = uv
                .triangles
                .iter()
                .flatten()
                .find(|&&i| i as usize >= uv.coords.len())
            {
                return Err(format!(
                    "point cache '{}': UV index {i} out of range ({} UVs)",
                    self.name,
                    uv.coords.len()
                ));
            }
        }
        Ok(())
    }
}

/// The units and up axis a point cache is written in (`--out-units cm|m`, `--out-up y|z`):
/// garmentbake works in metres, Y-up, right-handed; Unreal wants centimetres, Z-up, Maya
/// centimetres, Y-up.
/// [`CacheSpace::point`] turns our points into it (the caller does, before writing); writers
/// record it where the format has a place (USD `metersPerUnit` / `upAxis`, Alembic's user
/// properties, a VAT's sidecar); PC2 and MDD have none.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CacheSpace {
    pub centimetres: bool,
    pub z_up: bool,
}

impl CacheSpace {
    /// Metres, Y-up: the points as garmentbake has them.
    pub const NATIVE: CacheSpace = CacheSpace {
        centimetres: false,
        z_up: false,
    };

    /// Our Y-up point turned Z-up by a right-handed quarter turn about +X, `(x, y, z) → (x, −z,
    /// y)` (Blender's glTF and USD importers turn Y-up files the same way: the garment's front,
    /// +Z, faces −Y), then scaled to the units.
    pub fn point(self, p: [f32; 3]) -> [f32; 3] {
        let s = self.scale();
        self.direction(p).map(|c| c * s)
    }

    /// A direction (a normal): turned, not scaled.
    pub fn direction(self, d: [f32; 3]) -> [f32; 3] {
        if self.z_up {
            [d[0], -d[2], d[1]]
        } else {
            d
        }
    }

    /// Units per metre: 100 for centimetres.
    pub fn scale(self) -> f32 {
        if self.centimetres {
            100.0
        } else {
            1.0
        }
    }

    /// USD `metersPerUnit`.
    pub fn meters_per_unit(self) -> f64 {
        1.0 / self.scale() as f64
    }

    /// `m` or `cm`.
    pub fn units(self) -> &'static str {
        if self.centimetres {
            "cm"
        } else {
            "m"
        }
    }

    /// `Y` or `Z` (USD's `upAxis` tokens).
    pub fn up_axis(self) -> &'static str {
        if self.z_up {
            "Z"
        } else {
            "Y"
        }
    }
}

/// Axis-aligned bounds `[min, max]` of points (USD `extent`).
pub fn extent(points: &[[f32; 3]]) -> [[f32; 3]; 2] {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in points {
        for c in 0..3 {
            lo[c] = lo[c].min(p[c]);
            hi[c] = hi[c].max(p[c]);
        }
    }
    [lo, hi]
}

/// A usable frame rate: finite and above zero (NaN is refused too).
fn positive_rate(fps: f32) -> bool {
    fps.is_finite() && fps > 0.0
}
