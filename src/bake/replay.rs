//! The bake's replay check: every frame of a clip played two ways and compared in world space,
//! the file (its base mesh, blend shapes, weights and skin, played by our LBS) against the
//! network's own forward pass (its template, basis and slot skin on the MLP's coefficients).
//! Both are formed a block of frames at a time, coordinate-major (`[3N][frames]`, one matrix
//! product per block into a buffer reused across blocks), so the skinning and the distances run
//! over frames in SIMD lanes: eight frames of one vertex, both sides skinned and compared in
//! registers.

use rayon::prelude::*;
use tch::{Kind, Tensor};

/// Frames per block: the lanes the skinning runs over.
const BLOCK: usize = 64;

/// Frames skinned together (one AVX register of f32).
const LANES: usize = 8;

type Lane = [f32; LANES];

/// Vertices per parallel task.
const VERTICES_PER_TASK: usize = 128;

/// One way of playing a clip: rest points `rest + weights · shapes` per frame, skinned with
/// each vertex's slots.
pub struct Played<'a> {
    /// Rest points, `[N * 3]`.
    pub rest: &'a [f32],
    /// Blend shapes `[K, N * 3]` (f32, on the CPU).
    pub shapes: &'a Tensor,
    /// Blend-shape weights per frame `[frames, K]` (f32, on the CPU).
    pub weights: &'a Tensor,
    /// Skinning matrices (row-major 3 × 4) per frame and joint, `[frames][J][12]`.
    pub skinning: &'a [f32],
    /// Joint and weight of each vertex's slots, `influences` per vertex.
    pub joints: &'a [usize],
    pub slot_weights: &'a [f32],
    pub influences: usize,
}

/// Per frame, the largest and the mean distance (m) between the points `a` and `b` play.
pub fn distances(a: &Played, b: &Played) -> Vec<(f32, f32)> {
    let frames = a.weights.size()[0] as usize;
    let n = a.rest.len() / 3;
    let (mut oa, mut ob) = (vec![0.0f32; 3 * n * BLOCK], vec![0.0f32; 3 * n * BLOCK]);
    let (mut ja, mut jb) = (Vec::new(), Vec::new());
    let fused = fused_kernel();
    let mut out = Vec::with_capacity(frames);
    for start in (0..frames).step_by(BLOCK) {
        let count = BLOCK.min(frames - start);
        offsets_block(a, start, count, &mut oa);
        offsets_block(b, start, count, &mut ob);
        joint_blocks(a.skinning, frames, start, &mut ja);
        joint_blocks(b.skinning, frames, start, &mut jb);
        let (side_a, side_b) = (Side::of(a, &ja, &oa), Side::of(b, &jb, &ob));
        let tasks: Vec<([f32; BLOCK], [f32; BLOCK])> = (0..n)
            .step_by(VERTICES_PER_TASK)
            .collect::<Vec<_>>()
            .into_par_iter()
            .map(|first| {
                let vertices = first..(first + VERTICES_PER_TASK).min(n);
                block_distances(&side_a, &side_b, vertices, fused)
            })
            .collect();
        // Summed in vertex order whatever the threads: the same figures every run.
        for f in 0..count {
            let largest = tasks.iter().map(|t| t.0[f]).fold(0.0, f32::max);
            let sum: f32 = tasks.iter().map(|t| t.1[f]).sum();
            out.push((largest, sum / n.max(1) as f32));
        }
    }
    out
}

/// Frame lanes of a block.
const CHUNKS: usize = BLOCK / LANES;

/// One joint's skinning matrices (row-major 3 × 4) over a block of frames,
/// `[lane chunk][element][lane]`: the twelve values one chunk of frames needs are contiguous.
type JointBlock = [[Lane; 12]; CHUNKS];

