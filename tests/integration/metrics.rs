//! The evaluation metrics against hand-computed values, and the exact inside-the-body test
//! (generalised winding number) on the real sample body.

use crate::common::{sample, unit_square};
use garmentbake::body::PosedBody;
use garmentbake::geometry::{PointIndex, SurfaceIndex};
use garmentbake::io::gltf_body::read_body;
use garmentbake::metrics::{ClothGeometry, Inside, InsideFrame};

/// A body of one vertex at (0, 0.5, 0.5) with normal +y: below y = 0.5 is "inside" for the proxy.
fn one_vertex_body(overlap: bool) -> PosedBody {
    let points = vec![[0.0, 0.5, 0.5]];
    PosedBody {
        index: PointIndex::new(&points).unwrap(),
        points,
        normals: vec![[0.0, 1.0, 0.0]],
        overlap: vec![overlap],
    }
}

#[test]
fn cloth_metrics_match_hand_computed_values() {
    // Unit square in the xz plane split along 1-2; vertex 1 lifted by 1 (as in the loss test).
    let rest = unit_square();
    let geometry = ClothGeometry::new(&rest, 0.5);
    let x = [
        [0.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
        [1.0, 0.0, 1.0],
    ];
    let m = geometry.frame(&x, &one_vertex_body(false));
    // Edges 0-1: 1 → √2, 1-2: √2 → √3, 1-3: 1 → √2; 0-2 and 2-3 keep their length.
    let (s2, s3) = (2f64.sqrt(), 3f64.sqrt());
    let edge_mm = 1e3 * (2.0 * (s2 - 1.0) + (s3 - s2)) / 5.0;
    assert!(
        (m.edge_mm - edge_mm).abs() < 1e-3,
        "{} vs {edge_mm}",
        m.edge_mm
    );
    // Face normals (−1, 1, 0)/√2 and (0, 1, 1)/√2: cos 0.5 across the one hinge.
    assert!((m.bend - 0.5).abs() < 1e-6, "{}", m.bend);
    // Vertex masses: area/3 of each triangle × 0.5 kg/m²; only vertex 1 (1/6 kg) is lifted.
    assert!((m.gravity_j - 9.81 / 6.0).abs() < 1e-5, "{}", m.gravity_j);
    // Vertices 0, 2, 3 lie below the body vertex's plane: 3 of 4 collided, none at overlap.
    assert!((m.collided_pct - 75.0).abs() < 1e-9);
    assert_eq!(m.collided_overlap_pct, 0.0);
    let at_overlap = geometry.frame(&x, &one_vertex_body(true));
    assert!((at_overlap.collided_overlap_pct - 75.0).abs() < 1e-9);
}

/// The unit cube [0, 1]³, outward triangles.
fn cube() -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let p = (0..8)
        .map(|i| [(i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32])
        .collect();
    let quads = [
        [0, 2, 3, 1], // z = 0
        [4, 5, 7, 6], // z = 1
        [0, 1, 5, 4], // y = 0
        [2, 6, 7, 3], // y = 1
        [0, 4, 6, 2], // x = 0
        [1, 3, 7, 5], // x = 1
    ];
    let t = quads
        .iter()
        .flat_map(|&[a, b, c, d]| [[a, b, c], [a, c, d]])
        .collect();
    (p, t)
}

#[test]
fn inside_figures_of_points_in_a_cube() {
    let (points, triangles) = cube();
    let surface = SurfaceIndex::new(&points, &triangles);
    let body = PosedBody {
        index: PointIndex::new(&points).unwrap(),
        normals: vec![[0.0, 1.0, 0.0]; 8],
        overlap: vec![false; 8],
        points,
    };
    let x = [[0.5, 0.5, 0.5], [0.5, 0.9, 0.5], [2.0, 2.0, 2.0]];
    let frame = InsideFrame::of(&x, &body, &surface);
    assert_eq!(frame.depths.len(), 2, "{frame:?}");
    let inside = Inside::of(&[&frame, &InsideFrame::of(&x[2..], &body, &surface)]);
    assert!(
        (inside.inside_pct - 50.0).abs() < 1e-9,
        "2 of 4: {inside:?}"
    );
    assert!((inside.depth_p50_mm - 100.0).abs() < 1e-3, "{inside:?}");
    assert!((inside.depth_max_mm - 500.0).abs() < 1e-3, "{inside:?}");
    assert_eq!((inside.worst_frame, inside.worst_frame_vertices), (0, 2));
}

#[test]
fn the_sample_body_is_inside_behind_its_skin_and_outside_in_front() {
    let body = read_body(&sample("body.glb")).unwrap();
    let surface = SurfaceIndex::new(&body.mesh().positions, &body.mesh().triangles);
    let shifted = |d: f32| -> Vec<[f32; 3]> {
        body.mesh()
            .positions
            .iter()
            .zip(&body.normals)
            .step_by(7)
            .map(|(p, n)| [p[0] + d * n[0], p[1] + d * n[1], p[2] + d * n[2]])
            .collect()
    };
    let (behind, front) = (shifted(-0.003), shifted(0.003));
    let inside = |x: &[[f32; 3]]| x.iter().filter(|&&p| surface.is_inside(p)).count();
    let n = behind.len();
    assert!(
        inside(&behind) * 1000 >= 995 * n,
        "{} of {n} behind the skin",
        inside(&behind)
    );
    // In front of the skin is outside, except where another part of the body is nearer than the
    // shift: keep the points at least 1.5 mm from any surface. Of those, the only ones inside
    // are where the MakeHuman mesh interpenetrates itself at rest: the closed lips and the toes.
    let clear: Vec<[f32; 3]> = front
        .into_iter()
        .filter(|&p| surface.distance(p) > 0.0015)
        .collect();
    assert!(clear.len() * 100 >= 95 * n, "{} of {n} clear", clear.len());
    let stray: Vec<[f32; 3]> = clear
        .iter()
        .copied()
        .filter(|&p| surface.is_inside(p))
        .collect();
    let lips_or_toes = |p: &[f32; 3]| (p[1] > 1.45 && p[2] > 0.1) || p[1] < 0.03;
    assert!(stray.iter().all(lips_or_toes), "{stray:?}");
    assert!(
        stray.len() * 100 <= 2 * clear.len(),
        "{} of {}",
        stray.len(),
        clear.len()
    );
    let depths: Vec<f32> = behind.iter().map(|&p| surface.distance(p)).collect();
    let mean = depths.iter().sum::<f32>() / n as f32;
    assert!((0.002..=0.0031).contains(&mean), "mean depth {mean} m");
    // Far away: outside; the hip joint's position at rest: inside.
    assert!(!surface.is_inside([0.0, 0.9, 1.0]));
    assert!(surface.is_inside([0.0, 0.95, 0.0]));
}

/// The body's self-overlap as [`garmentbake::body::self_overlap`] defines it, vertex by vertex
/// through a radius query of the whole posed body: the reference for its patch-by-patch search.
fn self_overlap_by_definition(rest: &[[f32; 3]], posed: &PosedBody) -> Vec<bool> {
    let v3 = |p: [f32; 3]| nalgebra::Vector3::from(p);
    (0..posed.points.len())
        .map(|v| {
            let other = posed
                .index
                .within(posed.points[v], 0.05)
                .into_iter()
                .filter(|&(u, _)| (v3(rest[u as usize]) - v3(rest[v])).norm() > 0.1)
                .min_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
            other.is_some_and(|(u, _)| {
                let u = u as usize;
                (v3(posed.points[v]) - v3(posed.points[u])).dot(&v3(posed.normals[u])) < 0.0
            })
        })
        .collect()
}

#[test]
fn the_body_overlap_search_flags_what_its_definition_flags() {
    let body = read_body(&sample("body.glb")).unwrap();
    let clip = garmentbake::motion::load_clip(
        &sample("motions/131_02.bvh"),
        &Default::default(),
        &body,
        Some(30.0),
    )
    .unwrap();
    // Frame 92 has the clip's most overlapping vertices (2,272: the arms against the sides).
    for frame in [0, 92, 250] {
        let posed = PosedBody::new(&body, &clip.animation.local_pose(frame));
        let expected = self_overlap_by_definition(&body.mesh().positions, &posed);
        let flagged = |o: &[bool]| o.iter().filter(|&&x| x).count();
        eprintln!(
            "frame {frame}: {} vertices flagged",
            flagged(&posed.overlap)
        );
        assert!(flagged(&expected) > 0, "frame {frame}: nothing to find");
        assert!(
            posed.overlap == expected,
            "frame {frame}: {} flagged, {} by the definition",
            flagged(&posed.overlap),
            flagged(&expected)
        );
    }
}
