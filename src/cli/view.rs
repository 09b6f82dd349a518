//! `garmentbake view`: a baked glTF (and point caches on its garment) in one self-contained HTML
//! page, written to disk or served on 127.0.0.1. Also the `--view PAGE.html` of bake, eval and
//! rollout.

use super::args::{output_set, OutputArgs, Writes};
use super::Execute;
use crate::bake::{animation_asset, skeleton_asset, skinned_mesh_asset, BODY_COLOR};
use crate::body::Body;
use crate::geometry::TriMesh;
use crate::io::point_cache::read_pc2;
use crate::rig::{JointTransform, SkelAnimation};
use anyhow::{bail, Context, Result};
use exporters::viewer::{Page, Track};
use serde::Serialize;
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};

/// Look at a bake in the browser: clips, frames, body, point caches, error colours.
///
/// Writes ONE self-contained HTML page (three.js, the glb and the caches inlined: it opens
/// offline by double-click and can be attached to a review ticket), or serves it on 127.0.0.1.
/// The page has a clip selector (one entry per glTF animation), play / pause / scrub with the
/// frame number and time, body on/off, a turntable and the fixed views of `garmentbake preview`,
/// wireframe, and with --error-vs per-vertex colours (distance in mm) with a legend.
///
/// --with caches (e.g. from `eval`, `rollout`, `simulate`) play on the garment mesh beside or
/// over the bake, at the selected clip's frame rate (or --fps): give caches of that clip.
/// A link can open one frame: PAGE.html#clip=131_02&frame=40&view=front (see docs/view.md).
#[derive(clap::Args)]
#[command(group(clap::ArgGroup::new("target").required(true).args(["out", "serve"])))]
pub struct Args {
    /// Binary glTF (.glb), e.g. from `garmentbake bake`; its mesh named `garment` (else the first)
    /// is the one caches play on.
    pub file: PathBuf,
    /// Point cache(s) (.pc2) of the garment to play beside or instead of the bake; repeat.
    #[arg(long = "with")]
    pub with: Vec<PathBuf>,
    /// Colour every shown garment by its distance (mm) to this cache (.pc2), frame by frame:
    /// e.g. the network's `eval` output against a bake, a simulation against a roll-out.
    #[arg(long)]
    pub error_vs: Option<PathBuf>,
    /// Distance at the red end of the error colours (mm).
    #[arg(long, default_value_t = 10.0, value_parser = super::args::positive::<f32>())]
    pub error_scale_mm: f32,
    /// Rate the caches play at (default: the selected clip's, or 30 without animations).
    #[arg(long, value_parser = super::args::positive::<f32>())]
    pub fps: Option<f32>,
    /// Write the page here (.html).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Serve the page on http://127.0.0.1:PORT/ until interrupted (Ctrl-C).
    #[arg(long)]
    pub serve: bool,
    /// Port for --serve (0: any free port; the URL is printed).
    #[arg(long, default_value_t = 8017, requires = "serve")]
    pub port: u16,
    #[command(flatten)]
    pub output: OutputArgs,
}

/// The page written.
#[derive(Serialize)]
pub struct Report {
    pub out: Option<PathBuf>,
    /// Size of the page in bytes (everything inlined).
    pub bytes: u64,
    /// The glTF's animations, in the order of the page's clip selector.
    pub clips: Vec<String>,
    pub garment: String,
    pub garment_vertices: usize,
    pub caches: Vec<CacheReport>,
    pub error_vs: Option<CacheReport>,
    pub three_version: String,
}

#[derive(Clone, Serialize)]
pub struct CacheReport {
    pub path: PathBuf,
    pub frames: usize,
    pub points: usize,
}

impl Execute for Args {
    type Report = Report;

