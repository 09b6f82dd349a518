//! A glTF evaluated as the spec says, independently of the code that wrote it: animation
//! samplers (STEP, LINEAR with slerp for rotations, CUBICSPLINE), node TRS down the hierarchy,
//! morph targets added to the base positions, then skinning by
//! `Σ w · world(joint) · inverseBind` (the skinned node's own transform is ignored, §3.7.3.3).
//! Runs only on documents whose structure passed, so indices and counts are trusted.

use super::accessor::Values;
use super::container::Document;
use super::structure::Accessors;
use gltf::json;
use json::animation::{Interpolation, Property};
use json::validation::Checked::Valid;
use nalgebra::{Matrix4, Quaternion, Translation3, UnitQuaternion, Vector3};

/// What is needed to pose one mesh node at any time of one animation.
pub struct Scene<'a> {
    doc: &'a Document,
    accessors: &'a Accessors,
    parents: Vec<Option<usize>>,
}

/// A node's local transform as the spec composes it: T · R · S (or its matrix).
#[derive(Clone, Copy)]
struct Trs {
    t: Vector3<f64>,
    r: UnitQuaternion<f64>,
    s: Vector3<f64>,
    matrix: Option<Matrix4<f64>>,
}

impl Trs {
    fn of(node: &json::Node) -> Trs {
        let v = |a: [f32; 3]| Vector3::new(a[0] as f64, a[1] as f64, a[2] as f64);
        Trs {
            t: node.translation.map_or(Vector3::zeros(), v),
            r: node
                .rotation
                .map_or(UnitQuaternion::identity(), |q| quat(&q.0.map(f64::from))),
            s: node.scale.map_or(Vector3::repeat(1.0), v),
            matrix: node
                .matrix
                .map(|m| Matrix4::from_column_slice(&m.map(f64::from))),
        }
    }

    fn matrix(&self) -> Matrix4<f64> {
        self.matrix.unwrap_or_else(|| {
            Translation3::from(self.t).to_homogeneous()
                * self.r.to_homogeneous()
                * Matrix4::new_nonuniform_scaling(&self.s)
        })
    }
}

/// `[x, y, z, w]` → unit quaternion (renormalised: the structure check allows small drift).
fn quat(q: &[f64]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(Quaternion::new(q[3], q[0], q[1], q[2]))
}

impl<'a> Scene<'a> {
    pub fn new(doc: &'a Document, accessors: &'a Accessors) -> Scene<'a> {
        let mut parents = vec![None; doc.root.nodes.len()];
        for (n, node) in doc.root.nodes.iter().enumerate() {
            for c in node.children.iter().flatten() {
                parents[c.value()] = Some(n);
            }
        }
        Scene {
            doc,
            accessors,
            parents,
        }
    }

    fn values(&self, index: json::Index<json::Accessor>) -> Option<&Values> {
        self.accessors.get(index.value())?.as_ref().ok()
    }

    /// The animation's keys: times of its first sampler (all of ours share one input).
    pub fn times(&self, animation: usize) -> Vec<f64> {
        let anim = &self.doc.root.animations[animation];
        anim.samplers
            .first()
            .and_then(|s| self.values(s.input))
            .map_or_else(Vec::new, |v| v.data.clone())
    }

    /// World positions of every vertex of `node`'s mesh (primitives in order) at time `t` of
    /// `animation` (`None`: the rest pose).
    pub fn positions(&self, node: usize, animation: Option<usize>, t: f64) -> Vec<[f64; 3]> {
        let root = &self.doc.root;
        let mut local: Vec<Trs> = root.nodes.iter().map(Trs::of).collect();
        let mut weights: Vec<Option<Vec<f64>>> = vec![None; root.nodes.len()];
        if let Some(a) = animation {
            self.animate(a, t, &mut local, &mut weights);
        }
        let world = self.world(&local);
        let n = &root.nodes[node];
        let Some(mesh) = n.mesh.map(|m| &root.meshes[m.value()]) else {
            return Vec::new();
        };
        let morph: Vec<f64> = weights[node].clone().unwrap_or_else(|| {
            n.weights
                .as_ref()
                .or(mesh.weights.as_ref())
                .map_or_else(Vec::new, |w| w.iter().map(|&x| x as f64).collect())
        });
        let joints: Option<Vec<Matrix4<f64>>> = n.skin.map(|s| {
            let skin = &root.skins[s.value()];
            let ibm = skin.inverse_bind_matrices.and_then(|i| self.values(i));
            skin.joints
                .iter()
                .enumerate()
                .map(|(j, node)| {
                    let bind = ibm.map_or(Matrix4::identity(), |v| {
                        Matrix4::from_column_slice(v.element(j))
                    });
                    world[node.value()] * bind
                })
                .collect()
        });
        mesh.primitives
            .iter()
            .flat_map(|p| self.primitive(p, &morph, joints.as_deref(), &world[node]))
            .collect()
    }

    fn primitive(
        &self,
        prim: &json::mesh::Primitive,
        morph: &[f64],
        joints: Option<&[Matrix4<f64>]>,
        node_world: &Matrix4<f64>,
    ) -> Vec<[f64; 3]> {
        use json::mesh::Semantic as S;
        let attr = |s: S| prim.attributes.get(&Valid(s)).and_then(|&i| self.values(i));
        let Some(base) = attr(S::Positions) else {
            return Vec::new();
        };
        let mut points: Vec<Vector3<f64>> = (0..base.count())
            .map(|v| Vector3::from_column_slice(base.element(v)))
            .collect();
        for (target, &w) in prim.targets.iter().flatten().zip(morph) {
            if w == 0.0 {
                continue;
            }
            if let Some(d) = target.positions.and_then(|i| self.values(i)) {
                for (v, p) in points.iter_mut().enumerate() {
                    let e = d.element(v);
                    *p += w * Vector3::new(d.real(e[0]), d.real(e[1]), d.real(e[2]));
                }
            }
        }
        let sets: Vec<(&Values, &Values)> = (0..)
            .map_while(|s| Some((attr(S::Joints(s))?, attr(S::Weights(s))?)))
            .collect();
        points
            .iter()
            .enumerate()
            .map(|(v, p)| {
                let m = match joints {
                    Some(joints) if !sets.is_empty() => {
                        let mut m = Matrix4::zeros();
                        for (j, w) in &sets {
                            for k in 0..4 {
                                let weight = w.real(w.element(v)[k]);
                                if weight != 0.0 {
                                    m += weight * joints[j.element(v)[k] as usize];
                                }
                            }
                        }
                        m
                    }
                    _ => *node_world,
                };
                let q = m.transform_point(&nalgebra::Point3::from(*p));
                [q.x, q.y, q.z]
            })
            .collect()
    }

    fn world(&self, local: &[Trs]) -> Vec<Matrix4<f64>> {
        let mut world: Vec<Option<Matrix4<f64>>> = vec![None; local.len()];
        for n in 0..local.len() {
            // Walk up to the first node already known (the tree is acyclic: checked before).
            let mut chain = vec![n];
            while let Some(up) = self.parents[*chain.last().expect("non-empty")] {
                if world[up].is_some() {
                    break;
                }
                chain.push(up);
            }
            for &c in chain.iter().rev() {
                if world[c].is_none() {
                    let parent = self.parents[c]
                        .and_then(|p| world[p])
                        .unwrap_or_else(Matrix4::identity);
                    world[c] = Some(parent * local[c].matrix());
                }
            }
        }
        world.into_iter().map(|m| m.expect("every node")).collect()
    }

    fn animate(&self, a: usize, t: f64, local: &mut [Trs], weights: &mut [Option<Vec<f64>>]) {
        let anim = &self.doc.root.animations[a];
        for channel in &anim.channels {
            let sampler = &anim.samplers[channel.sampler.value()];
            let (Some(input), Some(output), Valid(path), Valid(interp)) = (
                self.values(sampler.input),
                self.values(sampler.output),
                &channel.target.path,
                &sampler.interpolation,
            ) else {
                continue;
            };
            let node = channel.target.node.value();
            let width = match path {
                Property::MorphTargetWeights => {
                    output.count()
                        / input.count().max(1)
                        / if *interp == Interpolation::CubicSpline {
                            3
                        } else {
                            1
                        }
                }
                _ => output.comps,
            };
            let value = sample(
                input,
                output,
                *interp,
                width,
                t,
                *path == Property::Rotation,
            );
            let trs = &mut local[node];
            match path {
                Property::Translation => trs.t = Vector3::from_column_slice(&value),
                Property::Scale => trs.s = Vector3::from_column_slice(&value),
                Property::Rotation => trs.r = quat(&value),
                Property::MorphTargetWeights => weights[node] = Some(value),
            }
        }
    }
}

