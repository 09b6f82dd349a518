//! The exact signed distance to a closed-ish mesh sampled on a regular grid: distance to the
//! nearest triangle, negative where the generalised winding number says inside. Trilinear
//! interpolation between nodes (on the tensor side) makes it differentiable; the values at the
//! nodes are exact, not learnt.

use super::SurfaceIndex;

#[derive(Clone, Debug, PartialEq)]
pub struct SdfGrid {
    /// Position of node (0, 0, 0) and the node spacing (metres).
    pub lo: [f32; 3],
    pub spacing: f32,
    /// Nodes along x, y, z.
    pub dims: [usize; 3],
    /// Values, x fastest then y then z (`[z][y][x]`, a `[D, H, W]` volume).
    pub values: Vec<f32>,
}

impl SdfGrid {
    /// The grid over the box `[lo, hi]` grown by `pad`, nodes `spacing` apart.
    pub fn new(
        surface: &SurfaceIndex,
        lo: [f32; 3],
        hi: [f32; 3],
        pad: f32,
        spacing: f32,
    ) -> SdfGrid {
        let lo = lo.map(|c| c - pad);
        let dims: [usize; 3] =
            std::array::from_fn(|k| ((hi[k] + pad - lo[k]) / spacing).ceil() as usize + 1);
        let nodes: Vec<[f32; 3]> = (0..dims[2])
            .flat_map(|z| (0..dims[1]).flat_map(move |y| (0..dims[0]).map(move |x| [x, y, z])))
            .map(|[x, y, z]| {
                [
                    lo[0] + x as f32 * spacing,
                    lo[1] + y as f32 * spacing,
                    lo[2] + z as f32 * spacing,
                ]
            })
            .collect();
        let values = surface
            .query_many(&nodes)
            .into_iter()
            .map(|(w, d)| if w >= 0.5 { -d } else { d })
            .collect();
        SdfGrid {
            lo,
            spacing,
            dims,
            values,
        }
    }

    /// Trilinear value at `p` (clamped to the grid): the reference for the tensor sampler.
    pub fn sample(&self, p: [f32; 3]) -> f32 {
        let mut base = [0usize; 3];
        let mut frac = [0f32; 3];
        for k in 0..3 {
            let t = ((p[k] - self.lo[k]) / self.spacing).clamp(0.0, (self.dims[k] - 1) as f32);
            base[k] = (t.floor() as usize).min(self.dims[k].saturating_sub(2));
            frac[k] = t - base[k] as f32;
        }
        let at =
            |x: usize, y: usize, z: usize| self.values[(z * self.dims[1] + y) * self.dims[0] + x];
        let mut v = 0.0;
        for corner in 0..8 {
            let o = [corner & 1, (corner >> 1) & 1, (corner >> 2) & 1];
            let w: f32 = (0..3)
                .map(|k| if o[k] == 1 { frac[k] } else { 1.0 - frac[k] })
                .product();
            v += w * at(base[0] + o[0], base[1] + o[1], base[2] + o[2]);
        }
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::test_meshes::uv_sphere;

    #[test]
    fn signed_distance_of_a_sphere() {
        let sphere = uv_sphere(48, 24);
        let surface = SurfaceIndex::new(&sphere.positions, &sphere.triangles);
        let grid = SdfGrid::new(&surface, [-1.0; 3], [1.0; 3], 0.2, 0.05);
        for (p, want) in [
            ([0.0, 0.0, 0.0], -1.0),
            ([0.5, 0.0, 0.0], -0.5),
            ([1.1, 0.0, 0.0], 0.1),
            ([0.0, 0.62, 0.62], -0.1232),
            ([0.0, 0.8, 0.8], 0.1314),
        ] {
            let got = grid.sample(p);
            assert!((got - want).abs() < 0.01, "{p:?}: {got} vs {want}");
        }
    }
}
