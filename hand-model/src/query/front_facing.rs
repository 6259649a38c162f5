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
//! A silhouette piece (contour line or sphere arc) whose closest point is buried is clipped
//! instead, as the thesis's arrangement splits the silhouette curves where they enter another
//! element (Fig. 3.10): the search walks along the piece to where it leaves the burying element
//! (regula falsi on that element's `φ`) and takes that exit point if it is not buried itself.
//!
//! # Approximations
//! - Orthographic silhouette: under [`View::Perspective`] the contour generator of each element
//!   is computed for the orthographic view along the ray from the camera center through the data
//!   point `p` (the thesis uses one orthographic camera for the whole model; a per-point ray is
//!   closer to the true perspective contour near `p`). The front-facing tests of candidates 2
//!   and 3 and of `Π_M(p)` use the exact perspective direction `q − camera_center`.
//! - Buried tangent-plane and per-element footpoints are discarded, not clipped, and curves
//!   where an element's front surface enters another element are not candidates. Clipping
//!   follows a piece through at most 4 burying elements; along an arc the crossing found is an
//!   exit from the burying element but not necessarily the first one when the arc re-enters it.
//!   The result is then a valid front-facing or silhouette point that may be farther than the
//!   true closest one (on a single element, or on disjoint elements, the search is exact).
//! - If every candidate is rejected, the plain (back-facing) projection is returned.

use super::bounded_heap::BoundedHeap;
use super::geometry::{ElementFrame, SphereMeshGeometry};
use super::point_wedge::WedgeFrame;
use super::silhouette::{
    arc_point, contour_points, segment_point, ContourPoint, Piece, ViewBasis,
    MAX_CONTOUR_POINTS,
};
use super::{is_finite, Part, Projection, View};
use nalgebra::Vector3;

/// A candidate is buried when it is deeper than this inside an element (model units, mm): points
/// on an element's own surface evaluate to about ±1e-12 there.
pub const BURIED_TOLERANCE: f64 = 1e-6;

/// A clipped contour line may be buried again by a further element; give up after this many.
const MAX_CLIPS: usize = 4;
/// Regula-falsi iterations when clipping a contour line.
const MAX_ROOT_ITERATIONS: usize = 60;

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
        let mut search = FrontSearch {
            geometry: self,
            p,
            view,
            basis,
            best_d2: f64::INFINITY,
            best: None,
            burier_hint: e0,
            heap: BoundedHeap::new(Item::Element(0)),
            slots: [Candidate::default(); CANDIDATE_SLOTS],
            used: 0,
        };
        search.run(e0, d0);
        Some(match search.best {
            Some((e, pr)) => {
                let mut pr = self.globalize(e, pr);
                pr.distance = search.best_d2.sqrt().copysign(d0);
                pr
            }
            None => plain,
        })
    }
}

/// Candidates held in the queue of one search (beyond that they are checked immediately).
const CANDIDATE_SLOTS: usize = 32;
/// Queue capacity (elements and candidates).
const QUEUE: usize = 96;

/// A queued unit of work of the best-first search.
#[derive(Copy, Clone, Debug)]
enum Item {
    /// An element keyed by its bounding-ball gap.
    Element(u32),
    /// An element keyed by `φ_e(p)²`.
    Refined(u32),
    /// A candidate, by slot.
    Candidate(u16),
}

/// A candidate footpoint of one element (local sphere indices).
#[derive(Copy, Clone, Debug)]
struct Candidate {
    element: u32,
    part: Part,
    point: ContourPoint,
}

impl Default for Candidate {
    fn default() -> Self {
        Self {
            element: 0,
            part: Part::Silhouette,
            point: ContourPoint::default(),
        }
    }
}

/// State of one front-facing search: the best unburied candidate so far and the queue.
struct FrontSearch<'a> {
    geometry: &'a SphereMeshGeometry,
    p: &'a Vector3<f64>,
    view: &'a View,
    basis: ViewBasis,
    best_d2: f64,
    /// Element and element-local projection of the best candidate.
    best: Option<(usize, Projection)>,
    /// The element that buried the last rejected candidate: neighbours bury each other's
    /// candidates repeatedly, so it is tried first.
    burier_hint: usize,
    heap: BoundedHeap<Item, QUEUE>,
    slots: [Candidate; CANDIDATE_SLOTS],
    used: usize,
}

