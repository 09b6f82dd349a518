//! Edge connectivity: unique edges, hinges (for bending), boundaries and non-manifold edges.

use crate::geometry::edges::sorted_pair;
use crate::geometry::mesh::TriMesh;

/// Two triangles sharing an interior edge; the unit of the bending energy.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Hinge {
    /// The shared edge, as a sorted pair.
    pub edge: [u32; 2],
    /// The two triangles, in increasing index order.
    pub faces: [u32; 2],
    /// The vertex of each face opposite the edge (`opposite[i]` belongs to `faces[i]`).
    pub opposite: [u32; 2],
}

/// Edge-based connectivity of a triangle mesh. Everything is sorted, so it is deterministic.
#[derive(Clone, Debug, PartialEq)]
pub struct Topology {
    /// Unique undirected edges as sorted pairs `[lo, hi]`, in increasing order.
    pub edges: Vec<[u32; 2]>,
    /// One hinge per edge shared by exactly two triangles, in edge order.
    pub hinges: Vec<Hinge>,
    /// Edges used by exactly one triangle, in edge order, each *directed as in its triangle's
    /// winding* (so walking them follows the boundary consistently with the surface).
    pub boundary_edges: Vec<[u32; 2]>,
    /// Edges used by three or more triangles (sorted pairs, in edge order). They get no hinge.
    pub non_manifold_edges: Vec<[u32; 2]>,
}

/// One triangle's use of an edge: the sort key plus what a hinge or boundary needs.
#[derive(Clone, Copy)]
struct EdgeUse {
    key: [u32; 2],
    face: u32,
    opposite: u32,
    directed: [u32; 2],
}

impl Topology {
    /// Connectivity of `mesh`'s triangles (positions are not looked at).
    pub fn new(mesh: &TriMesh) -> Topology {
        let uses = sorted_edge_uses(&mesh.triangles);
        let mut topo = Topology {
            edges: Vec::new(),
            hinges: Vec::new(),
            boundary_edges: Vec::new(),
            non_manifold_edges: Vec::new(),
        };
        for group in uses.chunk_by(|a, b| a.key == b.key) {
            let key = group[0].key;
            topo.edges.push(key);
            match group {
                [single] => topo.boundary_edges.push(single.directed),
                [f0, f1] => topo.hinges.push(Hinge {
                    edge: key,
                    faces: [f0.face, f1.face],
                    opposite: [f0.opposite, f1.opposite],
                }),
                _ => topo.non_manifold_edges.push(key),
            }
        }
        topo
    }

    /// Whether every edge has at most two triangles.
    pub fn is_manifold(&self) -> bool {
        self.non_manifold_edges.is_empty()
    }

    /// Index of the undirected edge `(a, b)` in [`Topology::edges`].
    pub fn edge_index(&self, a: u32, b: u32) -> Option<usize> {
        self.edges.binary_search(&sorted_pair(a, b)).ok()
    }

    /// The boundary as closed loops of vertex indices (the first vertex is not repeated at the
    /// end). Each loop starts at the first unused boundary edge and runs in that edge's winding
    /// direction; at a vertex with several boundary edges (a "bow-tie") the lowest-numbered
    /// unused edge is taken. A chain that cannot be closed (only possible on broken meshes) is
    /// returned open, as it was walked.
    pub fn boundary_loops(&self) -> Vec<Vec<u32>> {
        let incident = self.boundary_incidence();
        let mut used = vec![false; self.boundary_edges.len()];
        let mut loops = Vec::new();
        for start in 0..self.boundary_edges.len() {
            if used[start] {
                continue;
            }
            used[start] = true;
            let [first, mut current] = self.boundary_edges[start];
            let mut chain = vec![first];
            while current != first {
                chain.push(current);
                let next = incident_edges(&incident, current)
                    .iter()
                    .map(|&(_, e)| e as usize)
                    .find(|&e| !used[e]);
                let Some(e) = next else { break };
                used[e] = true;
                let [a, b] = self.boundary_edges[e];
                current = if a == current { b } else { a };
            }
            loops.push(chain);
        }
        loops
    }

    /// Sorted neighbour lists (vertices sharing an edge) for `n_vertices` vertices.
    pub fn vertex_neighbors(&self, n_vertices: usize) -> Vec<Vec<u32>> {
        let mut neighbors = vec![Vec::new(); n_vertices];
        for &[a, b] in &self.edges {
            neighbors[a as usize].push(b);
            neighbors[b as usize].push(a);
        }
        for list in &mut neighbors {
            list.sort_unstable();
        }
        neighbors
    }

