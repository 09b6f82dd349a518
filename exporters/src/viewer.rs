//! One self-contained HTML page that plays a baked glTF (and point caches on its garment) in the
//! browser: `garmentbake view`. The page code is `exporters/viewer/` (a template and one ES
//! module); three.js is the pinned npm package embedded at build time (see `build.rs`). Everything
//! is inlined (base64), so the page opens offline from disk and can be attached to a ticket.

use crate::atomic::write_atomic;
use serde::Serialize;
use std::path::Path;

const TEMPLATE: &str = include_str!("../viewer/page.html");
const VIEWER_JS: &str = include_str!("../viewer/viewer.js");
const THREE_PACKAGE: &str = include_str!(concat!(env!("OUT_DIR"), "/three/package.json"));
const THREE_LICENSE: &str = include_str!(concat!(env!("OUT_DIR"), "/three/LICENSE"));

/// The three.js modules inlined, by the specifier the page imports them with.
const MODULES: [(&str, &str); 3] = [
    (
        "three",
        include_str!(concat!(env!("OUT_DIR"), "/three/three.module.min.js")),
    ),
    (
        "three/examples/jsm/loaders/GLTFLoader.js",
        include_str!(concat!(env!("OUT_DIR"), "/three/GLTFLoader.js")),
    ),
    (
        "three/examples/jsm/utils/BufferGeometryUtils.js",
        include_str!(concat!(env!("OUT_DIR"), "/three/BufferGeometryUtils.js")),
    ),
];

#[derive(Debug, thiserror::Error)]
pub enum ViewerError {
    #[error("this garmentbake was built without three.js (tools/node/node_modules/three): run scripts/setup.sh, then rebuild")]
    NoThree,
    #[error("{0}")]
    Io(#[from] std::io::Error),
}

/// A per-frame point cache played on the glTF's garment mesh.
#[derive(Clone, Debug)]
pub struct Track {
    pub name: String,
    pub point_count: usize,
    /// `[frame * point_count + point]`, metres, Y-up.
    pub points: Vec<[f32; 3]>,
}

/// What one page shows.
#[derive(Clone, Debug)]
pub struct Page<'a> {
    pub title: String,
    /// The `.glb` bytes.
    pub glb: &'a [u8],
    /// Node name of the garment mesh the caches play on (the first mesh when `None`).
    pub garment: Option<String>,
    /// False when the glTF's garment is only the caches' mesh (its rest pose is not a bake).
    pub garment_is_bake: bool,
    /// For each garment vertex of the glTF, the cache point it shows (the bake splits vertices at
    /// UV seams); `None` when the counts are equal.
    pub vertex_map: Option<Vec<u32>>,
    /// Rate the caches play at; `None`: the selected clip's.
    pub fps: Option<f32>,
    pub tracks: Vec<Track>,
    /// Per-vertex error colours: distance to this cache, in mm.
    pub reference: Option<Track>,
    /// Distance at the top of the colour scale.
    pub error_scale_mm: f32,
    /// Vertex animation textures played on their own mesh in a vertex shader: the garment,
    /// replacing the glTF's (`glb` may then be empty: the VAT alone).
    pub vat: Option<&'a crate::vat::Played>,
}

/// The page's data block, read by viewer.js.
#[derive(Serialize)]
#[serde(rename_all = "camelCase")]
struct Data<'a> {
    title: &'a str,
    glb: Option<String>,
    garment: Option<&'a str>,
    garment_is_bake: bool,
    vertex_map: Option<&'a [u32]>,
    fps: Option<f32>,
    tracks: Vec<TrackData<'a>>,
    reference: Option<TrackData<'a>>,
    /// The reference is this track (inlined once).
    reference_track: Option<usize>,
    error_scale_mm: f32,
    vat: Option<VatData<'a>>,
}

/// A VAT as the page gets it: its glb, the sidecar's figures and both textures' texels.
#[derive(Serialize)]
#[serde(rename_all = "camelCase")]
struct VatData<'a> {
    glb: String,
    width: usize,
    height: usize,
    fps: f32,
    bounds_min: [f32; 3],
    bounds_max: [f32; 3],
    /// Little-endian float32 RGB texels, row-major from the top row (row = frame), base64.
    positions: String,
    normals: String,
    name: &'a str,
}

impl<'a> From<&'a crate::vat::Played> for VatData<'a> {
    fn from(v: &'a crate::vat::Played) -> Self {
        let floats =
            |t: &[f32]| base64::encode(t.iter().flat_map(|c| c.to_le_bytes()).collect::<Vec<u8>>());
        VatData {
            glb: base64::encode(&v.glb),
            width: v.sidecar.width,
            height: v.sidecar.height,
            fps: v.sidecar.fps,
            bounds_min: v.sidecar.bounds_min,
            bounds_max: v.sidecar.bounds_max,
            positions: floats(&v.positions),
            normals: floats(&v.normals),
            name: &v.sidecar.positions,
        }
    }
}

#[derive(Serialize)]
#[serde(rename_all = "camelCase")]
struct TrackData<'a> {
    name: &'a str,
    points: usize,
    frames: usize,
    /// Little-endian float32 xyz, base64.
    data: String,
}

impl<'a> From<&'a Track> for TrackData<'a> {
    fn from(t: &'a Track) -> Self {
        let bytes: Vec<u8> = t
            .points
            .iter()
            .flatten()
            .flat_map(|c| c.to_le_bytes())
            .collect();
        TrackData {
            name: &t.name,
            points: t.point_count,
            frames: t.points.len() / t.point_count.max(1),
            data: base64::encode(bytes),
        }
    }
}

