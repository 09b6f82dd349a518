//! Putting a retargeted clip's feet on the floor, by the skinned feet, not the foot joints: a
//! foot pitched onto its toes or rolled onto its edge reaches below its joints (a joint at its
//! rest height left the sole 35–60 mm through the floor on dance and basketball takes).

use super::{SkelAnimation, Skeleton, Skin};

/// The body's feet as the grounding sees them: the vertices mostly skinned to a foot joint (a
/// joint within 12 cm of the lowest joint at rest), their rest positions and skin, and the rest
/// floor (the lowest of them).
#[derive(Clone, Debug)]
pub struct Feet {
    rest: Vec<[f32; 3]>,
    skin: Skin,
    floor: f32,
}

impl Feet {
    /// The feet of a body whose rest mesh is `positions`, skinned by `skin` to `skeleton`.
    pub fn of(skeleton: &Skeleton, positions: &[[f32; 3]], skin: &Skin) -> Feet {
        let rest: Vec<f32> = skeleton.rest_world().iter().map(|m| m[(1, 3)]).collect();
        let lowest = rest.iter().copied().fold(f32::INFINITY, f32::min);
        let foot = |j: usize| rest[j] < lowest + 0.12;
        let region: Vec<u32> = (0..positions.len() as u32)
            .filter(|&v| {
                skin.vertex(v as usize)
                    .max_by(|a, b| a.1.total_cmp(&b.1))
                    .is_some_and(|(j, _)| foot(j))
            })
            .collect();
        let rest: Vec<[f32; 3]> = region.iter().map(|&v| positions[v as usize]).collect();
        let floor = rest.iter().map(|p| p[1]).fold(f32::INFINITY, f32::min);
        Feet {
            skin: skin.subset(&region),
            rest,
            floor,
        }
    }

    /// Per frame, how far the lowest foot vertex sits above (+) or below (−) the rest floor.
    fn clearance(&self, anim: &SkelAnimation, skeleton: &Skeleton) -> Vec<f32> {
        (0..anim.frame_count())
            .map(|f| {
                let skinning = skeleton.skinning_matrices(&anim.local_pose(f));
                self.skin
                    .skin_points(&self.rest, &skinning)
                    .iter()
                    .map(|p| p[1] - self.floor)
                    .fold(f32::INFINITY, f32::min)
            })
            .collect()
    }
}

/// Puts the feet on the floor: a constant offset (10th percentile of the clearance, robust to
/// jumps; the 1st when the take climbs), then a per-frame correction of what remains while the
/// feet are near the floor (full within 5 cm, fading out by 15 cm so jumps stay jumps), smoothed
/// over ±0.1 s. Other proportions than the performer's (a wide stance lowers their hips less than
/// ours) otherwise float the feet. Returns the constant offset (metres). A body with no foot
/// vertices is left as it is.
pub fn ground(anim: &mut SkelAnimation, skeleton: &Skeleton, feet: &Feet) -> f32 {
    if feet.rest.is_empty() {
        return 0.0;
    }
    let clearance = feet.clearance(anim, skeleton);
    if clearance.is_empty() {
        return 0.0;
    }
    let mut sorted = clearance.clone();
    sorted.sort_by(f32::total_cmp);
    // A take spent mostly on something higher (a climb, a playground structure) has its 10th
    // percentile up there: when the lowest 1 % lies more than 10 cm below it, the floor is there.
    let (p1, p10) = (sorted[sorted.len() / 100], sorted[sorted.len() / 10]);
    let offset = if p1 < p10 - 0.10 { -p1 } else { -p10 };
    let residual: Vec<f32> = clearance.iter().map(|c| c + offset).collect();
    let correction: Vec<f32> = residual.iter().map(|&r| -r * contact_weight(r)).collect();
    let half = (0.1 * anim.fps).round() as usize;
    for (f, t) in anim.translations.iter_mut().enumerate() {
        let window = &correction[f.saturating_sub(half)..(f + half + 1).min(correction.len())];
        t[0].y += offset + window.iter().sum::<f32>() / window.len() as f32;
    }
    offset
}

fn contact_weight(residual: f32) -> f32 {
    ((0.15 - residual.abs()) / 0.10).clamp(0.0, 1.0)
}
