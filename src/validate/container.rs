//! The glTF container: a `.glb` (12-byte header, a JSON chunk, an optional BIN chunk) or a
//! `.gltf` (JSON text with buffers beside it or in data URIs), parsed into the typed document
//! and the bytes of every buffer. Anything wrong is a [`Problems`] entry, never a panic.

use super::Problems;
use gltf::json;
use std::path::Path;

const JSON_CHUNK: u32 = 0x4E4F_534A;
const BIN_CHUNK: u32 = 0x004E_4942;

/// A parsed glTF: the document and each buffer's bytes (`None` where they could not be found).
pub struct Document {
    pub root: json::Root,
    pub buffers: Vec<Option<Vec<u8>>>,
}

fn u32_at(bytes: &[u8], o: usize) -> Option<u32> {
    bytes
        .get(o..o.checked_add(4)?)
        .map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")))
}

/// The JSON and BIN chunks of a GLB, with every layout rule checked.
fn split_glb(bytes: &[u8], problems: &mut Problems) -> Option<(Vec<u8>, Option<Vec<u8>>)> {
    let (Some(version), Some(length)) = (u32_at(bytes, 4), u32_at(bytes, 8)) else {
        problems.error("/", "GLB: the 12-byte header is cut short");
        return None;
    };
    if version != 2 {
        problems.error("/", format!("GLB: version {version}, expected 2"));
        return None;
    }
    if length < 12 || (length as usize) > bytes.len() {
        problems.error(
            "/",
            format!(
                "GLB: the header declares {length} bytes, the file has only {}",
                bytes.len()
            ),
        );
        return None;
    }
    if (length as usize) < bytes.len() {
        // Readers stop at the declared length; what follows is ignored (a warning, as Khronos).
        problems.warning(
            "/",
            format!(
                "GLB: {} bytes after the declared end ({length} bytes) are ignored",
                bytes.len() - length as usize
            ),
        );
    }
    let bytes = &bytes[..length as usize];
    let mut chunks: Vec<(u32, &[u8])> = Vec::new();
    let mut at = 12;
    while at < bytes.len() {
        let (Some(len), Some(kind)) = (u32_at(bytes, at), u32_at(bytes, at + 4)) else {
            problems.error("/", format!("GLB: chunk header at byte {at} is cut short"));
            return None;
        };
        let start = at + 8;
        let Some(data) = bytes.get(start..start.saturating_add(len as usize)) else {
            problems.error(
                "/",
                format!("GLB: chunk at byte {at} declares {len} bytes, past the end of the file"),
            );
            return None;
        };
        if len % 4 != 0 {
            problems.error(
                "/",
                format!("GLB: chunk length {len} at byte {at} is not a multiple of 4"),
            );
        }
        chunks.push((kind, data));
        at = start + len as usize;
    }
    let Some(&(JSON_CHUNK, json)) = chunks.first() else {
        problems.error("/", "GLB: the first chunk is not JSON");
        return None;
    };
    if json.is_empty() {
        problems.error("/", "GLB: the JSON chunk is empty");
    }
    let bin_chunks: Vec<usize> = (0..chunks.len())
        .filter(|&i| chunks[i].0 == BIN_CHUNK)
        .collect();
    match bin_chunks.as_slice() {
        [] | [1] => {}
        [_] => problems.error("/", "GLB: the BIN chunk must be the second chunk"),
        _ => problems.error("/", "GLB: more than one BIN chunk"),
    }
    if chunks.iter().skip(1).any(|c| c.0 == JSON_CHUNK) {
        problems.error("/", "GLB: more than one JSON chunk");
    }
    let bin = chunks
        .get(1)
        .filter(|c| c.0 == BIN_CHUNK)
        .map(|c| c.1.to_vec());
    Some((json.to_vec(), bin))
}

