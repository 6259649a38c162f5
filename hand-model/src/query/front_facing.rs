//! Monocular front-facing correspondences (thesis §3.3.1 "Monocular Correspondences", Fig. 3.9).
//!
//! A single depth camera sees only the front-facing part of the model, so a data point must not
//! be registered to a back-facing footpoint. When the model-wide footpoint `Π_M(p)` is
//! back-facing (`n·v ≥ 0`), it is replaced by the closest to `p` among these candidates:
//! 1. the object-space silhouette: per element, the closest point of every piece (sphere arc,
//!    cone contour line) of its contour generator for the viewing direction, computed exactly
//!    for an orthographic view (see `silhouette.rs`);
//! 2. the front-facing tangent planes of wedges: the orthogonal foot of `p` on such a plane when
//!    it falls inside the plane's tangent triangle;
//! 3. (beyond the thesis) each element's own footpoint `Π_{E_e}(p)` when it is front-facing: a
//!    front-facing local closest point of a neighbouring element is a valid, often closer,
//!    correspondence that the two candidate kinds above would miss.
//!
//! Candidates buried inside an element (`φ_M(q) < −tol`, the thesis's merge test) are discarded.
//!
//! # Approximations
//! - Orthographic silhouette: under [`View::Perspective`] the contour generator of each element
//!   is computed for the orthographic view along the ray from the camera center through the data
//!   point `p` (the thesis uses one orthographic camera for the whole model; a per-point ray is
//!   closer to the true perspective contour near `p`). The front-facing tests of candidates 2
//!   and 3 and of `Π_M(p)` use the exact perspective direction `q − camera_center`.
//! - Only the closest point of each silhouette piece is a candidate. When that point is buried
//!   in another element, the piece's remaining (unburied) part is not searched, and curves where
//!   an element's front surface enters another element (the arrangement splits of Fig. 3.10) are
//!   not candidates. The result is then a valid front-facing or silhouette point that may be
//!   farther than the true closest one; on a single element (or disjoint elements) it is exact.
//! - If every candidate is rejected, the plain (back-facing) projection is returned.

use super::geometry::{ElementFrame, SphereMeshGeometry};
use super::point_wedge::WedgeFrame;
use super::silhouette::{contour_points, ContourPoint, ViewBasis, MAX_CONTOUR_POINTS};
use super::{is_finite, Part, Projection, View};
use nalgebra::Vector3;

/// A candidate is buried when it is deeper than this inside an element (model units, mm): points
/// on an element's own surface evaluate to about ±1e-12 there.
pub const BURIED_TOLERANCE: f64 = 1e-6;

/// Silhouette pieces + own footpoint + two tangent planes.
const MAX_CANDIDATES: usize = MAX_CONTOUR_POINTS + 3;

impl SphereMeshGeometry {
    /// Front-facing closest-point correspondence for a monocular view (thesis §3.3.1, Fig. 3.9):
    /// the plain projection [`project`](Self::project) when its footpoint faces the camera,
    /// otherwise the closest among the silhouette, front-facing tangent-plane and front-facing
    /// per-element candidates described in the module docs (see there for the approximations).
    ///
    /// The returned footpoint is front-facing or on the silhouette (normal orthogonal to the
    /// orthographic viewing direction), [`Projection::distance`] is `‖p − q‖` with the sign of
    /// `φ_M(p)`, and the identity `q = Σ w_i c_i + (Σ w_i r_i)·n` holds. `None` for a non-finite
    /// point, an invalid view (zero or non-finite direction), `p` at the camera center, or a model
    /// without elements.
    pub fn project_front_facing(&self, p: &Vector3<f64>, view: &View) -> Option<Projection> {
        if !view.is_valid() {
            return None;
        }
        let fixed = match view {
            View::Orthographic(d) => Some(ViewBasis::new(d.normalize())),
            View::Perspective { .. } => None,
        };
        self.front_facing_with(p, view, fixed.as_ref())
    }

    /// [`project_front_facing`](Self::project_front_facing) for many points, writing into `out`
    /// (same length as `points`). Allocates nothing; for an orthographic view the silhouette
    /// frame is set up once for the batch.
    ///
    /// # Panics
    /// If `out.len() != points.len()`.
    #[track_caller]
    pub fn project_points_front_facing(
        &self,
        points: &[Vector3<f64>],
        view: &View,
        out: &mut [Option<Projection>],
    ) {
        assert_eq!(points.len(), out.len(), "one output slot per point");
        if !view.is_valid() {
            out.fill(None);
            return;
        }
        let fixed = match view {
            View::Orthographic(d) => Some(ViewBasis::new(d.normalize())),
            View::Perspective { .. } => None,
        };
        for (p, o) in points.iter().zip(out.iter_mut()) {
            *o = self.front_facing_with(p, view, fixed.as_ref());
        }
    }

