//! A posed sphere-mesh prepared for queries: per-element tangent planes and bounding balls,
//! refreshed once per solver iteration, and the model-wide closest-point projection
//! `Π_M(p)` (Eq. 3.6: the element with the smallest `φ_e(p)` wins).

use super::bounding::{BallBlocks, BoundingBall};
use super::bvh::ElementTree;
use super::point_pill::{valid_sphere, PillFrame};
use super::point_wedge::WedgeFrame;
use super::{is_usable, Projection, NO_SEED};
use crate::shape::{Element, Sphere};
use nalgebra::Vector3;

/// Why a [`SphereMeshGeometry`] could not be built or updated.
#[derive(Copy, Clone, Debug, PartialEq, thiserror::Error)]
pub enum GeometryError {
    /// An element names a sphere that does not exist.
    #[error("element {element} refers to sphere {sphere}, but the model has {count} spheres")]
    SphereIndexOutOfRange {
        /// Element index.
        element: usize,
        /// The offending sphere index.
        sphere: u32,
        /// Number of spheres.
        count: usize,
    },
    /// A sphere has a non-finite center or radius, or a negative radius.
    #[error("sphere {index} has a non-finite center or radius, or a negative radius")]
    InvalidSphere {
        /// Sphere index.
        index: usize,
    },
    /// [`SphereMeshGeometry::update`] got a different number of spheres than the model has.
    #[error("expected {expected} spheres, got {got}")]
    SphereCountMismatch {
        /// Number of spheres of the model.
        expected: usize,
        /// Number of spheres passed.
        got: usize,
    },
}

/// The per-pose data of one element.
#[derive(Copy, Clone, Debug, PartialEq)]
#[expect(
    clippy::large_enum_variant,
    reason = "frames sit inline in one Vec scanned by every query; boxing wedges would add a \
              pointer chase per element visit"
)]
pub(crate) enum ElementFrame {
    Pill(PillFrame),
    Wedge(WedgeFrame),
}

impl ElementFrame {
    #[inline]
    pub(crate) fn distance(&self, p: &Vector3<f64>) -> f64 {
        match self {
            ElementFrame::Pill(f) => f.distance(p),
            ElementFrame::Wedge(f) => f.distance(p),
        }
    }

    /// The distance when it is not above `best`, otherwise some value `> best`.
    #[inline]
    pub(crate) fn distance_below(&self, p: &Vector3<f64>, best: f64) -> f64 {
        match self {
            ElementFrame::Pill(f) => f.distance_below(p, best),
            ElementFrame::Wedge(f) => f.distance_below(p, best),
        }
    }

    #[inline]
    pub(crate) fn project(&self, p: &Vector3<f64>) -> Projection {
        match self {
            ElementFrame::Pill(f) => f.project(p),
            ElementFrame::Wedge(f) => f.project(p),
        }
    }

    pub(crate) fn centers(&self) -> &[Vector3<f64>] {
        match self {
            ElementFrame::Pill(f) => &f.centers,
            ElementFrame::Wedge(f) => &f.centers,
        }
    }

    pub(crate) fn radii(&self) -> &[f64] {
        match self {
            ElementFrame::Pill(f) => &f.radii,
            ElementFrame::Wedge(f) => &f.radii,
        }
    }

    fn build(element: &Element, spheres: &[Sphere]) -> Self {
        let s = |i: u32| &spheres[i as usize];
        match element {
            Element::Pill([a, b]) => ElementFrame::Pill(PillFrame::new(s(*a), s(*b))),
            Element::Wedge([a, b, c]) => {
                ElementFrame::Wedge(WedgeFrame::new([s(*a), s(*b), s(*c)]))
            }
        }
    }

    fn bound(&self) -> BoundingBall {
        match self {
            ElementFrame::Pill(f) => BoundingBall::of_pill(f),
            ElementFrame::Wedge(f) => BoundingBall::of_wedge(f),
        }
    }
}