impl FrontSearch<'_> {
    /// Best-first search: elements enter the queue keyed by a lower bound of their candidates'
    /// squared distances (bounding-ball gap, refined to `φ_e(p)²` when first popped) and are
    /// expanded into candidates when popped; candidates are checked for burial in order of
    /// distance, buried silhouette pieces are clipped. The search ends when the smallest key in
    /// the queue is not below the best unburied candidate, which is then the answer.
    fn run(&mut self, e0: usize, d0: f64) {
        let p = self.p;
        // The plain footpoint's element first: its φ is known and its silhouette is near.
        self.expand(e0, Some(d0));
        for (e, &[x, y, z, radius]) in self.geometry.packed.iter().enumerate() {
            let gap = ((p - Vector3::new(x, y, z)).norm() - radius).max(0.0);
            if e != e0 && gap * gap < self.best_d2 {
                if let Err(item) = self.heap.push(gap * gap, Item::Element(e as u32)) {
                    self.handle(item);
                }
            }
        }
        while let Some((key, item)) = self.heap.pop() {
            if key >= self.best_d2 {
                break;
            }
            self.handle(item);
        }
    }

    fn handle(&mut self, item: Item) {
        match item {
            Item::Element(e) => {
                let e = e as usize;
                let phi = self.geometry.frames[e].distance(self.p);
                // Every candidate is on the element's surface, at least |φ_e(p)| away: requeue
                // with that tighter key unless it is still the smallest.
                let key = phi * phi;
                if key >= self.best_d2 {
                    return;
                }
                if self.heap.peek_key().is_some_and(|next| key > next) {
                    if let Err(item) = self.heap.push(key, Item::Refined(e as u32)) {
                        self.handle(item);
                    }
                    return;
                }
                self.expand(e, None);
            }
            Item::Refined(e) => self.expand(e as usize, None),
            Item::Candidate(slot) => {
                let c = self.slots[slot as usize];
                self.check(&c);
            }
        }
    }

    /// Queues the candidates of element `e`. `own` is `φ_e(p)` when `e` holds the plain
    /// footpoint, which is back-facing and therefore not a candidate.
    fn expand(&mut self, e: usize, own: Option<f64>) {
        let (g, p, view) = (self.geometry, self.p, self.view);
        let frame = &g.frames[e];
        let mut contour = [ContourPoint::default(); MAX_CONTOUR_POINTS];
        let k = contour_points(frame.centers(), frame.radii(), &self.basis, p, &mut contour);
        for c in &contour[..k] {
            self.offer(e, Part::Silhouette, c);
        }
        if own.is_none() {
            let pr = frame.project(p);
            if !view.is_back_facing(&pr.point, &pr.normal) {
                self.offer(e, pr.part, &from_projection(&pr, p));
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
                        self.offer(e, Part::Plane, &from_projection(&pr, p));
                    }
                }
            }
        }
    }

    /// Queues a candidate that could beat the best, or checks it at once when the queue is full.
    fn offer(&mut self, e: usize, part: Part, c: &ContourPoint) {
        if c.dist2 >= self.best_d2 {
            return;
        }
        let candidate = Candidate { element: e as u32, part, point: *c };
        if self.used < CANDIDATE_SLOTS {
            let slot = self.used;
            if self.heap.push(c.dist2, Item::Candidate(slot as u16)).is_ok() {
                self.slots[slot] = candidate;
                self.used += 1;
                return;
            }
        }
        self.check(&candidate);
    }

    /// Accepts an unburied candidate, clips a buried one.
    fn check(&mut self, c: &Candidate) {
        if c.point.dist2 >= self.best_d2 {
            return;
        }
        let e = c.element as usize;
        match self.geometry.burier(&c.point.point, BURIED_TOLERANCE, self.burier_hint) {
            None => self.accept(e, c.part, &c.point),
            Some(b) => {
                self.burier_hint = b;
                self.clip(e, &self.geometry.frames[e], &c.point, b);
            }
        }
    }

    fn accept(&mut self, e: usize, part: Part, c: &ContourPoint) {
        self.best_d2 = c.dist2;
        self.best = Some((
            e,
            Projection {
                point: c.point,
                normal: c.normal,
                skeleton_point: c.skeleton_point,
                element: 0,
                spheres: c.spheres.map(|i| i as u32),
                weights: c.weights,
                distance: c.dist2.sqrt(),
                part,
            },
        ));
    }

    /// The silhouette piece of `c` (element `e`) has its closest point buried in element
    /// `burier`: walk from that point toward each end of the piece to where it leaves the burying
    /// element(s), and accept the first exit point on each side that is not buried. Distances to
    /// `p` grow monotonically along the way (on a line from the foot of `p`, on a circle from the
    /// angle of `p`), so the walk stops as soon as it cannot beat the best candidate.
    fn clip(&mut self, e: usize, frame: &ElementFrame, c: &ContourPoint, burier: usize) {
        let (g, p) = (self.geometry, self.p);
        let (centers, radii) = (frame.centers(), frame.radii());
        let [i, j, _] = c.spheres;
        let normal = c.normal;
        let basis = self.basis;
        let (start, ends) = match c.piece {
            Piece::Segment(t) => (t, [0.0, 1.0]),
            Piece::Arc { theta, lo, hi } => (theta, [lo, hi]),
            Piece::None => return,
        };
        let at = |s: f64| match c.piece {
            Piece::Arc { .. } => arc_point(centers, radii, &basis, i, s, p),
            _ => segment_point(centers, radii, [i, j], normal, s, p),
        };
        for end in ends {
            let (mut from, mut blocker) = (start, burier);
            for _ in 0..MAX_CLIPS {
                let phi = |s: f64| g.frames[blocker].distance(&at(s).point) + BURIED_TOLERANCE;
                let at_end = phi(end);
                if at_end < 0.0 {
                    break; // still inside `blocker` at the end of the piece
                }
                let s = exit_crossing(&phi, from, phi(from), end, at_end);
                let x = at(s);
                if x.dist2 >= self.best_d2 {
                    break;
                }
                match g.burier(&x.point, BURIED_TOLERANCE, blocker) {
                    None => {
                        self.accept(e, Part::Silhouette, &x);
                        break;
                    }
                    Some(b) => {
                        from = s;
                        blocker = b;
                    }
                }
            }
        }
    }
}

