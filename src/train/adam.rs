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

    /// One Adam step; `lr[i]` is parameter `i`'s learning rate.
    pub fn update(&mut self, params: &[Tensor], lr: &[f64]) {
        self.step += 1;
        let c1 = 1.0 - BETA1.powi(self.step as i32);
        let c2 = 1.0 - BETA2.powi(self.step as i32);
        tch::no_grad(|| {
            for (((p, m), v), &lr) in params.iter().zip(&mut self.m).zip(&mut self.v).zip(lr) {
                let mut g = p.grad();
                if !g.defined() {
                    continue;
                }
                let _ = m.lerp_(&g, 1.0 - BETA1);
                let _ = v.g_mul_scalar_(BETA2);
                let _ = v.addcmul_(&(&g * (1.0 - BETA2)), &g);
                let denom = (v.g_div_scalar(c2)).sqrt() + EPSILON;
                let mut p = p.shallow_clone();
                let _ = p.addcdiv_(&(&*m * (-lr / c1)), &denom);
                let _ = g.zero_();
            }
        });
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