/// A posed sphere-mesh `M` (Eq. 3.1) prepared for closest-point queries (§3.3.1): it caches,
/// per element, the tangent planes of wedges and a bounding ball, so that
/// [`project`](Self::project) evaluates the closed-form projections of Fig. 3.7 only on the few
/// elements that can win the argmin of Eq. 3.6.
///
/// Build it once per model with [`new`](Self::new), then call [`update`](Self::update) with the
/// posed spheres every solver iteration; `update` and every query allocate nothing.
///
/// # Example
/// ```
/// use hand_model::query::{Part, SphereMeshGeometry, View};
/// use hand_model::shape::{Element, Sphere};
/// use nalgebra::Vector3;
///
/// // A finger-like pill along +y, radius 8 → 6 mm.
/// let spheres = [
///     Sphere::new(Vector3::new(0.0, 0.0, 0.0), 8.0),
///     Sphere::new(Vector3::new(0.0, 40.0, 0.0), 6.0),
/// ];
/// let g = SphereMeshGeometry::new(&spheres, &[Element::Pill([0, 1])])?;
/// let p = Vector3::new(20.0, 20.0, 0.0);
/// let q = g.project(&p).expect("finite point");
/// assert_eq!(q.part, Part::Cone);
/// assert!(((p - q.point).norm() - q.distance).abs() < 1e-12);
/// assert_eq!(q.reevaluate(g.spheres()), Some(q.point)); // q = Σ w c + (Σ w r) n, bit for bit
///
/// // Seen along +z from a camera in front of −z, a point behind the pill is matched to the
/// // silhouette instead of the back-facing footpoint.
/// let behind = g.project_front_facing(&Vector3::new(2.0, 20.0, 15.0), &View::Orthographic(Vector3::z()));
/// assert_eq!(behind.map(|q| q.part), Some(Part::Silhouette));
/// # Ok::<(), hand_model::query::GeometryError>(())
/// ```
#[derive(Clone, Debug)]
pub struct SphereMeshGeometry {
    pub(super) spheres: Vec<Sphere>,
    pub(super) elements: Vec<Element>,
    pub(super) frames: Vec<ElementFrame>,
    pub(super) bounds: Vec<BoundingBall>,
    /// The bounding balls again as packed `[x, y, z, R]`, for the burial and silhouette tests.
    pub(super) packed: Vec<[f64; 4]>,
    /// Bounding-ball hierarchy over the elements, for a first guess of the nearest element.
    pub(super) tree: ElementTree,
    /// The bounding balls once more in `f32` blocks, for the vectorised first culling pass.
    pub(super) blocks: BallBlocks,
}

impl SphereMeshGeometry {
    /// Prepares the sphere-mesh with these spheres and elements (thesis §3.1, Fig. 3.4).
    pub fn new(spheres: &[Sphere], elements: &[Element]) -> Result<Self, GeometryError> {
        check_spheres(spheres)?;
        for (e, el) in elements.iter().enumerate() {
            if let Some(&sphere) = el.spheres().iter().find(|&&i| i as usize >= spheres.len()) {
                return Err(GeometryError::SphereIndexOutOfRange {
                    element: e,
                    sphere,
                    count: spheres.len(),
                });
            }
        }
        let frames: Vec<ElementFrame> = elements
            .iter()
            .map(|el| ElementFrame::build(el, spheres))
            .collect();
        let bounds: Vec<BoundingBall> = frames.iter().map(ElementFrame::bound).collect();
        let tree = ElementTree::build(&bounds);
        Ok(Self {
            spheres: spheres.to_vec(),
            elements: elements.to_vec(),
            frames,
            packed: bounds.iter().map(pack).collect(),
            blocks: BallBlocks::new(&bounds, tree.leaf_order(), block_origin(&tree)),
            tree,
            bounds,
        })
    }

    /// Re-poses the model with new sphere centers and radii (same count and order as in
    /// [`new`](Self::new)), recomputing tangent planes and bounding balls: the per-iteration
    /// refresh of the skeleton `S` of Eq. 3.1 after the kinematics moved its vertices
    /// (Fig. 3.4). Allocates nothing.
    /// On error the geometry is left unchanged.
    pub fn update(&mut self, spheres: &[Sphere]) -> Result<(), GeometryError> {
        if spheres.len() != self.spheres.len() {
            return Err(GeometryError::SphereCountMismatch {
                expected: self.spheres.len(),
                got: spheres.len(),
            });
        }
        check_spheres(spheres)?;
        self.spheres.copy_from_slice(spheres);
        for ((frame, bound), el) in self
            .frames
            .iter_mut()
            .zip(self.bounds.iter_mut())
            .zip(&self.elements)
        {
            *frame = ElementFrame::build(el, spheres);
            *bound = frame.bound();
        }
        for (packed, b) in self.packed.iter_mut().zip(&self.bounds) {
            *packed = pack(b);
        }
        self.tree.refit(&self.bounds);
        self.blocks.refit(&self.bounds, block_origin(&self.tree));
        Ok(())
    }

