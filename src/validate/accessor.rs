//! Reading glTF accessors by the spec's layout rules (offsets, strides, matrix column padding,
//! sparse substitution), refusing anything that reaches outside its buffer view or buffer.
//! Every value comes back as f64 in the component's own units (integers exact, not normalised),
//! so both the structural rules and the replay read the same numbers.

use gltf::json;
use json::accessor::{ComponentType, Type};
use json::validation::Checked::Valid;

/// One accessor's elements, element-major: `data[element * comps + component]`.
#[derive(Clone, Debug)]
pub struct Values {
    pub comps: usize,
    pub component: ComponentType,
    pub type_: Type,
    pub normalized: bool,
    pub data: Vec<f64>,
}

impl Values {
    pub fn count(&self) -> usize {
        self.data.len().checked_div(self.comps).unwrap_or(0)
    }

    pub fn element(&self, i: usize) -> &[f64] {
        &self.data[i * self.comps..(i + 1) * self.comps]
    }

    /// The value a client uses: normalised integers mapped to [0, 1] or [-1, 1] (glTF 2.0 §3.11).
    pub fn real(&self, v: f64) -> f64 {
        if !self.normalized {
            return v;
        }
        match self.component {
            ComponentType::U8 => v / 255.0,
            ComponentType::U16 => v / 65535.0,
            ComponentType::I8 => (v / 127.0).max(-1.0),
            ComponentType::I16 => (v / 32767.0).max(-1.0),
            _ => v,
        }
    }

    /// `(component type, type)` as the spec names them, e.g. `FLOAT VEC3`.
    pub fn format(&self) -> String {
        format_name(self.component, self.type_, self.normalized)
    }
}

/// `FLOAT VEC3`, `UNSIGNED_SHORT normalized VEC4`, ... for messages.
pub fn format_name(component: ComponentType, type_: Type, normalized: bool) -> String {
    let c = match component {
        ComponentType::I8 => "BYTE",
        ComponentType::U8 => "UNSIGNED_BYTE",
        ComponentType::I16 => "SHORT",
        ComponentType::U16 => "UNSIGNED_SHORT",
        ComponentType::U32 => "UNSIGNED_INT",
        ComponentType::F32 => "FLOAT",
    };
    let n = if normalized { " normalized" } else { "" };
    format!("{c}{n} {type_:?}").to_uppercase()
}

pub fn component_size(c: ComponentType) -> usize {
    match c {
        ComponentType::I8 | ComponentType::U8 => 1,
        ComponentType::I16 | ComponentType::U16 => 2,
        ComponentType::U32 | ComponentType::F32 => 4,
    }
}

/// Bytes of one element: matrix columns of 1- and 2-byte components start on 4-byte boundaries.
fn element_size(c: ComponentType, t: Type) -> (usize, usize, usize) {
    let size = component_size(c);
    let (columns, rows) = match t {
        Type::Mat2 => (2, 2),
        Type::Mat3 => (3, 3),
        Type::Mat4 => (4, 4),
        other => (1, other.multiplicity()),
    };
    let column = if columns > 1 {
        (rows * size).next_multiple_of(4)
    } else {
        rows * size
    };
    (columns * column, column, rows)
}

fn decode(bytes: &[u8], c: ComponentType) -> f64 {
    match c {
        ComponentType::I8 => bytes[0] as i8 as f64,
        ComponentType::U8 => bytes[0] as f64,
        ComponentType::I16 => i16::from_le_bytes([bytes[0], bytes[1]]) as f64,
        ComponentType::U16 => u16::from_le_bytes([bytes[0], bytes[1]]) as f64,
        ComponentType::U32 => u32::from_le_bytes(bytes[..4].try_into().expect("4 bytes")) as f64,
        ComponentType::F32 => f32::from_le_bytes(bytes[..4].try_into().expect("4 bytes")) as f64,
    }
}

/// The bytes of a buffer view, checked against its buffer.
pub fn view_bytes<'a>(
    root: &json::Root,
    buffers: &'a [Option<Vec<u8>>],
    index: json::Index<json::buffer::View>,
) -> Result<(&'a [u8], Option<usize>), String> {
    let view = root
        .get(index)
        .ok_or_else(|| format!("bufferView {} does not exist", index.value()))?;
    let buffer = root
        .get(view.buffer)
        .ok_or_else(|| format!("buffer {} does not exist", view.buffer.value()))?;
    let data = buffers
        .get(view.buffer.value())
        .and_then(Option::as_deref)
        .ok_or_else(|| format!("the data of buffer {} is missing", view.buffer.value()))?;
    let offset = view.byte_offset.map_or(0, |o| o.0);
    let end = offset.checked_add(view.byte_length.0);
    let limit = buffer.byte_length.0.min(data.len() as u64);
    match end {
        Some(end) if end <= limit => Ok((
            &data[offset as usize..end as usize],
            view.byte_stride.map(|s| s.0),
        )),
        _ => Err(format!(
            "bufferView {} (offset {offset}, length {}) does not fit buffer {} ({} bytes)",
            index.value(),
            view.byte_length.0,
            view.buffer.value(),
            limit
        )),
    }
}

