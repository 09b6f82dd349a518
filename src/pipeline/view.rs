//! The `view` page: a baked glTF and point caches on its garment in one self-contained HTML page
//! (exporters::viewer), written or served on 127.0.0.1; also the pages `bake`, `eval` and
//! `rollout` write with `--view`, for which it builds a glb of the body and the garment at rest.

use crate::bake::{animation_asset, skeleton_asset, skinned_mesh_asset, BODY_COLOR};
use crate::body::Body;
use crate::geometry::TriMesh;
use crate::io::point_cache::read_pc2;
use crate::rig::{JointTransform, SkelAnimation};
use anyhow::{bail, Context, Result};
use exporters::atomic::OutputSet;
use exporters::vat::Played;
use exporters::viewer::{Page, Track};
use serde::Serialize;
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};

/// A cache shown on the page: where it came from and its size.
#[derive(Clone, Serialize)]
pub struct CacheReport {
    pub path: PathBuf,
    pub frames: usize,
    pub points: usize,
}

/// Refuses a page name that is not `.html` (checked before a command's long work).
pub fn check_page_path(out: &Path) -> Result<()> {
    if !out
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("html") || e.eq_ignore_ascii_case("htm"))
    {
        bail!("{}: the page is HTML: name it .html", out.display());
    }
    Ok(())
}

/// Writes `page` atomically; its size in bytes.
pub fn write_page(out: &Path, page: &Page) -> Result<u64> {
    check_page_path(out)?;
    exporters::viewer::write(out, page).with_context(|| format!("writing {}", out.display()))
}

pub fn file_name(path: &Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into(),
    )
}

/// Whether `path` names vertex animation textures (`NAME.vat.exr`, `.vat.png`, `.vat.json`).
pub fn is_vat(path: &Path) -> bool {
    let name = file_name(path).to_ascii_lowercase();
    exporters::vat::Encoding::of(path).is_some() || name.ends_with(".vat.json")
}

/// The VAT `path` names, read back from its files (sidecar, textures, glb).
pub fn read_vat(path: &Path) -> Result<Played> {
    exporters::vat::read(path).map_err(anyhow::Error::from)
}

/// The VAT an `--out` wrote, read from where `outputs` staged it (before the set is committed):
/// what a `--view` page of that command plays. None when `out` is no VAT.
pub fn staged_vat(outputs: &OutputSet, out: &Path) -> Result<Option<Played>> {
    if !is_vat(out) {
        return Ok(None);
    }
    Ok(Some(read_vat(&outputs.staged(out)?)?))
}

/// The page of a VAT alone: its glb's mesh played by its textures at the sidecar's rate.
pub fn vat_page<'a>(vat: &'a Played, title: String) -> Page<'a> {
    Page {
        title,
        glb: &[],
        garment: None,
        garment_is_bake: true,
        vertex_map: None,
        fps: Some(vat.sidecar.fps),
        tracks: Vec::new(),
        reference: None,
        error_scale_mm: 10.0,
        vat: Some(vat),
    }
}

pub fn read_glb(path: &Path) -> Result<Vec<u8>> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    if !bytes.starts_with(b"glTF") {
        bail!(
            "{}: not a binary glTF (.glb); view inlines one file: bake with --out NAME.glb",
            path.display()
        );
    }
    Ok(bytes)
}

/// What the page needs to know of the glTF before writing it.
pub struct Scene {
    pub clips: Vec<String>,
    /// Node name of the mesh caches play on.
    pub garment: String,
    pub vertices: usize,
    /// `sourceVertex` of the garment mesh (the bake splits vertices at UV seams).
    pub vertex_map: Option<Vec<u32>>,
    file: PathBuf,
}

impl Scene {
    pub fn of(glb: &[u8], path: &Path) -> Result<Scene> {
        let gltf =
            gltf::Gltf::from_slice(glb).with_context(|| format!("{}: bad glTF", path.display()))?;
        let meshes: Vec<(String, gltf::Mesh)> = gltf
            .nodes()
            .filter_map(|n| Some((n.name().unwrap_or_default().to_string(), n.mesh()?)))
            .collect();
        // The bake's garment node is named `garment`; another file's first mesh stands in.
        let Some((name, mesh)) = meshes
            .iter()
            .find(|(n, _)| n == "garment")
            .or(meshes.first())
        else {
            bail!("{}: no mesh to show", path.display());
        };
        let vertices = mesh
            .primitives()
            .next()
            .and_then(|p| p.get(&gltf::Semantic::Positions))
            .map_or(0, |a| a.count());
        let vertex_map = mesh
            .extras()
            .as_ref()
            .and_then(|raw| serde_json::from_str::<serde_json::Value>(raw.get()).ok())
            .and_then(|v| serde_json::from_value::<Vec<u32>>(v["sourceVertex"].clone()).ok())
            .filter(|m| m.len() == vertices);
        Ok(Scene {
            clips: gltf
                .animations()
                .enumerate()
                .map(|(i, a)| a.name().map_or_else(|| format!("clip {i}"), str::to_string))
                .collect(),
            garment: name.clone(),
            vertices,
            vertex_map,
            file: path.to_path_buf(),
        })
    }

    /// Points per frame a cache of this garment has: the source mesh's count when the bake split
    /// vertices at seams.
    fn cache_points(&self) -> usize {
        self.vertex_map.as_ref().map_or(self.vertices, |m| {
            m.iter().max().map_or(0, |&x| x as usize + 1)
        })
    }