    /// `(vertex, boundary edge index)` for both ends of each boundary edge, sorted.
    fn boundary_incidence(&self) -> Vec<(u32, u32)> {
        let mut incident: Vec<(u32, u32)> = self
            .boundary_edges
            .iter()
            .enumerate()
            .flat_map(|(i, &[a, b])| [(a, i as u32), (b, i as u32)])
            .collect();
        incident.sort_unstable();
        incident
    }
}

/// The slice of a sorted incidence list belonging to `vertex`.
fn incident_edges(incident: &[(u32, u32)], vertex: u32) -> &[(u32, u32)] {
    let lo = incident.partition_point(|&(v, _)| v < vertex);
    let hi = incident.partition_point(|&(v, _)| v <= vertex);
    &incident[lo..hi]
}

/// Every (triangle, edge) incidence, sorted by edge then face, so equal edges are adjacent.
fn sorted_edge_uses(triangles: &[[u32; 3]]) -> Vec<EdgeUse> {
    let mut uses = Vec::with_capacity(triangles.len() * 3);
    for (f, &[a, b, c]) in triangles.iter().enumerate() {
        for (u, v, opposite) in [(a, b, c), (b, c, a), (c, a, b)] {
            uses.push(EdgeUse {
                key: sorted_pair(u, v),
                face: f as u32,
                opposite,
                directed: [u, v],
            });
        }
    }
    uses.sort_unstable_by_key(|e| (e.key, e.face));
    uses
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::test_meshes::{grid, uv_sphere};

    #[test]
    fn grid_counts() {
        // A w×h quad grid split into triangles: V - E + F = 1 for a disc.
        let (w, h) = (4, 3);
        let m = grid(w, h, 1.0);
        let t = Topology::new(&m);
        let v = (w + 1) * (h + 1);
        let f = 2 * w * h;
        assert_eq!(v as i64 - t.edges.len() as i64 + f as i64, 1);
        assert_eq!(t.boundary_edges.len(), 2 * (w + h));
        assert_eq!(t.hinges.len(), t.edges.len() - t.boundary_edges.len());
        assert!(t.is_manifold());
        assert!(t.edges.windows(2).all(|w| w[0] < w[1]));
        assert!(t.edges.iter().all(|e| e[0] < e[1]));
    }

    #[test]
    fn hinges_name_faces_and_opposites() {
        let m = grid(1, 1, 1.0); // triangles [0,1,3] and [0,3,2]
        let t = Topology::new(&m);
        assert_eq!(
            t.hinges,
            vec![Hinge {
                edge: [0, 3],
                faces: [0, 1],
                opposite: [1, 2]
            }]
        );
        assert_eq!(t.edge_index(3, 0), Some(2));
        assert_eq!(t.edge_index(1, 2), None);
    }

    #[test]
    fn boundary_loop_of_a_grid_follows_the_winding() {
        let m = grid(2, 2, 1.0);
        let loops = Topology::new(&m).boundary_loops();
        assert_eq!(loops.len(), 1);
        // Counter-clockwise seen from +z, since the grid's triangles face +z.
        assert_eq!(loops[0], vec![0, 1, 2, 5, 8, 7, 6, 3]);
    }

    #[test]
    fn closed_sphere_has_no_boundary_and_annulus_has_two() {
        let sphere = uv_sphere(8, 6);
        let t = Topology::new(&sphere);
        assert!(t.boundary_edges.is_empty() && t.is_manifold());
        assert_eq!(t.hinges.len(), t.edges.len());
        // Drop both pole caps: an open tube with two boundary loops of 8 vertices each.
        let poles = [0u32, sphere.vertex_count() as u32 - 1];
        let (tube, _) = sphere.submesh(|v| !poles.contains(&v));
        let loops = Topology::new(&tube).boundary_loops();
        assert_eq!(loops.len(), 2);
        assert!(loops.iter().all(|l| l.len() == 8));
    }

    #[test]
    fn non_manifold_fin_is_reported() {
        let mut m = grid(1, 1, 1.0);
        m.positions.push([0.5, 0.5, 1.0]);
        m.triangles.push([0, 3, 4]); // a third face on edge (0, 3)
        let t = Topology::new(&m);
        assert_eq!(t.non_manifold_edges, vec![[0, 3]]);
        assert!(t.hinges.is_empty());
        assert!(!t.is_manifold());
    }

    #[test]
    fn neighbors_are_sorted_and_symmetric() {
        let m = grid(2, 2, 1.0);
        let nb = Topology::new(&m).vertex_neighbors(m.vertex_count());
        assert_eq!(nb[4], vec![0, 1, 3, 5, 7, 8]);
        for (v, list) in nb.iter().enumerate() {
            for &u in list {
                assert!(nb[u as usize].contains(&(v as u32)));
            }
        }
    }
}
