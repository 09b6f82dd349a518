//! `FABRIC.toml`: the physical parameters of the garment (training potential, metrics), the shipped presets
//! (`samples/fabrics/*.toml`, also usable by name: `--config denim`).
//!
//! ```toml
//! name = "cotton"
//! edge = 50.0        # λe: stretch stiffness (J/m² per m² of edge error)
//! bend = 1.0e-3      # λb: bending weight (summed over hinges: tune it per garment mesh)
//! density = 0.15     # kg/m² (gravity: vertex mass = vertex area × density)
//! # optional: collision = 25.0, margin = 0.004, pin = 1000.0,
//! # pinned = [..] (replaces the garment sidecar's pin set),
//! # [[regions]] vertices = [..], edge = 2.0, bend = 0.5   (per-vertex multipliers)
//! ```

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Standard gravity, m/s² (the potential's gravity term and the metrics' energy).
pub const GRAVITY: f32 = 9.81;

/// Presets compiled in, so `--config NAME` works anywhere.
pub const PRESETS: [(&str, &str); 4] = [
    ("cotton", include_str!("../samples/fabrics/cotton.toml")),
    ("silk", include_str!("../samples/fabrics/silk.toml")),
    ("denim", include_str!("../samples/fabrics/denim.toml")),
    ("jersey", include_str!("../samples/fabrics/jersey.toml")),
];

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Fabric {
    pub name: String,
    /// λe: weight of `Σ w_e (|e| − |e_T|)²`.
    pub edge: f32,
    /// λb: weight of `Σ w_h |n_a − n_b|²`.
    pub bend: f32,
    /// Areal density, kg/m².
    pub density: f32,
    /// λc: weight of `Σ min(d·n − ε, 0)²`.
    #[serde(default = "default_collision")]
    pub collision: f32,
    /// ε, metres.
    #[serde(default = "default_margin")]
    pub margin: f32,
    /// λpin: weight of `Σ |D_i|²` over pinned vertices.
    #[serde(default = "default_pin")]
    pub pin: f32,
    /// Pinned vertices; `None` keeps the garment sidecar's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pinned: Option<Vec<u32>>,
    /// Per-vertex multipliers of λe and λb (PBNS's per-vertex outfit weights).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub regions: Vec<Region>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Region {
    pub vertices: Vec<u32>,
    #[serde(default = "one")]
    pub edge: f32,
    #[serde(default = "one")]
    pub bend: f32,
}

fn default_collision() -> f32 {
    25.0
}
fn default_margin() -> f32 {
    0.004
}
fn default_pin() -> f32 {
    1.0e3
}
fn one() -> f32 {
    1.0
}

impl Fabric {
    /// A preset name or a TOML file.
    pub fn load(spec: &str) -> Result<Fabric> {
        let path = Path::new(spec);
        let (text, origin) = if path.exists() {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("cannot read {}", path.display()))?;
            (text, path.display().to_string())
        } else if let Some((_, text)) = PRESETS.iter().find(|(n, _)| *n == spec) {
            (text.to_string(), format!("preset '{spec}'"))
        } else {
            let names: Vec<&str> = PRESETS.iter().map(|p| p.0).collect();
            bail!(
                "--config {spec}: no such file, and not a preset (presets: {})",
                names.join(", ")
            );
        };
        let fabric: Fabric =
            toml::from_str(&text).with_context(|| format!("{origin}: invalid fabric config"))?;
        fabric.check().with_context(|| origin.clone())?;
        Ok(fabric)
    }

    fn check(&self) -> Result<()> {
        for (name, v) in [
            ("edge", self.edge),
            ("bend", self.bend),
            ("density", self.density),
            ("collision", self.collision),
            ("margin", self.margin),
            ("pin", self.pin),
        ] {
            if !v.is_finite() || v < 0.0 {
                bail!("{name} = {v} must be a finite non-negative number");
            }
        }
        Ok(())
    }

    /// Per-vertex (edge, bend) multipliers for an `n`-vertex garment.
    pub fn vertex_multipliers(&self, n: usize) -> Result<(Vec<f32>, Vec<f32>)> {
        let mut edge = vec![1.0; n];
        let mut bend = vec![1.0; n];
        for r in &self.regions {
            for &v in &r.vertices {
                if v as usize >= n {
                    bail!(
                        "fabric '{}': region vertex {v} out of range ({n} vertices)",
                        self.name
                    );
                }
                edge[v as usize] = r.edge;
                bend[v as usize] = r.bend;
            }
        }
        Ok((edge, bend))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_parse_and_unknown_names_fail() {
        for (name, _) in PRESETS {
            let f = Fabric::load(name).unwrap();
            assert_eq!(f.name, name);
            assert_eq!(f.margin, 0.004);
        }
        let err = Fabric::load("tweed").unwrap_err().to_string();
        assert!(
            err.contains("presets: cotton, silk, denim, jersey"),
            "{err}"
        );
    }
}