    /// The spheres `(c_*, r_*)` of the current pose (the skeleton vertices of Eq. 3.1).
    pub fn spheres(&self) -> &[Sphere] {
        &self.spheres
    }

    /// The elements `E^e` (pills and wedges) of Eq. 3.6.
    pub fn elements(&self) -> &[Element] {
        &self.elements
    }

    /// The bounding ball of each element in the current pose (culling of Eq. 3.6).
    pub fn bounding_balls(&self) -> &[BoundingBall] {
        &self.bounds
    }

    /// The model's implicit function `φ_M(p) = min_e φ_e(p)` (Eq. 3.6) as a signed distance:
    /// exact outside the model; inside, the depth in the element that contains `p` most deeply
    /// (a lower bound of the depth in the union where elements overlap). `None` for a non-finite
    /// point or a model without elements.
    pub fn phi(&self, p: &Vector3<f64>) -> Option<f64> {
        if !is_usable(p) {
            return None;
        }
        self.nearest(p, None).map(|(_, d)| d)
    }

    /// Signed distance from `p` to element `element` alone (`φ_e(p)`, Eq. 3.1 on one element).
    /// `None` for a non-finite point or an out-of-range index.
    pub fn phi_element(&self, element: usize, p: &Vector3<f64>) -> Option<f64> {
        if !is_usable(p) {
            return None;
        }
        self.frames.get(element).map(|f| f.distance(p))
    }

    /// Closest-point projection on one element (Fig. 3.7), with global sphere indices.
    /// `None` for a non-finite point or an out-of-range index.
    pub fn project_on_element(&self, element: usize, p: &Vector3<f64>) -> Option<Projection> {
        if !is_usable(p) {
            return None;
        }
        let frame = self.frames.get(element)?;
        Some(self.globalize(element, frame.project(p)))
    }

    /// The model-wide closest-point projection `q = Π_M(p)` (Eq. 3.6): the footpoint on the
    /// element with the smallest signed distance `φ_e(p)`. Its outward normal is
    /// [`Projection::normal`] and its signed distance `φ_M(p)` is [`Projection::distance`].
    ///
    /// Elements are culled with their bounding balls: an element is evaluated only if its lower
    /// bound `‖p − C_e‖ − R_e` is not above the best distance found so far; ties go to the lower
    /// element index. `None` for a non-finite point or a model without elements.
    pub fn project(&self, p: &Vector3<f64>) -> Option<Projection> {
        self.project_from(p, None)
    }

    /// [`project`](Self::project) with the search started at element `seed` (if in range).
    ///
    /// A seed is usually the answer, so it is projected in full up front rather than first
    /// evaluated for its distance only (a projection's `distance` is bit for bit the element's
    /// `distance`, so the search is the same).
    #[inline]
    pub(super) fn project_from(&self, p: &Vector3<f64>, seed: Option<usize>) -> Option<Projection> {
        if !is_usable(p) {
            return None;
        }
        let e = match seed.filter(|&e| e < self.frames.len()) {
            Some(first) => {
                let pr = self.frames[first].project(p);
                let (e, _) = self.search(p, first, pr.distance, 0.0).nearest;
                if e == first {
                    return Some(self.globalize(e, pr));
                }
                e
            }
            None => self.nearest(p, None)?.0,
        };
        Some(self.globalize(e, self.frames[e].project(p)))
    }

    /// [`project`](Self::project) (Eq. 3.6) for many points, e.g. the 2500 data points of one
    /// frame (§3.3.1), writing into `out` (same length as `points`). Allocates nothing.
    ///
    /// # Panics
    /// If `out.len() != points.len()`.
    #[track_caller]
    pub fn project_points(&self, points: &[Vector3<f64>], out: &mut [Option<Projection>]) {
        self.project_batch(points, None, out);
    }

