//! Undirected edge keys, shared by the mesh operations and the topology (neither imports the other).

/// An undirected edge key.
#[inline]
pub fn sorted_pair(a: u32, b: u32) -> [u32; 2] {
    if a < b {
        [a, b]
    } else {
        [b, a]
    }
}

/// Unique undirected edges (sorted pairs, sorted) of any triangle list, e.g. UV triangles.
pub fn unique_edges(triangles: &[[u32; 3]]) -> Vec<[u32; 2]> {
    let mut edges: Vec<[u32; 2]> = triangles
        .iter()
        .flat_map(|&[a, b, c]| [sorted_pair(a, b), sorted_pair(b, c), sorted_pair(c, a)])
        .collect();
    edges.sort_unstable();
    edges.dedup();
    edges
}
