//! The triangle mesh with optional face-varying UVs, and the operations that produce new meshes.

use std::collections::HashMap;

use thiserror::Error;

use crate::geometry::edges::{sorted_pair, unique_edges};
use crate::geometry::{arr3, v3};

/// Face-varying UVs (as in OBJ / USD faceVarying): one UV triangle per mesh triangle.
///
/// `triangles[t]` indexes `coords` for the three corners of mesh triangle `t`, so a vertex on a
/// UV seam has one position but several UVs.
#[derive(Clone, Debug, PartialEq)]
pub struct FaceVaryingUv {
    pub coords: Vec<[f32; 2]>,
    pub triangles: Vec<[u32; 3]>,
}

/// An indexed triangle mesh. Units and axes follow the project conventions (metres, Y-up) once
/// importers have converted their input.
#[derive(Clone, Debug, PartialEq)]
pub struct TriMesh {
    pub positions: Vec<[f32; 3]>,
    pub triangles: Vec<[u32; 3]>,
    pub uv: Option<FaceVaryingUv>,
}

/// Why a mesh is unusable. Each message is one line.
#[derive(Clone, Debug, PartialEq, Error)]
pub enum MeshError {
    #[error("triangle {triangle} uses vertex {index}, but the mesh has {vertex_count} vertices")]
    IndexOutOfRange {
        triangle: usize,
        index: u32,
        vertex_count: usize,
    },
    #[error("triangle {triangle} repeats vertex {index} (degenerate face)")]
    RepeatedIndex { triangle: usize, index: u32 },
    #[error("vertex {vertex} has a non-finite position {position:?}")]
    NonFinitePosition { vertex: usize, position: [f32; 3] },
    #[error("the mesh has {triangles} triangles but its UV set has {uv_triangles} UV triangles")]
    UvTriangleCountMismatch {
        triangles: usize,
        uv_triangles: usize,
    },
    #[error("UV triangle {triangle} uses UV {index}, but the UV set has {uv_count} coordinates")]
    UvIndexOutOfRange {
        triangle: usize,
        index: u32,
        uv_count: usize,
    },
    #[error("the mesh has {0} vertices; indices are 32-bit, so at most 4294967295 are allowed")]
    TooManyVertices(usize),
    #[error("face {face} has {corners} corners; a face needs at least 3")]
    TooFewCorners { face: usize, corners: u32 },
    #[error("the faces' corner counts add up to {expected} but there are {found} corner indices")]
    CornerCountMismatch { expected: usize, found: usize },
}

impl TriMesh {
    /// A mesh without UVs.
    pub fn new(positions: Vec<[f32; 3]>, triangles: Vec<[u32; 3]>) -> Self {
        TriMesh {
            positions,
            triangles,
            uv: None,
        }
    }

    /// A mesh from polygons given as corner counts and flat corner indices (USD's
    /// faceVertexCounts / faceVertexIndices), fan-triangulated from each face's first corner
    /// like OBJ faces; validated.
    pub fn from_polygons(
        positions: Vec<[f32; 3]>,
        counts: &[u32],
        indices: &[u32],
    ) -> Result<TriMesh, MeshError> {
        let expected = counts.iter().map(|&n| n as usize).sum();
        if expected != indices.len() {
            return Err(MeshError::CornerCountMismatch {
                expected,
                found: indices.len(),
            });
        }
        let mut triangles = Vec::with_capacity(expected.saturating_sub(2 * counts.len()));
        let mut start = 0;
        for (face, &corners) in counts.iter().enumerate() {
            if corners < 3 {
                return Err(MeshError::TooFewCorners { face, corners });
            }
            let f = &indices[start..start + corners as usize];
            triangles.extend((2..f.len()).map(|k| [f[0], f[k - 1], f[k]]));
            start += corners as usize;
        }
        let mesh = TriMesh::new(positions, triangles);
        mesh.validate()?;
        Ok(mesh)
    }

    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// Checks indices, finiteness and the UV set; the first problem found is returned.
    pub fn validate(&self) -> Result<(), MeshError> {
        let n = self.positions.len();
        if n > u32::MAX as usize {
            return Err(MeshError::TooManyVertices(n));
        }
        if let Some((vertex, &position)) = self
            .positions
            .iter()
            .enumerate()
            .find(|(_, p)| !p.iter().all(|c| c.is_finite()))
        {
            return Err(MeshError::NonFinitePosition { vertex, position });
        }
        if let Some((triangle, index)) = out_of_range(&self.triangles, n) {
            return Err(MeshError::IndexOutOfRange {
                triangle,
                index,
                vertex_count: n,
            });
        }
        for (t, tri) in self.triangles.iter().enumerate() {
            if let Some(index) = repeated_index(tri) {
                return Err(MeshError::RepeatedIndex { triangle: t, index });
            }
        }
        if let Some(uv) = &self.uv {
            uv.validate(self.triangles.len())?;
        }
        Ok(())
    }

