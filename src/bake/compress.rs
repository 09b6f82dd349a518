//! Compressing a pose-space-deformation basis into fewer blend shapes.
//!
//! The network adds `O_f = Σ_k X_fk D_k` to the rest mesh at frame f. Over the baked clips these
//! offsets span far fewer than K directions, so we keep the leading singular vectors of the
//! stacked offsets `O = X D` (frames × 3N). `D` is wide (K × 3N), so the decomposition works on
//! K × K Gram matrices only ([`spectrum_of_product`]).

use anyhow::{bail, Result};
use exporters::asset::SHORT_STEPS;
use nalgebra::DMatrix;

/// How many blend shapes to keep: the target budget of every bake (`bake`, `rollout --out
/// x.glb`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Targets {
    /// Every direction the offsets have (a PBNS bake without pruning: the network's own basis,
    /// uncompressed, K = MLP width).
    Full,
    Count(usize),
    /// The fewest whose max offset error over the baked frames is within this many metres.
    Tolerance(f32),
}

impl Targets {
    /// The budget `--max-targets K` / `--tolerance-mm T` ask for (K at least 1, T positive;
    /// `--max-targets` wins), `otherwise` with neither.
    pub fn from_flags(
        max_targets: Option<usize>,
        tolerance_mm: Option<f32>,
        otherwise: Targets,
    ) -> Result<Targets> {
        Ok(match (max_targets, tolerance_mm) {
            (Some(0), _) => bail!("--max-targets must be at least 1"),
            (Some(k), _) => Targets::Count(k),
            (None, Some(t)) if t > 0.0 => Targets::Tolerance(t * 1e-3),
            (None, Some(t)) => bail!("--tolerance-mm must be positive, got {t}"),
            (None, None) => otherwise,
        })
    }
}

/// The network's basis and its coefficients over the frames to bake.
pub struct UsedOffsets<'a> {
    /// K components, each N offsets.
    pub basis: &'a [Vec<[f32; 3]>],
    /// Coefficients per frame (all clips stacked), K each.
    pub coefficients: &'a [Vec<f32>],
}

/// A blend-shape set and its per-frame weights reproducing the used offsets.
#[derive(Clone, Debug)]
pub struct Compressed {
    pub targets: Vec<Vec<[f32; 3]>>,
    /// Weights per frame (same order as the input coefficients).
    pub weights: Vec<Vec<f32>>,
    /// Largest vertex offset error (m) over all frames, before skinning (skinning by a convex
    /// blend of rotations never enlarges it).
    pub max_error: f32,
    pub mean_error: f32,
}

/// Singular directions of the used offsets, strongest first, with the frame coefficients.
pub struct Spectrum {
    directions: Directions,
    coefficients: DMatrix<f64>,
    pub singular_values: Vec<f64>,
}

/// Where a spectrum's directions (3N each) come from.
enum Directions {
    /// Column c is direction c (3N × rank).
    Explicit(DMatrix<f64>),
    /// Direction c is `basisᵀ · mix[:, c]` (`basis` K × 3N, `mix` K × rank, f64), then past the
    /// rank the rows of `pad` (f32) scaled to unit length: formed only for the directions kept.
    Mixed {
        basis: tch::Tensor,
        mix: tch::Tensor,
        pad: tch::Tensor,
    },
}

/// [`spectrum_of_product`] of the used offsets as f64 tensors.
pub fn spectrum(used: &UsedOffsets) -> Spectrum {
    use tch::Tensor;
    let k = used.basis.len();
    let n3 = used.basis.first().map_or(0, |b| b.len() * 3);
    let frames = used.coefficients.len();
    let d: Vec<f32> = used.basis.iter().flatten().flatten().copied().collect();
    let x: Vec<f32> = used.coefficients.iter().flatten().copied().collect();
    spectrum_of_product(
        &Tensor::from_slice(&x).view([frames as i64, k as i64]),
        &Tensor::from_slice(&d).view([k as i64, n3 as i64]),
    )
}

