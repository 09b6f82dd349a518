//! Skeleton: named joints, parents before children, rest transforms local to the parent and
//! inverse bind matrices (world → joint at bind time), as in UsdSkel and glTF skins.

use super::RigError;
use nalgebra::{Matrix4, Quaternion, UnitQuaternion, Vector3};

/// A joint's local transform (scale kept for completeness; our rigs do not scale).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointTransform {
    pub translation: Vector3<f32>,
    pub rotation: UnitQuaternion<f32>,
    pub scale: Vector3<f32>,
}

impl JointTransform {
    pub fn from_translation(t: Vector3<f32>) -> Self {
        JointTransform {
            translation: t,
            rotation: UnitQuaternion::identity(),
            scale: Vector3::repeat(1.0),
        }
    }

    pub fn to_matrix(&self) -> Matrix4<f32> {
        let mut m = self.rotation.to_homogeneous();
        for c in 0..3 {
            for r in 0..3 {
                m[(r, c)] *= self.scale[c];
            }
        }
        m.fixed_view_mut::<3, 1>(0, 3).copy_from(&self.translation);
        m
    }
}

/// A skeleton as plain arrays, the way files store it (model metadata, baked assets): the
/// exporter-neutral type, so both read the same fields.
pub use exporters::asset::Skeleton as PlainSkeleton;

#[derive(Clone, Debug, PartialEq)]
pub struct Skeleton {
    pub joint_names: Vec<String>,
    pub parents: Vec<Option<usize>>,
    pub rest: Vec<JointTransform>,
    pub inverse_bind: Vec<Matrix4<f32>>,
}

impl Skeleton {
    /// Plain arrays (unit scale is implied: our rigs do not scale).
    pub fn to_plain(&self) -> PlainSkeleton {
        PlainSkeleton {
            joint_names: self.joint_names.clone(),
            parents: self.parents.clone(),
            rest_translations: self.rest.iter().map(|r| r.translation.into()).collect(),
            rest_rotations: self.rest.iter().map(|r| r.rotation.coords.into()).collect(),
            inverse_bind_matrices: self
                .inverse_bind
                .iter()
                .map(|m| m.as_slice().try_into().expect("4x4"))
                .collect(),
        }
    }

    /// The skeleton of [`Skeleton::to_plain`], checked like [`Skeleton::new`].
    pub fn from_plain(plain: &PlainSkeleton) -> Result<Skeleton, RigError> {
        let rest = plain
            .rest_translations
            .iter()
            .zip(&plain.rest_rotations)
            .map(|(t, r)| JointTransform {
                translation: Vector3::from(*t),
                rotation: UnitQuaternion::from_quaternion(Quaternion::new(r[3], r[0], r[1], r[2])),
                scale: Vector3::repeat(1.0),
            })
            .collect();
        let ibm = plain
            .inverse_bind_matrices
            .iter()
            .map(|m| Matrix4::from_column_slice(m))
            .collect();
        Skeleton::new(plain.joint_names.clone(), plain.parents.clone(), rest, ibm)
    }

    /// Checks the invariants every consumer relies on: equal lengths, unique names, parents first.
    pub fn new(
        joint_names: Vec<String>,
        parents: Vec<Option<usize>>,
        rest: Vec<JointTransform>,
        inverse_bind: Vec<Matrix4<f32>>,
    ) -> Result<Self, RigError> {
        let n = joint_names.len();
        if parents.len() != n || rest.len() != n || inverse_bind.len() != n {
            return Err(RigError::Invalid(format!(
                "skeleton arrays disagree on the joint count ({n})"
            )));
        }
        if n == 0 {
            return Err(RigError::Invalid("skeleton has no joints".into()));
        }
        for (j, p) in parents.iter().enumerate() {
            if p.is_some_and(|p| p >= j) {
                return Err(RigError::Invalid(format!(
                    "joint '{}' comes before its parent",
                    joint_names[j]
                )));
            }
        }
        let mut seen = std::collections::HashSet::new();
        if let Some(dup) = joint_names.iter().find(|n| !seen.insert(n.as_str())) {
            return Err(RigError::Invalid(format!(
                "joint name '{dup}' appears twice"
            )));
        }
        Ok(Skeleton {
            joint_names,
            parents,
            rest,
            inverse_bind,
        })
    }