/// The sampler's value at `t` (clamped to its keys), `width` numbers per key.
fn sample(
    input: &Values,
    output: &Values,
    interp: Interpolation,
    width: usize,
    t: f64,
    rotation: bool,
) -> Vec<f64> {
    let times = &input.data;
    let cubic = interp == Interpolation::CubicSpline;
    // Key k's value (for cubic: the middle of in-tangent, value, out-tangent).
    let key = |k: usize, part: usize| -> Vec<f64> {
        let start = if cubic {
            (3 * k + part) * width
        } else {
            k * width
        };
        output.data[start..start + width]
            .iter()
            .map(|&x| output.real(x))
            .collect()
    };
    let last = times.len() - 1;
    if t <= times[0] {
        return key(0, 1);
    }
    if t >= times[last] {
        return key(last, 1);
    }
    let k = times.partition_point(|&x| x <= t) - 1;
    let (t0, t1) = (times[k], times[k + 1]);
    let dt = t1 - t0;
    let u = (t - t0) / dt;
    match interp {
        Interpolation::Step => key(k, 1),
        Interpolation::Linear if rotation => {
            let (a, b) = (quat(&key(k, 1)), quat(&key(k + 1, 1)));
            let q = a.try_slerp(&b, u, 1e-9).unwrap_or(b);
            let c = q.coords;
            vec![c.x, c.y, c.z, c.w]
        }
        Interpolation::Linear => {
            let (a, b) = (key(k, 1), key(k + 1, 1));
            a.iter().zip(&b).map(|(x, y)| x + u * (y - x)).collect()
        }
        Interpolation::CubicSpline => {
            let (p0, m0, p1, m1) = (key(k, 1), key(k, 2), key(k + 1, 1), key(k + 1, 0));
            let (u2, u3) = (u * u, u * u * u);
            let v: Vec<f64> = (0..width)
                .map(|c| {
                    (2.0 * u3 - 3.0 * u2 + 1.0) * p0[c]
                        + (u3 - 2.0 * u2 + u) * dt * m0[c]
                        + (-2.0 * u3 + 3.0 * u2) * p1[c]
                        + (u3 - u2) * dt * m1[c]
                })
                .collect();
            if rotation {
                let c = quat(&v).coords;
                vec![c.x, c.y, c.z, c.w]
            } else {
                v
            }
        }
    }
}
