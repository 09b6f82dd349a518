//! Collision correspondences for training: the nearest body vertex of every garment vertex in
//! every training pose, without a k-d tree query inside the training step.
//!
//! The body pose set is fixed, so the posed body (near the garment) is computed once per pose
//! and kept as a tensor, with one k-d tree per pose. Every few epochs each (pose, garment
//! vertex) gets a short list of candidate body vertices from the tree, queried at the model's
//! current output; inside a step the nearest candidate is picked with tensor ops (a gather and
//! an argmin). The garment moves little between refreshes, so the true nearest vertex stays in
//! the list; the reference code instead called a CPU k-d tree from its GPU loop every step.

use super::fused::Contacts;
use crate::body::Body;
use crate::geometry::{CandidateTree, PointIndex};
use crate::rig::JointTransform;
use rayon::prelude::*;
use std::sync::Arc;
use std::thread::JoinHandle;
use tch::{Device, Kind, Tensor};

/// Points, normals and tree of the body subset in one pose.
type PosedSubset = (Vec<[f32; 3]>, Vec<[f32; 3]>, CandidateTree);

struct CpuCopy {
    /// Shared with refresh workers, which start each query from the current lists.
    points: Arc<Vec<[f32; 3]>>,
    normals: Vec<[f32; 3]>,
    candidates: Arc<Vec<i64>>,
    /// Whether `candidates` came from a refresh (before one they are all row 0).
    refreshed: bool,
    /// The lists before the installed ones, whose buffer the next refresh fills: 66 MB for the
    /// skirt, which a fresh allocation would page in (and zero) at every refresh.
    spare: Option<Vec<i64>>,
}

pub struct Correspondences {
    /// Posed body vertices (the subset near the garment) of all poses, `[P * M, 3]`.
    points: Tensor,
    normals: Tensor,
    /// One tree per pose over the posed subset (shared with refresh workers).
    trees: Arc<Vec<CandidateTree>>,
    /// Candidate rows of `points`, `[P, N, C]`, on the device (on the CPU the arrays of `cpu`
    /// are the lists, and this tensor is made from them only when asked for).
    candidates: Tensor,
    /// `[P, N, C]`.
    shape: [usize; 3],
    /// On the CPU: `points`, `normals` and `candidates` as arrays, for [`super::fused`].
    cpu: Option<CpuCopy>,
    subset: usize,
    per_vertex: usize,
}

impl Correspondences {
    /// Poses the body subset `subset` (body vertex indices) for every pose.
    pub fn new(
        body: &Body,
        subset: &[u32],
        poses: &[Vec<JointTransform>],
        per_vertex: usize,
        garment_vertices: usize,
        device: Device,
    ) -> Correspondences {
        let rest: Vec<[f32; 3]> = subset
            .iter()
            .map(|&v| body.mesh().positions[v as usize])
            .collect();
        let rest_n: Vec<[f32; 3]> = subset.iter().map(|&v| body.normals[v as usize]).collect();
        let skin = body.skin.subset(subset);
        let posed: Vec<PosedSubset> = poses
            .par_iter()
            .map(|pose| {
                let m = body.skeleton.skinning_matrices(pose);
                let p = skin.skin_points(&rest, &m);
                let n = skin.skin_normals(&rest_n, &m);
                let tree = CandidateTree::new(&p);
                (p, n, tree)
            })
            .collect();
        let flat = |f: &dyn Fn(&PosedSubset) -> &Vec<[f32; 3]>| {
            let v: Vec<f32> = posed
                .iter()
                .flat_map(|x| f(x).iter().flatten().copied())
                .collect();
            Tensor::from_slice(&v).view([-1, 3]).to_device(device)
        };
        let points = flat(&|x| &x.0);
        let normals = flat(&|x| &x.1);
        let cpu = (device == Device::Cpu).then(|| CpuCopy {
            points: Arc::new(posed.iter().flat_map(|x| x.0.iter().copied()).collect()),
            normals: posed.iter().flat_map(|x| x.1.iter().copied()).collect(),
            candidates: Arc::new(vec![0; poses.len() * garment_vertices * per_vertex]),
            refreshed: false,
            spare: None,
        });
        let trees = Arc::new(posed.into_iter().map(|x| x.2).collect());
        Correspondences {
            points,
            normals,
            trees,
            // On the CPU the lists live in `cpu`; a device keeps them as a tensor.
            candidates: Tensor::zeros(
                match device {
                    Device::Cpu => [0, garment_vertices as i64, per_vertex as i64],
                    _ => [
                        poses.len() as i64,
                        garment_vertices as i64,
                        per_vertex as i64,
                    ],
                },
                (Kind::Int64, device),
            ),
            cpu,
            shape: [poses.len(), garment_vertices, per_vertex],
            subset: subset.len(),
            per_vertex,
        }
    }

