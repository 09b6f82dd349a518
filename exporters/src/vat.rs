//! Vertex animation textures (VAT): a point cache as textures a vertex shader reads, so an
//! engine plays a 300-frame roll-out with no blend shapes. The layout is SideFX Labs' "soft body"
//! VAT 3.0 one (positions stored as offsets from the rest mesh, normalised into the bounds of
//! all offsets; a normals texture; a mesh whose second UV set addresses each vertex's column;
//! frame count, rate and bounds beside it), with these choices of ours (docs/caches.md):
//!
//! - one texel column per cache point, one row per frame (frame 0 the image's top row); Labs
//!   wraps long meshes over several rows per frame, we refuse more than [`MAX_SIDE`] columns;
//! - the bounds are per axis (`bounds_min` / `bounds_max`, three values each), and both
//!   encodings are normalised: `P = rest + min + texel · (max − min)`; normals `N = 2·texel − 1`;
//! - `.vat.exr` is 32-bit float RGB (the `image` crate's EXR writer, uncompressed), `.vat.png`
//!   16-bit RGB;
//! - the sidecar is our JSON (`NAME.vat.json`), the mesh a glb (`NAME.vat.glb`): `TEXCOORD_1` =
//!   `((column + 0.5) / width, 0.5 / height)`, frame f read at `v + f / height`.
//!
//! Files for `--out NAME.vat.exr` (or `.vat.png`): `NAME.vat.exr` (positions),
//! `NAME.vat.normals.exr`, `NAME.vat.json`, `NAME.vat.glb`, all in the folder of the given path
//! (so an [`crate::atomic::OutputSet`] stages and moves them together).

use crate::asset::{BakedAsset, Mesh};
use crate::atomic::write_atomic;
use std::path::{Path, PathBuf};

/// The widest (and tallest) texture written: what current engines and GPUs load (Unreal and
/// Unity cap textures at 16,384 texels a side).
pub const MAX_SIDE: usize = 16_384;

#[derive(Debug, thiserror::Error)]
pub enum VatError {
    #[error("{0}")]
    Io(#[from] std::io::Error),
    #[error("cannot write {path}: {reason}")]
    Invalid { path: String, reason: String },
}

/// How texels are stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Encoding {
    /// `.vat.exr`: 32-bit float RGB.
    Float32,
    /// `.vat.png`: 16-bit unsigned RGB (65,535 steps over each axis' bounds).
    Uint16,
}

impl Encoding {
    /// The encoding a `NAME.vat.exr` / `NAME.vat.png` path names.
    pub fn of(path: &Path) -> Option<Encoding> {
        let name = path.file_name()?.to_string_lossy().to_ascii_lowercase();
        if name.ends_with(".vat.exr") {
            Some(Encoding::Float32)
        } else if name.ends_with(".vat.png") {
            Some(Encoding::Uint16)
        } else {
            None
        }
    }

    fn extension(self) -> &'static str {
        match self {
            Encoding::Float32 => "exr",
            Encoding::Uint16 => "png",
        }
    }
}

/// A point cache with what a VAT needs beyond it: every point's rest position and every
/// frame's normals, and the mesh it plays on.
pub struct VertexAnimation<'a> {
    pub fps: f32,
    /// Rest position of each cache point (its column's origin).
    pub rest: &'a [[f32; 3]],
    /// Frame-major: `points[frame * rest.len() + point]`.
    pub points: &'a [[f32; 3]],
    /// Unit normals, laid out as `points`.
    pub normals: &'a [[f32; 3]],
    /// The mesh to play it on, at rest (vertices may be split at UV seams:
    /// `mesh.source_vertex` names each one's cache point, i.e. its column).
    pub mesh: Mesh,
    /// Recorded in the sidecar: the units (`m`, `cm`) and up axis (`y`, `z`) of the points.
    pub units: &'a str,
    pub up: &'a str,
}