    /// Axis-aligned bounds `(min, max)`. An empty mesh gives the inverted box `(+inf, -inf)`.
    pub fn bounds(&self) -> ([f32; 3], [f32; 3]) {
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in &self.positions {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        (lo, hi)
    }

    /// Area of each triangle.
    pub fn face_areas(&self) -> Vec<f32> {
        self.triangles
            .iter()
            .map(|t| triangle_area(&self.positions, t))
            .collect()
    }

    /// Barycentric vertex areas: each vertex gets a third of the area of every adjacent
    /// triangle. They sum to the surface area; used as lumped cloth mass (area × density).
    pub fn vertex_areas(&self) -> Vec<f32> {
        let mut areas = vec![0.0f32; self.positions.len()];
        for (tri, area) in self.triangles.iter().zip(self.face_areas()) {
            for &i in tri {
                areas[i as usize] += area / 3.0;
            }
        }
        areas
    }

    /// Indices of triangles whose area is at most `eps_area` (this includes triangles with
    /// repeated vertex indices, which have zero area).
    pub fn degenerate_faces(&self, eps_area: f32) -> Vec<usize> {
        self.face_areas()
            .iter()
            .enumerate()
            .filter(|(_, &a)| a <= eps_area)
            .map(|(t, _)| t)
            .collect()
    }

    /// The same mesh with every position mapped through `f` (unit or axis conversion, posing).
    pub fn transformed(&self, f: impl Fn([f32; 3]) -> [f32; 3]) -> TriMesh {
        TriMesh {
            positions: self.positions.iter().map(|&p| f(p)).collect(),
            triangles: self.triangles.clone(),
            uv: self.uv.clone(),
        }
    }

    /// One step of midpoint subdivision: every triangle becomes four.
    ///
    /// Vertex order: the original vertices keep their indices; vertex `n + i` is the midpoint of
    /// `Topology::new(self).edges[i]` (edges sorted), so per-vertex data such as skinning weights
    /// can be subdivided the same way. Triangle `t` becomes triangles `4t..4t+4`:
    /// `[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]` (winding preserved).
    /// UVs are subdivided on the UV triangles' own edges, so a seam stays a seam.
    pub fn subdivide_midpoint(&self) -> TriMesh {
        let (positions, triangles) = subdivide_indexed(&self.positions, &self.triangles, |a, b| {
            arr3((v3(a) + v3(b)) * 0.5)
        });
        let uv = self.uv.as_ref().map(|uv| {
            let (coords, triangles) = subdivide_indexed(&uv.coords, &uv.triangles, |a, b| {
                [(a[0] + b[0]) * 0.5, (a[1] + b[1]) * 0.5]
            });
            FaceVaryingUv { coords, triangles }
        });
        TriMesh {
            positions,
            triangles,
            uv,
        }
    }

    /// The part of the mesh on the vertices for which `keep` is true, and the new→old vertex map.
    ///
    /// Every kept vertex stays (even if isolated) and keeps its relative order, so the map is
    /// increasing; a triangle stays when its three vertices are kept. UV coordinates are
    /// compacted to those the kept triangles use, also in their original order.
    pub fn submesh(&self, keep: impl Fn(u32) -> bool) -> (TriMesh, Vec<u32>) {
        let n = self.positions.len() as u32;
        let new_to_old: Vec<u32> = (0..n).filter(|&v| keep(v)).collect();
        let old_to_new = inverse_map(&new_to_old, n as usize);
        let kept: Vec<usize> = (0..self.triangles.len())
            .filter(|&t| {
                self.triangles[t]
                    .iter()
                    .all(|&v| old_to_new[v as usize].is_some())
            })
            .collect();
        let positions = new_to_old
            .iter()
            .map(|&v| self.positions[v as usize])
            .collect();
        let triangles = kept
            .iter()
            .map(|&t| self.triangles[t].map(|v| old_to_new[v as usize].unwrap_or(0)))
            .collect();
        let uv = self.uv.as_ref().map(|uv| uv.subset(&kept));
        let mesh = TriMesh {
            positions,
            triangles,
            uv,
        };
        (mesh, new_to_old)
    }

    /// Splits vertices along UV seams, as glTF and other per-vertex-attribute formats need.
    ///
    /// A new vertex is a distinct (position index, UV index) pair; new vertices are numbered in
    /// order of first appearance walking the triangles corner by corner, and vertices no
    /// triangle uses are dropped. Returns the new→old vertex map, the UV of each new vertex and
    /// the triangles on new vertices. Without UVs nothing is split: the identity map over all
    /// vertices, an empty UV list and the original triangles.
    pub fn split_by_uv(&self) -> (Vec<u32>, Vec<[f32; 2]>, Vec<[u32; 3]>) {
        let Some(uv) = &self.uv else {
            let identity = (0..self.positions.len() as u32).collect();
            return (identity, Vec::new(), self.triangles.clone());
        };
        let mut index: HashMap<(u32, u32), u32> = HashMap::new();
        let mut new_to_old = Vec::new();
        let mut uvs = Vec::new();
        let mut triangles = Vec::with_capacity(self.triangles.len());
        for (tri, uv_tri) in self.triangles.iter().zip(&uv.triangles) {
            let mut out = [0u32; 3];
            for k in 0..3 {
                out[k] = *index.entry((tri[k], uv_tri[k])).or_insert_with(|| {
                    new_to_old.push(tri[k]);
                    uvs.push(uv.coords[uv_tri[k] as usize]);
                    (new_to_old.len() - 1) as u32
                });
            }
            triangles.push(out);
        }
        (new_to_old, uvs, triangles)
    }
}

impl FaceVaryingUv {
    fn validate(&self, triangle_count: usize) -> Result<(), MeshError> {
        if self.triangles.len() != triangle_count {
            return Err(MeshError::UvTriangleCountMismatch {
                triangles: triangle_count,
                uv_triangles: self.triangles.len(),
            });
        }
        let n = self.coords.len();
        match out_of_range(&self.triangles, n) {
            Some((triangle, index)) => Err(MeshError::UvIndexOutOfRange {
                triangle,
                index,
                uv_count: n,
            }),
            None => Ok(()),
        }
    }

