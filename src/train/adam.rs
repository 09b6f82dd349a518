//! Adam (Kingma & Ba) written out, so its state goes into checkpoints and resume is exact.

use anyhow::Result;
use tch::Tensor;

/// The optimiser state: step count and the two moment estimates per parameter.
pub struct Adam {
    pub step: i64,
    m: Vec<Tensor>,
    v: Vec<Tensor>,
}

const BETA1: f64 = 0.9;
const BETA2: f64 = 0.999;
const EPSILON: f64 = 1e-8;

impl Adam {
    pub fn new(params: &[(String, &Tensor)]) -> Adam {
        Adam {
            step: 0,
            m: params.iter().map(|(_, p)| p.zeros_like()).collect(),
            v: params.iter().map(|(_, p)| p.zeros_like()).collect(),
        }
    }

    /// One Adam step on the gradients accumulated in the parameters (which it zeroes);
    /// `lr[i]` is parameter `i`'s learning rate.
    pub fn update(&mut self, params: &[Tensor], lr: &[f64]) {
        self.step += 1;
        tch::no_grad(|| {
            for (i, (p, &lr)) in params.iter().zip(lr).enumerate() {
                let mut g = p.grad();
                if !g.defined() {
                    continue;
                }
                self.apply(i, p, &g, lr);
                let _ = g.zero_();
            }
        });
    }

    /// One Adam step with `grads[i]` the gradient of `params[i]` (as `Tensor::run_backward`
    /// returns them, so nothing accumulates in the parameters). On the CPU each parameter is
    /// updated in one pass over its four arrays instead of a dozen tensor ops.
    pub fn update_with(&mut self, params: &[Tensor], grads: &[Tensor], lr: &[f64]) {
        self.step += 1;
        tch::no_grad(|| {
            for (i, ((p, g), &lr)) in params.iter().zip(grads).zip(lr).enumerate() {
                if !g.defined() {
                    continue;
                }
                if !self.apply_fused(i, p, g, lr) {
                    self.apply(i, p, g, lr);
                }
            }
        });
    }

    /// `p -= lr · m̂ / (√v̂ + ε)` with tensor ops.
    fn apply(&mut self, i: usize, p: &Tensor, g: &Tensor, lr: f64) {
        let (c1, c2) = self.corrections();
        let (m, v) = (&mut self.m[i], &mut self.v[i]);
        let _ = m.lerp_(g, 1.0 - BETA1);
        let _ = v.g_mul_scalar_(BETA2);
        let _ = v.addcmul_(&(g * (1.0 - BETA2)), g);
        let denom = (v.g_div_scalar(c2)).sqrt() + EPSILON;
        let mut p = p.shallow_clone();
        let _ = p.addcdiv_(&(&*m * (-lr / c1)), &denom);
    }

    /// The same update in one loop over contiguous f32 CPU arrays; false (nothing done) for
    /// tensors elsewhere.
    fn apply_fused(&mut self, i: usize, p: &Tensor, g: &Tensor, lr: f64) -> bool {
        let (m, v) = (&self.m[i], &self.v[i]);
        let cpu_f32 = |t: &Tensor| {
            t.device() == tch::Device::Cpu && t.kind() == tch::Kind::Float && t.is_contiguous()
        };
        let n = p.numel();
        if ![p, g, m, v].iter().all(|t| cpu_f32(t) && t.numel() == n) {
            return false;
        }
        let (c1, c2) = self.corrections();
        let (step, sqrt_c2) = ((lr / c1) as f32, c2.sqrt() as f32);
        let (b1, b2, eps) = (BETA1 as f32, BETA2 as f32, EPSILON as f32);
        // SAFETY: four distinct contiguous f32 CPU buffers of n elements (checked above; the
        // moments are allocated per parameter, the gradient is fresh from backward), and no
        // other reference to their data lives during the loop.
        let (p, g, m, v) = unsafe {
            let slice = |t: &Tensor| std::slice::from_raw_parts_mut(t.data_ptr() as *mut f32, n);
            (slice(p), &*slice(g), slice(m), slice(v))
        };
        for (((p, &g), m), v) in p.iter_mut().zip(g).zip(m).zip(v) {
            *m += (1.0 - b1) * (g - *m);
            *v = b2 * *v + (1.0 - b2) * g * g;
            *p -= step * *m / (v.sqrt() / sqrt_c2 + eps);
        }
        true
    }

    /// Bias corrections `1 − β₁ᵗ`, `1 − β₂ᵗ` of the current step.
    fn corrections(&self) -> (f64, f64) {
        (
            1.0 - BETA1.powi(self.step as i32),
            1.0 - BETA2.powi(self.step as i32),
        )
    }

    pub fn state(&self, params: &[(String, &Tensor)]) -> Vec<(String, Tensor)> {
        let mut out = vec![(
            "adam.step".to_string(),
            Tensor::from_slice(&[self.step as f32]),
        )];
        for ((name, _), (m, v)) in params.iter().zip(self.m.iter().zip(&self.v)) {
            out.push((format!("adam.m.{name}"), m.shallow_clone()));
            out.push((format!("adam.v.{name}"), v.shallow_clone()));
        }
        out
    }

    pub fn restore(
        &mut self,
        params: &[(String, &Tensor)],
        saved: &[(String, Tensor)],
    ) -> Result<()> {
        let find = |name: &str| -> Result<&Tensor> {
            saved
                .iter()
                .find(|(n, _)| n == name)
                .map(|(_, t)| t)
                .ok_or_else(|| {
                    anyhow::anyhow!("checkpoint has no '{name}' (a model file, not a checkpoint?)")
                })
        };
        self.step = find("adam.step")?.double_value(&[0]) as i64;
        for (i, (name, p)) in params.iter().enumerate() {
            self.m[i] = find(&format!("adam.m.{name}"))?.to_device(p.device());
            self.v[i] = find(&format!("adam.v.{name}"))?.to_device(p.device());
        }
        Ok(())
    }
}