/// Singular directions of the offsets `O = X D` (`x` frames × K coefficients, `d` the K × 3N
/// basis), computed in f64 through two small Gram matrices and libtorch's symmetric
/// eigensolver, without a factorisation of the tall `Dᵀ` (its QR was most of the bake's time,
/// `bench bake`). Coefficients that are 0 on every frame (an MLP unit whose ReLU never fires)
/// add nothing to `O`: their rows of `D` are left out. Of the rest (`X_a`, `D_a`),
/// `D_a D_aᵀ = U Λ Uᵀ` (eigenvalues above 1e-12 of the largest: D_a's rank r), so `O = M Qᵀ`
/// with `M = X_a U Λ^½` (frames × r) and `Q = D_aᵀ U Λ^-½` orthonormal; `Mᵀ M = V Σ² Vᵀ` gives
/// the coefficients `C = M V = U_O Σ` and the directions `Q V`, formed only for the directions
/// kept ([`Spectrum::leading`]). Squaring costs accuracy only in directions weaker than about
/// 1e-7 of the strongest, under the rank a bake counts (1e-6). Past the r directions of `D_a`
/// come the unused units' own basis vectors (unit length, weight 0), as the QR's directions past
/// the offsets' rank had (nearly) 0 weight: min(frames, r + unused units) directions in all,
/// min(frames, K) as the QR gave when `D` has full rank (a trained basis does).
pub fn spectrum_of_product(x: &tch::Tensor, d: &tch::Tensor) -> Spectrum {
    use tch::{Kind, Tensor};
    let (frames, k, n3) = (x.size()[0], d.size()[0], d.size()[1]);
    if x.numel() == 0 || d.numel() == 0 {
        return Spectrum {
            directions: Directions::Explicit(DMatrix::zeros(n3 as usize, 0)),
            coefficients: DMatrix::zeros(frames as usize, 0),
            singular_values: Vec::new(),
        };
    }
    let to_vec = |t: &Tensor| Vec::<f64>::try_from(&t.contiguous().view([-1])).expect("f64");
    let (x, d) = (x.to_device(tch::Device::Cpu), d.to_device(tch::Device::Cpu));
    let active = active_columns(&x);
    let idle: Vec<i64> = (0..k).filter(|i| !active.contains(i)).collect();
    let x = x
        .index_select(1, &Tensor::from_slice(&active))
        .to_kind(Kind::Double);
    let d_active = d
        .index_select(0, &Tensor::from_slice(&active))
        .to_kind(Kind::Double);
    // Eigenpairs of a symmetric matrix, strongest first: those above `floor` × the largest
    // (every one without a floor), at most `most`.
    let leading = |m: &Tensor, floor: Option<f64>, most: i64| {
        let (values, vectors) = m.linalg_eigh("L");
        let values = to_vec(&values);
        let top = values.iter().copied().fold(0.0, f64::max);
        let keep: Vec<i64> = (0..values.len())
            .rev()
            .filter(|&i| floor.is_none_or(|f| values[i] > f * top))
            .take(most.max(0) as usize)
            .map(|i| i as i64)
            .collect();
        let kept: Vec<f64> = keep.iter().map(|&i| values[i as usize].max(0.0)).collect();
        (kept, vectors.index_select(1, &Tensor::from_slice(&keep)))
    };
    let (sigma2, coefficients, mix) = if active.is_empty() {
        let none = Tensor::zeros([0, 0], (Kind::Double, tch::Device::Cpu));
        (
            Vec::new(),
            Tensor::zeros([frames, 0], (Kind::Double, tch::Device::Cpu)),
            none,
        )
    } else {
        let (lambda, u) = leading(&d_active.matmul(&d_active.tr()), Some(1e-12), i64::MAX);
        let root = Tensor::from_slice(&lambda.iter().map(|l| l.sqrt()).collect::<Vec<_>>());
        let m = x.matmul(&u) * root.unsqueeze(0);
        let (sigma2, v) = leading(&m.tr().matmul(&m), None, frames);
        (sigma2, m.matmul(&v), (u / root.unsqueeze(0)).matmul(&v))
    };
    let rank = sigma2.len();
    let pad: Vec<i64> = idle
        .iter()
        .copied()
        .take((frames.min(k) as usize).saturating_sub(rank))
        .collect();
    let count = rank + pad.len();
    let c = to_vec(&coefficients);
    let coefficients = DMatrix::from_fn(frames as usize, count, |f, j| {
        if j < rank {
            c[f * rank + j]
        } else {
            0.0
        }
    });
    Spectrum {
        directions: Directions::Mixed {
            basis: d_active,
            mix,
            pad: d.index_select(0, &Tensor::from_slice(&pad)),
        },
        coefficients,
        singular_values: sigma2
            .iter()
            .map(|s| s.sqrt())
            .chain(std::iter::repeat_n(0.0, pad.len()))
            .collect(),
    }
}