/// The skinning matrices `[frames][J][12]` of frames `start..start + BLOCK` into `out`, one
/// [`JointBlock`] per joint (frames past the clip's end zero).
fn joint_blocks(skinning: &[f32], frames: usize, start: usize, out: &mut Vec<JointBlock>) {
    let per_frame = skinning.len() / frames.max(1);
    out.clear();
    out.resize(per_frame / 12, [[[0.0; LANES]; 12]; CHUNKS]);
    for (i, rows) in skinning
        .chunks_exact(per_frame.max(1))
        .skip(start)
        .take(BLOCK)
        .enumerate()
    {
        let (chunk, lane) = (i / LANES, i % LANES);
        for (joint, m) in out.iter_mut().zip(rows.chunks_exact(12)) {
            for (e, &value) in m.iter().enumerate() {
                joint[chunk][e][lane] = value;
            }
        }
    }
}

/// `weights · shapes` for frames `start..start + count` into `out`, coordinate-major
/// `[N * 3][BLOCK]` (frames past the clip's end zero); the rest points are added in the lanes.
fn offsets_block(p: &Played, start: usize, count: usize, out: &mut [f32]) {
    let n3 = p.rest.len();
    assert_eq!(out.len(), n3 * BLOCK, "one block of offsets");
    tch::no_grad(|| {
        let mut weights = p.weights.narrow(0, start as i64, count as i64);
        if count < BLOCK {
            weights = weights.constant_pad_nd([0, 0, 0, (BLOCK - count) as i64]);
        }
        let weights = weights.to_kind(Kind::Float);
        // SAFETY: `out` is a live, exclusively borrowed f32 buffer of exactly n3 × BLOCK values
        // (asserted above), row-major as the strides say; the tensor viewing it is written by
        // the one product below and dropped at the end of this closure, before `out` is read.
        let target = unsafe {
            Tensor::from_blob(
                out.as_mut_ptr().cast::<u8>(),
                &[n3 as i64, BLOCK as i64],
                &[BLOCK as i64, 1],
                Kind::Float,
                tch::Device::Cpu,
            )
        };
        let _ = p
            .shapes
            .to_kind(Kind::Float)
            .tr()
            .matmul_out(&target, &weights.tr());
        assert_eq!(
            target.data_ptr().cast::<f32>(),
            out.as_mut_ptr(),
            "the product written in place"
        );
    });
}

/// One side of a block: its rest points, offsets and skinning in lanes, and its slots.
struct Side<'a> {
    /// One per joint.
    skinning: &'a [JointBlock],
    /// `[N * 3]`.
    rest: &'a [f32],
    /// `[N * 3][BLOCK]`.
    offsets: &'a [[f32; BLOCK]],
    joints: &'a [usize],
    weights: &'a [f32],
    influences: usize,
}

impl<'a> Side<'a> {
    fn of(p: &Played<'a>, skinning: &'a [JointBlock], offsets: &'a [f32]) -> Side<'a> {
        Side {
            skinning,
            rest: p.rest,
            offsets: offsets.as_chunks::<BLOCK>().0,
            joints: p.joints,
            weights: p.slot_weights,
            influences: p.influences,
        }
    }
}

/// Whether this CPU runs the fused-multiply-add kernel (AVX2 and FMA).
fn fused_kernel() -> bool {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
        return true;
    }
    false
}

