//! Small procedural meshes for unit tests, with known counts and orientation.

use std::f32::consts::PI;

use crate::geometry::mesh::{FaceVaryingUv, TriMesh};

/// A `w × h` quad grid in the z = 0 plane with spacing `s`, each quad split along its
/// (0,0)–(1,1) diagonal; vertex `(x, y)` is `y * (w + 1) + x`; triangles face +z.
pub fn grid(w: usize, h: usize, s: f32) -> TriMesh {
    let mut positions = Vec::new();
    for y in 0..=h {
        for x in 0..=w {
            positions.push([x as f32 * s, y as f32 * s, 0.0]);
        }
    }
    let mut triangles = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let v00 = (y * (w + 1) + x) as u32;
            let (v10, v01) = (v00 + 1, v00 + (w + 1) as u32);
            let v11 = v01 + 1;
            triangles.push([v00, v10, v11]);
            triangles.push([v00, v11, v01]);
        }
    }
    TriMesh::new(positions, triangles)
}

/// The unit square as two triangles whose UV charts are separate: the diagonal (vertices 0 and
/// 2) is a UV seam. UV = (x, y) on triangle 0 and (x + 10, y) on triangle 1.
pub fn seamed_quad() -> TriMesh {
    TriMesh {
        positions: vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ],
        triangles: vec![[0, 1, 2], [0, 2, 3]],
        uv: Some(FaceVaryingUv {
            coords: vec![
                [0.0, 0.0],
                [1.0, 0.0],
                [1.0, 1.0],
                [10.0, 0.0],
                [11.0, 1.0],
                [10.0, 1.0],
            ],
            triangles: vec![[0, 1, 2], [3, 4, 5]],
        }),
    }
}

/// A closed unit sphere (Y-up) with `n_lon` segments and `n_lat` bands; vertex 0 is the north
/// pole, the last vertex the south pole; triangles face outward.
pub fn uv_sphere(n_lon: usize, n_lat: usize) -> TriMesh {
    let mut positions = vec![[0.0, 1.0, 0.0]];
    for j in 1..n_lat {
        let theta = PI * j as f32 / n_lat as f32;
        for i in 0..n_lon {
            let phi = 2.0 * PI * i as f32 / n_lon as f32;
            let r = theta.sin();
            positions.push([r * phi.cos(), theta.cos(), r * phi.sin()]);
        }
    }
    positions.push([0.0, -1.0, 0.0]);
    let ring = |j: usize, i: usize| (1 + (j - 1) * n_lon + i % n_lon) as u32;
    let south = (positions.len() - 1) as u32;
    let mut triangles = Vec::new();
    for i in 0..n_lon {
        triangles.push([0, ring(1, i + 1), ring(1, i)]);
        for j in 1..n_lat - 1 {
            let (a, b) = (ring(j, i), ring(j, i + 1));
            let (c, d) = (ring(j + 1, i), ring(j + 1, i + 1));
            triangles.push([a, b, d]);
            triangles.push([a, d, c]);
        }
        triangles.push([south, ring(n_lat - 1, i), ring(n_lat - 1, i + 1)]);
    }
    TriMesh::new(positions, triangles)
}

/// Checks a [`TriMesh::split_by_uv`] result: every corner maps back to its original position
/// index, position and UV.
pub fn assert_split_roundtrip(
    mesh: &TriMesh,
    (new_to_old, uvs, tris): &(Vec<u32>, Vec<[f32; 2]>, Vec<[u32; 3]>),
) {
    let uv = mesh.uv.as_ref().expect("mesh has UVs");
    assert_eq!(uvs.len(), new_to_old.len());
    assert_eq!(tris.len(), mesh.triangle_count());
    let corners = tris.iter().zip(&mesh.triangles).zip(&uv.triangles);
    for ((new_tri, old_tri), uv_tri) in corners {
        for ((&new, &old), &uv_index) in new_tri.iter().zip(old_tri).zip(uv_tri) {
            let new = new as usize;
            assert_eq!(new_to_old[new], old);
            assert_eq!(
                mesh.positions[new_to_old[new] as usize],
                mesh.positions[old as usize]
            );
            assert_eq!(uvs[new], uv.coords[uv_index as usize]);
        }
    }
}