/// What was written, as the sidecar says it.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Sidecar {
    pub convention: String,
    pub frame_count: usize,
    pub fps: f32,
    pub vertex_count: usize,
    /// Texture size: `width` = vertex count, `height` = frame count.
    pub width: usize,
    pub height: usize,
    /// Per axis, the least and greatest offset from the rest mesh over every point and frame.
    pub bounds_min: [f32; 3],
    pub bounds_max: [f32; 3],
    /// `float32` (EXR) or `uint16` (PNG, texel / 65535).
    pub encoding: String,
    /// File names, in the sidecar's folder.
    pub positions: String,
    pub normals: String,
    pub mesh: String,
    pub units: String,
    pub up: String,
    /// The decoding rules, for a person reading the file.
    pub decode: Vec<String>,
}

impl Sidecar {
    /// The largest error the encoding adds to a coordinate, in the points' units: half a 16-bit
    /// step of the widest axis for PNG, 2⁻²⁴ of it for float32.
    pub fn quantisation(&self) -> f32 {
        let range = (0..3)
            .map(|a| self.bounds_max[a] - self.bounds_min[a])
            .fold(0.0f32, f32::max);
        match self.encoding.as_str() {
            "uint16" => 0.5 * range / 65535.0,
            _ => range * f32::EPSILON,
        }
    }
}

/// The four files of `--out NAME.vat.exr|png`: positions (the path itself), normals, sidecar
/// and mesh.
pub fn file_names(path: &Path) -> Option<[PathBuf; 4]> {
    let encoding = Encoding::of(path)?;
    let name = path.file_name()?.to_string_lossy();
    let stem = &name[..name.len() - ".vat.exr".len()];
    let ext = encoding.extension();
    let sibling = |n: String| path.with_file_name(n);
    Some([
        path.to_path_buf(),
        sibling(format!("{stem}.vat.normals.{ext}")),
        sibling(format!("{stem}.vat.json")),
        sibling(format!("{stem}.vat.glb")),
    ])
}