/// Largest and summed distance per frame of the block over `vertices`.
fn block_distances(
    a: &Side,
    b: &Side,
    vertices: std::ops::Range<usize>,
    fused: bool,
) -> ([f32; BLOCK], [f32; BLOCK]) {
    #[cfg(target_arch = "x86_64")]
    if fused {
        // SAFETY: `fused` is true only where the CPU has AVX2 and FMA ([`fused_kernel`]), the
        // function's only requirement.
        return unsafe { block_distances_fma(a, b, vertices) };
    }
    let _ = fused;
    block_distances_lanes::<false>(a, b, vertices)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn block_distances_fma(
    a: &Side,
    b: &Side,
    vertices: std::ops::Range<usize>,
) -> ([f32; BLOCK], [f32; BLOCK]) {
    block_distances_lanes::<true>(a, b, vertices)
}

/// `a · b + c`, fused (one rounding) in the FMA kernel.
#[inline(always)]
fn madd<const FMA: bool>(a: f32, b: f32, c: f32) -> f32 {
    if FMA {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

#[inline(always)]
fn block_distances_lanes<const FMA: bool>(
    a: &Side,
    b: &Side,
    vertices: std::ops::Range<usize>,
) -> ([f32; BLOCK], [f32; BLOCK]) {
    let (mut largest, mut sum) = ([[0.0f32; LANES]; CHUNKS], [[0.0f32; LANES]; CHUNKS]);
    for v in vertices {
        for chunk in 0..CHUNKS {
            let pa = skin_lanes::<FMA>(a, v, chunk);
            let pb = skin_lanes::<FMA>(b, v, chunk);
            let (largest, sum) = (&mut largest[chunk], &mut sum[chunk]);
            for f in 0..LANES {
                let (dx, dy, dz) = (
                    pa[0][f] - pb[0][f],
                    pa[1][f] - pb[1][f],
                    pa[2][f] - pb[2][f],
                );
                let d = madd::<FMA>(dx, dx, madd::<FMA>(dy, dy, dz * dz)).sqrt();
                largest[f] = largest[f].max(d);
                sum[f] += d;
            }
        }
    }
    let flat = |lanes: [[f32; LANES]; CHUNKS]| -> [f32; BLOCK] {
        lanes.as_flattened().try_into().expect("a block")
    };
    (flat(largest), flat(sum))
}

/// Linear blend skinning of vertex `v` over the frames of lane chunk `chunk`:
/// `Σ_s w_s (S_{j_s} · [r; 1])`, `r` the rest point plus the frame's offset.
#[inline(always)]
fn skin_lanes<const FMA: bool>(side: &Side, v: usize, chunk: usize) -> [Lane; 3] {
    let point = |axis: usize| -> Lane {
        let rest = side.rest[3 * v + axis];
        side.offsets[3 * v + axis].as_chunks::<LANES>().0[chunk].map(|o| rest + o)
    };
    let (x, y, z) = (point(0), point(1), point(2));
    let mut out = [[0.0f32; LANES]; 3];
    for s in v * side.influences..(v + 1) * side.influences {
        let w = side.weights[s];
        if w == 0.0 {
            continue;
        }
        let m = &side.skinning[side.joints[s]][chunk];
        for (row, out) in out.iter_mut().enumerate() {
            let (m0, m1, m2, m3) = (
                &m[4 * row],
                &m[4 * row + 1],
                &m[4 * row + 2],
                &m[4 * row + 3],
            );
            for f in 0..LANES {
                let p = if FMA {
                    m0[f].mul_add(x[f], m1[f].mul_add(y[f], m2[f].mul_add(z[f], m3[f])))
                } else {
                    m0[f] * x[f] + m1[f] * y[f] + m2[f] * z[f] + m3[f]
                };
                out[f] = madd::<FMA>(w, p, out[f]);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::Skin;
    use nalgebra::Matrix4;

    /// A deterministic pseudo-random number in [-1, 1).
    fn noise(i: usize) -> f32 {
        ((i.wrapping_mul(2_654_435_761) >> 7) % 2000) as f32 / 1000.0 - 1.0
    }

    #[test]
    fn the_blocked_replay_is_the_per_frame_lbs() {
        // 70 frames (a block and a part), 9 vertices, 3 joints, 2 shapes: the blocked,
        // coordinate-major replay against `Skin::skin_points` frame by frame, vertex by vertex.
        let (frames, n, joints, k) = (70, 9, 3, 2);
        let rest: Vec<f32> = (0..3 * n).map(|i| noise(i) * 0.5).collect();
        let shapes: Vec<f32> = (0..k * 3 * n).map(|i| noise(i + 100) * 0.1).collect();
        let weights: Vec<f32> = (0..frames * k).map(|i| noise(i + 900)).collect();
        let matrices: Vec<Vec<Matrix4<f32>>> = (0..frames)
            .map(|f| {
                (0..joints)
                    .map(|j| {
                        let mut m = Matrix4::identity();
                        for r in 0..3 {
                            for c in 0..4 {
                                m[(r, c)] += noise(1000 + 12 * (f * joints + j) + 4 * r + c) * 0.3;
                            }
                        }
                        m
                    })
                    .collect()
            })
            .collect();
        let rows: Vec<f32> = matrices
            .iter()
            .flatten()
            .flat_map(|m| (0..3).flat_map(move |r| (0..4).map(move |c| m[(r, c)])))
            .collect();
        // Two influences a vertex, the second empty on every third vertex.
        let skin = Skin {
            influences: 2,
            joint_indices: (0..n)
                .flat_map(|v| [(v % 3) as u16, ((v + 1) % 3) as u16])
                .collect(),
            joint_weights: (0..n)
                .flat_map(|v| if v % 3 == 0 { [1.0, 0.0] } else { [0.7, 0.3] })
                .collect(),
        };
        let joint_list: Vec<usize> = skin.joint_indices.iter().map(|&j| j as usize).collect();
        let (shapes_t, weights_t) = (
            Tensor::from_slice(&shapes).view([k as i64, 3 * n as i64]),
            Tensor::from_slice(&weights).view([frames as i64, k as i64]),
        );
        let played = Played {
            rest: &rest,
            shapes: &shapes_t,
            weights: &weights_t,
            skinning: &rows,
            joints: &joint_list,
            slot_weights: &skin.joint_weights,
            influences: 2,
        };
        // Against itself: nothing. Against the same points moved 1 cm along x after skinning
        // (a translation of every joint): 1 cm at every frame.
        assert!(distances(&played, &played).iter().all(|d| d.0 == 0.0));
        let moved: Vec<f32> = rows
            .iter()
            .enumerate()
            .map(|(i, &v)| if i % 12 == 3 { v + 0.01 } else { v })
            .collect();
        let shifted = Played {
            skinning: &moved,
            ..played
        };
        for (f, d) in distances(&played, &shifted).iter().enumerate() {
            assert!(
                (d.0 - 0.01).abs() < 1e-6 && (d.1 - 0.01).abs() < 1e-6,
                "{f}: {d:?}"
            );
        }
        // Against the rest points alone, the distance is the blend shapes' skinned offsets.
        let no_shapes = Tensor::zeros([frames as i64, k as i64], (Kind::Float, tch::Device::Cpu));
        let still = Played {
            weights: &no_shapes,
            ..played
        };
        let blocked = distances(&played, &still);
        for (f, m) in matrices.iter().enumerate() {
            let point = |with: bool| -> Vec<[f32; 3]> {
                let at: Vec<[f32; 3]> = (0..n)
                    .map(|v| {
                        [0, 1, 2].map(|a| {
                            let offset: f32 = (0..k)
                                .map(|s| weights[f * k + s] * shapes[s * 3 * n + 3 * v + a])
                                .sum();
                            rest[3 * v + a] + if with { offset } else { 0.0 }
                        })
                    })
                    .collect();
                skin.skin_points(&at, m)
            };
            let (a, b) = (point(true), point(false));
            let d: Vec<f32> = a
                .iter()
                .zip(&b)
                .map(|(p, q)| (0..3).map(|i| (p[i] - q[i]).powi(2)).sum::<f32>().sqrt())
                .collect();
            let largest = d.iter().copied().fold(0.0, f32::max);
            let mean = d.iter().sum::<f32>() / n as f32;
            assert!(
                (blocked[f].0 - largest).abs() < 1e-5 && (blocked[f].1 - mean).abs() < 1e-5,
                "frame {f}: blocked {:?}, per frame ({largest}, {mean})",
                blocked[f]
            );
        }
        assert_eq!(blocked.len(), frames);
    }
}
