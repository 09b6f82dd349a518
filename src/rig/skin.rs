//! Linear blend skinning with a fixed number of influences per vertex (UsdSkel jointIndices /
//! jointWeights, vertex-major), and the top-k pruning that keeps skins playable in engines.

use nalgebra::{Matrix4, Point3, Vector3};

#[derive(Clone, Debug, PartialEq)]
pub struct Skin {
    pub influences: usize,
    pub joint_indices: Vec<u16>,
    pub joint_weights: Vec<f32>,
}

impl Skin {
    /// Keeps the `influences` largest weights per vertex and renormalises them to sum to 1
    /// (empty slots: joint 0, weight 0). A vertex with no weight at all binds to `fallback_joint`.
    pub fn from_sparse(
        per_vertex: &[Vec<(u16, f32)>],
        influences: usize,
        fallback_joint: u16,
    ) -> Skin {
        let mut joint_indices = Vec::with_capacity(per_vertex.len() * influences);
        let mut joint_weights = Vec::with_capacity(per_vertex.len() * influences);
        for list in per_vertex {
            let mut list: Vec<(u16, f32)> =
                list.iter().copied().filter(|(_, w)| *w > 0.0).collect();
            // Largest first; ties broken by joint index so the result is deterministic.
            list.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
            list.truncate(influences);
            if list.is_empty() {
                list.push((fallback_joint, 1.0));
            }
            let weights = normalized(&list.iter().map(|(_, w)| *w).collect::<Vec<_>>());
            for (&(j, _), &w) in list.iter().zip(&weights) {
                joint_indices.push(j);
                joint_weights.push(w);
            }
            for _ in list.len()..influences {
                joint_indices.push(0);
                joint_weights.push(0.0);
            }
        }
        Skin {
            influences,
            joint_indices,
            joint_weights,
        }
    }

    /// The skin of the vertices `subset` (in that order).
    pub fn subset(&self, subset: &[u32]) -> Skin {
        fn rows<T: Copy>(v: &[T], subset: &[u32], k: usize) -> Vec<T> {
            subset
                .iter()
                .flat_map(|&s| v[s as usize * k..(s as usize + 1) * k].iter().copied())
                .collect()
        }
        let k = self.influences;
        Skin {
            influences: k,
            joint_indices: rows(&self.joint_indices, subset, k),
            joint_weights: rows(&self.joint_weights, subset, k),
        }
    }

    pub fn vertex_count(&self) -> usize {
        self.joint_indices.len() / self.influences.max(1)
    }

    /// `(joint, weight)` pairs of one vertex, zero weights included.
    pub fn vertex(&self, v: usize) -> impl Iterator<Item = (usize, f32)> + '_ {
        let r = v * self.influences..(v + 1) * self.influences;
        self.joint_indices[r.clone()]
            .iter()
            .zip(&self.joint_weights[r])
            .map(|(&j, &w)| (j as usize, w))
    }

    /// Dense `[vertex][joint]` weights pruned to the `influences` largest per vertex.
    pub fn from_dense(weights: &[Vec<f32>], influences: usize) -> Skin {
        let sparse: Vec<Vec<(u16, f32)>> = weights
            .iter()
            .map(|w| {
                w.iter()
                    .enumerate()
                    .filter(|(_, &x)| x > 0.0)
                    .map(|(j, &x)| (j as u16, x))
                    .collect()
            })
            .collect();
        Skin::from_sparse(&sparse, influences, 0)
    }

    /// Blended skinning matrix of vertex `v`.
    pub fn blended(&self, v: usize, skinning: &[Matrix4<f32>]) -> Matrix4<f32> {
        let mut m = Matrix4::zeros();
        for (j, w) in self.vertex(v) {
            if w != 0.0 {
                m += skinning[j] * w;
            }
        }
        m
    }

    /// Rest normals carried by the blended rotation part (renormalised); the file's smooth
    /// normals survive UV-seam splits, which recomputing from the posed faces would not.
    pub fn skin_normals(&self, normals: &[[f32; 3]], skinning: &[Matrix4<f32>]) -> Vec<[f32; 3]> {
        normals
            .iter()
            .enumerate()
            .map(|(v, n)| {
                let m = self.blended(v, skinning);
                let q = m.fixed_view::<3, 3>(0, 0) * Vector3::from(*n);
                let q = q / q.norm().max(f32::MIN_POSITIVE);
                [q.x, q.y, q.z]
            })
            .collect()
    }

    /// Linear blend skinning: `Σ w_j M_j p` for every rest point.
    pub fn skin_points(&self, rest: &[[f32; 3]], skinning: &[Matrix4<f32>]) -> Vec<[f32; 3]> {
        rest.iter()
            .enumerate()
            .map(|(v, p)| {
                let q = self.blended(v, skinning).transform_point(&Point3::from(*p));
                [q.x, q.y, q.z]
            })
            .collect()
    }
}

/// Renormalises so the f32 sum is 1 as exactly as f32 allows (validators check the sum).
fn normalized(weights: &[f32]) -> Vec<f32> {
    let total: f64 = weights.iter().map(|&w| w as f64).sum();
    let mut out: Vec<f32> = weights.iter().map(|&w| (w as f64 / total) as f32).collect();
    let rest: f32 = out[1..].iter().sum();
    out[0] = 1.0 - rest;
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_top_weights_and_normalises() {
        let skin = Skin::from_sparse(
            &[
                vec![(3, 0.1), (1, 0.5), (2, 0.3), (4, 0.05), (5, 0.05)],
                vec![],
            ],
            4,
            7,
        );
        let v0: Vec<_> = skin.vertex(0).collect();
        assert_eq!(v0.iter().map(|x| x.0).collect::<Vec<_>>(), [1, 2, 3, 4]);
        assert!((v0.iter().map(|x| x.1).sum::<f32>() - 1.0).abs() < 1e-7);
        assert_eq!(
            skin.vertex(1).collect::<Vec<_>>(),
            [(7, 1.0), (0, 0.0), (0, 0.0), (0, 0.0)]
        );
    }

    #[test]
    fn blends_matrices_linearly() {
        let skin = Skin::from_sparse(&[vec![(0, 0.5), (1, 0.5)]], 2, 0);
        let m = [
            Matrix4::identity(),
            Matrix4::new_translation(&Vector3::new(2.0, 0.0, 0.0)),
        ];
        assert_eq!(
            skin.skin_points(&[[0.0, 1.0, 0.0]], &m),
            vec![[1.0, 1.0, 0.0]]
        );
    }
}