/// Writes the VAT of `vat` for `path` (`NAME.vat.exr` or `NAME.vat.png`): the four files of
/// [`file_names`], each atomically. Returns the sidecar.
pub fn write(path: &Path, vat: &VertexAnimation) -> Result<Sidecar, VatError> {
    let invalid = |reason: String| VatError::Invalid {
        path: path.display().to_string(),
        reason,
    };
    let (encoding, files) = match (Encoding::of(path), file_names(path)) {
        (Some(e), Some(f)) => (e, f),
        _ => {
            return Err(invalid(
                "a VAT is named NAME.vat.exr or NAME.vat.png".into(),
            ))
        }
    };
    let width = vat.rest.len();
    if width == 0 || vat.points.is_empty() || !vat.points.len().is_multiple_of(width) {
        return Err(invalid(format!(
            "{} points are not whole frames of {width} points",
            vat.points.len()
        )));
    }
    let height = vat.points.len() / width;
    if vat.normals.len() != vat.points.len() {
        return Err(invalid("the normals do not match the points".into()));
    }
    if width > MAX_SIDE || height > MAX_SIDE {
        return Err(invalid(format!(
            "a VAT holds one column per vertex and one row per frame: {width} vertices x {height} frames, more than the {MAX_SIDE} texels a side engines load"
        )));
    }
    if !(vat.fps.is_finite() && vat.fps > 0.0) {
        return Err(invalid("the rate must be positive".into()));
    }
    if let Some(v) = vat
        .mesh
        .source_vertex
        .iter()
        .find(|&&v| v as usize >= width)
    {
        return Err(invalid(format!(
            "mesh vertex of cache point {v}, the cache has {width}"
        )));
    }
    if vat.points.iter().flatten().any(|c| !c.is_finite()) {
        return Err(invalid("the points are not all finite".into()));
    }
    let offsets: Vec<[f32; 3]> = vat
        .points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let r = vat.rest[i % width];
            [p[0] - r[0], p[1] - r[1], p[2] - r[2]]
        })
        .collect();
    let [lo, hi] = crate::asset::extent(&offsets);
    let range = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
    let unit = |d: &[f32; 3]| {
        [0, 1, 2].map(|a| {
            if range[a] > 0.0 {
                ((d[a] - lo[a]) / range[a]).clamp(0.0, 1.0)
            } else {
                0.0
            }
        })
    };
    let positions: Vec<[f32; 3]> = offsets.iter().map(unit).collect();
    let normals: Vec<[f32; 3]> = vat
        .normals
        .iter()
        .map(|n| n.map(|c| (c * 0.5 + 0.5).clamp(0.0, 1.0)))
        .collect();
    let name = |p: &PathBuf| {
        p.file_name()
            .map_or(String::new(), |n| n.to_string_lossy().into_owned())
    };
    let sidecar = Sidecar {
        convention: "SideFX Labs VAT 3.0 soft body; garmentbake layout: one row per frame (frame 0 at the top), one column per vertex, per-axis bounds".into(),
        frame_count: height,
        fps: vat.fps,
        vertex_count: width,
        width,
        height,
        bounds_min: lo,
        bounds_max: hi,
        encoding: match encoding {
            Encoding::Float32 => "float32",
            Encoding::Uint16 => "uint16",
        }
        .into(),
        positions: name(&files[0]),
        normals: name(&files[1]),
        mesh: name(&files[3]),
        units: vat.units.into(),
        up: vat.up.into(),
        decode: vec![
            "texel(column, row): row = frame (0 = the image's top row), column = the vertex's TEXCOORD_1.u * width - 0.5; uint16 texels are divided by 65535".into(),
            "position = rest position (the glb's POSITION) + bounds_min + texel * (bounds_max - bounds_min), per axis".into(),
            "normal = 2 * texel - 1".into(),
            "TEXCOORD_1 = ((column + 0.5) / width, 0.5 / height): frame f is read at v + f / height".into(),
        ],
    };
    let image = |texels: &[[f32; 3]]| encode(encoding, texels, width, height);
    let positions = image(&positions).map_err(|e| invalid(e.to_string()))?;
    let normals = image(&normals).map_err(|e| invalid(e.to_string()))?;
    let json = serde_json::to_vec_pretty(&sidecar).map_err(|e| invalid(e.to_string()))?;
    let glb = crate::gltf::to_glb(&mesh_asset(vat, &sidecar, name(&files[2])));
    for (file, bytes) in files.iter().zip([&positions, &normals, &json, &glb]) {
        write_atomic(file, bytes)?;
    }
    Ok(sidecar)
}

/// A VAT read back from its files, as an engine gets it.
#[derive(Clone, Debug)]
pub struct Played {
    pub sidecar: Sidecar,
    /// The `NAME.vat.glb` bytes.
    pub glb: Vec<u8>,
    /// Texels as stored (in `[0, 1]`, PNG's divided by 65535), RGB, row-major from the top row
    /// (row = frame).
    pub positions: Vec<f32>,
    pub normals: Vec<f32>,
}