/// Reads every element of accessor `index`, applying sparse substitution; errors name the rule.
pub fn read(
    root: &json::Root,
    buffers: &[Option<Vec<u8>>],
    index: json::Index<json::Accessor>,
) -> Result<Values, String> {
    let acc = root
        .get(index)
        .ok_or_else(|| format!("accessor {} does not exist", index.value()))?;
    let (Valid(component), Valid(type_)) = (&acc.component_type, &acc.type_) else {
        return Err("invalid componentType or type".into());
    };
    let (component, type_) = (component.0, *type_);
    if acc.normalized && matches!(component, ComponentType::U32 | ComponentType::F32) {
        return Err("only (unsigned) byte and short accessors can be normalized".into());
    }
    let count = usize::try_from(acc.count.0).map_err(|_| "count too large".to_string())?;
    if count == 0 {
        return Err("count must be at least 1".into());
    }
    let (elem, column, rows) = element_size(component, type_);
    let comps = type_.multiplicity();
    let size = component_size(component);
    // 4 GiB of elements is beyond any file we read; refusing early keeps memory bounded.
    let total = count
        .checked_mul(comps)
        .filter(|&n| n <= 1 << 30)
        .ok_or_else(|| format!("count {count} is too large"))?;
    let mut data = vec![0.0; total];
    if let Some(view_index) = acc.buffer_view {
        let (bytes, stride) = view_bytes(root, buffers, view_index)?;
        let offset = acc.byte_offset.map_or(0, |o| o.0 as usize);
        let view_offset = root
            .get(view_index)
            .and_then(|v| v.byte_offset)
            .map_or(0, |o| o.0 as usize);
        if !offset.is_multiple_of(size) {
            return Err(format!(
                "byteOffset {offset} is not a multiple of the component size {size}"
            ));
        }
        if !(offset + view_offset).is_multiple_of(size) {
            return Err(format!(
                "total byteOffset {} is not a multiple of the component size {size}",
                offset + view_offset
            ));
        }
        let stride = stride.unwrap_or(elem);
        if stride < elem {
            return Err(format!(
                "byteStride {stride} is less than the element size {elem}"
            ));
        }
        let needed = (count - 1)
            .checked_mul(stride)
            .and_then(|n| n.checked_add(offset + elem));
        if needed.is_none_or(|n| n > bytes.len()) {
            return Err(format!(
                "{count} elements from offset {offset} (stride {stride}) do not fit bufferView {} ({} bytes)",
                view_index.value(),
                bytes.len()
            ));
        }
        for e in 0..count {
            let start = offset + e * stride;
            for k in 0..comps {
                let (col, row) = (k / rows, k % rows);
                let at = start + col * column + row * size;
                data[e * comps + k] = decode(&bytes[at..at + size], component);
            }
        }
    }
    if let Some(sparse) = &acc.sparse {
        apply_sparse(root, buffers, sparse, count, comps, component, &mut data)?;
    }
    Ok(Values {
        comps,
        component,
        type_,
        normalized: acc.normalized,
        data,
    })
}

fn apply_sparse(
    root: &json::Root,
    buffers: &[Option<Vec<u8>>],
    sparse: &json::accessor::sparse::Sparse,
    count: usize,
    comps: usize,
    component: ComponentType,
    data: &mut [f64],
) -> Result<(), String> {
    let n = sparse.count.0 as usize;
    if n == 0 || n > count {
        return Err(format!(
            "sparse count {n} must be between 1 and the accessor's count {count}"
        ));
    }
    let Valid(index_type) = &sparse.indices.component_type else {
        return Err("invalid sparse indices componentType".into());
    };
    let index_type = index_type.0;
    let (ibytes, _) = view_bytes(root, buffers, sparse.indices.buffer_view)?;
    let isize = component_size(index_type);
    let ioff = sparse.indices.byte_offset.0 as usize;
    if ioff.checked_add(n * isize).is_none_or(|e| e > ibytes.len()) {
        return Err("sparse indices do not fit their bufferView".into());
    }
    let (vbytes, _) = view_bytes(root, buffers, sparse.values.buffer_view)?;
    let size = component_size(component);
    let voff = sparse.values.byte_offset.0 as usize;
    if voff
        .checked_add(n * comps * size)
        .is_none_or(|e| e > vbytes.len())
    {
        return Err("sparse values do not fit their bufferView".into());
    }
    let mut previous: Option<usize> = None;
    for s in 0..n {
        let at = ioff + s * isize;
        let target = decode(&ibytes[at..at + isize], index_type) as usize;
        if target >= count {
            return Err(format!(
                "sparse index {target} at {s} is not below the accessor's count {count}"
            ));
        }
        if previous.is_some_and(|p| target <= p) {
            return Err(format!("sparse indices are not strictly increasing at {s}"));
        }
        previous = Some(target);
        for k in 0..comps {
            let at = voff + (s * comps + k) * size;
            data[target * comps + k] = decode(&vbytes[at..at + size], component);
        }
    }
    Ok(())
}
