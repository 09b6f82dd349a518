//! Generalised winding numbers and point-surface distances for posed body meshes.
//!
//! The body mesh may have open holes (neck, wrists, ...), so a parity / ray-casting
//! inside test is unreliable. The generalised winding number (sum of signed solid
//! angles over all triangles divided by 4π, Barill et al. 2018) degrades gracefully
//! across holes: it is exactly 1 inside and 0 outside a closed, outward-oriented
//! mesh and varies smoothly across a hole. "Inside" means winding >= 0.5.
//!
//! Sign convention: triangles counter-clockwise seen from outside (outward normals)
//! give +1 inside; reversing every triangle gives -1.
//!
//! Triangle solid angles use the formula of Van Oosterom & Strackee (1983). Far-away
//! clusters of triangles are replaced by a Taylor expansion of the double-layer
//! kernel about the cluster's area-weighted centre: the dipole term (summed
//! area-weighted normal), the second-order term (normal ⊗ offset moment matrix)
//! and the third-order term (normal ⊗ offset ⊗ offset tensor). Every moment is an
//! exact integral over the triangles, so for a closed cluster all terms vanish
//! outside, as the true winding does. All maths is done in f64.

use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;
use std::f64::consts::PI;

type Vec3 = Vector3<f64>;

/// Maximum number of triangles in a leaf; leaves are always evaluated exactly.
const LEAF_SIZE: usize = 8;
/// Default far-field accuracy parameter: a cluster is expanded when the query point
/// is farther than `beta` times the cluster radius from its centre. Measured on a
/// 32×16 UV sphere with the third-order expansion, beta = 2 leaves errors up to
/// ~6e-3 (clusters expanded at twice their radius still err by a few per cent of
/// their contribution, and for points 2–3 radii from a closed mesh those
/// contributions are large and cancel); beta = 3 keeps them below ~4e-4 for
/// about 2× the (small) winding-query cost.
const DEFAULT_BETA: f64 = 3.0;
/// A triangle whose area is below this fraction of |ab|·|ac| (the sine of the angle
/// at its first corner) counts as zero-area: it contributes no solid angle.
const FLAT_TOLERANCE: f64 = 1e-12;
/// Relative size (against the cube of the longest corner vector) below which the
/// solid-angle numerator/denominator count as zero, i.e. the query point lies on
/// the triangle (its interior, an edge or a vertex).
const ON_TRIANGLE_TOLERANCE: f64 = 1e-14;
const FOUR_PI: f64 = 4.0 * PI;

/// A triangle in f64 with its degeneracy flag precomputed.
#[derive(Clone, Copy, Debug)]
struct Triangle {
    v: [Vec3; 3],
    /// Zero area: no solid angle, distance measured to its edges.
    flat: bool,
}

impl Triangle {
    fn new(v: [Vec3; 3]) -> Triangle {
        let ab = v[1] - v[0];
        let ac = v[2] - v[0];
        let flat = ab.cross(&ac).norm() <= FLAT_TOLERANCE * ab.norm() * ac.norm();
        Triangle { v, flat }
    }

    /// Area times unit normal (right-hand rule over v0, v1, v2).
    fn area_vector(&self) -> Vec3 {
        0.5 * (self.v[1] - self.v[0]).cross(&(self.v[2] - self.v[0]))
    }

    fn centroid(&self) -> Vec3 {
        (self.v[0] + self.v[1] + self.v[2]) / 3.0
    }
}

fn to_vec3(p: [f32; 3]) -> Vec3 {
    Vec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]))
}

/// Looks up a triangle's corners; `None` for out-of-range indices or non-finite
/// coordinates, so that bad user data is skipped instead of panicking.
fn load_triangle(positions: &[[f32; 3]], tri: &[u32; 3]) -> Option<Triangle> {
    let mut v = [Vec3::zeros(); 3];
    for (slot, &i) in v.iter_mut().zip(tri.iter()) {
        let q = positions.get(usize::try_from(i).ok()?)?;
        if !q.iter().all(|c| c.is_finite()) {
            return None;
        }
        *slot = to_vec3(*q);
    }
    Some(Triangle::new(v))
}

/// Signed solid angle of triangle `t` seen from `p` (Van Oosterom & Strackee):
/// tan(Ω/2) = a·(b×c) / (|a||b||c| + (a·b)|c| + (a·c)|b| + (b·c)|a|).
///
/// When `p` lies on the triangle (numerator ~0 and denominator not positive) the
/// angle jumps between +2π and -2π; we return the mean, 0, which also covers the
/// 0/0 cases on edges and vertices, so no NaN can arise from finite inputs.
fn solid_angle(t: &Triangle, p: &Vec3) -> f64 {
    if t.flat {
        return 0.0;
    }
    let a = t.v[0] - p;
    let b = t.v[1] - p;
    let c = t.v[2] - p;
    let (la, lb, lc) = (a.norm(), b.norm(), c.norm());
    let num = a.dot(&b.cross(&c));
    let den = la * lb * lc + a.dot(&b) * lc + a.dot(&c) * lb + b.dot(&c) * la;
    let tol = ON_TRIANGLE_TOLERANCE * la.max(lb).max(lc).powi(3);
    if num.abs() <= tol && den <= tol {
        return 0.0;
    }
    2.0 * num.atan2(den)
}

/// Solid-angle-based winding number of `p` w.r.t. a triangle soup, summed exactly over all triangles (reference; O(T)).
///
/// Triangles with out-of-range indices or non-finite corners are ignored.
pub fn winding_number_exact(positions: &[[f32; 3]], triangles: &[[u32; 3]], p: [f32; 3]) -> f64 {
    let p = to_vec3(p);
    let total: f64 = triangles
        .iter()
        .filter_map(|tri| load_triangle(positions, tri))
        .map(|t| solid_angle(&t, &p))
        .sum();
    total / FOUR_PI
}