    /// The batch's candidates and the posed body as arrays (CPU training only).
    pub fn contacts(&self, poses: &[i64]) -> Option<Contacts<'_>> {
        let cpu = self.cpu.as_ref()?;
        let per_pose = self.shape[1] * self.shape[2];
        Some(Contacts {
            candidates: poses
                .iter()
                .map(|&p| &cpu.candidates[p as usize * per_pose..(p as usize + 1) * per_pose])
                .collect(),
            per_vertex: self.per_vertex,
            points: &cpu.points,
            normals: &cpu.normals,
        })
    }

    /// Body vertices considered (the subset near the garment).
    pub fn subset_len(&self) -> usize {
        self.subset
    }

    /// New candidate lists from the garment's current positions in every pose, now.
    pub fn refresh(&mut self, garment: &[Vec<[f32; 3]>]) {
        let buffer = self.spare_buffer();
        let lists = candidate_lists(
            &self.trees,
            garment,
            self.subset,
            self.per_vertex,
            self.previous().as_ref(),
            buffer,
        );
        self.apply(lists);
    }

    /// New candidate lists by brute force on the tensors' device, from the garment in every
    /// pose `x: [P, N, 3]`: the `c` posed body vertices nearest each garment vertex (`cdist` +
    /// `topk`, a few poses at a time). On a GPU this takes a few kernels instead of a round trip
    /// through CPU k-d trees; on the CPU the trees are faster (and run on a worker thread).
    pub fn refresh_dense(&mut self, x: &Tensor) {
        let (m, c) = (self.subset as i64, self.per_vertex as i64);
        let size = x.size();
        let (poses, n) = (size[0], size[1]);
        let body = self.points.view([poses, m, 3]);
        // Poses per chunk so one distance block stays near 2^27 floats (512 MB).
        let chunk = ((1i64 << 27) / (n * m).max(1)).clamp(1, poses.max(1));
        let lists: Vec<Tensor> = tch::no_grad(|| {
            (0..poses)
                .step_by(chunk as usize)
                .map(|start| {
                    let len = chunk.min(poses - start);
                    let d = Tensor::cdist(
                        &x.narrow(0, start, len),
                        &body.narrow(0, start, len),
                        2.0,
                        None::<i64>,
                    );
                    let (_, nearest) = d.topk(c.min(m), -1, false, true);
                    let base =
                        Tensor::arange_start(start, start + len, (Kind::Int64, x.device())) * m;
                    let nearest = nearest + base.view([len, 1, 1]);
                    if c > m {
                        // A tiny subset holds fewer than c points: repeat the nearest.
                        let first = nearest.narrow(2, 0, 1).expand([len, n, c - m], false);
                        Tensor::cat(&[nearest, first], 2)
                    } else {
                        nearest
                    }
                })
                .collect()
        });
        let all = Tensor::cat(&lists, 0);
        match &mut self.cpu {
            Some(cpu) => {
                cpu.candidates = Arc::new(crate::models::pbns::flat(&all, Kind::Int64));
                cpu.refreshed = true;
            }
            None => self.candidates = all,
        }
    }

    /// The same, computed on a worker thread (the garment's prediction and the k-d tree queries
    /// run there while torch keeps training on its own thread); hand the result to
    /// [`Correspondences::apply`].
    pub fn spawn_refresh(
        &mut self,
        garment: impl FnOnce() -> Vec<Vec<[f32; 3]>> + Send + 'static,
    ) -> JoinHandle<Vec<i64>> {
        let trees = Arc::clone(&self.trees);
        let (m, c) = (self.subset, self.per_vertex);
        let previous = self.previous();
        let buffer = self.spare_buffer();
        std::thread::spawn(move || {
            candidate_lists(&trees, &garment(), m, c, previous.as_ref(), buffer)
        })
    }

    /// The spare lists' buffer for a refresh to fill (empty if there is none yet).
    fn spare_buffer(&mut self) -> Vec<i64> {
        self.cpu
            .as_mut()
            .and_then(|cpu| cpu.spare.take())
            .unwrap_or_default()
    }

    /// The installed lists and the posed body they index (CPU, after a first refresh): a
    /// refresh starts each query from them.
    fn previous(&self) -> Option<Previous> {
        let cpu = self.cpu.as_ref()?;
        cpu.refreshed.then(|| Previous {
            lists: Arc::clone(&cpu.candidates),
            points: Arc::clone(&cpu.points),
        })
    }

    /// Installs candidate lists from [`Correspondences::spawn_refresh`].
    pub fn apply(&mut self, lists: Vec<i64>) {
        match &mut self.cpu {
            Some(cpu) => {
                let old = std::mem::replace(&mut cpu.candidates, Arc::new(lists));
                // The refresh that read the old lists has finished: the buffer is free.
                cpu.spare = Arc::try_unwrap(old).ok();
                cpu.refreshed = true;
            }
            None => {
                let [p, n, c] = self.shape.map(|x| x as i64);
                self.candidates = Tensor::from_slice(&lists)
                    .view([p, n, c])
                    .to_device(self.points.device());
            }
        }
    }

    /// The candidate lists as a `[P, N, C]` tensor on the device.
    fn candidate_tensor(&self) -> Tensor {
        match &self.cpu {
            Some(cpu) => {
                let [p, n, c] = self.shape.map(|x| x as i64);
                Tensor::from_slice(&cpu.candidates).view([p, n, c])
            }
            None => self.candidates.shallow_clone(),
        }
    }

    /// Nearest body point and normal `[B, N, 3]` for the batch's poses `[B]` and garment `x`.
    pub fn resolve(&self, poses: &Tensor, x: &Tensor) -> (Tensor, Tensor) {
        tch::no_grad(|| {
            let cand = self.candidate_tensor().index_select(0, poses);
            let size = cand.size();
            let (b, n, c) = (size[0], size[1], size[2]);
            let p = self
                .points
                .index_select(0, &cand.view([-1]))
                .view([b, n, c, 3]);
            let d2 = (p - x.detach().unsqueeze(2))
                .square()
                .sum_dim_intlist(-1, false, Kind::Float);
            let best = cand.gather(2, &d2.argmin(-1, true), false).view([-1]);
            (
                self.points.index_select(0, &best).view([b, n, 3]),
                self.normals.index_select(0, &best).view([b, n, 3]),
            )
        })
    }
}

