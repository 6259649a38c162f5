//! Monocular front-facing correspondences (thesis §3.3.1 "Monocular Correspondences", Fig. 3.9).
//!
//! A single depth camera sees only the front-facing part of the model, so a data point must not
//! be registered to a back-facing footpoint. When the model-wide footpoint `Π_M(p)` is
//! back-facing (`n·v ≥ 0`, `v` the viewing direction toward it), it is replaced by the closest to
//! `p` among:
//! 1. the object-space silhouette `∂M` of the model (see `union_silhouette.rs`): the contour
//!    generators of all elements for the view's orthographic direction, with the parts buried
//!    inside other elements (`φ_M < −tol`) removed; its points have normals orthogonal to the
//!    orthographic direction;
//! 2. the front-facing tangent planes of wedges: the orthogonal foot of `p` on such a plane when
//!    it falls inside the plane's tangent triangle and is not buried;
//! 3. (beyond the thesis) each element's own footpoint `Π_{E_e}(p)` when it is front-facing and
//!    not buried: a front-facing local closest point of a neighbouring element is a valid, often
//!    closer, correspondence that the two candidate kinds above would miss;
//! 4. (beyond the thesis) when a front-facing candidate of kind 2 or 3 on element `a` is buried
//!    in element `b`, the nearest point of the crease `∂E_a ∩ ∂E_b` found by a local search from
//!    it (Newton steps onto both surfaces alternating with steps along the crease toward `p`),
//!    if front-facing and not buried: where an element's front surface dives into another, the
//!    visible surface ends on that crease, not on a silhouette.
//!
//! # Approximations
//! - Orthographic silhouette (as in the thesis): the silhouette is computed once per call for
//!   one direction, [`SphereMeshGeometry::silhouette_direction`]: the view's direction for
//!   [`View::Orthographic`], and for [`View::Perspective`] the direction from the camera center
//!   to the center of the model's bounding ball. Silhouette points have normals orthogonal to
//!   that direction, so under perspective `n·(q − camera)` is only close to 0 (by the angle
//!   between the two directions). Front-facing tests of footpoints (the plain one, kinds 2–4)
//!   use the exact viewing direction `q − camera_center`.
//! - Creases are only searched from buried front-facing candidates (kind 4), locally: a crease
//!   point not reachable that way is missed (in tests against brute force, almost only for query
//!   points inside the model). The answer is then a valid front-facing or silhouette point that
//!   can be farther than the closest visible one. On a single element the search is exact.
//! - Silhouette clipping resolves features down to 0.01 mm and keeps at most 3 visible ranges per
//!   contour piece and 256 pieces per model (a 30-element hand has about 150); pieces beyond
//!   that are dropped.
//! - If no candidate survives, the plain (back-facing) projection is returned.

use super::coherence::Coherence;
use super::geometry::{ElementFrame, SphereMeshGeometry};
use super::point_wedge::WedgeFrame;
use super::silhouette::ViewBasis;
use super::union_silhouette::UnionSilhouette;
use super::{is_usable, Part, Projection, View, NO_SEED};
use nalgebra::Vector3;

/// The merge test of the thesis's silhouette computation (§3.3.1: discard `v` with
/// `φ_M(v) < 0`) with a tolerance: a candidate is buried when it is deeper than this inside an
/// element (model units, mm), since points on an element's own surface evaluate to about ±1e-12.
pub const BURIED_TOLERANCE: f64 = 1e-6;

/// Outer iterations (two Newton steps onto the crease, then a step along it) of the crease
/// search.
const CREASE_ITERATIONS: usize = 6;
/// Buried candidates kept per query for crease searches.
const MAX_CREASE_SEARCHES: usize = 16;

/// How a front-facing batch finds its plain projections (Eq. 3.6) before replacing the
/// back-facing ones.
enum PlainSearch<'a> {
    /// From the bounding-tree guess.
    Fresh,
    /// From the given seeds (written back by `project_batch`).
    Seeded(&'a mut [u32]),
    /// With the temporal coherence of `coherence.rs`, skipping the points flagged (if any).
    Coherent(&'a mut Coherence, Option<&'a [bool]>),
}