/// The three.js version embedded (from its package.json), e.g. `0.170.0`.
pub fn three_version() -> Option<String> {
    let v: serde_json::Value = serde_json::from_str(THREE_PACKAGE).ok()?;
    v["version"].as_str().map(str::to_string)
}

/// The whole page as one HTML string.
pub fn html(page: &Page) -> Result<String, ViewerError> {
    let version = three_version().ok_or(ViewerError::NoThree)?;
    if MODULES.iter().any(|(_, src)| src.is_empty()) {
        return Err(ViewerError::NoThree);
    }
    // A reference that is also a track (e.g. bake vs the network's cache) is inlined once.
    let reference_track = page.reference.as_ref().and_then(|r| {
        page.tracks
            .iter()
            .position(|t| t.point_count == r.point_count && t.points == r.points)
    });
    let data = Data {
        title: &page.title,
        glb: (!page.glb.is_empty()).then(|| base64::encode(page.glb)),
        garment: page.garment.as_deref(),
        garment_is_bake: page.garment_is_bake,
        vertex_map: page.vertex_map.as_deref(),
        fps: page.fps,
        tracks: page.tracks.iter().map(TrackData::from).collect(),
        reference: page
            .reference
            .as_ref()
            .filter(|_| reference_track.is_none())
            .map(TrackData::from),
        reference_track,
        error_scale_mm: page.error_scale_mm,
        vat: page.vat.map(VatData::from),
    };
    let modules: Vec<(&str, String)> = MODULES
        .iter()
        .map(|(name, src)| (*name, base64::encode(bare_imports(src, name))))
        .collect();
    let modules = serde_json::to_string(&modules).expect("strings serialise");
    let data = serde_json::to_string(&data).expect("page data serialises");
    Ok(TEMPLATE
        .replace("{{TITLE}}", &escape_html(&page.title))
        .replace("{{THREE_VERSION}}", &escape_html(&version))
        .replace("{{THREE_LICENSE}}", &escape_html(THREE_LICENSE))
        .replace("{{MODULES}}", &script_safe(&modules))
        .replace("{{VIEWER}}", &base64::encode(VIEWER_JS))
        .replace("{{DATA}}", &script_safe(&data)))
}

/// Writes the page atomically; returns its size in bytes.
pub fn write(path: &Path, page: &Page) -> Result<u64, ViewerError> {
    let text = html(page)?;
    write_atomic(path, text.as_bytes())?;
    Ok(text.len() as u64)
}

/// A module's relative imports (`from '../utils/X.js'`) as bare specifiers of the package
/// (`three/examples/jsm/utils/X.js`): the page loads modules from blob URLs, against which a
/// relative specifier cannot be resolved, while the import map resolves bare ones.
fn bare_imports(source: &str, name: &str) -> String {
    let dir: Vec<&str> = name.split('/').collect();
    let dir = &dir[..dir.len().saturating_sub(1)];
    let mut out = String::with_capacity(source.len());
    let mut rest = source;
    while let Some(i) = rest.find("from '.") {
        let (head, tail) = rest.split_at(i + "from '".len());
        out.push_str(head);
        let end = tail.find('\'').unwrap_or(tail.len());
        out.push_str(&resolve(dir, &tail[..end]));
        rest = &tail[end..];
    }
    out.push_str(rest);
    out
}

/// `relative` (`./a.js`, `../b/c.js`) resolved against the folder `dir` (path segments).
fn resolve(dir: &[&str], relative: &str) -> String {
    let mut parts: Vec<&str> = dir.to_vec();
    for seg in relative.split('/') {
        match seg {
            "." => {}
            ".." => {
                parts.pop();
            }
            s => parts.push(s),
        }
    }
    parts.join("/")
}

/// JSON placed inside a `<script>` element: `<` escaped so no string can close the element.
fn script_safe(json: &str) -> String {
    json.replace('<', "\\u003c")
}

fn escape_html(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_imports_become_package_specifiers() {
        let src = "import { a } from 'three';\nimport { t } from '../utils/BufferGeometryUtils.js';\nx('./y');";
        let out = bare_imports(src, "three/examples/jsm/loaders/GLTFLoader.js");
        assert_eq!(
            out,
            "import { a } from 'three';\nimport { t } from 'three/examples/jsm/utils/BufferGeometryUtils.js';\nx('./y');"
        );
    }

    #[test]
    fn the_embedded_loader_imports_only_modules_the_page_carries() {
        let names: Vec<&str> = MODULES.iter().map(|m| m.0).collect();
        for (name, src) in MODULES {
            let src = bare_imports(src, name);
            // Import statements only (comments quote URLs after "from" too).
            let imports = src
                .lines()
                .filter(|l| l.starts_with("import ") || l.starts_with("} from '"))
                .filter_map(|l| l.split("from '").nth(1));
            for spec in imports {
                let spec = &spec[..spec.find('\'').unwrap()];
                assert!(names.contains(&spec), "{name} imports {spec}");
            }
        }
    }

    #[test]
    fn data_cannot_close_its_script_element() {
        assert_eq!(
            script_safe(r#"{"a":"</script>"}"#),
            r#"{"a":"\u003c/script>"}"#
        );
    }
}
