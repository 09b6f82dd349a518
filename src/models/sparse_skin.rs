//! Linear blend skinning on the CPU over each vertex's `influences` slots, with its gradient
//! written out. The tensor LBS ([`super::Pbns::skin_points`]) blends a dense `[N, J]` weight
//! matrix (every joint, most weights zero), and its autograd backward does the same. CPU
//! inference skins here; the CPU training step also takes the backward: the rest-space
//! gradient (for the PSD basis and the network, which stay with autograd) and the slot logits'
//! gradient (which then needs no autograd at all).

/// A vertex's slot joints and softmax weights, `influences` per vertex.
pub struct Slots {
    pub joints: Vec<i64>,
    pub weights: Vec<f32>,
    pub influences: usize,
}

/// Posed points `[B, N, 3]` and each vertex's blended 3×4 matrix (kept for the backward).
pub struct Skinned {
    pub points: Vec<f32>,
    blended: Vec<[f32; 12]>,
}

/// `x = (Σ_s w_s S_{j_s}) · [r; 1]` for rest points `rest: [B, N, 3]` and row-major 3×4
/// skinning matrices `skinning: [B, J, 12]`.
pub fn skin(rest: &[f32], skinning: &[f32], joints: usize, slots: &Slots) -> Skinned {
    let n = slots.joints.len() / slots.influences;
    let batch = rest.len() / (3 * n);
    let mut points = vec![0.0f32; rest.len()];
    let mut blended = vec![[0.0f32; 12]; batch * n];
    for b in 0..batch {
        let s = &skinning[b * joints * 12..(b + 1) * joints * 12];
        for v in 0..n {
            let m = blend(s, slots, v);
            let i = b * n + v;
            let r = &rest[3 * i..3 * i + 3];
            for row in 0..3 {
                points[3 * i + row] = apply_row(&m, row, r);
            }
            blended[i] = m;
        }
    }
    Skinned { points, blended }
}

/// The gradients of `Σ grad·x` with respect to the rest points (`[B, N, 3]`) and to the slot
/// logits (`[N, influences]`, through the softmax), for the points [`skin`] returned.
pub fn backward(
    rest: &[f32],
    skinning: &[f32],
    joints: usize,
    slots: &Slots,
    skinned: &Skinned,
    grad: &[f32],
) -> (Vec<f32>, Vec<f32>) {
    let k = slots.influences;
    let n = slots.joints.len() / k;
    let batch = rest.len() / (3 * n);
    let mut grad_rest = vec![0.0f32; rest.len()];
    // Per-slot weight gradients summed over the batch in a fixed order (deterministic).
    let mut grad_weight = vec![0.0f64; n * k];
    for b in 0..batch {
        let s = &skinning[b * joints * 12..(b + 1) * joints * 12];
        for v in 0..n {
            let i = b * n + v;
            let (r, g) = (&rest[3 * i..3 * i + 3], &grad[3 * i..3 * i + 3]);
            let m = &skinned.blended[i];
            for c in 0..3 {
                grad_rest[3 * i + c] = m[c] * g[0] + m[4 + c] * g[1] + m[8 + c] * g[2];
            }
            for slot in 0..k {
                if slots.weights[v * k + slot] == 0.0 {
                    continue;
                }
                let j = slots.joints[v * k + slot] as usize;
                let sj = &s[j * 12..j * 12 + 12];
                let dot: f32 = (0..3).map(|row| g[row] * apply_row(sj, row, r)).sum();
                grad_weight[v * k + slot] += dot as f64;
            }
        }
    }
    let mut grad_logits = vec![0.0f32; n * k];
    for v in 0..n {
        let w = &slots.weights[v * k..(v + 1) * k];
        let gw = &grad_weight[v * k..(v + 1) * k];
        let mean: f64 = w.iter().zip(gw).map(|(&w, &g)| w as f64 * g).sum();
        for slot in 0..k {
            grad_logits[v * k + slot] = (w[slot] as f64 * (gw[slot] - mean)) as f32;
        }
    }
    (grad_rest, grad_logits)
}

/// `Σ_s w_s S_{j_s}` of vertex `v`.
fn blend(s: &[f32], slots: &Slots, v: usize) -> [f32; 12] {
    let k = slots.influences;
    let mut m = [0.0f32; 12];
    for slot in 0..k {
        let w = slots.weights[v * k + slot];
        if w == 0.0 {
            continue;
        }
        let j = slots.joints[v * k + slot] as usize;
        for (m, &sj) in m.iter_mut().zip(&s[j * 12..j * 12 + 12]) {
            *m += w * sj;
        }
    }
    m
}

/// Row `row` of the 3×4 matrix `m` applied to the point `r`.
fn apply_row(m: &[f32], row: usize, r: &[f32]) -> f32 {
    let m = &m[4 * row..4 * row + 4];
    m[0] * r[0] + m[1] * r[1] + m[2] * r[2] + m[3]
}
