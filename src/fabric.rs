//! `FABRIC.toml`: the physical parameters of the garment (training potential, metrics), the shipped presets
//! (`samples/fabrics/*.toml`, also usable by name: `--fabric denim`).
//!
//! ```toml
//! name = "cotton"
//! edge = 50.0        # λe: stretch stiffness (J/m² per m² of edge error)
//! bend = 1.0e-3      # λb: bending weight (summed over hinges: tune it per garment mesh)
//! density = 0.15     # kg/m² (gravity: vertex mass = vertex area × density)
//! # optional: collision = 25.0, margin = 0.004, pin = 1000.0,
//! # pinned = [..] (replaces the garment sidecar's pin set),
//! # [[regions]] vertices = [..], edge = 2.0, bend = 0.5   (per-vertex multipliers)
//! [simulate]         # Blender's cloth solver for `garmentbake simulate` (all optional)
//! mass = 0.3         # per vertex, Blender's units (its presets' values; not SI)
//! tension = 15.0     # ...compression, shear, bending and their *_damping, air_damping
//! quality = 10       # solver steps per frame; collision_quality, distance (m), self_collision
//! ```

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Standard gravity, m/s² (the potential's gravity term and the metrics' energy).
pub const GRAVITY: f32 = 9.81;

/// Presets compiled in, so `--fabric NAME` works anywhere.
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
    /// Blender's cloth settings for ground-truth simulation; not used by training.
    #[serde(default)]
    pub simulate: ClothSim,
}

/// The settings of Blender's Cloth and Collision modifiers, named as in Blender's Python API.
/// Stiffness and mass are Blender's units (its presets' values carry over); distances are metres.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ClothSim {
    /// Solver steps per frame (raise for fast limbs).
    pub quality: u32,
    /// Collision passes per step.
    pub collision_quality: u32,
    /// Mass per vertex.
    pub mass: f32,
    pub air_damping: f32,
    pub tension: f32,
    pub compression: f32,
    pub shear: f32,
    pub bending: f32,
    pub tension_damping: f32,
    pub compression_damping: f32,
    pub shear_damping: f32,
    pub bending_damping: f32,
    /// Cloth-to-body distance the solver keeps (metres).
    pub distance: f32,
    /// The body's outer collision shell (metres).
    pub body_thickness: f32,
    /// Friction between cloth and body.
    pub friction: f32,
    pub self_collision: bool,
    /// Cloth-to-cloth distance (metres).
    pub self_distance: f32,
}

impl Default for ClothSim {
    /// Blender's "Cotton" preset, with more solver and collision steps for mocap limbs and
    /// distances for garments fitted a few millimetres off the skin.
    fn default() -> ClothSim {
        ClothSim {
            quality: 10,
            collision_quality: 4,
            mass: 0.3,
            air_damping: 1.0,
            tension: 15.0,
            compression: 15.0,
            shear: 15.0,
            bending: 0.5,
            tension_damping: 5.0,
            compression_damping: 5.0,
            shear_damping: 5.0,
            bending_damping: 0.5,
            distance: 0.004,
            body_thickness: 0.002,
            friction: 5.0,
            self_collision: true,
            self_distance: 0.003,
        }
    }
}

impl ClothSim {
    fn check(&self) -> Result<()> {
        if self.quality == 0 || self.collision_quality == 0 {
            bail!("[simulate] quality and collision_quality must be at least 1");
        }
        for (name, v) in [
            ("mass", self.mass),
            ("air_damping", self.air_damping),
            ("tension", self.tension),
            ("compression", self.compression),
            ("shear", self.shear),
            ("bending", self.bending),
            ("tension_damping", self.tension_damping),
            ("compression_damping", self.compression_damping),
            ("shear_damping", self.shear_damping),
            ("bending_damping", self.bending_damping),
            ("distance", self.distance),
            ("body_thickness", self.body_thickness),
            ("friction", self.friction),
            ("self_distance", self.self_distance),
        ] {
            if !v.is_finite() || v < 0.0 {
                bail!("[simulate] {name} = {v} must be a finite non-negative number");
            }
        }
        if self.mass == 0.0 {
            bail!("[simulate] mass must be positive");
        }
        Ok(())
    }
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
                "--fabric {spec}: no such file, and not a preset (presets: {})",
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
        self.simulate.check()
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