    fn front_facing_with(
        &self,
        p: &Vector3<f64>,
        view: &View,
        fixed: Option<&ViewBasis>,
    ) -> Option<Projection> {
        if !is_finite(p) {
            return None;
        }
        let (e0, d0) = self.nearest(p)?;
        let plain = self.globalize(e0, self.frames[e0].project(p));
        if !view.is_back_facing(&plain.point, &plain.normal) {
            return Some(plain);
        }
        let basis = match fixed {
            Some(b) => *b,
            None => {
                let ray = view.direction_to(p).or_else(|| view.direction_to(&plain.point))?;
                ViewBasis::new(ray)
            }
        };
        let mut best: Option<(f64, usize, Projection)> = None;
        self.visit_element(p, view, &basis, e0, Some(d0), &mut best);
        for e in 0..self.frames.len() {
            if e != e0 {
                self.visit_element(p, view, &basis, e, None, &mut best);
            }
        }
        Some(match best {
            Some((d2, e, pr)) => {
                let mut pr = self.globalize(e, pr);
                pr.distance = d2.sqrt().copysign(d0);
                pr
            }
            None => plain,
        })
    }

    /// Adds the candidates of element `e` that can beat `best` (squared distance, element,
    /// local projection). `own` is `φ_e(p)` when already known; its footpoint is then the
    /// back-facing plain projection and is not a candidate.
    fn visit_element(
        &self,
        p: &Vector3<f64>,
        view: &View,
        basis: &ViewBasis,
        e: usize,
        own: Option<f64>,
        best: &mut Option<(f64, usize, Projection)>,
    ) {
        let bound = best.as_ref().map_or(f64::INFINITY, |b| b.0);
        // Every candidate lies on the element's surface: farther than its bounding ball and than
        // the element's own closest point.
        let ball = &self.bounds[e];
        let ball_gap = ((p - ball.center).norm() - ball.radius).max(0.0);
        if ball_gap * ball_gap >= bound {
            return;
        }
        let frame = &self.frames[e];
        let phi = own.unwrap_or_else(|| frame.distance(p));
        if phi * phi >= bound {
            return;
        }

        let mut cands = [(f64::INFINITY, Part::Silhouette, ContourPoint::default()); MAX_CANDIDATES];
        let mut count = 0;
        let mut contour = [ContourPoint::default(); MAX_CONTOUR_POINTS];
        let k = contour_points(frame.centers(), frame.radii(), basis, p, &mut contour);
        for c in &contour[..k] {
            cands[count] = (c.dist2, Part::Silhouette, *c);
            count += 1;
        }
        if own.is_none() {
            let pr = frame.project(p);
            if !view.is_back_facing(&pr.point, &pr.normal) {
                let c = from_projection(&pr, p);
                cands[count] = (c.dist2, pr.part, c);
                count += 1;
            }
        }
        if let ElementFrame::Wedge(w) = frame {
            if let Some(tp) = &w.planes {
                for side in 0..2 {
                    let foot = WedgeFrame::planar_foot(tp, &w.centers[0], p, side);
                    if !foot.inside() {
                        continue;
                    }
                    let pr = w.plane_projection(tp, &foot);
                    if !view.is_back_facing(&pr.point, &pr.normal) {
                        let c = from_projection(&pr, p);
                        cands[count] = (c.dist2, Part::Plane, c);
                        count += 1;
                    }
                }
            }
        }

        let cands = &mut cands[..count];
        cands.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        for (d2, part, c) in cands.iter() {
            if *d2 >= best.as_ref().map_or(f64::INFINITY, |b| b.0) {
                break;
            }
            if !self.is_buried(&c.point, BURIED_TOLERANCE) {
                let pr = Projection {
                    point: c.point,
                    normal: c.normal,
                    skeleton_point: c.skeleton_point,
                    element: 0,
                    spheres: c.spheres.map(|i| i as u32),
                    weights: c.weights,
                    distance: d2.sqrt(),
                    part: *part,
                };
                *best = Some((*d2, e, pr));
                break;
            }
        }
    }
}

fn from_projection(pr: &Projection, p: &Vector3<f64>) -> ContourPoint {
    ContourPoint {
        point: pr.point,
        normal: pr.normal,
        skeleton_point: pr.skeleton_point,
        spheres: pr.spheres.map(|i| i as usize),
        weights: pr.weights,
        dist2: (p - pr.point).norm_squared(),
    }
}