/// The point of segment ab closest to `p`.
fn segment_closest(p: &Vec3, a: &Vec3, b: &Vec3) -> Vec3 {
    let ab = b - a;
    let len2 = ab.norm_squared();
    let t = if len2 > 0.0 {
        ((p - a).dot(&ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    a + t * ab
}

/// Squared distance from `p` to segment `a`-`b` (a point when a == b).
fn segment_distance2(p: &Vec3, a: &Vec3, b: &Vec3) -> f64 {
    (p - segment_closest(p, a, b)).norm_squared()
}

/// Which part of a triangle (not flat) is closest to a point: a corner, an edge or the face.
enum Feature {
    Corner(usize),
    Edge(usize, usize),
    Face,
}

/// Classifies `p` against the Voronoi regions of triangle `t` (corners, edges, face).
fn closest_feature(t: &Triangle, p: &Vec3) -> Feature {
    let [a, b, c] = t.v;
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(&ap);
    let d2 = ac.dot(&ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return Feature::Corner(0);
    }
    let bp = p - b;
    let d3 = ab.dot(&bp);
    let d4 = ac.dot(&bp);
    if d3 >= 0.0 && d4 <= d3 {
        return Feature::Corner(1);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return Feature::Edge(0, 1);
    }
    let cp = p - c;
    let d5 = ab.dot(&cp);
    let d6 = ac.dot(&cp);
    if d6 >= 0.0 && d5 <= d6 {
        return Feature::Corner(2);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return Feature::Edge(0, 2);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        return Feature::Edge(1, 2);
    }
    Feature::Face
}

/// The three edges of a triangle, as corner pairs.
const EDGES: [(usize, usize); 3] = [(0, 1), (1, 2), (2, 0)];

/// Squared distance from `p` to the closest point of triangle `t`, by classifying
/// `p` against the triangle's Voronoi regions (vertices, edges, face). Zero-area
/// triangles are measured to their edges.
fn triangle_distance2(t: &Triangle, p: &Vec3) -> f64 {
    let v = &t.v;
    if t.flat {
        return EDGES
            .iter()
            .map(|&(i, j)| segment_distance2(p, &v[i], &v[j]))
            .fold(f64::INFINITY, f64::min);
    }
    match closest_feature(t, p) {
        Feature::Corner(i) => (p - v[i]).norm_squared(),
        Feature::Edge(i, j) => segment_distance2(p, &v[i], &v[j]),
        Feature::Face => {
            // Distance to the supporting plane (more exact than projecting).
            let n = (v[1] - v[0]).cross(&(v[2] - v[0]));
            let h = (p - v[0]).dot(&n);
            h * h / n.norm_squared()
        }
    }
}

/// The point of triangle `t` closest to `p` (of a zero-area triangle: of its edges), and whether
/// it lies inside the face (not on an edge or a corner).
fn triangle_closest(t: &Triangle, p: &Vec3) -> (Vec3, bool) {
    let v = &t.v;
    let on_edge = |&(i, j): &(usize, usize)| segment_closest(p, &v[i], &v[j]);
    if t.flat {
        let c = EDGES
            .iter()
            .map(on_edge)
            .min_by(|x, y| (p - x).norm_squared().total_cmp(&(p - y).norm_squared()))
            .unwrap_or(v[0]);
        return (c, false);
    }
    match closest_feature(t, p) {
        Feature::Corner(i) => (v[i], false),
        Feature::Edge(i, j) => (on_edge(&(i, j)), false),
        Feature::Face => {
            let n = (v[1] - v[0]).cross(&(v[2] - v[0]));
            (p - n * ((p - v[0]).dot(&n) / n.norm_squared()), true)
        }
    }
}

/// ∫_T (x−c)(x−c)ᵀ dA / area for triangle `t`: (Σ dᵢdᵢᵀ + S Sᵀ)/12 with dᵢ = vᵢ − c
/// and S = Σ dᵢ (exact for a linear triangle).
fn second_moment_per_area(t: &Triangle, c: &Vec3) -> Matrix3<f64> {
    let d = [t.v[0] - c, t.v[1] - c, t.v[2] - c];
    let sum = d[0] + d[1] + d[2];
    (d[0] * d[0].transpose()
        + d[1] * d[1].transpose()
        + d[2] * d[2].transpose()
        + sum * sum.transpose())
        / 12.0
}

/// Squared distance from `p` to an axis-aligned box (0 inside).
fn box_distance2(p: &Vec3, bmin: &Vec3, bmax: &Vec3) -> f64 {
    (0..3)
        .map(|k| {
            let d = (bmin[k] - p[k]).max(p[k] - bmax[k]).max(0.0);
            d * d
        })
        .sum()
}

/// One BVH node: bounds for distance pruning and the far-field expansion data.
#[derive(Clone, Debug)]
struct Node {
    bmin: Vec3,
    bmax: Vec3,
    /// Total (unsigned) area.
    area: f64,
    /// Area-weighted centre: the expansion point.
    centre: Vec3,
    /// Σ area·normal: the dipole strength.
    normal: Vec3,
    /// Σ (area·normal) ⊗ (centroid − centre): the second-order moment Mⱼₖ.
    moment: Matrix3<f64>,
    /// Third-order moment Tⱼₖₗ: `third_moment[j]` = Σ (area·normal)ⱼ ∫(x−c)(x−c)ᵀ dA / area.
    third_moment: [Matrix3<f64>; 3],
    /// The expansion as polynomial coefficients in `r` (from `normal`, `moment`, `third_moment`).
    expansion: Expansion,
    /// Max distance from `centre` to the node's vertices (bounds all its points).
    radius: f64,
    /// Range of the node's triangles in `SurfaceIndex::triangles`.
    start: u32,
    end: u32,
    /// Child node indices; `None` for a leaf.
    children: Option<(u32, u32)>,
}

impl Node {
    /// A leaf: moments computed directly from its triangles `tris[ids[..]]`, which
    /// will occupy `start..start + ids.len()` in the final triangle order.
    fn leaf(tris: &[Triangle], centroids: &[Vec3], ids: &[u32], start: usize) -> Node {
        let mut area = 0.0;
        let mut weighted = Vec3::zeros();
        let mut normal = Vec3::zeros();
        let mut bmin = Vec3::repeat(f64::INFINITY);
        let mut bmax = Vec3::repeat(f64::NEG_INFINITY);
        for &id in ids {
            let t = &tris[id as usize];
            let s = t.area_vector();
            area += s.norm();
            weighted += s.norm() * centroids[id as usize];
            normal += s;
            for v in &t.v {
                bmin = bmin.inf(v);
                bmax = bmax.sup(v);
            }
        }
        let centre = weighted_centre(area, &weighted, &bmin, &bmax);
        let mut moment = Matrix3::zeros();
        let mut third_moment = [Matrix3::zeros(); 3];
        for &id in ids {
            let t = &tris[id as usize];
            let s = t.area_vector();
            moment += s * (centroids[id as usize] - centre).transpose();
            let spread = second_moment_per_area(t, &centre);
            for (q, sj) in third_moment.iter_mut().zip(s.iter()) {
                *q += *sj * spread;
            }
        }
        Node {
            bmin,
            bmax,
            area,
            centre,
            normal,
            expansion: Expansion::new(&normal, &moment, &third_moment),
            moment,
            third_moment,
            radius: vertex_radius(tris, ids, &centre),
            start: start as u32,
            end: (start + ids.len()) as u32,
            children: None,
        }
    }

    /// An inner node: moments of the two children translated to the combined
    /// centre (parallel-axis rule), so the build stays O(T log T) with small
    /// constants; the radius is still measured exactly over the vertices.
    fn parent(tris: &[Triangle], ids: &[u32], kids: (&Node, &Node), indices: (u32, u32)) -> Node {
        let (l, r) = kids;
        let area = l.area + r.area;
        let weighted = l.area * l.centre + r.area * r.centre;
        let bmin = l.bmin.inf(&r.bmin);
        let bmax = l.bmax.sup(&r.bmax);
        let centre = weighted_centre(area, &weighted, &bmin, &bmax);
        let mut moment = Matrix3::zeros();
        let mut third_moment = [Matrix3::zeros(); 3];
        for kid in [l, r] {
            let delta = kid.centre - centre;
            moment += kid.moment + kid.normal * delta.transpose();
            for (j, q) in third_moment.iter_mut().enumerate() {
                let m_j = kid.moment.row(j).transpose();
                *q += kid.third_moment[j]
                    + m_j * delta.transpose()
                    + delta * m_j.transpose()
                    + kid.normal[j] * delta * delta.transpose();
            }
        }
        let normal = l.normal + r.normal;
        Node {
            bmin,
            bmax,
            area,
            centre,
            normal,
            expansion: Expansion::new(&normal, &moment, &third_moment),
            moment,
            third_moment,
            radius: vertex_radius(tris, ids, &centre),
            start: l.start,
            end: r.end,
            children: Some(indices),
        }
    }

    /// Winding number of the node's triangles at `p` from the Taylor expansion about
    /// the centre, given r = c − p and |r|² ([`Expansion`]).
    fn far_field(&self, r: &Vec3, dist2: f64) -> f64 {
        self.expansion.at(r, dist2)
    }
}

/// A node's far field as a polynomial in `r = c − p` over powers of `1/|r|`, its coefficients
/// precomputed from the moments (a query then costs a few dozen multiplies instead of 3×3
/// matrix products). The kernel is f(x) = (x − p)/(4π|x − p|³):
/// - first order: N·f(c) = N·r/(4π|r|³);
/// - second: ∂ₖfⱼ = (δⱼₖ/|r|³ − 3rⱼrₖ/|r|⁵)/4π contracted with Mⱼₖ: tr M/|r|³ − 3 rᵀMr/|r|⁵;
/// - third: ½ ∂ₗ∂ₖfⱼ = ½(−3(δⱼₖrₗ + δⱼₗrₖ + δₖₗrⱼ)/|r|⁵ + 15rⱼrₖrₗ/|r|⁷)/4π contracted with
///   Tⱼₖₗ (symmetric in k, l): −(3/2) L·r/|r|⁵ + (15/2) T(r, r, r)/|r|⁷, with
///   Lₖ = 2 Σⱼ Tⱼₖⱼ + Σⱼ Tₖⱼⱼ.
#[derive(Clone, Debug)]
struct Expansion {
    /// N, and tr M.
    normal: [f64; 3],
    trace: f64,
    /// rᵀMr as xx, yy, zz, xy, xz, yz coefficients.
    quadratic: [f64; 6],
    /// L.
    linear: [f64; 3],
    /// T(r, r, r) as coefficients of the ten cubic monomials ([`CUBIC`]).
    cubic: [f64; 10],
}

/// The cubic monomials rₐr_br_c (a ≤ b ≤ c) in the order of [`Expansion::cubic`].
const CUBIC: [[usize; 3]; 10] = [
    [0, 0, 0],
    [1, 1, 1],
    [2, 2, 2],
    [0, 0, 1],
    [0, 0, 2],
    [0, 1, 1],
    [1, 1, 2],
    [0, 2, 2],
    [1, 2, 2],
    [0, 1, 2],
];

/// The slot in [`CUBIC`] of the monomial rⱼrₖrₗ, for any order of j, k, l.
const CUBIC_SLOT: [[[usize; 3]; 3]; 3] = cubic_slots();

const fn cubic_slots() -> [[[usize; 3]; 3]; 3] {
    let mut slots = [[[0; 3]; 3]; 3];
    let mut i = 0;
    while i < CUBIC.len() {
        let [a, b, c] = CUBIC[i];
        // Every ordering of (a, b, c).
        let orders = [
            [a, b, c],
            [a, c, b],
            [b, a, c],
            [b, c, a],
            [c, a, b],
            [c, b, a],
        ];
        let mut o = 0;
        while o < orders.len() {
            let [j, k, l] = orders[o];
            slots[j][k][l] = i;
            o += 1;
        }
        i += 1;
    }
    slots
}

impl Expansion {
    fn new(normal: &Vec3, moment: &Matrix3<f64>, third: &[Matrix3<f64>; 3]) -> Expansion {
        let m = |a: usize, b: usize| moment[(a, b)];
        let mut cubic = [0.0; 10];
        let mut linear = [0.0; 3];
        for (j, q) in third.iter().enumerate() {
            for k in 0..3 {
                linear[k] += 2.0 * q[(k, j)];
                for l in 0..3 {
                    cubic[CUBIC_SLOT[j][k][l]] += q[(k, l)];
                }
            }
            linear[j] += q.trace();
        }
        Expansion {
            normal: [normal.x, normal.y, normal.z],
            trace: moment.trace(),
            quadratic: [
                m(0, 0),
                m(1, 1),
                m(2, 2),
                m(0, 1) + m(1, 0),
                m(0, 2) + m(2, 0),
                m(1, 2) + m(2, 1),
            ],
            linear,
            cubic,
        }
    }

    /// The winding number at `r = c − p`, `dist2 = |r|²`.
    fn at(&self, r: &Vec3, dist2: f64) -> f64 {
        let [x, y, z] = [r.x, r.y, r.z];
        let inv_d2 = 1.0 / dist2;
        let inv_d3 = inv_d2 / dist2.sqrt();
        let inv_d5 = inv_d3 * inv_d2;
        let (n, q, l, c) = (&self.normal, &self.quadratic, &self.linear, &self.cubic);
        let first = n[0] * x + n[1] * y + n[2] * z + self.trace;
        let quadratic =
            q[0] * x * x + q[1] * y * y + q[2] * z * z + q[3] * x * y + q[4] * x * z + q[5] * y * z;
        let linear = l[0] * x + l[1] * y + l[2] * z;
        let cubic = c[0] * x * x * x
            + c[1] * y * y * y
            + c[2] * z * z * z
            + c[3] * x * x * y
            + c[4] * x * x * z
            + c[5] * x * y * y
            + c[6] * y * y * z
            + c[7] * x * z * z
            + c[8] * y * z * z
            + c[9] * x * y * z;
        (first * inv_d3 - (3.0 * quadratic + 1.5 * linear) * inv_d5 + 7.5 * cubic * inv_d5 * inv_d2)
            / FOUR_PI
    }
}

/// The point of a surface closest to a query point ([`SurfaceIndex::closest`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Closest {
    pub point: [f32; 3],
    /// The unit normal of the closest triangle (outwards for counter-clockwise triangles).
    pub normal: [f32; 3],
    /// Whether the closest point lies inside the triangle's face, not on an edge or a corner:
    /// then the side of the face's plane is the side of the surface (for a closed surface that
    /// does not cross itself), with no winding number to sum.
    pub on_face: bool,
}

/// A BVH over a posed triangle mesh answering winding-number and distance queries fast.
#[derive(Clone, Debug)]
pub struct SurfaceIndex {
    /// Valid triangles, reordered so every node covers a contiguous range.
    triangles: Vec<Triangle>,
    /// Nodes, children before parents; the root is the last (none for an empty mesh).
    nodes: Vec<Node>,
    beta: f64,
}

impl SurfaceIndex {
    /// Builds the tree (deterministic: same input → same tree). Panics on nothing: empty mesh gives winding 0, distance infinity.
    ///
    /// Triangles with out-of-range indices or non-finite corners are skipped.
    pub fn new(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> SurfaceIndex {
        let tris: Vec<Triangle> = triangles
            .iter()
            .filter_map(|tri| load_triangle(positions, tri))
            .collect();
        let centroids: Vec<Vec3> = tris.iter().map(Triangle::centroid).collect();
        let mut order: Vec<u32> = (0..tris.len() as u32).collect();
        let mut nodes = Vec::new();
        if !tris.is_empty() {
            build_node(&tris, &centroids, &mut order, 0, &mut nodes);
        }
        let triangles = order.iter().map(|&i| tris[i as usize]).collect();
        SurfaceIndex {
            triangles,
            nodes,
            beta: DEFAULT_BETA,
        }
    }

    /// Returns the index with a different far-field accuracy parameter (larger is
    /// more accurate and slower); non-finite or negative values keep the default.
    pub fn with_beta(mut self, beta: f64) -> SurfaceIndex {
        if beta.is_finite() && beta >= 0.0 {
            self.beta = beta;
        }
        self
    }

    /// Fast winding number (far clusters by their multipole expansion up to third order, near triangles exactly).
    /// Accuracy parameter beta = 3.0 by default (see `with_beta`); max error ~4e-4 on the tests.
    pub fn winding_number(&self, p: [f32; 3]) -> f64 {
        let p = to_vec3(p);
        let mut total = 0.0;
        let mut stack: Vec<u32> = Vec::with_capacity(64);
        if let Some(root) = self.root() {
            stack.push(root);
        }
        while let Some(i) = stack.pop() {
            let node = &self.nodes[i as usize];
            let r = node.centre - p;
            let dist2 = r.norm_squared();
            let reach = self.beta * node.radius;
            if dist2 > reach * reach {
                total += node.far_field(&r, dist2);
            } else if let Some((left, right)) = node.children {
                stack.push(right);
                stack.push(left);
            } else {
                total += self
                    .leaf_triangles(node)
                    .iter()
                    .map(|t| solid_angle(t, &p))
                    .sum::<f64>()
                    / FOUR_PI;
            }
        }
        total
    }

    /// winding_number(p) >= 0.5
    pub fn is_inside(&self, p: [f32; 3]) -> bool {
        self.winding_number(p) >= 0.5
    }

    /// Unsigned distance from `p` to the closest point of the surface (exact point-triangle distance, BVH-pruned), metres.
    pub fn distance(&self, p: [f32; 3]) -> f32 {
        self.nearest_triangle(&to_vec3(p))
            .map_or(f64::INFINITY, |(_, d2)| d2)
            .sqrt() as f32
    }

    /// The point of the surface closest to `p` (none for an empty mesh).
    pub fn closest_point(&self, p: [f32; 3]) -> Option<[f32; 3]> {
        self.closest(p).map(|c| c.point)
    }

    /// The point of the surface closest to `p`, its triangle's normal and whether it lies inside
    /// that triangle's face (none for an empty mesh).
    pub fn closest(&self, p: [f32; 3]) -> Option<Closest> {
        let q = to_vec3(p);
        self.nearest_triangle(&q).map(|(i, _)| {
            let t = &self.triangles[i];
            let (c, on_face) = triangle_closest(t, &q);
            let n = (t.v[1] - t.v[0]).cross(&(t.v[2] - t.v[0]));
            let n = n / n.norm().max(f64::MIN_POSITIVE);
            let f = |v: Vec3| [v.x as f32, v.y as f32, v.z as f32];
            Closest {
                point: f(c),
                normal: f(n),
                on_face,
            }
        })
    }

    /// The triangle closest to `p` and its squared distance.
    fn nearest_triangle(&self, p: &Vec3) -> Option<(usize, f64)> {
        let mut best: Option<(usize, f64)> = None;
        let best2 = |b: &Option<(usize, f64)>| b.map_or(f64::INFINITY, |(_, d2)| d2);
        let mut stack: Vec<(u32, f64)> = Vec::with_capacity(64);
        if let Some(root) = self.root() {
            stack.push(self.child_with_bound(root, p));
        }
        while let Some((i, bound2)) = stack.pop() {
            if bound2 >= best2(&best) {
                continue;
            }
            let node = &self.nodes[i as usize];
            match node.children {
                None => {
                    for (k, t) in self.leaf_triangles(node).iter().enumerate() {
                        let d2 = triangle_distance2(t, p);
                        if d2 < best2(&best) {
                            best = Some((node.start as usize + k, d2));
                        }
                    }
                }
                Some((left, right)) => {
                    let near = self.child_with_bound(left, p);
                    let far = self.child_with_bound(right, p);
                    let (near, far) = if far.1 < near.1 {
                        (far, near)
                    } else {
                        (near, far)
                    };
                    // Push the farther child first so the nearer one is searched first.
                    for child in [far, near] {
                        if child.1 < best2(&best) {
                            stack.push(child);
                        }
                    }
                }
            }
        }
        best
    }

    /// For many points in parallel (rayon): (winding number, distance) for each.
    pub fn query_many(&self, points: &[[f32; 3]]) -> Vec<(f64, f32)> {
        points
            .par_iter()
            .map(|&p| (self.winding_number(p), self.distance(p)))
            .collect()
    }

    fn root(&self) -> Option<u32> {
        self.nodes.len().checked_sub(1).map(|i| i as u32)
    }

    fn leaf_triangles(&self, node: &Node) -> &[Triangle] {
        &self.triangles[node.start as usize..node.end as usize]
    }

    fn child_with_bound(&self, child: u32, p: &Vec3) -> (u32, f64) {
        let node = &self.nodes[child as usize];
        (child, box_distance2(p, &node.bmin, &node.bmax))
    }
}

/// Recursively builds the subtree over `order` (whose first element sits at
/// `start` in the final triangle order), children before parents, and returns its
/// node index. Splits at the median centroid along the longest axis of the
/// centroid bounds; ties are broken by triangle index so the tree depends only on
/// the input.
fn build_node(
    tris: &[Triangle],
    centroids: &[Vec3],
    order: &mut [u32],
    start: usize,
    nodes: &mut Vec<Node>,
) -> u32 {
    if order.len() <= LEAF_SIZE {
        nodes.push(Node::leaf(tris, centroids, order, start));
        return nodes.len() as u32 - 1;
    }
    let axis = longest_centroid_axis(centroids, order);
    let mid = order.len() / 2;
    order.select_nth_unstable_by(mid, |&a, &b| {
        centroids[a as usize][axis]
            .total_cmp(&centroids[b as usize][axis])
            .then(a.cmp(&b))
    });
    let (lower, upper) = order.split_at_mut(mid);
    let left = build_node(tris, centroids, lower, start, nodes);
    let right = build_node(tris, centroids, upper, start + mid, nodes);
    let node = Node::parent(
        tris,
        order,
        (&nodes[left as usize], &nodes[right as usize]),
        (left, right),
    );
    nodes.push(node);
    nodes.len() as u32 - 1
}

/// Expansion centre: area-weighted, or the box centre for an all-zero-area node.
fn weighted_centre(area: f64, weighted: &Vec3, bmin: &Vec3, bmax: &Vec3) -> Vec3 {
    if area > 0.0 {
        weighted / area
    } else {
        0.5 * (bmin + bmax)
    }
}

/// Max distance from `centre` to the vertices of `tris[ids[..]]`; the ball of that
/// radius contains every point of those triangles.
fn vertex_radius(tris: &[Triangle], ids: &[u32], centre: &Vec3) -> f64 {
    ids.iter()
        .flat_map(|&id| tris[id as usize].v.iter())
        .map(|v| (v - centre).norm_squared())
        .fold(0.0, f64::max)
        .sqrt()
}

/// Axis (0, 1, 2) along which the centroids of `ids` spread most; lowest on ties.
fn longest_centroid_axis(centroids: &[Vec3], ids: &[u32]) -> usize {
    let mut lo = Vec3::repeat(f64::INFINITY);
    let mut hi = Vec3::repeat(f64::NEG_INFINITY);
    for &id in ids {
        lo = lo.inf(&centroids[id as usize]);
        hi = hi.sup(&centroids[id as usize]);
    }
    let extent = hi - lo;
    let mut axis = 0;
    for k in 1..3 {
        if extent[k] > extent[axis] {
            axis = k;
        }
    }
    axis
}

#[cfg(test)]
mod tests {

    use super::*;
    use std::time::Instant;

    type Mesh = (Vec<[f32; 3]>, Vec<[u32; 3]>);

    /// Deterministic 64-bit LCG (Knuth's MMIX constants) giving f64 in [0, 1).
    struct Lcg(u64);

    impl Lcg {
        fn next(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }

        fn range(&mut self, lo: f64, hi: f64) -> f64 {
            lo + (hi - lo) * self.next()
        }

        /// Unit vector by rejection sampling in the unit ball.
        fn direction(&mut self) -> [f64; 3] {
            loop {
                let v = [
                    self.range(-1.0, 1.0),
                    self.range(-1.0, 1.0),
                    self.range(-1.0, 1.0),
                ];
                let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
                if n > 0.1 && n <= 1.0 {
                    return [v[0] / n, v[1] / n, v[2] / n];
                }
            }
        }
    }

    fn scaled(d: [f64; 3], s: f64) -> [f32; 3] {
        [(d[0] * s) as f32, (d[1] * s) as f32, (d[2] * s) as f32]
    }

    fn norm(p: [f32; 3]) -> f64 {
        to_vec3(p).norm()
    }

    /// UV sphere, outward counter-clockwise; `bump` perturbs the radius to make a
    /// "sphere-like" blob.
    fn uv_sphere(radius: f64, segments: u32, rings: u32, bump: f64) -> Mesh {
        let mut positions = vec![[0.0, 0.0, radius as f32]];
        for i in 1..rings {
            let theta = PI * f64::from(i) / f64::from(rings);
            for j in 0..segments {
                let phi = 2.0 * PI * f64::from(j) / f64::from(segments);
                let r = radius * (1.0 + bump * (3.0 * theta).sin() * (2.0 * phi).sin());
                positions.push([
                    (r * theta.sin() * phi.cos()) as f32,
                    (r * theta.sin() * phi.sin()) as f32,
                    (r * theta.cos()) as f32,
                ]);
            }
        }
        positions.push([0.0, 0.0, -radius as f32]);
        let south = positions.len() as u32 - 1;
        let ring = |i: u32, j: u32| 1 + (i - 1) * segments + j % segments;
        let mut triangles = Vec::new();
        for j in 0..segments {
            triangles.push([0, ring(1, j), ring(1, j + 1)]);
            triangles.push([ring(rings - 1, j), south, ring(rings - 1, j + 1)]);
        }
        for i in 1..rings - 1 {
            for j in 0..segments {
                let (a, b, c, d) = (
                    ring(i, j),
                    ring(i + 1, j),
                    ring(i + 1, j + 1),
                    ring(i, j + 1),
                );
                triangles.push([a, b, c]);
                triangles.push([a, c, d]);
            }
        }
        (positions, triangles)
    }

    fn reversed(triangles: &[[u32; 3]]) -> Vec<[u32; 3]> {
        triangles.iter().map(|t| [t[0], t[2], t[1]]).collect()
    }

    /// Unit cube [0,1]³ as 6 faces × 2 triangles, oriented outward (checked from
    /// the geometry). Faces are ordered -x, +x, -y, +y, -z, +z.
    fn unit_cube() -> Mesh {
        let positions: Vec<[f32; 3]> = (0..8u32)
            .map(|i| [(i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32])
            .collect();
        let mut triangles = Vec::new();
        for axis in 0..3 {
            for side in 0..2u32 {
                let (u, w) = ((axis + 1) % 3, (axis + 2) % 3);
                let corner = |a: u32, b: u32| (side << axis) | (a << u) | (b << w);
                let quad = [corner(0, 0), corner(1, 0), corner(1, 1), corner(0, 1)];
                for t in [[quad[0], quad[1], quad[2]], [quad[0], quad[2], quad[3]]] {
                    triangles.push(orient_outward(&positions, t));
                }
            }
        }
        (positions, triangles)
    }

    fn orient_outward(positions: &[[f32; 3]], t: [u32; 3]) -> [u32; 3] {
        let tri = load_triangle(positions, &t).expect("cube indices are valid");
        let outward = tri.centroid() - Vec3::repeat(0.5);
        if tri.area_vector().dot(&outward) > 0.0 {
            t
        } else {
            [t[0], t[2], t[1]]
        }
    }

    /// Solid angle of a square of half-side `a` seen from distance `h` on its axis.
    fn square_solid_angle(a: f64, h: f64) -> f64 {
        4.0 * (a * a / (h * (2.0 * a * a + h * h).sqrt())).atan()
    }

    #[test]
    fn sphere_winding_inside_outside_and_fast_matches_exact() {
        let (pos, tri) = uv_sphere(1.0, 32, 16, 0.0);
        let index = SurfaceIndex::new(&pos, &tri);
        let mut rng = Lcg(7);
        let mut probes = vec![([0.0f32; 3], 1.0)];
        for _ in 0..50 {
            let d = rng.direction();
            probes.push((scaled(d, 0.9), 1.0));
            probes.push((scaled(d, 1.1), 0.0));
            probes.push((scaled(d, 3.0), 0.0));
        }
        for (p, expected) in probes {
            let exact = winding_number_exact(&pos, &tri, p);
            let fast = index.winding_number(p);
            assert!((exact - expected).abs() < 1e-9, "exact {exact} at {p:?}");
            assert!((fast - expected).abs() < 1e-3, "fast {fast} at {p:?}");
        }

        let beta2 = index.clone().with_beta(2.0);
        let (mut max_err, mut max_err_beta2) = (0.0f64, 0.0f64);
        let mut accepted = 0;
        while accepted < 500 {
            let p = [
                rng.range(-2.0, 2.0) as f32,
                rng.range(-2.0, 2.0) as f32,
                rng.range(-2.0, 2.0) as f32,
            ];
            // Away from both the mesh and the ideal sphere, so |p| < r is the truth.
            if index.distance(p) <= 0.02 || (norm(p) - 1.0).abs() <= 0.02 {
                continue;
            }
            accepted += 1;
            let exact = winding_number_exact(&pos, &tri, p);
            let fast = index.winding_number(p);
            max_err = max_err.max((fast - exact).abs());
            max_err_beta2 = max_err_beta2.max((beta2.winding_number(p) - exact).abs());
            assert!(
                (fast - exact).abs() < 1e-3,
                "fast {fast} exact {exact} at {p:?}"
            );
            assert_eq!(index.is_inside(p), norm(p) < 1.0, "is_inside at {p:?}");
        }
        println!(
            "max |fast - exact| over 500 box points: {max_err:.3e} (default beta), {max_err_beta2:.3e} (beta 2)"
        );
    }

    #[test]
    fn reversed_sphere_gives_minus_one_inside() {
        let (pos, tri) = uv_sphere(1.0, 32, 16, 0.0);
        let tri = reversed(&tri);
        let index = SurfaceIndex::new(&pos, &tri);
        for p in [[0.0, 0.0, 0.0], [0.3, -0.2, 0.5]] {
            assert!((winding_number_exact(&pos, &tri, p) + 1.0).abs() < 1e-9);
            assert!((index.winding_number(p) + 1.0).abs() < 1e-3);
            assert!(!index.is_inside(p));
        }
        assert!(index.winding_number([0.0, 0.0, 2.0]).abs() < 1e-3);
    }

    #[test]
    fn cube_with_open_face_has_fractional_winding() {
        let (pos, mut tri) = unit_cube();
        tri.truncate(10); // drop the two +z triangles: a square hole at z = 1
        let index = SurfaceIndex::new(&pos, &tri);
        let check = |p: [f32; 3], expected: f64| {
            let exact = winding_number_exact(&pos, &tri, p);
            let fast = index.winding_number(p);
            assert!(
                (exact - expected).abs() < 1e-9,
                "exact {exact} vs {expected} at {p:?}"
            );
            assert!(
                (fast - expected).abs() < 1e-3,
                "fast {fast} vs {expected} at {p:?}"
            );
            fast
        };
        // Centre: the hole subtends 4π/6, so 1 − 1/6.
        let centre = check([0.5, 0.5, 0.5], 5.0 / 6.0);
        assert!((5.0 / 6.0 - 1.0 + square_solid_angle(0.5, 0.5) / FOUR_PI).abs() < 1e-12);
        assert!(centre >= 0.5 && index.is_inside([0.5, 0.5, 0.5]));
        // Just outside the hole the five walls subtend a bit less than a half space.
        let h = f64::from(1.01f32) - 1.0;
        let above = check([0.5, 0.5, 1.01], square_solid_angle(0.5, h) / FOUR_PI);
        assert!(above < 0.5 && !index.is_inside([0.5, 0.5, 1.01]));
        // Below the bottom, looking through the open box: minus the hole's angle.
        let below = check([0.5, 0.5, -3.0], -square_solid_angle(0.5, 4.0) / FOUR_PI);
        assert!(below.abs() < 0.01 && !index.is_inside([0.5, 0.5, -3.0]));
    }

    #[test]
    fn closed_cube_near_faces_edges_and_corners() {
        let (pos, tri) = unit_cube();
        let index = SurfaceIndex::new(&pos, &tri);
        let d = 1e-4;
        let e = d / 2f64.sqrt();
        let c = d / 3f64.sqrt();
        let cases: [([f64; 3], [f64; 3]); 3] = [
            ([0.5, 0.5, 1.0], [0.0, 0.0, d]), // top face centre, along the normal
            ([1.0, 1.0, 0.5], [e, e, 0.0]),   // edge midpoint, along the bisector
            ([1.0, 1.0, 1.0], [c, c, c]),     // corner, along the diagonal
        ];
        for (base, offset) in cases {
            for (sign, inside) in [(-1.0, true), (1.0, false)] {
                let p = [
                    (base[0] + sign * offset[0]) as f32,
                    (base[1] + sign * offset[1]) as f32,
                    (base[2] + sign * offset[2]) as f32,
                ];
                let expected = if inside { 1.0 } else { 0.0 };
                let exact = winding_number_exact(&pos, &tri, p);
                assert!((exact - expected).abs() < 1e-6, "exact {exact} at {p:?}");
                assert_eq!(index.is_inside(p), inside, "is_inside at {p:?}");
            }
        }
        for p in [
            [0.5, 0.5, 1.0],
            [1.0, 1.0, 1.0],
            [0.0, 0.0, 0.0],
            [1.0, 0.5, 0.25],
        ] {
            let w = index.winding_number(p);
            let exact = winding_number_exact(&pos, &tri, p);
            assert!(
                w.is_finite() && exact.is_finite(),
                "on-surface winding {w} / {exact} at {p:?}"
            );
            assert!((0.0..=1.0).contains(&w), "on-surface winding {w} at {p:?}");
            assert_eq!(index.distance(p), 0.0);
        }
    }

    #[test]
    fn distance_to_sphere_and_cube_features() {
        let (segments, rings) = (32u32, 16u32);
        let (pos, tri) = uv_sphere(1.0, segments, rings, 0.0);
        let index = SurfaceIndex::new(&pos, &tri);
        // Every edge spans at most π/rings in latitude plus 2π/segments in
        // longitude, so its chord is ≤ L = 2 sin(that/2). A point Σλᵢvᵢ of a triangle
        // inscribed in the unit sphere has |q|² = 1 − Σλᵢλⱼ|vᵢ−vⱼ|² ≥ 1 − L²/3.
        let span = PI / f64::from(rings) + 2.0 * PI / f64::from(segments);
        let chord = 2.0 * (span / 2.0).sin();
        let sagitta = 1.0 - (1.0 - chord * chord / 3.0).sqrt();
        let slack = 1e-6; // f32 rounding of vertices and of the result
        let mut rng = Lcg(11);
        for _ in 0..50 {
            let dir = rng.direction();
            let inner = f64::from(index.distance(scaled(dir, 0.5)));
            let outer = f64::from(index.distance(scaled(dir, 1.5)));
            assert!(
                inner <= 0.5 + slack && inner >= 0.5 - sagitta - slack,
                "inner {inner}"
            );
            assert!(
                outer >= 0.5 - slack && outer <= 0.5 + sagitta + slack,
                "outer {outer}"
            );
        }

        let (pos, tri) = unit_cube();
        let index = SurfaceIndex::new(&pos, &tri);
        let analytic = |p: [f32; 3], nearest: [f64; 3]| (to_vec3(p) - Vec3::from(nearest)).norm();
        let cases: [([f32; 3], [f64; 3]); 5] = [
            ([1.2, 1.1, 0.5], [1.0, 1.0, f64::from(0.5f32)]), // beside the x=y=1 edge
            ([1.1, 1.2, 1.3], [1.0, 1.0, 1.0]),               // beyond the corner
            ([-0.3, 0.4, -0.05], [0.0, f64::from(0.4f32), 0.0]), // beside the x=z=0 edge
            ([-0.01, -0.02, -0.03], [0.0, 0.0, 0.0]),         // near the origin corner
            (
                [0.95, 0.97, 0.5],
                [f64::from(0.95f32), 1.0, f64::from(0.5f32)],
            ), // inside, near the edge
        ];
        for (p, nearest) in cases {
            let d = f64::from(index.distance(p));
            let expected = analytic(p, nearest);
            assert!(
                (d - expected).abs() < 1e-6,
                "distance {d} vs {expected} at {p:?}"
            );
            let c = index.closest_point(p).map(to_vec3);
            assert!(
                c.is_some_and(|c| (c - Vec3::from(nearest)).norm() < 1e-6),
                "closest point {c:?} vs {nearest:?} at {p:?}"
            );
        }
        assert_eq!(SurfaceIndex::new(&[], &[]).closest_point([0.0; 3]), None);
        // Beside a face: on it, with the face's outward normal; beside an edge or a corner: not.
        let face = index.closest([0.5, 0.97, 0.4]).unwrap();
        assert!(face.on_face && face.normal == [0.0, 1.0, 0.0], "{face:?}");
        let outside = index.closest([0.5, 0.4, -0.2]).unwrap();
        assert!(
            outside.on_face && outside.normal == [0.0, 0.0, -1.0],
            "{outside:?}"
        );
        assert!(!index.closest([1.2, 1.1, 0.5]).unwrap().on_face);
        assert!(!index.closest([1.1, 1.2, 1.3]).unwrap().on_face);
        // A lattice sweep reaches every Voronoi region of every triangle (faces,
        // cube edges, face diagonals, corners): outside, the nearest point is the
        // clamp to the cube; inside, the nearest face.
        let coords = [-0.3f32, -0.05, 0.2, 0.5, 0.7, 0.97, 1.1, 1.25];
        for &x in &coords {
            for &y in &coords {
                for &z in &coords {
                    let q = to_vec3([x, y, z]);
                    let clamped = q.map(|c| c.clamp(0.0, 1.0));
                    let expected = if clamped == q {
                        q.iter()
                            .map(|&c| c.min(1.0 - c))
                            .fold(f64::INFINITY, f64::min)
                    } else {
                        (q - clamped).norm()
                    };
                    let d = f64::from(index.distance([x, y, z]));
                    assert!(
                        (d - expected).abs() < 1e-6,
                        "distance {d} vs {expected} at {q:?}"
                    );
                }
            }
        }
        // One triangle, every corner order, so each Voronoi region (face, 3 edges,
        // 3 corners) is met in each role of the region classification.
        let pos = [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let face = |q: Vec3| q.z.abs();
        let edge_ab = |q: Vec3| q.y.hypot(q.z);
        let edge_ac = |q: Vec3| q.x.hypot(q.z);
        let edge_bc = |q: Vec3| ((q.x + q.y - 1.0) / 2f64.sqrt()).hypot(q.z);
        let corner = |k: usize| move |q: Vec3| (q - to_vec3(pos[k])).norm();
        type Analytic<'a> = &'a dyn Fn(Vec3) -> f64;
        let cases: [([f32; 3], Analytic); 7] = [
            ([0.2, 0.3, 0.5], &face),
            ([0.5, -0.4, 0.3], &edge_ab),
            ([-0.4, 0.5, -0.3], &edge_ac),
            ([0.8, 0.8, 0.3], &edge_bc),
            ([-0.3, -0.4, 0.0], &corner(0)),
            ([1.3, -0.4, 0.2], &corner(1)),
            ([-0.2, 1.3, -0.2], &corner(2)),
        ];
        for order in [
            [0, 1, 2],
            [1, 2, 0],
            [2, 0, 1],
            [0, 2, 1],
            [2, 1, 0],
            [1, 0, 2],
        ] {
            let index = SurfaceIndex::new(&pos, &[order]);
            for (p, analytic) in &cases {
                let d = f64::from(index.distance(*p));
                let expected = analytic(to_vec3(*p));
                assert!(
                    (d - expected).abs() < 1e-6,
                    "distance {d} vs {expected} at {p:?}, corners {order:?}"
                );
            }
        }
        let empty = SurfaceIndex::new(&[], &[]);
        assert_eq!(empty.distance([0.0; 3]), f32::INFINITY);
        assert_eq!(empty.winding_number([0.0; 3]), 0.0);
    }

    #[test]
    fn building_twice_gives_identical_results() {
        let (pos, tri) = uv_sphere(1.0, 48, 24, 0.1);
        let mut rng = Lcg(3);
        let points: Vec<[f32; 3]> = (0..400)
            .map(|_| {
                [
                    rng.range(-1.5, 1.5) as f32,
                    rng.range(-1.5, 1.5) as f32,
                    rng.range(-1.5, 1.5) as f32,
                ]
            })
            .collect();
        let first = SurfaceIndex::new(&pos, &tri).query_many(&points);
        let second = SurfaceIndex::new(&pos, &tri).query_many(&points);
        let serial = SurfaceIndex::new(&pos, &tri);
        for (i, p) in points.iter().enumerate() {
            assert_eq!(
                first[i].0.to_bits(),
                second[i].0.to_bits(),
                "winding at {p:?}"
            );
            assert_eq!(
                first[i].1.to_bits(),
                second[i].1.to_bits(),
                "distance at {p:?}"
            );
            assert_eq!(first[i].0.to_bits(), serial.winding_number(*p).to_bits());
            assert_eq!(first[i].1.to_bits(), serial.distance(*p).to_bits());
        }
    }

    #[test]
    fn bad_input_is_skipped_not_fatal() {
        let (pos, mut tri) = unit_cube();
        tri.push([0, 1, 99]); // out of range
        tri.push([0, 0, 1]); // zero area
        let mut pos_nan = pos.clone();
        pos_nan.push([f32::NAN, 0.0, 0.0]);
        tri.push([0, 1, 8]); // non-finite corner
        let index = SurfaceIndex::new(&pos_nan, &tri);
        assert!((index.winding_number([0.5, 0.5, 0.5]) - 1.0).abs() < 1e-9);
        assert!((winding_number_exact(&pos_nan, &tri, [0.5, 0.5, 0.5]) - 1.0).abs() < 1e-9);
        assert!((index.distance([0.5, -0.5, 0.0]) - 0.5).abs() < 1e-6);
    }

    #[test]
    fn speed_sanity() {
        let (pos, tri) = uv_sphere(0.3, 140, 100, 0.15);
        let mut rng = Lcg(5);
        let points: Vec<[f32; 3]> = (0..3000)
            .map(|_| {
                [
                    rng.range(-0.5, 0.5) as f32,
                    rng.range(-0.5, 0.5) as f32,
                    rng.range(-0.5, 0.5) as f32,
                ]
            })
            .collect();
        let t0 = Instant::now();
        let index = SurfaceIndex::new(&pos, &tri);
        let build = t0.elapsed();
        let t1 = Instant::now();
        let serial: Vec<(f64, f32)> = points
            .iter()
            .map(|&p| (index.winding_number(p), index.distance(p)))
            .collect();
        let single = t1.elapsed();
        let t2 = Instant::now();
        let parallel = index.query_many(&points);
        let many = t2.elapsed();
        // Parallel results must be the serial ones, bit for bit and in order.
        assert_eq!(serial.len(), parallel.len());
        for (s, q) in serial.iter().zip(&parallel) {
            assert_eq!(
                (s.0.to_bits(), s.1.to_bits()),
                (q.0.to_bits(), q.1.to_bits())
            );
        }
        assert!(index.is_inside([0.0; 3]) && !index.is_inside([0.5; 3]));
        let t3 = Instant::now();
        for &p in &points {
            std::hint::black_box(index.winding_number(p));
        }
        let winding = t3.elapsed();
        let t4 = Instant::now();
        for &p in &points {
            std::hint::black_box(index.distance(p));
        }
        let distance = t4.elapsed();
        let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
        println!(
            "speed: {} vertices, {} triangles: build {:.2} ms; 3000 queries on one thread {:.2} ms \
             (winding alone {:.2} ms, distance alone {:.2} ms); query_many {:.2} ms ({} threads)",
            pos.len(),
            tri.len(),
            ms(build),
            ms(single),
            ms(winding),
            ms(distance),
            ms(many),
            rayon::current_num_threads()
        );
    }
}