    fn execute(&self, say: &dyn Fn(&str)) -> Result<Report> {
        if self.error_scale_mm.is_nan() || self.error_scale_mm <= 0.0 {
            bail!(
                "--error-scale-mm must be positive, got {}",
                self.error_scale_mm
            );
        }
        if self.fps.is_some_and(|f| f.is_nan() || f <= 0.0) {
            bail!("--fps must be positive");
        }
        let outputs = output_set(&[("--out", self.out.as_deref(), Writes::Page)])?;
        let glb = read_glb(&self.file)?;
        let scene = Scene::of(&glb, &self.file)?;
        let caches = self
            .with
            .iter()
            .map(|p| scene.cache(p))
            .collect::<Result<Vec<_>>>()?;
        let reference = self
            .error_vs
            .as_deref()
            .map(|p| scene.cache(p))
            .transpose()?;
        let page = Page {
            title: file_name(&self.file),
            glb: &glb,
            garment: Some(scene.garment.clone()),
            garment_is_bake: true,
            vertex_map: scene.vertex_map.clone(),
            fps: self.fps,
            tracks: caches.iter().map(|c| c.1.clone()).collect(),
            reference: reference.as_ref().map(|c| c.1.clone()),
            error_scale_mm: self.error_scale_mm,
        };
        let report = |out: Option<PathBuf>, bytes: u64| Report {
            out,
            bytes,
            clips: scene.clips.clone(),
            garment: scene.garment.clone(),
            garment_vertices: scene.vertices,
            caches: caches.iter().map(|c| c.0.clone()).collect(),
            error_vs: reference.as_ref().map(|c| c.0.clone()),
            three_version: exporters::viewer::three_version().unwrap_or_default(),
        };
        match &self.out {
            Some(out) => {
                let bytes = outputs.write(out, |p| write_page(p, &page))?;
                outputs.commit()?;
                Ok(report(Some(out.clone()), bytes))
            }
            None => {
                let html = exporters::viewer::html(&page)?;
                serve(&html, self.port, say)?;
                Ok(report(None, html.len() as u64))
            }
        }
    }

    fn print(r: &Report) {
        if let Some(out) = &r.out {
            println!(
                "wrote {} ({:.2} MB, three.js {} inlined)",
                out.display(),
                r.bytes as f64 / 1e6,
                r.three_version
            );
        }
        match r.clips.len() {
            0 => println!("no animations: the page shows the rest pose"),
            _ => println!("clips: {}", r.clips.join(", ")),
        }
        println!("garment: '{}', {} vertices", r.garment, r.garment_vertices);
        for c in &r.caches {
            println!(
                "with {}: {} frames of {} points",
                c.path.display(),
                c.frames,
                c.points
            );
        }
        if let Some(c) = &r.error_vs {
            println!(
                "error colours against {} ({} frames)",
                c.path.display(),
                c.frames
            );
        }
    }
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

fn file_name(path: &Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into(),
    )
}

fn read_glb(path: &Path) -> Result<Vec<u8>> {
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
struct Scene {
    clips: Vec<String>,
    /// Node name of the mesh caches play on.
    garment: String,
    vertices: usize,
    /// `sourceVertex` of the garment mesh (the bake splits vertices at UV seams).
    vertex_map: Option<Vec<u32>>,
    file: PathBuf,
}

impl Scene {
    fn of(glb: &[u8], path: &Path) -> Result<Scene> {
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
    fn cache(&self, path: &Path) -> Result<(CacheReport, Track)> {
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
        let frames = read_pc2(path, points)?;
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
                points: frames.into_iter().flatten().collect(),
            },
        ))
    }
}

/// Serves `html` at every path of http://127.0.0.1:PORT/ until the process is interrupted.
fn serve(html: &str, port: u16, say: &dyn Fn(&str)) -> Result<()> {
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
                &body.mesh,
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
/// error colours against it. Returns the size of the page.
pub fn cache_page(
    out: &Path,
    (body, garment): (&Body, &TriMesh),
    (clip, fps, poses): (&str, f32, &[Vec<JointTransform>]),
    cache: Cache,
    reference: Option<Cache>,
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
        tracks: std::iter::once(cache).chain(reference).map(track).collect(),
        reference: reference.map(track),
        error_scale_mm: 50.0,
    };
    write_page(out, &page)
}