/// The columns of `x` (frames × K coefficients) that are not 0 on every frame, in order.
pub fn active_columns(x: &tch::Tensor) -> Vec<i64> {
    let largest: Vec<f32> = Vec::try_from(
        &x.abs()
            .amax([0].as_slice(), false)
            .to_device(tch::Device::Cpu)
            .to_kind(tch::Kind::Float),
    )
    .expect("f32");
    (0..largest.len() as i64)
        .filter(|&i| largest[i as usize] != 0.0)
        .collect()
}

/// Singular directions of explicit offsets (3N × frames): used when the offsets are not a
/// product of a small basis (e.g. with skinning correctives added). Through the frames × frames
/// Gram matrix and libtorch's symmetric eigensolver, which is an order of magnitude faster than a
/// full SVD of the tall matrix; directions whose energy is below 1e-12 of the largest are dropped.
pub fn spectrum_of(offsets: &DMatrix<f32>) -> Spectrum {
    use tch::{Kind, Tensor};
    let (rows, cols) = offsets.shape();
    // nalgebra is column-major: the buffer read row-major is the transpose (frames × 3N).
    let o = Tensor::from_slice(offsets.as_slice())
        .view([cols as i64, rows as i64])
        .to_kind(Kind::Double);
    let (evals, evecs) = o.matmul(&o.tr()).linalg_eigh("L");
    let evals: Vec<f64> = Vec::<f64>::try_from(&evals).expect("eigenvalues");
    let top = evals.iter().copied().fold(0.0, f64::max);
    // Ascending from libtorch: keep the significant ones, strongest first.
    let keep: Vec<i64> = (0..evals.len())
        .rev()
        .filter(|&i| evals[i] > 1e-12 * top && evals[i] > 0.0)
        .map(|i| i as i64)
        .collect();
    let sv: Vec<f64> = keep.iter().map(|&i| evals[i as usize].sqrt()).collect();
    let index = Tensor::from_slice(&keep);
    let u = evecs.index_select(1, &index);
    let inv = Tensor::from_slice(&sv.iter().map(|s| 1.0 / s).collect::<Vec<_>>());
    let v = o.tr().matmul(&u) * inv.unsqueeze(0);
    let k = sv.len();
    let u: Vec<f64> = Vec::<f64>::try_from(&u.contiguous().view([-1])).expect("U");
    let v: Vec<f64> = Vec::<f64>::try_from(&v.contiguous().view([-1])).expect("V");
    let directions = DMatrix::from_fn(rows, k, |r, c| v[r * k + c]);
    let coefficients = DMatrix::from_fn(cols, k, |f, c| u[f * k + c] * sv[c]);
    Spectrum {
        directions: Directions::Explicit(directions),
        coefficients,
        singular_values: sv,
    }
}

impl Spectrum {
    pub fn rank(&self) -> usize {
        self.singular_values.len()
    }

    /// Keeps the `count` strongest directions; errors measured against `reference`, the offsets
    /// to reproduce (3N × frames, see [`offset_matrix`]).
    pub fn truncate(&self, reference: &DMatrix<f32>, count: usize) -> Compressed {
        let (targets, weights) = self.leading(count);
        let (max_error, mean_error) = errors(reference, &targets, &weights);
        Compressed {
            targets,
            weights,
            max_error,
            mean_error,
        }
    }

