//! Face and vertex normals. Counter-clockwise winding faces the viewer (glTF / USD default).

use crate::geometry::{arr3, v3, Vec3};

/// Unit normal of each triangle; `[0, 0, 0]` for a degenerate (zero-area) triangle.
pub fn face_normals(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> Vec<[f32; 3]> {
    triangles
        .iter()
        .map(|t| arr3(unit_or_zero(face_cross(positions, t))))
        .collect()
}

/// Unit vertex normals, **angle-weighted** (Thürmer & Wüthrich): each adjacent triangle adds its
/// normal times its corner angle at the vertex. Unlike area weighting, the result does not
/// change when a neighbouring face is split, which matters on irregular garment meshes.
/// Vertices with no (non-degenerate) triangle get `[0, 0, 0]`.
pub fn vertex_normals(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> Vec<[f32; 3]> {
    let mut sums = vec![Vec3::zeros(); positions.len()];
    for tri in triangles {
        let n = unit_or_zero(face_cross(positions, tri));
        if n == Vec3::zeros() {
            continue;
        }
        let p = tri.map(|i| v3(positions[i as usize]));
        for k in 0..3 {
            let angle = corner_angle(p[k], p[(k + 1) % 3], p[(k + 2) % 3]);
            sums[tri[k] as usize] += n * angle;
        }
    }
    sums.into_iter().map(|s| arr3(unit_or_zero(s))).collect()
}

/// Un-normalised face normal (length = twice the area).
fn face_cross(positions: &[[f32; 3]], tri: &[u32; 3]) -> Vec3 {
    let [a, b, c] = tri.map(|i| v3(positions[i as usize]));
    (b - a).cross(&(c - a))
}

/// Angle at `at` between the edges to `b` and `c`; atan2 stays accurate for tiny/flat angles.
fn corner_angle(at: Vec3, b: Vec3, c: Vec3) -> f32 {
    let (u, v) = (b - at, c - at);
    u.cross(&v).norm().atan2(u.dot(&v))
}

fn unit_or_zero(v: Vec3) -> Vec3 {
    let len = v.norm();
    if len > f32::MIN_POSITIVE && len.is_finite() {
        v / len
    } else {
        Vec3::zeros()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::test_meshes::{grid, uv_sphere};

    #[test]
    fn flat_grid_faces_up() {
        let m = grid(3, 2, 0.25);
        for n in face_normals(&m.positions, &m.triangles) {
            assert_eq!(n, [0.0, 0.0, 1.0]);
        }
        for n in vertex_normals(&m.positions, &m.triangles) {
            assert!((n[2] - 1.0).abs() < 1e-6);
        }
    }

    #[test]
    fn sphere_vertex_normals_point_outward() {
        let m = uv_sphere(24, 16);
        let normals = vertex_normals(&m.positions, &m.triangles);
        for (p, n) in m.positions.iter().zip(&normals) {
            let (p, n) = (v3(*p), v3(*n));
            assert!((n.norm() - 1.0).abs() < 1e-5);
            // On a unit sphere the true normal is the position itself.
            assert!(n.dot(&p.normalize()) > 0.99, "p={p:?} n={n:?}");
        }
    }

    #[test]
    fn degenerate_face_gets_zero_normal_and_no_vote() {
        let positions = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [9.0; 3]];
        let triangles = vec![[0, 1, 2]];
        assert_eq!(face_normals(&positions, &triangles), vec![[0.0; 3]]);
        assert_eq!(vertex_normals(&positions, &triangles), vec![[0.0; 3]; 4]);
    }

    #[test]
    fn angle_weighting_ignores_how_a_neighbour_is_split() {
        // Vertex 0 of a corner: one face in the xy plane, one in the xz plane. Splitting the
        // xz face into two must not tilt the normal (it would with area or count weighting).
        let positions = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, -1.0],
            [0.5, 0.0, -0.5],
        ];
        let one = vertex_normals(&positions, &[[0, 1, 2], [0, 3, 1]]);
        let two = vertex_normals(&positions, &[[0, 1, 2], [0, 3, 4], [0, 4, 1]]);
        for k in 0..3 {
            assert!((one[0][k] - two[0][k]).abs() < 1e-6);
        }
    }
}