/// Reads the VAT that `path` names (`NAME.vat.exr`, `NAME.vat.png` or `NAME.vat.json`): the
/// sidecar, then the files it names beside it, each texture checked against its size.
pub fn read(path: &Path) -> Result<Played, VatError> {
    let invalid = |p: &Path, reason: String| VatError::Invalid {
        path: p.display().to_string(),
        reason,
    };
    let name = path
        .file_name()
        .map_or(String::new(), |n| n.to_string_lossy().to_ascii_lowercase());
    let json = if name.ends_with(".vat.json") {
        path.to_path_buf()
    } else {
        match file_names(path) {
            Some(files) => files[2].clone(),
            None => {
                return Err(invalid(
                    path,
                    "a VAT is named NAME.vat.exr, NAME.vat.png or NAME.vat.json".into(),
                ))
            }
        }
    };
    let read = |p: &Path| {
        std::fs::read(p).map_err(|e| {
            invalid(
                p,
                format!("cannot read it: {}", crate::atomic::io_message(&e)),
            )
        })
    };
    let sidecar: Sidecar = serde_json::from_slice(&read(&json)?)
        .map_err(|e| invalid(&json, format!("not a VAT sidecar: {e}")))?;
    let beside = |n: &str| json.with_file_name(n);
    let texels = |n: &str| -> Result<Vec<f32>, VatError> {
        let p = beside(n);
        let img = image::load_from_memory(&read(&p)?).map_err(|e| invalid(&p, e.to_string()))?;
        if (img.width() as usize, img.height() as usize) != (sidecar.width, sidecar.height) {
            return Err(invalid(
                &p,
                format!(
                    "{}x{} texels, the sidecar says {}x{}",
                    img.width(),
                    img.height(),
                    sidecar.width,
                    sidecar.height
                ),
            ));
        }
        Ok(match sidecar.encoding.as_str() {
            "uint16" => img
                .into_rgb16()
                .into_raw()
                .into_iter()
                .map(|t| f32::from(t) / 65535.0)
                .collect(),
            _ => img.into_rgb32f().into_raw(),
        })
    };
    Ok(Played {
        positions: texels(&sidecar.positions)?,
        normals: texels(&sidecar.normals)?,
        glb: read(&beside(&sidecar.mesh))?,
        sidecar,
    })
}

/// Texels in `[0, 1]`, row-major from the top row, as the encoding's file bytes.
fn encode(
    encoding: Encoding,
    texels: &[[f32; 3]],
    width: usize,
    height: usize,
) -> image::ImageResult<Vec<u8>> {
    let mut bytes = std::io::Cursor::new(Vec::new());
    let (w, h) = (width as u32, height as u32);
    let too_big = || {
        image::ImageError::Limits(image::error::LimitError::from_kind(
            image::error::LimitErrorKind::DimensionError,
        ))
    };
    match encoding {
        Encoding::Float32 => {
            let flat: Vec<f32> = texels.iter().flatten().copied().collect();
            image::Rgb32FImage::from_raw(w, h, flat)
                .ok_or_else(too_big)?
                .write_to(&mut bytes, image::ImageFormat::OpenExr)?;
        }
        Encoding::Uint16 => {
            let flat: Vec<u16> = texels
                .iter()
                .flatten()
                .map(|c| (c * 65535.0).round() as u16)
                .collect();
            image::ImageBuffer::<image::Rgb<u16>, _>::from_raw(w, h, flat)
                .ok_or_else(too_big)?
                .write_to(&mut bytes, image::ImageFormat::Png)?;
        }
    }
    Ok(bytes.into_inner())
}