/// Reads `path` (already in memory as `bytes`) into a document; `None` when it is not glTF at
/// all (the reason is in `problems`).
pub fn parse(path: &Path, bytes: &[u8], problems: &mut Problems) -> Option<Document> {
    let glb = bytes.starts_with(b"glTF");
    let (json_bytes, bin) = if glb {
        split_glb(bytes, problems)?
    } else {
        (bytes.to_vec(), None)
    };
    let root: json::Root = match serde_json::from_slice(&json_bytes) {
        Ok(root) => root,
        Err(e) => {
            let what = if serde_json::from_slice::<serde_json::Value>(&json_bytes).is_ok() {
                "the JSON does not follow the glTF schema"
            } else {
                "invalid JSON"
            };
            problems.error("/", format!("{what}: {e}"));
            return None;
        }
    };
    let mut bin = bin;
    let buffers = root
        .buffers
        .iter()
        .enumerate()
        .map(|(i, b)| {
            let at = format!("/buffers/{i}");
            let data = match &b.uri {
                None if glb && i == 0 => {
                    let data = bin.take();
                    if data.is_none() {
                        problems.error(&at, "refers to the GLB BIN chunk, which is missing");
                    }
                    data
                }
                None => {
                    problems.error(&at, "has no uri and is not the GLB BIN chunk");
                    None
                }
                Some(uri) => resolve_uri(path, uri, &at, problems),
            };
            let data = data?;
            let declared = b.byte_length.0;
            if (data.len() as u64) < declared {
                problems.error(
                    &at,
                    format!(
                        "byteLength {declared} but only {} bytes of data",
                        data.len()
                    ),
                );
            } else if glb && b.uri.is_none() && data.len() as u64 > declared + 3 {
                problems.warning(
                    &at,
                    format!(
                        "the BIN chunk has {} bytes beyond byteLength {declared}",
                        data.len() as u64 - declared
                    ),
                );
            }
            Some(data)
        })
        .collect();
    Some(Document { root, buffers })
}

/// A buffer's bytes from a data URI (base64) or a file relative to the glTF.
fn resolve_uri(gltf: &Path, uri: &str, at: &str, problems: &mut Problems) -> Option<Vec<u8>> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let Some((_, payload)) = rest.split_once(";base64,") else {
            problems.error(at, "data URI is not base64");
            return None;
        };
        let decoded = base64(payload);
        if decoded.is_none() {
            problems.error(at, "data URI holds invalid base64");
        }
        return decoded;
    }
    if uri.contains("://") {
        problems.error(at, format!("uri '{uri}' is not a relative file path"));
        return None;
    }
    let file = gltf
        .parent()
        .unwrap_or(Path::new("."))
        .join(percent_decode(uri));
    // A device or a pipe (`../../dev/zero`) would never end: only plain files hold buffers.
    if file.metadata().is_ok_and(|m| !m.is_file()) {
        problems.error(at, format!("{} is not a plain file", file.display()));
        return None;
    }
    match std::fs::read(&file) {
        Ok(data) => Some(data),
        Err(e) => {
            problems.error(at, format!("cannot read {}: {e}", file.display()));
            None
        }
    }
}

fn percent_decode(s: &str) -> String {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex = bytes
            .get(i + 1..i + 3)
            .and_then(|h| std::str::from_utf8(h).ok())
            .and_then(|h| u8::from_str_radix(h, 16).ok());
        match (bytes[i], hex) {
            (b'%', Some(b)) => {
                out.push(b);
                i += 3;
            }
            (b, _) => {
                out.push(b);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// Standard base64 (RFC 4648, with or without padding); `None` on a foreign character.
fn base64(text: &str) -> Option<Vec<u8>> {
    let value = |c: u8| -> Option<u32> {
        Some(match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => return None,
        } as u32)
    };
    let digits: Vec<u8> = text.bytes().filter(|&c| c != b'=').collect();
    let mut out = Vec::with_capacity(digits.len() * 3 / 4);
    for group in digits.chunks(4) {
        let mut acc = 0u32;
        for &c in group {
            acc = (acc << 6) | value(c)?;
        }
        let bits = 6 * group.len();
        acc <<= 24 - bits;
        let bytes = acc.to_be_bytes();
        out.extend_from_slice(&bytes[1..1 + bits / 8]);
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    #[test]
    fn base64_decodes_padded_and_unpadded() {
        assert_eq!(super::base64("aGVsbG8=").unwrap(), b"hello");
        assert_eq!(super::base64("aGVsbG8").unwrap(), b"hello");
        assert_eq!(super::base64("AAEC").unwrap(), [0, 1, 2]);
        assert!(super::base64("a*b=").is_none());
    }
}