    /// The `count` strongest directions as targets and their weights per frame, unmeasured
    /// ([`Spectrum::truncate`] without the errors, which need the offsets themselves).
    pub fn leading(&self, count: usize) -> (Vec<Vec<[f32; 3]>>, Vec<Vec<f32>>) {
        let count = count.min(self.rank());
        let targets = match &self.directions {
            Directions::Explicit(directions) => {
                let n = directions.nrows() / 3;
                (0..count)
                    .map(|c| {
                        (0..n)
                            .map(|v| [0, 1, 2].map(|a| directions[(3 * v + a, c)] as f32))
                            .collect()
                    })
                    .collect::<Vec<Vec<[f32; 3]>>>()
            }
            Directions::Mixed { basis, mix, pad } => {
                let n3 = basis.size()[1] as usize;
                let mixed = (count as i64).min(mix.size()[1]);
                let t = mix
                    .narrow(1, 0, mixed)
                    .tr()
                    .matmul(basis)
                    .to_kind(tch::Kind::Float)
                    .contiguous()
                    .view([-1]);
                let t = Vec::<f32>::try_from(&t).expect("f32 targets");
                let padding = pad
                    .narrow(0, 0, count as i64 - mixed)
                    .contiguous()
                    .view([-1]);
                let padding = Vec::<f32>::try_from(&padding).expect("f32 basis rows");
                let unit = |row: &[f32]| {
                    let length = row.iter().map(|&v| (v as f64).powi(2)).sum::<f64>().sqrt();
                    let scale = if length > 0.0 { 1.0 / length } else { 0.0 };
                    row.iter()
                        .map(|&v| (v as f64 * scale) as f32)
                        .collect::<Vec<f32>>()
                };
                t.chunks_exact(n3.max(1))
                    .map(<[f32]>::to_vec)
                    .chain(padding.chunks_exact(n3.max(1)).map(unit))
                    .map(|c| c.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect())
                    .collect()
            }
        };
        let weights: Vec<Vec<f32>> = (0..self.coefficients.nrows())
            .map(|f| {
                (0..count)
                    .map(|c| self.coefficients[(f, c)] as f32)
                    .collect()
            })
            .collect();
        (targets, weights)
    }

    /// The smallest count whose max error is within `tolerance` (m); the full rank otherwise.
    pub fn within(&self, reference: &DMatrix<f32>, tolerance: f32) -> Compressed {
        self.budget(reference, Targets::Tolerance(tolerance), None)
    }

    /// What `budget` keeps: `Count(k)` the k strongest directions (all of them when fewer),
    /// `Tolerance(t)` the fewest whose max error is within t (m), `Full` every direction. With
    /// `unit = Some(grid)` the targets are scaled to a largest component of 1
    /// ([`Compressed::normalized`]) and, with `grid`, put on the 16-bit grid: the rounding is
    /// counted in the error a tolerance must meet and in the error reported.
    pub fn budget(
        &self,
        reference: &DMatrix<f32>,
        budget: Targets,
        unit: Option<bool>,
    ) -> Compressed {
        let keep = |count| {
            let kept = self.truncate(reference, count);
            match unit {
                Some(grid) => kept.normalized(reference, grid),
                None => kept,
            }
        };
        match budget {
            Targets::Full => keep(self.rank()),
            Targets::Count(k) => keep(k),
            Targets::Tolerance(t) => self.fewest(t, keep),
        }
    }

    /// Bisects on the count: the error falls as targets are added.
    fn fewest(&self, tolerance: f32, keep: impl Fn(usize) -> Compressed) -> Compressed {
        let (mut lo, mut hi) = (0, self.rank());
        while lo < hi {
            let mid = (lo + hi) / 2;
            if keep(mid).max_error <= tolerance {
                hi = mid;
            } else {
                lo = mid + 1;
            }
        }
        keep(lo)
    }
}