/// Regula falsi (Illinois variant) for the crossing of `f` between `a` (`f(a) = fa < 0`) and
/// `b` (`f(b) = fb ≥ 0`); returns a parameter on the `f ≥ 0` side of the crossing, so that the
/// point it names is never buried in the element `f` measures.
fn exit_crossing(f: &impl Fn(f64) -> f64, mut a: f64, mut fa: f64, mut b: f64, mut fb: f64) -> f64 {
    if fa >= 0.0 {
        return a;
    }
    let mut side = 0i8;
    for _ in 0..MAX_ROOT_ITERATIONS {
        // Stop once the unburied end is within a hair of the crossing.
        if (b - a).abs() <= 1e-12 || fb <= 1e-9 {
            break;
        }
        let c = (a * fb - b * fa) / (fb - fa);
        if !(c > a.min(b) && c < a.max(b)) {
            break;
        }
        let fc = f(c);
        if fc < 0.0 {
            a = c;
            fa = fc;
            if side == -1 {
                fb *= 0.5;
            }
            side = -1;
        } else {
            b = c;
            fb = fc;
            if side == 1 {
                fa *= 0.5;
            }
            side = 1;
        }
    }
    b
}

fn from_projection(pr: &Projection, p: &Vector3<f64>) -> ContourPoint {
    ContourPoint {
        piece: Piece::None,
        point: pr.point,
        normal: pr.normal,
        skeleton_point: pr.skeleton_point,
        spheres: pr.spheres.map(|i| i as usize),
        weights: pr.weights,
        dist2: (p - pr.point).norm_squared(),
    }
}
