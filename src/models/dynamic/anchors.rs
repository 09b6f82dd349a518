//! Body anchor points: where the dynamic model measures the garment from and what skins it.
//! Farthest-point sampling (Euclidean, on the rest body's vertices near the garment: anchors far
//! from every garment vertex would carry no weight), each anchor labelled with a body part by its
//! dominant joint; one learnable kernel radius per part.

use crate::body::Body;
use crate::geometry::PointIndex;
use anyhow::{bail, Result};
use nalgebra::Matrix4;

/// Body parts with their own kernel radius (left and right share one).
pub const PARTS: [&str; 7] = [
    "torso",
    "thigh",
    "calf",
    "foot",
    "upper arm",
    "forearm",
    "hand",
];

/// The part a joint name belongs to (CMU / MakeHuman naming).
pub fn part_of(joint: &str) -> usize {
    let j = joint.to_ascii_lowercase();
    let has = |s: &str| j.contains(s);
    if has("upleg") {
        1
    } else if has("toe") || has("foot") {
        3
    } else if has("leg") {
        2
    } else if has("forearm") {
        5
    } else if has("hand") || has("finger") || has("thumb") {
        6
    } else if has("arm") {
        4
    } else {
        0
    }
}

/// The anchors: body vertex, rest position, part.
#[derive(Clone, Debug, PartialEq)]
pub struct BodyAnchors {
    pub vertices: Vec<u32>,
    pub rest: Vec<[f32; 3]>,
    pub parts: Vec<usize>,
}

impl BodyAnchors {
    /// `count` anchors by farthest-point sampling over the body vertices within `reach` metres of
    /// the garment at rest, starting from the one nearest the garment's centroid.
    pub fn sample(
        body: &Body,
        garment: &[[f32; 3]],
        count: usize,
        reach: f32,
    ) -> Result<BodyAnchors> {
        let index = PointIndex::new(garment)?;
        let near: Vec<u32> = (0..body.mesh().vertex_count() as u32)
            .filter(|&v| index.nearest(body.mesh().positions[v as usize]).1 <= reach)
            .collect();
        if near.len() < count {
            bail!("only {} body vertices lie within {reach} m of the garment, {count} seeds asked for", near.len());
        }
        let p = |v: u32| nalgebra::Vector3::from(body.mesh().positions[v as usize]);
        let n = garment.len() as f32;
        let centroid = garment.iter().fold(nalgebra::Vector3::zeros(), |a, g| {
            a + nalgebra::Vector3::from(*g) / n
        });
        let first = *near
            .iter()
            .min_by(|&&a, &&b| {
                (p(a) - centroid)
                    .norm()
                    .total_cmp(&(p(b) - centroid).norm())
            })
            .expect("non-empty");
        let mut chosen = vec![first];
        let mut gap: Vec<f32> = near.iter().map(|&v| (p(v) - p(first)).norm()).collect();
        while chosen.len() < count {
            let (k, _) = gap
                .iter()
                .enumerate()
                .max_by(|a, b| a.1.total_cmp(b.1))
                .expect("non-empty");
            let next = near[k];
            chosen.push(next);
            for (g, &v) in gap.iter_mut().zip(&near) {
                *g = g.min((p(v) - p(next)).norm());
            }
        }
        let parts = chosen
            .iter()
            .map(|&v| {
                let (j, _) = body
                    .skin
                    .vertex(v as usize)
                    .max_by(|a, b| a.1.total_cmp(&b.1))
                    .expect("skinned");
                part_of(&body.skeleton.joint_names[j])
            })
            .collect();
        Ok(BodyAnchors {
            rest: chosen
                .iter()
                .map(|&v| body.mesh().positions[v as usize])
                .collect(),
            vertices: chosen,
            parts,
        })
    }

    /// Anchors stored by body vertex (a model file's), checked against the body.
    pub fn from_vertices(body: &Body, vertices: &[u32], parts: &[usize]) -> Result<BodyAnchors> {
        let rest = vertices
            .iter()
            .map(|&v| body.mesh().positions.get(v as usize).copied())
            .collect::<Option<Vec<_>>>();
        match rest {
            Some(rest)
                if parts.len() == vertices.len() && parts.iter().all(|&p| p < PARTS.len()) =>
            {
                Ok(BodyAnchors {
                    vertices: vertices.to_vec(),
                    rest,
                    parts: parts.to_vec(),
                })
            }
            _ => bail!(
                "seed vertices or parts do not fit the body ({} vertices)",
                body.mesh().vertex_count()
            ),
        }
    }

    /// Each anchor's LBS transform (rows 0..3 of the blended skinning matrix, row-major 3×4).
    pub fn transforms(&self, body: &Body, skinning: &[Matrix4<f32>]) -> Vec<[f32; 12]> {
        self.vertices
            .iter()
            .map(|&v| {
                let m = body.skin.blended(v as usize, skinning);
                std::array::from_fn(|k| m[(k / 4, k % 4)])
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn joints_map_to_parts() {
        let names = [
            "Hips",
            "LeftUpLeg",
            "RightLeg",
            "LeftFoot",
            "RightToeBase",
            "LeftArm",
            "RightForeArm",
            "LeftHand",
            "RightHandFinger1",
            "Spine1",
            "LHipJoint",
        ];
        let parts: Vec<&str> = names.iter().map(|n| PARTS[part_of(n)]).collect();
        assert_eq!(
            parts,
            [
                "torso",
                "thigh",
                "calf",
                "foot",
                "foot",
                "upper arm",
                "forearm",
                "hand",
                "hand",
                "torso",
                "torso"
            ]
        );
    }
}