    /// The UV triangles `kept` (in that order), with coordinates compacted to the used ones.
    fn subset(&self, kept: &[usize]) -> FaceVaryingUv {
        let mut used = vec![false; self.coords.len()];
        for &t in kept {
            for &i in &self.triangles[t] {
                used[i as usize] = true;
            }
        }
        let new_to_old: Vec<u32> = (0..self.coords.len() as u32)
            .filter(|&i| used[i as usize])
            .collect();
        let old_to_new = inverse_map(&new_to_old, self.coords.len());
        FaceVaryingUv {
            coords: new_to_old
                .iter()
                .map(|&i| self.coords[i as usize])
                .collect(),
            triangles: kept
                .iter()
                .map(|&t| self.triangles[t].map(|i| old_to_new[i as usize].unwrap_or(0)))
                .collect(),
        }
    }
}

/// Area of one triangle of `positions`.
pub fn triangle_area(positions: &[[f32; 3]], tri: &[u32; 3]) -> f32 {
    let [a, b, c] = tri.map(|i| v3(positions[i as usize]));
    0.5 * (b - a).cross(&(c - a)).norm()
}

/// The first index that appears twice in a triangle, if any.
/// The first triangle with an index ≥ `n`, and that index.
fn out_of_range(triangles: &[[u32; 3]], n: usize) -> Option<(usize, u32)> {
    triangles
        .iter()
        .enumerate()
        .find_map(|(t, tri)| tri.iter().find(|&&i| i as usize >= n).map(|&i| (t, i)))
}

fn repeated_index(tri: &[u32; 3]) -> Option<u32> {
    if tri[0] == tri[1] || tri[0] == tri[2] {
        Some(tri[0])
    } else if tri[1] == tri[2] {
        Some(tri[1])
    } else {
        None
    }
}

/// old→new lookup for an increasing new→old map.
fn inverse_map(new_to_old: &[u32], old_count: usize) -> Vec<Option<u32>> {
    let mut old_to_new = vec![None; old_count];
    for (new, &old) in new_to_old.iter().enumerate() {
        old_to_new[old as usize] = Some(new as u32);
    }
    old_to_new
}

/// Midpoint subdivision of any indexed attribute (positions or UVs) over its own triangles.
/// New items are appended in sorted-edge order; see [`TriMesh::subdivide_midpoint`].
fn subdivide_indexed<T: Copy>(
    items: &[T],
    triangles: &[[u32; 3]],
    midpoint: impl Fn(T, T) -> T,
) -> (Vec<T>, Vec<[u32; 3]>) {
    let edges = unique_edges(triangles);
    let n = items.len() as u32;
    let mut out_items = items.to_vec();
    out_items.extend(
        edges
            .iter()
            .map(|e| midpoint(items[e[0] as usize], items[e[1] as usize])),
    );
    // Every triangle edge is in `edges`, so the search always succeeds.
    let mid = |a: u32, b: u32| n + edges.binary_search(&sorted_pair(a, b)).unwrap_or(0) as u32;
    let mut out_tris = Vec::with_capacity(triangles.len() * 4);
    for &[a, b, c] in triangles {
        let (ab, bc, ca) = (mid(a, b), mid(b, c), mid(c, a));
        out_tris.extend([[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
    }
    (out_items, out_tris)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::test_meshes::{assert_split_roundtrip, grid, seamed_quad};
    use crate::geometry::topology::Topology;

    #[test]
    fn from_polygons_fans_each_face_and_checks_counts() {
        let square = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ];
        let mut points = square.clone();
        points.push([2.0, 0.5, 0.0]);
        let m = TriMesh::from_polygons(points.clone(), &[4, 3], &[0, 1, 2, 3, 1, 4, 2]).unwrap();
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3], [1, 4, 2]]);
        assert_eq!(
            TriMesh::from_polygons(points.clone(), &[4, 2], &[0, 1, 2, 3, 1, 4]),
            Err(MeshError::TooFewCorners {
                face: 1,
                corners: 2
            })
        );
        assert_eq!(
            TriMesh::from_polygons(points.clone(), &[4], &[0, 1, 2]),
            Err(MeshError::CornerCountMismatch {
                expected: 4,
                found: 3
            })
        );
        assert!(matches!(
            TriMesh::from_polygons(square, &[3], &[0, 1, 7]),
            Err(MeshError::IndexOutOfRange { index: 7, .. })
        ));
    }