/// The glb: the mesh at rest, its second UV set addressing each vertex's column (and the first
/// too when the mesh has no UVs, as glTF wants its sets numbered from 0).
fn mesh_asset(vat: &VertexAnimation, sidecar: &Sidecar, json: String) -> BakedAsset {
    let (w, h) = (sidecar.width as f32, sidecar.height as f32);
    let mut mesh = vat.mesh.clone();
    let columns: Vec<[f32; 2]> = mesh
        .source_vertex
        .iter()
        .map(|&v| [(v as f32 + 0.5) / w, 0.5 / h])
        .collect();
    if mesh.uvs.is_none() {
        mesh.uvs = Some(columns.clone());
    }
    mesh.uvs2 = Some(columns);
    BakedAsset {
        meshes: vec![mesh],
        provenance: vec![
            ("generator".into(), "garmentbake".into()),
            ("vat".into(), sidecar.positions.clone()),
            ("vat_sidecar".into(), json),
        ],
        ..Default::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rest points, frames of points, normals.
    type Sample = (Vec<[f32; 3]>, Vec<[f32; 3]>, Vec<[f32; 3]>);

    fn sample(frames: usize) -> Sample {
        let rest = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let mut points = Vec::new();
        for f in 0..frames {
            for (i, r) in rest.iter().enumerate() {
                let t = f as f32 * 0.1 + i as f32 * 0.01;
                points.push([r[0] + t, r[1] - 0.5 * t, r[2] + t * t]);
            }
        }
        let normals = vec![[0.0, 0.0, 1.0]; points.len()];
        (rest, points, normals)
    }

    fn vat<'a>(
        rest: &'a [[f32; 3]],
        points: &'a [[f32; 3]],
        normals: &'a [[f32; 3]],
    ) -> VertexAnimation<'a> {
        VertexAnimation {
            fps: 30.0,
            rest,
            points,
            normals,
            mesh: Mesh {
                name: "garment".into(),
                points: rest.to_vec(),
                triangles: vec![[0, 1, 2]],
                source_vertex: vec![0, 1, 2],
                ..Default::default()
            },
            units: "m",
            up: "y",
        }
    }

    #[test]
    fn names_the_four_files() {
        let f = file_names(Path::new("out/shot.VAT.png")).unwrap();
        assert_eq!(f[1], Path::new("out/shot.vat.normals.png"));
        assert_eq!(f[2], Path::new("out/shot.vat.json"));
        assert_eq!(f[3], Path::new("out/shot.vat.glb"));
        assert!(file_names(Path::new("shot.png")).is_none());
    }

    #[test]
    fn png_texels_decode_within_half_a_step() {
        let dir = std::env::temp_dir().join(format!("gb-vat-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (rest, points, normals) = sample(4);
        let path = dir.join("t.vat.png");
        let side = write(&path, &vat(&rest, &points, &normals)).unwrap();
        assert_eq!((side.width, side.height, side.frame_count), (3, 4, 4));
        let img = image::open(&path).unwrap().into_rgb16();
        assert_eq!(img.dimensions(), (3, 4));
        let mut worst = 0.0f32;
        for f in 0..4 {
            for v in 0..3 {
                let t = img.get_pixel(v as u32, f as u32).0;
                for a in 0..3 {
                    let d = side.bounds_min[a]
                        + t[a] as f32 / 65535.0 * (side.bounds_max[a] - side.bounds_min[a]);
                    worst = worst.max((rest[v][a] + d - points[f * 3 + v][a]).abs());
                }
            }
        }
        assert!(worst <= side.quantisation() * 1.01 + 1e-6, "{worst}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn reads_back_what_it_wrote() {
        let dir = std::env::temp_dir().join(format!("gb-vat-read-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (rest, points, normals) = sample(5);
        for ext in ["exr", "png"] {
            let path = dir.join(format!("t.vat.{ext}"));
            let side = write(&path, &vat(&rest, &points, &normals)).unwrap();
            let played = read(&dir.join("t.vat.json")).unwrap();
            assert_eq!(played.sidecar, side);
            assert_eq!(played.positions.len(), 3 * 3 * 5);
            let mut worst = 0.0f32;
            for (i, p) in points.iter().enumerate() {
                for a in 0..3 {
                    let t = played.positions[3 * i + a];
                    let range = side.bounds_max[a] - side.bounds_min[a];
                    let d = rest[i % 3][a] + side.bounds_min[a] + t * range;
                    worst = worst.max((d - p[a]).abs());
                }
                assert!((played.normals[3 * i + 2] - 1.0).abs() < 1e-4);
            }
            assert!(worst <= side.quantisation() * 1.01 + 1e-6, "{ext}: {worst}");
            assert_eq!(&played.glb[..4], b"glTF");
        }
        assert!(read(&dir.join("t.png")).is_err());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn refuses_ragged_frames() {
        let (rest, mut points, normals) = sample(2);
        points.pop();
        let e = write(Path::new("x.vat.exr"), &vat(&rest, &points, &normals));
        assert!(e.is_err());
    }
}