    /// Reads a cache that must fit the garment mesh.
    pub fn cache(&self, path: &Path) -> Result<(CacheReport, Track)> {
        let points = self.cache_points();
        let header = exporters::pc2::read(
            &std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?,
        )
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?
        .0;
        if header.points != points {
            bail!(
                "{}: {} points per frame, but the garment '{}' of {} has {points} (a cache of another mesh?)",
                path.display(),
                header.points,
                self.garment,
                self.file.display()
            );
        }
        // The page plays the cache at the glb's rate (PC2 has none).
        let frames = read_pc2(path, points, 0.0)?;
        Ok((
            CacheReport {
                path: path.to_path_buf(),
                frames: frames.len(),
                points,
            },
            Track {
                name: path
                    .file_stem()
                    .map_or("cache".into(), |s| s.to_string_lossy().into_owned()),
                point_count: points,
                points: frames.into_points().into_iter().flatten().collect(),
            },
        ))
    }
}

/// Serves `html` at every path of http://127.0.0.1:PORT/ until the process is interrupted.
pub fn serve(html: &str, port: u16, say: &dyn Fn(&str)) -> Result<()> {
    let listener = std::net::TcpListener::bind(("127.0.0.1", port))
        .with_context(|| format!("cannot listen on 127.0.0.1:{port} (in use? try --port)"))?;
    let port = listener.local_addr()?.port();
    // On stderr too, so a --json run (or a script) still learns the address.
    eprintln!("serving http://127.0.0.1:{port}/ (Ctrl-C to stop)");
    say(&format!("{} bytes per request", html.len()));
    for stream in listener.incoming() {
        let Ok(mut stream) = stream else { continue };
        // Only the request line matters; an unreadable request gets no answer.
        let mut line = String::new();
        if BufReader::new(&stream).read_line(&mut line).is_err() {
            continue;
        }
        let head = format!(
            "HTTP/1.1 200 OK\r\nContent-Type: text/html; charset=utf-8\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
            html.len()
        );
        let _ = stream
            .write_all(head.as_bytes())
            .and_then(|_| stream.write_all(html.as_bytes()));
    }
    Ok(())
}

/// `--view PAGE.html` of bake: the page of a glb just baked (no caches); the size of the page.
pub fn glb_page(out: &Path, glb: &[u8], title: &str) -> Result<u64> {
    let scene = Scene::of(glb, Path::new(title))?;
    let page = Page {
        title: title.to_string(),
        glb,
        garment: Some(scene.garment.clone()),
        garment_is_bake: true,
        vertex_map: scene.vertex_map,
        fps: None,
        tracks: Vec::new(),
        reference: None,
        error_scale_mm: 10.0,
        vat: None,
    };
    write_page(out, &page)
}

/// The scene for caches of a model's garment (eval, rollout): the body posed by `poses` and the
/// garment's own mesh at rest, which the caches play on (it is not shown itself).
pub fn cache_scene(
    body: &Body,
    garment: &TriMesh,
    clip: &str,
    fps: f32,
    poses: &[Vec<JointTransform>],
) -> Vec<u8> {
    let anim = SkelAnimation::from_poses(clip, fps, poses);
    let garment = exporters::asset::Mesh {
        name: "garment".into(),
        points: garment.positions.clone(),
        triangles: garment.triangles.clone(),
        source_vertex: (0..garment.vertex_count() as u32).collect(),
        ..Default::default()
    };
    let asset = exporters::BakedAsset {
        skeleton: skeleton_asset(&body.skeleton),
        meshes: vec![
            garment,
            skinned_mesh_asset(
                "body",
                body.mesh(),
                Some(&body.normals),
                &body.skin,
                BODY_COLOR,
            ),
        ],
        animations: vec![animation_asset(&anim)],
        provenance: Vec::new(),
    };
    exporters::gltf::to_glb(&asset)
}

/// A cache of the garment shown by `cache_page`: its name and frames.
pub type Cache<'a> = (&'a str, &'a [Vec<[f32; 3]>]);

/// `--view PAGE.html` of eval and rollout: the body over the clip and the written cache on the
/// garment; with a reference (rollout --reference: the simulation), the reference beside it and
/// error colours against it. With `vat` (the command wrote vertex animation textures, see
/// [`staged_vat`]) the page plays the VAT's own mesh and textures instead of the cache. Returns
/// the size of the page.
pub fn cache_page(
    out: &Path,
    (body, garment): (&Body, &TriMesh),
    (clip, fps, poses): (&str, f32, &[Vec<JointTransform>]),
    cache: Cache,
    reference: Option<Cache>,
    vat: Option<&Played>,
) -> Result<u64> {
    let glb = cache_scene(body, garment, clip, fps, poses);
    let track = |(name, frames): Cache| Track {
        name: name.to_string(),
        point_count: garment.vertex_count(),
        points: frames.iter().flatten().copied().collect(),
    };
    let page = Page {
        title: format!("{clip} ({})", file_name(out)),
        glb: &glb,
        garment: Some("garment".into()),
        garment_is_bake: false,
        vertex_map: None,
        fps: Some(fps),
        tracks: std::iter::once(cache)
            .filter(|_| vat.is_none())
            .chain(reference)
            .map(track)
            .collect(),
        reference: reference.map(track),
        error_scale_mm: 50.0,
        vat,
    };
    write_page(out, &page)
}
