//! The frames before a clip: rest pose held where the clip starts, then a smooth blend into the
//! clip's first pose. The root stays at the clip's first position throughout: blending it from
//! the origin would slide the body metres in a second (131_01 starts 1.8 m away) and fling
//! the garment before frame 0.

use crate::rig::{JointTransform, Skeleton};

/// `hold` frames of the rest pose, then `blend` frames easing (smoothstep) into `first`; the
/// last blend frame stops one step short of `first`, which the clip's frame 0 then plays.
pub fn poses(
    skeleton: &Skeleton,
    first: &[JointTransform],
    hold: usize,
    blend: usize,
) -> Vec<Vec<JointTransform>> {
    let mut rest = skeleton.rest.clone();
    for (j, parent) in skeleton.parents.iter().enumerate() {
        if parent.is_none() {
            rest[j].translation = first[j].translation;
        }
    }
    let rest = &rest;
    let mut out = vec![rest.clone(); hold];
    for k in 0..blend {
        let t = k as f32 / blend as f32;
        let s = t * t * (3.0 - 2.0 * t);
        out.push(rest.iter().zip(first).map(|(a, b)| mix(a, b, s)).collect());
    }
    out
}

fn mix(a: &JointTransform, b: &JointTransform, s: f32) -> JointTransform {
    JointTransform {
        translation: a.translation.lerp(&b.translation, s),
        rotation: a
            .rotation
            .try_slerp(&b.rotation, s, 1e-6)
            .unwrap_or(if s < 0.5 { a.rotation } else { b.rotation }),
        scale: a.scale.lerp(&b.scale, s),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{UnitQuaternion, Vector3};

    #[test]
    fn holds_rest_then_eases_towards_the_first_pose() {
        let skeleton = Skeleton::new(
            vec!["root".into()],
            vec![None],
            vec![JointTransform::from_translation(Vector3::zeros())],
            vec![nalgebra::Matrix4::identity()],
        )
        .unwrap();
        let mut first = JointTransform::from_translation(Vector3::new(1.0, 0.0, 0.0));
        first.rotation = UnitQuaternion::from_euler_angles(0.0, 1.0, 0.0);
        let p = poses(&skeleton, &[first], 2, 4);
        assert_eq!(p.len(), 6);
        // The root waits where the clip starts, in the rest orientation.
        assert!(p.iter().all(|f| f[0].translation.x == 1.0));
        assert_eq!(p[1][0].rotation.angle(), 0.0);
        let angles: Vec<f32> = p[2..].iter().map(|f| f[0].rotation.angle()).collect();
        assert!(
            angles.windows(2).all(|w| w[1] > w[0]) && angles[3] < 1.0,
            "{angles:?}"
        );
        // Halfway in time is halfway in angle (smoothstep is symmetric).
        let angle = p[4][0].rotation.angle();
        assert!((angle - 0.5).abs() < 1e-4, "{angle}");
    }
}