    /// [`project_points`](Self::project_points) with temporal coherence, for a tracker that
    /// re-projects the same data points every solver iteration: `seeds[i]` names the element to
    /// try first for `points[i]` (the element of its previous answer; [`NO_SEED`] or any
    /// out-of-range value for none), which gives the culling of Eq. 3.6 a tight bound from the
    /// start instead of the bounding-tree guess. On return `seeds[i]` holds the element of
    /// `out[i]` ([`NO_SEED`] for `None`), ready for the next call.
    ///
    /// The seed only orders the search: `out` is bit for bit what
    /// [`project_points`](Self::project_points) returns, whatever the seeds (stale, wrong or
    /// out of range). Allocates nothing.
    ///
    /// # Panics
    /// If `out` or `seeds` is not as long as `points`.
    #[track_caller]
    pub fn project_points_seeded(
        &self,
        points: &[Vector3<f64>],
        seeds: &mut [u32],
        out: &mut [Option<Projection>],
    ) {
        self.project_batch(points, Some(seeds), out);
    }

    /// The plain batch projection, seeded or not; writes the new seeds back.
    #[track_caller]
    pub(super) fn project_batch(
        &self,
        points: &[Vector3<f64>],
        mut seeds: Option<&mut [u32]>,
        out: &mut [Option<Projection>],
    ) {
        assert_eq!(points.len(), out.len(), "one output slot per point");
        if let Some(s) = &seeds {
            assert_eq!(points.len(), s.len(), "one seed per point");
        }
        for (i, (p, o)) in points.iter().zip(out.iter_mut()).enumerate() {
            let seed = seeds.as_deref_mut().map(|s| &mut s[i]);
            *o = self.project_from(p, seed.as_deref().map(|&e| e as usize));
            if let Some(s) = seed {
                *s = o.map_or(NO_SEED, |q| q.element);
            }
        }
    }

    /// Whether `x` lies inside some element by more than `tol` (`φ_M(x) < −tol`): such a point
    /// of an element's surface is buried in another element and is not on the model's surface
    /// (the merge test of the thesis's silhouette computation, §3.3.1). `false` for a
    /// non-finite `x`.
    pub fn is_buried(&self, x: &Vector3<f64>, tol: f64) -> bool {
        is_usable(x) && self.burier(x, tol, 0).is_some()
    }

    /// The element burying `x` (`φ_e(x) < −tol`), trying `hint` first. Bounding balls cull the
    /// scan: `x` can be inside `e` by more than `tol` only if `‖x − C_e‖ < R_e − tol`.
    pub(super) fn burier(&self, x: &Vector3<f64>, tol: f64, hint: usize) -> Option<usize> {
        let inside = |e: usize, &[bx, by, bz, radius]: &[f64; 4]| {
            let reach = radius - tol;
            let (dx, dy, dz) = (x.x - bx, x.y - by, x.z - bz);
            reach > 0.0
                && dx * dx + dy * dy + dz * dz < reach * reach
                && self.frames[e].distance(x) < -tol
        };
        if let Some(b) = self.packed.get(hint) {
            if inside(hint, b) {
                return Some(hint);
            }
        }
        self.packed
            .iter()
            .enumerate()
            .position(|(e, b)| e != hint && inside(e, b))
    }

    /// The element minimising `φ_e(p)` and that minimum (`p` finite), ties going to the lower
    /// element index: [`search`](Self::search) from `seed` when given and in range (temporal
    /// coherence: the previous answer is usually still the nearest, or close), otherwise from
    /// the guess of a greedy descent of the bounding-ball tree.
    pub(super) fn nearest(&self, p: &Vector3<f64>, seed: Option<usize>) -> Option<(usize, f64)> {
        let first = match seed.filter(|&e| e < self.frames.len()) {
            Some(e) => e,
            None => self.tree.guess(p)?,
        };
        Some(
            self.search(p, first, self.frames[first].distance(p), 0.0)
                .nearest,
        )
    }