    #[test]
    fn validate_reports_each_problem() {
        let mut m = grid(2, 2, 1.0);
        assert_eq!(m.validate(), Ok(()));

        m.triangles[3] = [0, 1, 99];
        assert_eq!(
            m.validate().unwrap_err().to_string(),
            "triangle 3 uses vertex 99, but the mesh has 9 vertices"
        );

        m.triangles[3] = [4, 1, 4];
        assert_eq!(
            m.validate(),
            Err(MeshError::RepeatedIndex {
                triangle: 3,
                index: 4
            })
        );

        let mut m = grid(2, 2, 1.0);
        m.positions[5][1] = f32::NAN;
        assert!(matches!(
            m.validate(),
            Err(MeshError::NonFinitePosition { vertex: 5, .. })
        ));

        let mut m = seamed_quad();
        m.uv.as_mut().unwrap().triangles.pop();
        assert_eq!(
            m.validate().unwrap_err().to_string(),
            "the mesh has 2 triangles but its UV set has 1 UV triangles"
        );
    }

    #[test]
    fn areas_of_a_unit_square_grid() {
        let m = grid(4, 3, 0.5); // 2.0 × 1.5
        let total: f32 = m.face_areas().iter().sum();
        assert!((total - 3.0).abs() < 1e-5);
        let va = m.vertex_areas();
        assert!((va.iter().sum::<f32>() - 3.0).abs() < 1e-5);
        // A corner vertex touches one or two triangles; an interior one six (area 6 × 1/8 / 3).
        let interior = 1 + 5; // row 1, column 1 of a 5-wide vertex grid
        assert!((va[interior] - 0.25).abs() < 1e-6, "{}", va[interior]);
    }

    #[test]
    fn bounds_and_degenerate_faces() {
        let mut m = grid(2, 2, 1.0);
        assert_eq!(m.bounds(), ([0.0, 0.0, 0.0], [2.0, 2.0, 0.0]));
        m.positions[4] = [0.0, 0.0, 0.0]; // collapse the centre onto the corner
        let degenerate = m.degenerate_faces(1e-9);
        assert!(!degenerate.is_empty());
        for t in degenerate {
            assert!(m.triangles[t].contains(&4) && m.triangles[t].contains(&0));
        }
        let empty = TriMesh::new(vec![], vec![]);
        assert_eq!(empty.bounds().0, [f32::INFINITY; 3]);
    }

