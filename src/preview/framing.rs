//! Views (orthographic camera bases) and framings (the view-plane rectangle shown).

use super::{DrawMesh, Panel};

/// Fraction of the larger extent added on every side when fitting.
const MARGIN: f32 = 0.05;
/// Smallest extent (metres) a framing may have, so a point or a flat line still maps sanely.
const MIN_EXTENT: f32 = 1e-3;

/// Horizontal orthographic camera direction (see the module docs for each).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum View {
    Front,
    Side,
    Back,
    ThreeQuarter,
}

impl View {
    /// Unit vector from the subject towards the camera (world space).
    pub fn toward_camera(self) -> [f32; 3] {
        let h = std::f32::consts::FRAC_1_SQRT_2;
        match self {
            View::Front => [0.0, 0.0, 1.0],
            View::Side => [1.0, 0.0, 0.0],
            View::Back => [0.0, 0.0, -1.0],
            View::ThreeQuarter => [h, 0.0, h],
        }
    }

    /// Image-right direction in world space: up × toward_camera (right-handed).
    pub fn right(self) -> [f32; 3] {
        let c = self.toward_camera();
        [c[2], 0.0, -c[0]]
    }

    /// View-plane coordinates (u right, v up) and depth (larger = nearer the camera).
    #[inline]
    pub fn project(self, p: [f32; 3]) -> [f32; 3] {
        let (r, c) = (self.right(), self.toward_camera());
        [dot(p, r), p[1], dot(p, c)]
    }
}

#[inline]
pub(crate) fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Which framing a contact sheet uses for its panels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FramingMode {
    /// One framing per view over every panel with that view, so frames are comparable
    /// (a walking character is seen moving, sizes match).
    #[default]
    Shared,
    /// Each panel fitted to its own meshes (largest possible, not comparable).
    PerPanel,
}

/// The view-plane rectangle (metres, u right / v up) shown by a panel of `view`.
/// It is scaled uniformly to the panel (aspect kept) and centred.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Framing {
    pub view: View,
    pub min: [f32; 2],
    pub max: [f32; 2],
}

impl Framing {
    /// Bounds of the finite `points` as seen from `view`, plus a 5% margin.
    /// No finite point gives a 2 m square around the origin.
    pub fn fit<I: IntoIterator<Item = [f32; 3]>>(points: I, view: View) -> Framing {
        let mut min = [f32::INFINITY; 2];
        let mut max = [f32::NEG_INFINITY; 2];
        for p in points {
            let q = view.project(p);
            if q.iter().all(|x| x.is_finite()) {
                for k in 0..2 {
                    min[k] = min[k].min(q[k]);
                    max[k] = max[k].max(q[k]);
                }
            }
        }
        if min[0] > max[0] {
            return Framing {
                view,
                min: [-1.0; 2],
                max: [1.0; 2],
            };
        }
        let pad = MARGIN * (max[0] - min[0]).max(max[1] - min[1]).max(MIN_EXTENT);
        Framing {
            view,
            min: [min[0] - pad, min[1] - pad],
            max: [max[0] + pad, max[1] + pad],
        }
    }

    /// [`Framing::fit`] over every position of `meshes`.
    pub fn fit_meshes(meshes: &[DrawMesh], view: View) -> Framing {
        Framing::fit(
            meshes.iter().flat_map(|m| m.positions.iter().copied()),
            view,
        )
    }

    /// [`Framing::fit`] over every mesh of the panels whose view is `view`.
    pub fn fit_panels(panels: &[Panel], view: View) -> Framing {
        let meshes = panels
            .iter()
            .filter(|p| p.view == view)
            .flat_map(|p| p.meshes.iter());
        Framing::fit(meshes.flat_map(|m| m.positions.iter().copied()), view)
    }

    pub fn center(&self) -> [f32; 2] {
        [
            (self.min[0] + self.max[0]) * 0.5,
            (self.min[1] + self.max[1]) * 0.5,
        ]
    }

    /// Width and height, never below a millimetre.
    pub fn extent(&self) -> [f32; 2] {
        [
            (self.max[0] - self.min[0]).max(MIN_EXTENT),
            (self.max[1] - self.min[1]).max(MIN_EXTENT),
        ]
    }

    /// Pixels per metre that fit the whole rectangle into `w`×`h` with one scale for both axes.
    pub fn scale_for(&self, w: u32, h: u32) -> f32 {
        let e = self.extent();
        (w as f32 / e[0]).min(h as f32 / e[1])
    }
}