impl SphereMeshGeometry {
    /// Front-facing closest-point correspondence for a monocular view (thesis §3.3.1, Fig. 3.9):
    /// the plain projection [`project`](Self::project) when its footpoint faces the camera,
    /// otherwise the closest among the silhouette, front-facing tangent-plane and front-facing
    /// per-element candidates described in the module docs (see there for the approximations).
    ///
    /// The returned footpoint is front-facing or on the silhouette, [`Projection::distance`] is
    /// `‖p − q‖` with the sign of `φ_M(p)`, and the identity `q = Σ w_i c_i + (Σ w_i r_i)·n`
    /// holds. `None` for a non-finite point, an invalid view (zero or non-finite direction or
    /// camera center) or a model without elements.
    ///
    /// A back-facing point costs the clipping of the silhouette pieces near it: for many points
    /// use [`project_points_front_facing`](Self::project_points_front_facing), which clips each
    /// piece at most once per batch and returns the same results.
    pub fn project_front_facing(&self, p: &Vector3<f64>, view: &View) -> Option<Projection> {
        let mut out = [None];
        self.project_points_front_facing(core::slice::from_ref(p), view, &mut out);
        out[0]
    }

    /// [`project_front_facing`](Self::project_front_facing) (Fig. 3.9) for many points, e.g. the
    /// data points of one frame, writing into `out` (same length as `points`). Allocates
    /// nothing: the object-space silhouette (Fig. 3.10) is set up once for the batch (only if
    /// some footpoint is back-facing) in a buffer on the stack (under 64 KiB), and each of its
    /// pieces is clipped at most once, when a back-facing point first reaches it. `None` entries for
    /// non-finite points; all `None` for an invalid view.
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
        self.front_facing_batch(points, view, PlainSearch::Fresh, out);
    }

    /// [`project_points_front_facing`](Self::project_points_front_facing) with temporal
    /// coherence, as [`project_points_seeded`](Self::project_points_seeded) for the plain
    /// projection: `seeds[i]` names the element to start the plain search of `points[i]` from
    /// (the element of its previous answer; [`NO_SEED`](super::NO_SEED) or any out-of-range
    /// value for none), and on return holds the element of `out[i]` (`NO_SEED` for `None`).
    ///
    /// `out` is bit for bit what the unseeded call returns, whatever the seeds. Allocates
    /// nothing.
    ///
    /// # Panics
    /// If `out` or `seeds` is not as long as `points`.
    #[track_caller]
    pub fn project_points_front_facing_seeded(
        &self,
        points: &[Vector3<f64>],
        view: &View,
        seeds: &mut [u32],
        out: &mut [Option<Projection>],
    ) {
        assert_eq!(points.len(), seeds.len(), "one seed per point");
        self.front_facing_batch(points, view, PlainSearch::Seeded(&mut *seeds), out);
        for (s, o) in seeds.iter_mut().zip(out.iter()) {
            *s = o.map_or(NO_SEED, |q| q.element);
        }
    }

    /// [`project_points_front_facing`](Self::project_points_front_facing) with the plain
    /// projections of [`project_points_coherent`](Self::project_points_coherent): for a tracker
    /// that re-projects the same points every solver iteration, most points skip the search of
    /// Eq. 3.6, and the object-space silhouette is rebuilt in `state`'s storage instead of a
    /// fresh one on the stack. `out` is bit for bit what the call without `state` returns,
    /// whatever `state` holds. Allocates nothing once `state` has held as many points and a
    /// silhouette.
    ///
    /// # Panics
    /// If `out.len() != points.len()`.
    #[track_caller]
    pub fn project_points_front_facing_coherent(
        &self,
        points: &[Vector3<f64>],
        view: &View,
        state: &mut Coherence,
        out: &mut [Option<Projection>],
    ) {
        self.front_facing_batch(points, view, PlainSearch::Coherent(state, None), out);
    }

    /// [`project_points_front_facing_coherent`](Self::project_points_front_facing_coherent) for
    /// the points whose `skip` entry is false alone, as
    /// [`project_points_coherent_skipping`](Self::project_points_coherent_skipping): a skipped
    /// point's `out` is left as it is and never needs a substitute (no silhouette is built when
    /// only skipped points would have needed one). The projected points' `out` is bit for bit
    /// what [`project_points_front_facing`](Self::project_points_front_facing) returns.
    ///
    /// # Panics
    /// If `out` or `skip` is not as long as `points`.
    #[track_caller]
    pub fn project_points_front_facing_coherent_skipping(
        &self,
        points: &[Vector3<f64>],
        skip: &[bool],
        view: &View,
        state: &mut Coherence,
        out: &mut [Option<Projection>],
    ) {
        assert_eq!(points.len(), skip.len(), "one skip flag per point");
        let plain = PlainSearch::Coherent(state, Some(skip));
        self.front_facing_batch(points, view, plain, out);
    }

    /// The front-facing batch with the plain projections found by `plain`.
    #[track_caller]
    fn front_facing_batch(
        &self,
        points: &[Vector3<f64>],
        view: &View,
        plain: PlainSearch<'_>,
        out: &mut [Option<Projection>],
    ) {
        assert_eq!(points.len(), out.len(), "one output slot per point");
        if !view.is_valid() {
            out.fill(None);
            return;
        }
        let (state, skip) = match plain {
            PlainSearch::Fresh => {
                self.project_batch(points, None, out);
                (None, None)
            }
            PlainSearch::Seeded(seeds) => {
                self.project_batch(points, Some(seeds), out);
                (None, None)
            }
            PlainSearch::Coherent(state, skip) => {
                self.coherent_batch(points, skip, state, out);
                (Some(state), skip)
            }
        };
        let wanted = |i: usize| skip.is_none_or(|s| !s[i]);
        let back_facing = |i: usize, o: &Option<Projection>| {
            wanted(i) && o.is_some_and(|q| view.is_back_facing(&q.point, &q.normal))
        };
        if !out.iter().enumerate().any(|(i, o)| back_facing(i, o)) {
            return;
        }
        let Some(direction) = self.silhouette_direction(view) else {
            return;
        };
        let basis = ViewBasis::new(direction);
        // A coherent state keeps its silhouette between calls: rebuilt in place, the same
        // silhouette as a fresh one.
        let mut fresh = None;
        let silhouette: &mut UnionSilhouette = match state {
            Some(state) => match &mut state.silhouette {
                Some(s) => {
                    s.rebuild(self, basis, BURIED_TOLERANCE);
                    s
                }
                none => none.insert(Box::new(UnionSilhouette::build(
                    self,
                    basis,
                    BURIED_TOLERANCE,
                ))),
            },
            None => fresh.insert(UnionSilhouette::build(self, basis, BURIED_TOLERANCE)),
        };
        for (i, (p, o)) in points.iter().zip(out.iter_mut()).enumerate() {
            if back_facing(i, o) {
                if let Some(plain) = o {
                    *plain = self.substitute(p, plain, view, silhouette);
                }
            }
        }
    }

    /// The unit orthographic viewing direction for which the silhouette of
    /// [`project_front_facing`](Self::project_front_facing) is computed (the thesis approximates
    /// the sensor by an orthographic camera, §3.3.1): the view's direction, or for a perspective
    /// camera the direction from its center to the center of the model's bounding ball. `None`
    /// for an invalid view or an empty model.
    pub fn silhouette_direction(&self, view: &View) -> Option<Vector3<f64>> {
        if !view.is_valid() {
            return None;
        }
        match view {
            View::Orthographic(_) => view.direction_to(&Vector3::zeros()),
            View::Perspective { .. } => view.direction_to(&self.tree.root_ball()?.center),
        }
    }

    /// The point of the crease `∂E_a ∩ ∂E_b` nearest to `p` near `start` (a point of `∂E_a`
    /// buried in `E_b`), as a projection on element `a`, or `None` if the search fails or the
    /// point is buried in a third element. Newton steps put `y` on both surfaces (solving for
    /// `y − α n_a − β n_b` with `φ_a = φ_b = 0` to first order), alternating with steps along the
    /// crease tangent `n_a × n_b` toward `p`.
    fn crease_point(
        &self,
        a: usize,
        b: usize,
        start: &Vector3<f64>,
        p: &Vector3<f64>,
    ) -> Option<Projection> {
        let (fa, fb) = (&self.frames[a], &self.frames[b]);
        // One Newton step onto both surfaces; returns the crease tangent there.
        let newton = |y: &mut Vector3<f64>| -> Option<Vector3<f64>> {
            let (pa, pb) = (fa.project(y), fb.project(y));
            let c = pa.normal.dot(&pb.normal);
            let det = 1.0 - c * c;
            if det <= 1e-12 {
                return None; // tangent surfaces: no transversal crease
            }
            let alpha = (pa.distance - c * pb.distance) / det;
            let beta = (pb.distance - c * pa.distance) / det;
            *y -= pa.normal * alpha + pb.normal * beta;
            Some(pa.normal.cross(&pb.normal))
        };
        let mut y = *start;
        for _ in 0..CREASE_ITERATIONS {
            newton(&mut y)?;
            let tangent = newton(&mut y)?;
            let len = tangent.norm();
            if len <= 1e-9 {
                return None;
            }
            let t = tangent / len;
            let step = (p - y).dot(&t);
            y += t * step;
            if step.abs() <= 1e-9 * (1.0 + y.norm()) {
                break;
            }
        }
        let pr = fa.project(&y);
        let on_b = fb.distance(&pr.point);
        let near = 1e-3 * (1.0 + pr.point.norm() * 1e-6);
        (on_b >= -BURIED_TOLERANCE
            && on_b <= near
            && self.burier(&pr.point, BURIED_TOLERANCE, b).is_none())
        .then_some(pr)
    }

    /// The front-facing substitute for a back-facing plain projection `plain` of `p`.
    fn substitute(
        &self,
        p: &Vector3<f64>,
        plain: &Projection,
        view: &View,
        silhouette: &mut UnionSilhouette,
    ) -> Projection {
        if !is_usable(p) {
            return *plain;
        }
        let e0 = plain.element as usize;
        let mut best_d2 = f64::INFINITY;
        let mut best: Option<(usize, Projection)> = None;

        if let Some((d2, e, x)) = silhouette.nearest(self, p, e0, best_d2) {
            best_d2 = d2;
            let pr = Projection {
                point: x.point,
                normal: x.normal,
                skeleton_point: x.skeleton_point,
                element: 0,
                spheres: x.spheres.map(u32::from),
                weights: x.weights,
                distance: 0.0,
                part: Part::Silhouette,
            };
            best = Some((e, pr));
        }

        // Buried front-facing candidates, for crease searches once the best is known:
        // (lower bound², element, burying element, start point).
        let mut buried = [(0.0, 0, 0, Vector3::zeros()); MAX_CREASE_SEARCHES];
        let mut n_buried = 0;
        let mut consider = |e: usize,
                            pr: Projection,
                            best_d2: &mut f64,
                            best: &mut Option<(usize, Projection)>| {
            let d2 = (p - pr.point).norm_squared();
            if d2 >= *best_d2 || view.is_back_facing(&pr.point, &pr.normal) {
                return;
            }
            match self.burier(&pr.point, BURIED_TOLERANCE, e0) {
                None => {
                    *best_d2 = d2;
                    *best = Some((e, pr));
                }
                Some(b) => {
                    // The crease lies on ∂E_e beyond the footpoint and on ∂E_b.
                    let lb = d2.max(self.frames[b].distance(p).powi(2));
                    if lb < *best_d2 && n_buried < MAX_CREASE_SEARCHES {
                        buried[n_buried] = (lb, e, b, pr.point);
                        n_buried += 1;
                    }
                }
            }
        };
        for (e, (frame, b)) in self.frames.iter().zip(&self.packed).enumerate() {
            let gap = ((p - Vector3::new(b[0], b[1], b[2])).norm() - b[3]).max(0.0);
            if gap * gap >= best_d2 {
                continue;
            }
            // Every footpoint on the element is at least |φ_e(p)| away.
            let phi = if e == e0 {
                plain.distance
            } else {
                frame.distance(p)
            };
            if phi * phi >= best_d2 {
                continue;
            }
            if e != e0 {
                consider(e, frame.project(p), &mut best_d2, &mut best);
            }
            if let ElementFrame::Wedge(w) = frame {
                if let Some(tp) = &w.planes {
                    for side in 0..2 {
                        let foot = WedgeFrame::planar_foot(tp, &w.centers[0], p, side);
                        if foot.inside() {
                            consider(e, w.plane_projection(tp, &foot), &mut best_d2, &mut best);
                        }
                    }
                }
            }
        }

        // Where an element's front surface dives into another, the visible surface ends on the
        // crease: search those nearest first, while they can still win.
        let buried = &mut buried[..n_buried];
        buried.sort_unstable_by(|x, y| x.0.total_cmp(&y.0));
        for &(lb, a, b, start) in buried.iter() {
            if lb >= best_d2 {
                break;
            }
            if let Some(c) = self.crease_point(a, b, &start, p) {
                let d2 = (p - c.point).norm_squared();
                if d2 < best_d2 && !view.is_back_facing(&c.point, &c.normal) {
                    best_d2 = d2;
                    best = Some((a, c));
                }
            }
        }

        match best {
            Some((e, pr)) => {
                let mut pr = self.globalize(e, pr);
                pr.distance = best_d2.sqrt().copysign(plain.distance);
                pr
            }
            None => *plain,
        }
    }
}