impl Compressed {
    /// [`unit_targets`], errors re-measured against `reference`.
    pub fn normalized(mut self, reference: &DMatrix<f32>, grid: bool) -> Compressed {
        unit_targets(&mut self.targets, &mut self.weights, grid);
        (self.max_error, self.mean_error) = errors(reference, &self.targets, &self.weights);
        self
    }

    /// [`weights_from_zero`] on this set.
    pub fn weights_from_zero(&mut self) -> FromZero {
        weights_from_zero(&self.targets, &mut self.weights)
    }
}

/// Each target scaled to a largest component of 1, its weights (`[frame][target]`) scaled back
/// so the offsets are unchanged: a weight is then the target's largest displacement (m) at that
/// frame. With `grid`, the targets are rounded to the SHORT normalized grid `k / 32767`, as a
/// glTF under KHR_mesh_quantization stores them.
pub fn unit_targets(targets: &mut [Vec<[f32; 3]>], weights: &mut [Vec<f32>], grid: bool) {
    for (k, target) in targets.iter_mut().enumerate() {
        let scale = target.iter().flatten().fold(0.0f32, |m, v| m.max(v.abs()));
        if scale == 0.0 {
            continue;
        }
        for v in target.iter_mut().flatten() {
            *v /= scale;
            if grid {
                *v = (*v * SHORT_STEPS).round() / SHORT_STEPS;
            }
        }
        weights.iter_mut().for_each(|w| w[k] *= scale);
    }
}

/// What [`weights_from_zero`] moved: the base mesh's share of the offsets, and the weights that
/// take it back out.
pub struct FromZero {
    /// Rest-space offset `Σ_k min_k S_k` the base mesh takes on.
    pub base: Vec<[f32; 3]>,
    /// `-min_k` per target: the shifted weights at which the offsets vanish, i.e. the file's
    /// base mesh plays the unmoved rest mesh (what a reader should show with no animation).
    pub rest_weights: Vec<f32>,
}

/// Shifts each target's weights (`[frame][target]`) to start at 0 over the frames and returns
/// the rest-space offset `Σ_k min_k S_k` the base mesh takes on instead (the offsets are
/// unchanged). Readers clamp morph weights: Blender's glTF importer holds shape-key values
/// inside slider ranges that do not reach below 0 (a negative weight is lost), Godot clamps
/// to [-1, 1]; unit targets with weights from 0 play in both.
pub fn weights_from_zero(targets: &[Vec<[f32; 3]>], weights: &mut [Vec<f32>]) -> FromZero {
    let n = targets.first().map_or(0, Vec::len);
    let mut base = vec![[0.0f32; 3]; n];
    let mut rest_weights = vec![0.0f32; targets.len()];
    for (k, target) in targets.iter().enumerate() {
        let lowest = weights.iter().map(|w| w[k]).fold(f32::INFINITY, f32::min);
        if !lowest.is_finite() {
            continue;
        }
        weights.iter_mut().for_each(|w| w[k] -= lowest);
        rest_weights[k] = -lowest;
        for (b, t) in base.iter_mut().zip(target) {
            (0..3).for_each(|a| b[a] += lowest * t[a]);
        }
    }
    FromZero { base, rest_weights }
}

/// Rest-space offsets `Σ_k c_fk S_k` of every frame as a 3N × frames matrix, one contiguous
/// column per frame (one matrix product instead of a loop per frame and vertex: the bake's hot
/// spot).
pub fn offset_matrix(shapes: &[Vec<[f32; 3]>], coefficients: &[Vec<f32>]) -> DMatrix<f32> {
    use tch::Tensor;
    let (k, frames) = (shapes.len(), coefficients.len());
    let n3 = shapes.first().map_or(0, |s| s.len() * 3);
    if k == 0 || n3 == 0 || frames == 0 {
        return DMatrix::zeros(n3, frames);
    }
    // libtorch's BLAS (`bench bake`: nalgebra's product of the skirt's 256 shapes over 1,247
    // frames was most of the compression phase). Row-major frames × 3N is the column-major
    // 3N × frames nalgebra keeps.
    let s: Vec<f32> = shapes.iter().flatten().flatten().copied().collect();
    let c: Vec<f32> = coefficients
        .iter()
        .flat_map(|w| {
            assert_eq!(w.len(), k, "one coefficient per shape");
            w.iter().copied()
        })
        .collect();
    let s = Tensor::from_slice(&s).view([k as i64, n3 as i64]);
    let c = Tensor::from_slice(&c).view([frames as i64, k as i64]);
    let o = c.matmul(&s).contiguous().view([-1]);
    DMatrix::from_vec(n3, frames, Vec::<f32>::try_from(&o).expect("f32 offsets"))
}