    #[test]
    fn transformed_keeps_connectivity() {
        let m = seamed_quad();
        let t = m.transformed(|p| [p[0] * 0.1, p[2], -p[1]]);
        assert_eq!(t.triangles, m.triangles);
        assert_eq!(t.uv, m.uv);
        assert_eq!(t.positions[2], [0.1, 0.0, -1.0]);
    }

    #[test]
    fn subdivision_counts_order_and_area() {
        let m = grid(3, 2, 1.0);
        let topo = Topology::new(&m);
        let s = m.subdivide_midpoint();
        assert_eq!(s.vertex_count(), m.vertex_count() + topo.edges.len());
        assert_eq!(s.triangle_count(), 4 * m.triangle_count());
        assert_eq!(&s.positions[..m.vertex_count()], &m.positions[..]);
        for (i, e) in topo.edges.iter().enumerate() {
            let (a, b) = (m.positions[e[0] as usize], m.positions[e[1] as usize]);
            let mid = s.positions[m.vertex_count() + i];
            for k in 0..3 {
                assert!((mid[k] - 0.5 * (a[k] + b[k])).abs() < 1e-6);
            }
        }
        let area = |m: &TriMesh| m.face_areas().iter().sum::<f32>();
        assert!((area(&s) - area(&m)).abs() < 1e-5);
        assert_eq!(s.validate(), Ok(()));
        // Winding is preserved: all normals of a flat grid still point the same way.
        let normals = crate::geometry::face_normals(&s.positions, &s.triangles);
        assert!(normals.iter().all(|n| n[2] > 0.99));
    }

    #[test]
    fn subdivision_keeps_uv_seams_apart() {
        let m = seamed_quad();
        let s = m.subdivide_midpoint();
        let uv = s.uv.as_ref().unwrap();
        // The quad's diagonal is a UV seam: 5 position edges, 6 UV edges (diagonal doubled).
        assert_eq!(s.vertex_count(), 4 + 5);
        assert_eq!(uv.coords.len(), 6 + 6);
        assert_eq!(s.validate(), Ok(()));
        // Each child corner's UV is the same affine function of its position as in the parent
        // (per parent triangle, the UV chart is a translation of the xy plane).
        for t in 0..s.triangle_count() {
            let parent = t / 4;
            let offset = if parent == 0 { 0.0 } else { 10.0 };
            for k in 0..3 {
                let p = s.positions[s.triangles[t][k] as usize];
                let q = uv.coords[uv.triangles[t][k] as usize];
                assert_eq!([p[0] + offset, p[1]], q, "triangle {t} corner {k}");
            }
        }
    }

    #[test]
    fn submesh_keeps_whole_triangles() {
        let m = seamed_quad();
        // Keep vertices 0, 1, 2: only triangle 0 survives.
        let (s, map) = m.submesh(|v| v != 3);
        assert_eq!(map, vec![0, 1, 2]);
        assert_eq!(s.triangles, vec![m.triangles[0]]);
        let uv = s.uv.as_ref().unwrap();
        assert_eq!(uv.coords.len(), 3);
        assert_eq!(s.validate(), Ok(()));
        for k in 0..3 {
            let old_uv = m.uv.as_ref().unwrap();
            assert_eq!(
                uv.coords[uv.triangles[0][k] as usize],
                old_uv.coords[old_uv.triangles[0][k] as usize]
            );
        }
    }

    #[test]
    fn split_by_uv_duplicates_seam_vertices_only() {
        let m = seamed_quad();
        let split = m.split_by_uv();
        // The diagonal's two vertices are on the seam, so they are duplicated.
        assert_eq!(split.0, vec![0, 1, 2, 0, 2, 3]);
        assert_eq!(split.2, vec![[0, 1, 2], [3, 4, 5]]);
        assert_split_roundtrip(&m, &split);
        let plain = grid(2, 1, 1.0);
        let (map, uvs, tris) = plain.split_by_uv();
        assert_eq!(map, (0..6).collect::<Vec<_>>());
        assert!(uvs.is_empty());
        assert_eq!(tris, plain.triangles);
    }
}
