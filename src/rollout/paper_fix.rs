//! The paper's test-time collision fix (Sec. 5.1), kept as `--collision-solver paper` to compare
//! with: a residual displacement map `Θ` in UV space (bilinear per vertex, in the vertices' rest
//! frames) optimised with Adam for `|G̃ − G|₁ + |ΔG̃ − ΔG|₁ + λ3·L_collision` (λ3 = 100), plus
//! one term beyond the paper that keeps the edge lengths the garment had before the fix
//! (`λ_e·Σ_e ||G̃_e| − |G_e||`). Twenty iterations through libtorch: ~100 ms a frame.

use super::surface::Planes;
use super::Settings;
use crate::models::dynamic::{MeshEdges, MeshLaplacian, Space};
use tch::nn::{self, OptimizerConfig};
use tch::{Kind, Tensor};

/// λ3 of the collision objective.
pub const LAMBDA_COLLISION: f64 = 100.0;

/// The garment's operators the fix keeps its shape with.
pub struct ShapeTerms {
    pub laplacian: MeshLaplacian,
    pub edges: MeshEdges,
}

/// The decoded frame the fix starts from.
pub struct Decoded<'a> {
    /// The canonical (unskinned) garment `Θ` offsets, and the pose's anchor transforms.
    pub canonical: &'a Tensor,
    pub transforms: &'a Tensor,
    /// The skinned decode itself.
    pub skinned: &'a Tensor,
}

/// Optimises `Θ` on `garment` (`[1, V, 3]`, the decode after any strain limiting: `Θ`'s
/// displacement, skinned, is added to it) and returns the fixed garment.
pub fn resolve(
    space: &Space,
    decoded: &Decoded,
    garment: &Tensor,
    planes: &Planes,
    shape: &ShapeTerms,
    s: &Settings,
) -> Tensor {
    let device = garment.device();
    let to_tensor = |p: &[[f32; 3]]| super::to_tensor(p, device);
    let planes = (to_tensor(&planes.points), to_tensor(&planes.normals));
    let vs = nn::VarStore::new(device);
    let theta = vs.root().zeros("theta", &[1, 3, s.map, s.map]);
    let Ok(mut opt) = nn::Adam::default().build(&vs, s.learning_rate) else {
        return garment.shallow_clone();
    };
    let target_laplacian = tch::no_grad(|| shape.laplacian.of(garment));
    // Weight 0 is the paper's objective: the edge term is then left out, not computed at zero.
    let target_lengths =
        (s.edge_weight > 0.0).then(|| tch::no_grad(|| shape.edges.lengths(garment)));
    // The pose is fixed over the iterations: blend the anchors' transforms once.
    let posed = space.posed(decoded.transforms);
    // Skinning is affine in the canonical garment, so `Θ`'s displacement adds to any garment.
    let resolved = |theta: &Tensor| {
        let offsets = space.at_vertices(theta);
        posed.skin(&space.offset_canonical(decoded.canonical, &offsets)) - decoded.skinned + garment
    };
    for _ in 0..s.iterations {
        let g = resolved(&theta);
        let mut loss = (&g - garment).abs().sum(Kind::Float)
            + (shape.laplacian.of(&g) - &target_laplacian)
                .abs()
                .sum(Kind::Float);
        if let Some(lengths) = &target_lengths {
            loss += (shape.edges.lengths(&g) - lengths).abs().sum(Kind::Float) * s.edge_weight;
        }
        loss += collision_loss(&g, &planes, s.margin) * LAMBDA_COLLISION;
        opt.zero_grad();
        loss.backward();
        opt.step();
    }
    tch::no_grad(|| resolved(&theta))
}

/// `Σ ReLU(margin − o)` with `o = (g − b)·n`.
fn collision_loss(g: &Tensor, planes: &(Tensor, Tensor), margin: f32) -> Tensor {
    let o = ((g - &planes.0) * &planes.1).sum_dim_intlist(2, false, Kind::Float);
    (-(o - margin as f64)).relu().sum(Kind::Float)
}