/// Max and mean per-vertex distance between the network's offsets and the compressed ones.
fn errors(reference: &DMatrix<f32>, targets: &[Vec<[f32; 3]>], weights: &[Vec<f32>]) -> (f32, f32) {
    let mut residual = reference.clone();
    if !targets.is_empty() {
        residual -= offset_matrix(targets, weights);
    }
    let (mut max, mut sum, mut count) = (0.0f32, 0.0f64, 0usize);
    for column in residual.column_iter() {
        for v in column.as_slice().chunks_exact(3) {
            let e = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            max = max.max(e);
            sum += e as f64;
            count += 1;
        }
    }
    (max, (sum / count.max(1) as f64) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A rank-2 set of offsets hidden in a 5-component basis.
    fn fixture() -> (Vec<Vec<[f32; 3]>>, Vec<Vec<f32>>) {
        let n = 40;
        let a: Vec<[f32; 3]> = (0..n).map(|v| [v as f32 * 0.001, 0.0, 0.002]).collect();
        let b: Vec<[f32; 3]> = (0..n)
            .map(|v| [0.0, (v as f32 * 0.3).sin() * 0.01, 0.0])
            .collect();
        // Components: a, b, a+b, 2a-b, a-b (rank 2).
        let mix = |p: f32, q: f32| {
            a.iter()
                .zip(&b)
                .map(|(x, y)| [0, 1, 2].map(|i| p * x[i] + q * y[i]))
                .collect::<Vec<_>>()
        };
        let basis = vec![
            mix(1.0, 0.0),
            mix(0.0, 1.0),
            mix(1.0, 1.0),
            mix(2.0, -1.0),
            mix(1.0, -1.0),
        ];
        let coefficients = (0..30)
            .map(|f| {
                (0..5)
                    .map(|k| ((f * 7 + k * 3) % 11) as f32 / 11.0 - 0.5)
                    .collect()
            })
            .collect();
        (basis, coefficients)
    }

    #[test]
    fn a_unit_that_never_fires_pads_the_count_with_zero_weights() {
        // The fixture's coefficients with two more components whose coefficient is 0 on every
        // frame (a ReLU unit that never fires): the rank is still 2, the offsets still exact
        // with 2 directions, and past them come the unused units' own vectors, unit-length with
        // weight 0: 2 + 2 here, where the fixture's 5 used components span only 2 directions;
        // min(frames, K), as the QR of the whole basis gave, when they span 5 (a trained basis).
        let (mut basis, mut coefficients) = fixture();
        basis.push(basis[0].iter().map(|p| [p[2], p[0], 0.5]).collect());
        basis.push(basis[1].iter().map(|p| [p[1], -0.2, p[0]]).collect());
        coefficients.iter_mut().for_each(|c| c.extend([0.0, 0.0]));
        let used = UsedOffsets {
            basis: &basis,
            coefficients: &coefficients,
        };
        let reference = offset_matrix(&basis, &coefficients);
        let s = spectrum(&used);
        assert_eq!(s.rank(), 4, "{:?}", s.singular_values);
        assert!(s.singular_values[2] < 1e-6 * s.singular_values[0]);
        let two = s.truncate(&reference, 2);
        assert!(two.max_error < 1e-6, "{}", two.max_error);
        let (targets, weights) = s.leading(10);
        assert_eq!((targets.len(), weights[0].len()), (4, 4));
        for (k, target) in targets.iter().enumerate().skip(2) {
            let length = target.iter().flatten().map(|v| v * v).sum::<f32>().sqrt();
            assert!((length - 1.0).abs() < 1e-5, "target {k}: length {length}");
            assert!(weights.iter().all(|w| w[k].abs() < 1e-6), "target {k}");
        }
        // The directions that carry the offsets are orthonormal.
        let d = |a: &[[f32; 3]], b: &[[f32; 3]]| -> f32 {
            a.iter()
                .flatten()
                .zip(b.iter().flatten())
                .map(|(x, y)| x * y)
                .sum()
        };
        assert!((d(&targets[0], &targets[0]) - 1.0).abs() < 1e-5);
        assert!(d(&targets[0], &targets[1]).abs() < 1e-5);
    }

    #[test]
    fn finds_the_true_rank_and_reproduces_offsets_exactly() {
        let (basis, coefficients) = fixture();
        let used = UsedOffsets {
            basis: &basis,
            coefficients: &coefficients,
        };
        let reference = offset_matrix(&basis, &coefficients);
        for s in [spectrum(&used), spectrum_of(&reference)] {
            assert!(
                s.singular_values.get(2).copied().unwrap_or(0.0) < 1e-6 * s.singular_values[0],
                "{:?}",
                s.singular_values
            );
            let two = s.truncate(&reference, 2);
            assert!(two.max_error < 1e-6, "{}", two.max_error);
            let one = s.truncate(&reference, 1);
            assert!(
                one.max_error > 1e-4,
                "one direction cannot explain a rank-2 set"
            );
            let picked = s.within(&reference, 1e-6);
            assert_eq!(picked.targets.len(), 2);
        }
    }

    #[test]
    fn targets_on_the_short_grid_keep_the_offsets_within_the_tolerance() {
        let (basis, coefficients) = fixture();
        let reference = offset_matrix(&basis, &coefficients);
        let s = spectrum_of(&reference);
        let picked = s.budget(&reference, Targets::Tolerance(1e-5), Some(true));
        assert_eq!(picked.targets.len(), 2);
        for target in &picked.targets {
            let largest = target.iter().flatten().fold(0.0f32, |m, v| m.max(v.abs()));
            assert!((largest - 1.0).abs() < 1e-6, "largest component {largest}");
            for v in target.iter().flatten() {
                let k = v * SHORT_STEPS;
                assert!((k - k.round()).abs() < 1e-3, "{v} is off the grid");
            }
        }
        // The rounding costs something, far under the tolerance, and is what is reported.
        assert!(
            picked.max_error > 0.0 && picked.max_error <= 1e-5,
            "{}",
            picked.max_error
        );
        let exact = errors(&reference, &picked.targets, &picked.weights).0;
        assert_eq!(exact, picked.max_error);
        // From zero: every weight non-negative, and the base's offset plus the shifted targets
        // give the same offsets.
        let mut shifted = picked.clone();
        let FromZero { base, rest_weights } = shifted.weights_from_zero();
        assert!(shifted.weights.iter().flatten().all(|&w| w >= 0.0));
        assert!(shifted.weights.iter().flatten().any(|&w| w == 0.0));
        let moved = offset_matrix(&shifted.targets, &shifted.weights);
        let before = offset_matrix(&picked.targets, &picked.weights);
        for f in 0..moved.ncols() {
            for r in 0..moved.nrows() {
                let now = moved[(r, f)] + base[r / 3][r % 3];
                assert!((now - before[(r, f)]).abs() < 1e-6, "frame {f} row {r}");
            }
        }
        // The rest weights take the base's share back out: the unmoved rest mesh.
        let at_rest = offset_matrix(&shifted.targets, std::slice::from_ref(&rest_weights));
        for (r, v) in at_rest.column(0).iter().enumerate() {
            assert!((v + base[r / 3][r % 3]).abs() < 1e-6, "row {r}");
        }
    }
}