/// Body vertices within `reach` of any garment vertex at rest: the only ones a garment vertex
/// can be nearest to in a pose (the garment is skinned to the same bones).
pub fn body_subset(body: &Body, garment: &[[f32; 3]], reach: f32) -> Vec<u32> {
    let index = PointIndex::new(garment).expect("garment is finite");
    body.mesh()
        .positions
        .par_iter()
        .enumerate()
        .filter(|(_, &p)| index.nearest(p).1 <= reach)
        .map(|(i, _)| i as u32)
        .collect()
}

/// Candidate lists of a refresh and the posed body rows they index.
struct Previous {
    lists: Arc<Vec<i64>>,
    points: Arc<Vec<[f32; 3]>>,
}

/// Rows of the flattened `[P * m, 3]` body tensor: `c` per garment vertex per pose. With the
/// `previous` lists each query is bounded by the farthest previous candidate (the garment moves
/// little between refreshes), which gives the same candidates for a fraction of the tree walk.
fn candidate_lists(
    trees: &[CandidateTree],
    garment: &[Vec<[f32; 3]>],
    m: usize,
    c: usize,
    previous: Option<&Previous>,
    mut lists: Vec<i64>,
) -> Vec<i64> {
    let n = garment.first().map_or(0, Vec::len);
    lists.resize(garment.len() * n * c, 0);
    // One pose per task, written in place (no per-pose vectors to gather afterwards).
    lists
        .par_chunks_mut((n * c).max(1))
        .zip(garment.par_iter().zip(trees))
        .enumerate()
        .for_each(|(pose, (out, (x, tree)))| {
            let base = (pose * m) as i64;
            let mut list = Vec::with_capacity(c);
            for (v, (&p, out)) in x.iter().zip(out.chunks_exact_mut(c)).enumerate() {
                let bound = previous.map_or(f32::INFINITY, |prev| {
                    let rows = &prev.lists[(pose * n + v) * c..][..c];
                    rows.iter()
                        .map(|&r| squared_distance(prev.points[r as usize], p))
                        .fold(0.0f32, f32::max)
                });
                tree.nearest(p, c, bound, &mut list);
                // A tiny subset may hold fewer than c points: repeat the nearest.
                for (k, slot) in out.iter_mut().enumerate() {
                    *slot = base + *list.get(k).unwrap_or(&list[0]) as i64;
                }
            }
        });
    lists
}

fn squared_distance(a: [f32; 3], b: [f32; 3]) -> f32 {
    (0..3).map(|k| (a[k] - b[k]).powi(2)).sum()
}