    /// Branch and bound for the argmin of Eq. 3.6, given element `first` at distance `best`:
    /// every other element is evaluated only if its bound `‖p − C_e‖ − R_e` is not above the
    /// best distance so far plus `gap`. Blocks of bounding balls are first tested at once in
    /// `f32` with a widened bound ([`BallBlocks`]), and the survivors are evaluated. A skipped
    /// element has `φ_e(p) > d + gap`, every element tied with the final minimum is evaluated,
    /// and ties go to the lower index, so the answer is the exact argmin whatever `first`, `gap`
    /// and the evaluation order: seeds and gaps change the cost, never the result.
    ///
    /// A positive `gap` evaluates the elements within `gap` of the minimum as well, which makes
    /// [`Search::margin`] a lower bound that lasts (see `coherence.rs`), and names the nearest of
    /// them other than the minimum's as [`Search::runner`].
    pub(super) fn search(&self, p: &Vector3<f64>, first: usize, mut best: f64, gap: f64) -> Search {
        let mut best_e = first;
        // The smallest value seen of another element than `best_e` (its `φ_e` or a lower bound)
        // and that element; and the smallest value seen of the elements other than these two.
        let mut second = (f64::INFINITY, usize::MAX);
        let mut third = f64::INFINITY;
        let query = self.blocks.query(p);
        for block in 0..self.blocks.len() {
            let mut mask = self.blocks.survivors(&query, block, best + gap);
            let lanes = self.blocks.elements(block);
            while mask != 0 {
                let e = lanes[mask.trailing_zeros() as usize] as usize;
                mask &= mask - 1;
                // Padding lanes (kept only on overflow) name no element. The few survivors of
                // the widened `f32` test that the exact one would drop are evaluated as well:
                // evaluating more elements never changes the argmin.
                let Some(frame) = self.frames.get(e) else {
                    continue;
                };
                if e == first {
                    continue;
                }
                let d = frame.distance_below(p, best + gap);
                if d < best || (d == best && e < best_e) {
                    third = third.min(second.0);
                    second = (best, best_e);
                    best = d;
                    best_e = e;
                } else if d < second.0 {
                    third = third.min(second.0);
                    second = (d, e);
                } else {
                    third = third.min(d);
                }
            }
        }
        // Skipped elements and those `distance_below` bounded are above the culling bound of
        // their time, never below the final `best + gap`: a second value within it is exact.
        let cap = best + gap;
        let (runner, margin) = if second.0 <= cap && second.1 < self.frames.len() {
            (Some((second.1, second.0)), third.min(cap))
        } else {
            (None, second.0.min(cap))
        };
        Search {
            nearest: (best_e, best),
            runner,
            margin,
        }
    }

    /// Re-expresses an element-local projection over the model's sphere indices.
    pub(super) fn globalize(&self, element: usize, mut pr: Projection) -> Projection {
        let ids = self.elements[element].spheres();
        pr.spheres = pr.spheres.map(|l| ids[l as usize]);
        pr.element = element as u32;
        pr
    }
}

/// The answer of [`SphereMeshGeometry::search`].
#[derive(Copy, Clone, Debug, PartialEq)]
pub(super) struct Search {
    /// The element minimising `φ_e(p)`, and that minimum.
    pub(super) nearest: (usize, f64),
    /// The nearest element other than the minimum's and its `φ_e(p)` (evaluated exactly),
    /// when it is within the gap of the minimum.
    pub(super) runner: Option<(usize, f64)>,
    /// A lower bound of `φ_e(p)` over every element `e` other than the minimum's and the
    /// runner, at least the minimum (equal to it with a zero gap when another element ties).
    pub(super) margin: f64,
}

/// The origin of the `f32` culling blocks: the center of the model's bounding ball, so that
/// coordinates stored in `f32` stay small wherever the model is.
fn block_origin(tree: &ElementTree) -> Vector3<f64> {
    tree.root_ball().map_or_else(Vector3::zeros, |b| b.center)
}

fn pack(b: &BoundingBall) -> [f64; 4] {
    [b.center.x, b.center.y, b.center.z, b.radius]
}

fn check_spheres(spheres: &[Sphere]) -> Result<(), GeometryError> {
    match spheres.iter().position(|s| !valid_sphere(s)) {
        Some(index) => Err(GeometryError::InvalidSphere { index }),
        None => Ok(()),
    }
}