    /// Builds a skeleton from rest world positions only (joint frames aligned with the world axes),
    /// sorting joints so that parents come first. `parents` index into the input order.
    pub fn from_world_positions(
        names: &[String],
        parents: &[Option<usize>],
        world: &[Vector3<f32>],
    ) -> Result<Self, RigError> {
        let order = topological_order(parents)
            .ok_or_else(|| RigError::Invalid("joint parents form a cycle".into()))?;
        let mut new_index = vec![0; names.len()];
        for (new, &old) in order.iter().enumerate() {
            new_index[old] = new;
        }
        let joint_names = order.iter().map(|&o| names[o].clone()).collect();
        let new_parents: Vec<_> = order
            .iter()
            .map(|&o| parents[o].map(|p| new_index[p]))
            .collect();
        let rest = order
            .iter()
            .map(|&o| {
                JointTransform::from_translation(
                    world[o] - parents[o].map_or(Vector3::zeros(), |p| world[p]),
                )
            })
            .collect();
        let inverse_bind = order
            .iter()
            .map(|&o| Matrix4::new_translation(&-world[o]))
            .collect();
        Skeleton::new(joint_names, new_parents, rest, inverse_bind)
    }

    pub fn joint_count(&self) -> usize {
        self.joint_names.len()
    }

    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joint_names.iter().position(|n| n == name)
    }

    pub fn children(&self, joint: usize) -> impl Iterator<Item = usize> + '_ {
        self.parents
            .iter()
            .enumerate()
            .filter(move |(_, p)| **p == Some(joint))
            .map(|(c, _)| c)
    }

    /// Forward kinematics: world matrix of every joint for the given local transforms.
    pub fn world_matrices(&self, local: &[JointTransform]) -> Vec<Matrix4<f32>> {
        let mut world: Vec<Matrix4<f32>> = Vec::with_capacity(local.len());
        for (j, l) in local.iter().enumerate() {
            let m = l.to_matrix();
            world.push(match self.parents[j] {
                Some(p) => world[p] * m,
                None => m,
            });
        }
        world
    }

    pub fn rest_world(&self) -> Vec<Matrix4<f32>> {
        self.world_matrices(&self.rest)
    }

    /// World matrix × inverse bind: what linear blend skinning applies to rest points.
    pub fn skinning_matrices(&self, local: &[JointTransform]) -> Vec<Matrix4<f32>> {
        self.world_matrices(local)
            .iter()
            .zip(&self.inverse_bind)
            .map(|(w, ib)| w * ib)
            .collect()
    }

    /// True when both skeletons have the same joints in the same order with the same parents.
    pub fn same_topology(&self, other: &Skeleton) -> bool {
        self.joint_names == other.joint_names && self.parents == other.parents
    }
}

/// Parents-first order, stable with respect to the input order (deterministic output).
pub fn topological_order(parents: &[Option<usize>]) -> Option<Vec<usize>> {
    let n = parents.len();
    let mut placed = vec![false; n];
    let mut order = Vec::with_capacity(n);
    while order.len() < n {
        let before = order.len();
        for j in 0..n {
            if !placed[j] && parents[j].is_none_or(|p| placed[p]) {
                placed[j] = true;
                order.push(j);
            }
        }
        if order.len() == before {
            return None;
        }
    }
    Some(order)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chain() -> Skeleton {
        let names: Vec<String> = ["b", "a", "c"].iter().map(|s| s.to_string()).collect();
        // input order: b's parent is a, a is root, c's parent is b.
        let parents = [Some(1), None, Some(0)];
        let world = [
            Vector3::new(0.0, 1.0, 0.0),
            Vector3::zeros(),
            Vector3::new(0.0, 2.0, 0.0),
        ];
        Skeleton::from_world_positions(&names, &parents, &world).unwrap()
    }

    #[test]
    fn sorts_parents_first_and_binds_at_rest() {
        let s = chain();
        assert_eq!(s.joint_names, ["a", "b", "c"]);
        assert_eq!(s.parents, [None, Some(0), Some(1)]);
        for m in s.skinning_matrices(&s.rest) {
            assert!((m - Matrix4::identity()).norm() < 1e-6);
        }
    }

    #[test]
    fn fk_rotates_children_about_parent() {
        let s = chain();
        let mut pose = s.rest.clone();
        pose[1].rotation =
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f32::consts::FRAC_PI_2);
        let world = s.world_matrices(&pose);
        let tip = world[2].transform_point(&nalgebra::Point3::origin());
        // c sits 1 above b; rotating b by 90° about z swings it to -x.
        assert!(
            (tip.coords - Vector3::new(-1.0, 1.0, 0.0)).norm() < 1e-6,
            "{tip}"
        );
    }

    #[test]
    fn rejects_cycles_and_duplicates() {
        let names: Vec<String> = ["a", "b"].iter().map(|s| s.to_string()).collect();
        assert!(Skeleton::from_world_positions(
            &names,
            &[Some(1), Some(0)],
            &[Vector3::zeros(); 2]
        )
        .is_err());
        let dup: Vec<String> = ["a", "a"].iter().map(|s| s.to_string()).collect();
        assert!(
            Skeleton::from_world_positions(&dup, &[None, Some(0)], &[Vector3::zeros(); 2]).is_err()
        );
    }
}
