//! The object-space silhouette `∂M` of the whole model for one orthographic viewing direction
//! (thesis §3.3.1 "Silhouette computation", Fig. 3.10): every element's contour pieces, minus the
//! parts buried inside other elements.
//!
//! The thesis builds a 2-D arrangement of the projected outlines, traverses it, re-projects it to
//! 3-D and discards vertices with `φ_M(v) < 0`. Here each element's contour piece (a sphere arc
//! or a generator segment, see `silhouette.rs`) is clipped directly in 3-D against the elements
//! whose bounding balls it meets: along the piece, `g(s) = min_B φ_B(x(s)) + tol` is
//! `speed`-Lipschitz (`φ_B` is 1-Lipschitz and `x(s)` moves at most `speed` per unit of `s`),
//! so an adaptive subdivision classifies whole sub-ranges as visible (`g ≥ 0` everywhere) or
//! buried from the values at their ends, and regula falsi pins each visible/buried boundary on
//! the visible side. Features shorter than [`MIN_FEATURE`] (or 10⁻⁴ of the piece) are not
//! resolved.
//!
//! Set up once per batch of points (it depends on the pose and the view only), clipped lazily
//! piece by piece as queries reach them, and kept on the stack: at most [`MAX_PIECES`] pieces
//! with [`MAX_VISIBLE`] visible ranges each.

use super::geometry::{ElementFrame, SphereMeshGeometry};
use super::silhouette::{
    element_pieces, sphere_arcs, Piece, PiecePoint, ViewBasis, MAX_ELEMENT_PIECES,
};
use nalgebra::{Vector2, Vector3};

/// Contour pieces held (≈ 5 per element; a 30-element hand has about 150).
pub(crate) const MAX_PIECES: usize = 256;
/// Visible ranges kept per piece (further ones are dropped).
pub(crate) const MAX_VISIBLE: usize = 3;
/// Visible/buried boundaries are resolved down to pieces of this length (mm): a dip of a piece
/// into another element narrower than this may be kept as visible.
pub(crate) const MIN_FEATURE: f64 = 0.01;
/// ... or of this fraction of the piece's length, whichever is longer, which bounds the
/// subdivision depth (and work) at any model scale.
const MIN_FEATURE_FRACTION: f64 = 1e-4;

/// The resolution of the subdivision for a range of this length.
fn resolution(length: f64) -> f64 {
    MIN_FEATURE.max(MIN_FEATURE_FRACTION * length)
}
/// Elements whose pieces are indexed per element (larger models scan all pieces).
const GROUPED_ELEMENTS: usize = 64;

/// A contour piece of one element with its visible parameter ranges.
#[derive(Copy, Clone, Debug)]
pub(crate) struct VisiblePiece {
    pub(crate) element: u32,
    pub(crate) piece: Piece,
    /// Ball `[x, y, z, R]` containing the piece.
    bound: [f64; 4],
    visible: [Span; MAX_VISIBLE],
    /// Number of visible ranges, or [`UNCLIPPED`].
    n_visible: u8,
}

/// A visible parameter range `[a, b]`; for arcs also the unit in-plane directions at its ends,
/// so that queries need no trigonometry.
#[derive(Copy, Clone, Debug, Default)]
struct Span {
    a: f64,
    b: f64,
    da: Vector2<f64>,
    db: Vector2<f64>,
}

impl Default for VisiblePiece {
    fn default() -> Self {
        Self {
            element: 0,
            piece: Piece::Segment {
                spheres: [0, 0],
                normal: Vector3::zeros(),
            },
            bound: [0.0; 4],
            visible: [Span::default(); MAX_VISIBLE],
            n_visible: 0,
        }
    }
}

/// [`VisiblePiece::n_visible`] of a piece not clipped yet.
const UNCLIPPED: u8 = u8::MAX;

/// The clipped silhouette of the model for one view.
#[derive(Clone, Debug)]
pub(crate) struct UnionSilhouette {
    basis: ViewBasis,
    /// The burial tolerance of the clipping.
    tol: f64,
    pieces: [VisiblePiece; MAX_PIECES],
    len: usize,
    /// Pieces of element `e` are `pieces[first[e]..first[e + 1]]` (when `grouped`).
    first: [u16; GROUPED_ELEMENTS + 1],
    grouped: bool,
}

impl UnionSilhouette {
    /// The contour pieces of `g` for the view `basis`, clipped against the other elements with
    /// tolerance `tol`.
    ///
    /// Clipping dominates the cost (tens of µs per element on a hand) while a batch of points
    /// usually has only a few back-facing footpoints, near a few elements. So when every raw
    /// piece fits (at most [`GROUPED_ELEMENTS`] elements and [`MAX_PIECES`] pieces), pieces are
    /// stored unclipped and [`nearest`](Self::nearest) clips each one the first time a query
    /// reaches it. Clipping a piece depends only on the piece and the model, and pieces left
    /// with no visible range are skipped by queries, so the answers are those of clipping
    /// everything up front (what happens otherwise, keeping the first [`MAX_PIECES`] visible
    /// pieces in element order).
    pub(crate) fn build(g: &SphereMeshGeometry, basis: ViewBasis, tol: f64) -> Self {
        Self::build_with(g, basis, tol, true)
    }

    /// [`build`](Self::build), lazily clipped only when `lazy` (and every raw piece fits).
    fn build_with(g: &SphereMeshGeometry, basis: ViewBasis, tol: f64, lazy: bool) -> Self {
        let mut sil = Self {
            basis,
            tol,
            pieces: [VisiblePiece::default(); MAX_PIECES],
            len: 0,
            first: [0; GROUPED_ELEMENTS + 1],
            grouped: false,
        };
        sil.refill(g, basis, tol, lazy);
        sil
    }

    /// [`build`](Self::build) in place, reusing `self`'s storage: only the pieces it stores are
    /// written (those beyond `len` are never read), which spares the ≈ 56 KiB initialization
    /// and move of a fresh silhouette per batch.
    pub(crate) fn rebuild(&mut self, g: &SphereMeshGeometry, basis: ViewBasis, tol: f64) {
        self.refill(g, basis, tol, true);
    }

    fn refill(&mut self, g: &SphereMeshGeometry, basis: ViewBasis, tol: f64, lazy: bool) {
        self.basis = basis;
        self.tol = tol;
        self.len = 0;
        self.first = [0; GROUPED_ELEMENTS + 1];
        self.grouped = g.frames.len() <= GROUPED_ELEMENTS;
        if !(lazy && self.grouped && self.fill(g, true)) {
            self.len = 0;
            self.fill(g, false);
        }
    }

    /// Stores every element's pieces, unclipped when `lazy`, otherwise clipped with only the
    /// visible ones kept. Returns `false` if a lazy fill ran out of room.
    fn fill(&mut self, g: &SphereMeshGeometry, lazy: bool) -> bool {
        let mut raw = [Piece::Segment {
            spheres: [0, 0],
            normal: Vector3::zeros(),
        }; MAX_ELEMENT_PIECES];
        for (e, frame) in g.frames.iter().enumerate() {
            if self.grouped {
                self.first[e] = self.len as u16;
            }
            let (centers, radii) = (frame.centers(), frame.radii());
            let k = element_pieces(centers, radii, &self.basis, &mut raw);
            for piece in &raw[..k] {
                if self.len == MAX_PIECES {
                    if lazy {
                        return false;
                    }
                    break;
                }
                let mut vp = VisiblePiece {
                    element: e as u32,
                    piece: *piece,
                    bound: piece.bound(centers, radii),
                    ..VisiblePiece::default()
                };
                if lazy {
                    vp.n_visible = UNCLIPPED;
                } else {
                    clip(g, e, &self.basis, self.tol, &mut vp);
                }
                if vp.n_visible > 0 {
                    self.pieces[self.len] = vp;
                    self.len += 1;
                }
            }
        }
        if self.grouped {
            self.first[g.frames.len()] = self.len as u16;
        }
        true
    }

    /// The visible silhouette point nearest to `p` if closer than `bound_d2` (squared), as
    /// (squared distance, element, point). The pieces of element `first` are tried first.
    /// Clips the pieces it reaches that are not clipped yet.
    pub(crate) fn nearest(
        &mut self,
        g: &SphereMeshGeometry,
        p: &Vector3<f64>,
        first: usize,
        bound_d2: f64,
    ) -> Option<(f64, usize, PiecePoint)> {
        let mut search = Nearest {
            basis: self.basis,
            tol: self.tol,
            g,
            p,
            bound_d2,
            reach: bound_d2.sqrt(),
            best: None,
        };
        if self.grouped && first < g.frames.len().min(GROUPED_ELEMENTS) {
            let starts = self.first;
            let range = |e: usize| starts[e] as usize..starts[e + 1] as usize;
            search.scan(&mut self.pieces[range(first)]);
            for (e, b) in g.packed.iter().enumerate() {
                let reach = b[3] + search.reach;
                let d2 = (p - Vector3::new(b[0], b[1], b[2])).norm_squared();
                if e != first && d2 < reach * reach {
                    search.scan(&mut self.pieces[range(e)]);
                }
            }
        } else {
            search.scan(&mut self.pieces[..self.len]);
        }
        search.best
    }
}

/// State of [`UnionSilhouette::nearest`].
struct Nearest<'a> {
    basis: ViewBasis,
    tol: f64,
    g: &'a SphereMeshGeometry,
    p: &'a Vector3<f64>,
    bound_d2: f64,
    /// `√bound_d2`, for square-root-free ball tests.
    reach: f64,
    best: Option<(f64, usize, PiecePoint)>,
}

impl Nearest<'_> {
    /// Offers the nearest visible point of each of `pieces`, nearest pieces first (by the
    /// nearest point of the whole piece), [`MAX_ELEMENT_PIECES`] at a time: a piece whose whole
    /// nearest point is visible needs no clipping, and once one is found the pieces behind it
    /// need nothing at all.
    fn scan(&mut self, pieces: &mut [VisiblePiece]) {
        for chunk in pieces.chunks_mut(MAX_ELEMENT_PIECES) {
            let mut order = [(0.0, 0, PiecePoint::default()); MAX_ELEMENT_PIECES];
            let mut n = 0;
            for (k, vp) in chunk.iter().enumerate() {
                let [x, y, z, r] = vp.bound;
                let reach = r + self.reach;
                if (self.p - Vector3::new(x, y, z)).norm_squared() >= reach * reach {
                    continue;
                }
                let frame = &self.g.frames[vp.element as usize];
                let (lo, hi) = vp.piece.range();
                let whole = [Span::new(&vp.piece, lo, hi)];
                let (centers, radii) = (frame.centers(), frame.radii());
                let point = nearest_on(&vp.piece, &whole, centers, radii, &self.basis, self.p);
                order[n] = ((self.p - point.point).norm_squared(), k, point);
                n += 1;
            }
            let order = &mut order[..n];
            order.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            for &(d2, k, point) in order.iter() {
                if d2 >= self.bound_d2 {
                    break;
                }
                self.visit(&mut chunk[k], point);
            }
        }
    }

    /// Offers the nearest visible point of `vp`, given the nearest point of the whole piece,
    /// clipping the piece only when that point is buried.
    fn visit(&mut self, vp: &mut VisiblePiece, whole: PiecePoint) {
        let own = vp.element as usize;
        if vp.n_visible == UNCLIPPED {
            if visible_at(self.g, own, &self.basis, self.tol, vp, &whole) {
                self.offer(vp, whole);
                return;
            }
            clip(self.g, own, &self.basis, self.tol, vp);
        }
        if vp.n_visible == 0 {
            return;
        }
        let frame = &self.g.frames[own];
        let spans = &vp.visible[..vp.n_visible as usize];
        let (centers, radii) = (frame.centers(), frame.radii());
        let point = nearest_on(&vp.piece, spans, centers, radii, &self.basis, self.p);
        self.offer(vp, point);
    }

    /// Keeps `point` of `vp` if it is the nearest so far.
    fn offer(&mut self, vp: &VisiblePiece, point: PiecePoint) {
        let d2 = (self.p - point.point).norm_squared();
        if d2 < self.bound_d2 {
            self.bound_d2 = d2;
            self.reach = d2.sqrt();
            self.best = Some((d2, vp.element as usize, point));
        }
    }
}

impl Span {
    /// The range `[a, b]` of `piece` (with its end directions for an arc).
    fn new(piece: &Piece, a: f64, b: f64) -> Self {
        let dir = |t: f64| {
            let (sin, cos) = t.sin_cos();
            Vector2::new(cos, sin)
        };
        match piece {
            Piece::Arc { .. } => Span {
                a,
                b,
                da: dir(a),
                db: dir(b),
            },
            Piece::Segment { .. } => Span {
                a,
                b,
                ..Span::default()
            },
        }
    }
}

/// The point of `piece`'s `spans` (parameter ranges) nearest to `p`.
fn nearest_on(
    piece: &Piece,
    spans: &[Span],
    centers: &[Vector3<f64>],
    radii: &[f64],
    basis: &ViewBasis,
    p: &Vector3<f64>,
) -> PiecePoint {
    match *piece {
        Piece::Arc { sphere, .. } => {
            let u = basis.flatten(&(p - centers[sphere as usize]));
            let d = nearest_direction(spans, u);
            Piece::arc_at_direction(sphere, centers, radii, basis, &d)
        }
        Piece::Segment { .. } => {
            let (_, _, foot) = piece.segment_foot(centers, radii, p).unwrap_or_default();
            let mut t = foot;
            let mut gap = f64::INFINITY;
            for s in spans {
                let c = foot.clamp(s.a, s.b);
                if (c - foot).abs() < gap {
                    gap = (c - foot).abs();
                    t = c;
                }
            }
            piece.at(centers, radii, basis, t)
        }
    }
}

/// The unit direction within the visible arcs `spans` nearest (in angle) to the in-plane
/// direction `u` of the query point; the distance to the query grows with that angle.
fn nearest_direction(spans: &[Span], u: Vector2<f64>) -> Vector2<f64> {
    let len = u.norm();
    let Some(first) = spans.first() else {
        return Vector2::x();
    };
    if len <= 0.0 {
        return first.da; // every point of the circle is equally close
    }
    let u = u / len;
    let cross = |a: &Vector2<f64>, b: &Vector2<f64>| a.x * b.y - a.y * b.x;
    let mut best = first.da;
    let mut best_dot = f64::NEG_INFINITY;
    for s in spans {
        let inside = if s.b - s.a <= core::f64::consts::PI {
            cross(&s.da, &u) >= 0.0 && cross(&u, &s.db) >= 0.0
        } else {
            !(cross(&s.db, &u) > 0.0 && cross(&u, &s.da) > 0.0)
        };
        if inside {
            return u;
        }
        for d in [s.da, s.db] {
            let dot = d.dot(&u);
            if dot > best_dot {
                best_dot = dot;
                best = d;
            }
        }
    }
    best
}

/// How one element can bury a piece of another (see [`blockers`]).
enum Blocker<'a> {
    /// The piece is an arc of the blocker's sphere: visible only on the arcs (unwrapped
    /// angles) where that sphere supports the blocker's hull.
    SharedArc([(f64, f64); 2], usize),
    /// The piece is the generator segment of two of the blocker's spheres: wholly visible or
    /// wholly buried, as the pair supports the segment's normal or not.
    SharedSegment(bool),
    /// Any other element: buries where `φ_B + tol < 0`.
    Other(&'a ElementFrame),
}

/// The elements that may bury piece `vp` of element `own`: those whose bounding balls meet the
/// piece's. A blocker that contains the piece's sphere(s) is classified exactly: a sphere inside
/// a convex hull of spheres touches its boundary only where it is the hull's support, so the arc
/// stays visible on the blocker's active arcs of that sphere, and a generator segment of two of
/// its spheres is visible iff that pair supports the segment's normal.
fn blockers<'a>(
    g: &'a SphereMeshGeometry,
    own: usize,
    basis: &'a ViewBasis,
    vp: &'a VisiblePiece,
) -> impl Iterator<Item = Blocker<'a>> + 'a {
    let own_ids = g.elements[own].spheres();
    let [bx, by, bz, br] = vp.bound;
    let bound_center = Vector3::new(bx, by, bz);
    g.packed.iter().enumerate().filter_map(move |(b, ball)| {
        let reach = ball[3] + br;
        if b == own
            || (bound_center - Vector3::new(ball[0], ball[1], ball[2])).norm_squared()
                >= reach * reach
        {
            return None;
        }
        let blocker = &g.frames[b];
        let b_ids = g.elements[b].spheres();
        let local_in_b = |local: u8| b_ids.iter().position(|&x| x == own_ids[local as usize]);
        Some(match vp.piece {
            Piece::Arc { sphere, .. } => match local_in_b(sphere) {
                Some(k) => {
                    let (arcs, n) = sphere_arcs(blocker.centers(), blocker.radii(), basis, k);
                    Blocker::SharedArc(arcs, n)
                }
                None => Blocker::Other(blocker),
            },
            Piece::Segment {
                spheres: [i, j],
                normal,
            } => match (local_in_b(i), local_in_b(j)) {
                (Some(ki), Some(_)) => {
                    let (bc, br) = (blocker.centers(), blocker.radii());
                    let own_support = normal.dot(&bc[ki]) + br[ki];
                    Blocker::SharedSegment(bc.iter().zip(br).all(|(c, r)| {
                        normal.dot(c) + r <= own_support + 1e-9 * (1.0 + own_support.abs())
                    }))
                }
                _ => Blocker::Other(blocker),
            },
        })
    })
}

/// Whether the point `x` of piece `vp` (of element `own`) is visible: what [`clip`] decides
/// for it, from one evaluation per blocker instead of a subdivision of the whole piece. The two
/// agree but within the resolution of the clip's boundaries (which it pins on the visible side)
/// and on dips narrower than it.
fn visible_at(
    g: &SphereMeshGeometry,
    own: usize,
    basis: &ViewBasis,
    tol: f64,
    vp: &VisiblePiece,
    x: &PiecePoint,
) -> bool {
    use core::f64::consts::TAU;
    blockers(g, own, basis, vp).all(|blocker| match blocker {
        Blocker::SharedArc(arcs, n) => {
            // The arc's angle, from its in-plane normal direction.
            let d = basis.flatten(&x.normal);
            let angle = d.y.atan2(d.x);
            arcs[..n]
                .iter()
                .any(|&(lo, hi)| angle - ((angle - lo) / TAU).floor() * TAU <= hi)
        }
        Blocker::SharedSegment(supported) => supported,
        Blocker::Other(frame) => frame.distance(&x.point) + tol >= 0.0,
    })
}

/// Fills `vp.visible` with the parameter ranges of the piece not buried in another element
/// ([`blockers`]: exactly for the blockers that share its spheres, otherwise by the Lipschitz
/// subdivision of `φ_B(x(s)) + tol` on the still-visible ranges).
fn clip(g: &SphereMeshGeometry, own: usize, basis: &ViewBasis, tol: f64, vp: &mut VisiblePiece) {
    let frame = &g.frames[own];
    let (centers, radii) = (frame.centers(), frame.radii());
    let piece = vp.piece;
    let (lo, hi) = piece.range();
    let mut vis = Intervals::new(lo, hi);
    let speed = piece.speed(centers, radii).max(1e-12);
    for blocker in blockers(g, own, basis, vp) {
        let blocker = match blocker {
            Blocker::SharedArc(arcs, n) => {
                vis.intersect_circular(&arcs[..n]);
                if vis.is_empty() {
                    break;
                }
                continue;
            }
            Blocker::SharedSegment(supported) => {
                if !supported {
                    vis.clear();
                    break;
                }
                continue;
            }
            Blocker::Other(blocker) => blocker,
        };
        let f = |s: f64| blocker.distance(&piece.at(centers, radii, basis, s).point) + tol;
        let mut buried = Intervals::empty();
        for &(a, c) in vis.as_slice() {
            match piece {
                // A signed distance to a convex set is convex along a line.
                Piece::Segment { .. } => buried_range_convex(&f, a, c, speed, &mut buried),
                Piece::Arc { .. } => buried_ranges(&f, a, c, speed, &mut buried),
            }
        }
        for &(a, c) in buried.as_slice() {
            vis.subtract(a, c);
        }
        if vis.is_empty() {
            break;
        }
    }
    let kept = vis.as_slice();
    let n = kept.len().min(MAX_VISIBLE);
    for (span, &(a, b)) in vp.visible.iter_mut().zip(&kept[..n]) {
        *span = Span::new(&piece, a, b);
    }
    vp.n_visible = n as u8;
}

/// [`buried_ranges`] for a convex `f`: `{f < 0}` is one interval, found from a negative point
/// (an end, or one located by Lipschitz subdivision) and regula falsi on each side.
fn buried_range_convex(f: &impl Fn(f64) -> f64, lo: f64, hi: f64, speed: f64, out: &mut Intervals) {
    let (flo, fhi) = (f(lo), f(hi));
    let inside = if flo < 0.0 {
        Some((lo, flo))
    } else if fhi < 0.0 {
        Some((hi, fhi))
    } else {
        negative_point(f, lo, flo, hi, fhi, speed)
    };
    let Some((m, fm)) = inside else {
        return;
    };
    let start = if flo < 0.0 {
        lo
    } else {
        crossing(f, m, fm, lo, flo)
    };
    let end = if fhi < 0.0 {
        hi
    } else {
        crossing(f, m, fm, hi, fhi)
    };
    out.push(start, end);
}

/// A point of `[lo, hi]` where `f < 0`, given `f(lo), f(hi) ≥ 0` and `f` `speed`-Lipschitz, or
/// `None` when the subdivision rules it out down to the resolution.
fn negative_point(
    f: &impl Fn(f64) -> f64,
    lo: f64,
    flo: f64,
    hi: f64,
    fhi: f64,
    speed: f64,
) -> Option<(f64, f64)> {
    let mut stack = [(0.0, 0.0, 0.0, 0.0); 64];
    stack[0] = (lo, flo, hi, fhi);
    let mut len = 1;
    let min = resolution(speed * (hi - lo));
    while len > 0 {
        len -= 1;
        let (a, fa, b, fb) = stack[len];
        let reach = speed * (b - a);
        if fa + fb >= reach || reach <= min || len + 2 > stack.len() {
            continue;
        }
        let m = 0.5 * (a + b);
        let fm = f(m);
        if fm < 0.0 {
            return Some((m, fm));
        }
        stack[len] = (m, fm, b, fb);
        stack[len + 1] = (a, fa, m, fm);
        len += 2;
    }
    None
}

/// Appends to `out` the sub-ranges of `[lo, hi]` where `f < 0` (buried), for an `f` that is
/// `speed`-Lipschitz: depth-first subdivision, deciding a range from its end values when they
/// rule out a sign change (`|f(a)| + |f(b)| ≥ speed·(b − a)` with equal signs), with regula falsi
/// on the last sign change.
fn buried_ranges(f: &impl Fn(f64) -> f64, lo: f64, hi: f64, speed: f64, out: &mut Intervals) {
    let mut stack = [(0.0, 0.0, 0.0, 0.0); 64];
    stack[0] = (lo, f(lo), hi, f(hi));
    let mut len = 1;
    let min = resolution(speed * (hi - lo));
    let mut open: Option<(f64, f64)> = None;
    let close = |open: &mut Option<(f64, f64)>, out: &mut Intervals| {
        if let Some((a, b)) = open.take() {
            out.push(a, b);
        }
    };
    while len > 0 {
        len -= 1;
        let (a, fa, b, fb) = stack[len];
        let reach = speed * (b - a);
        let bury = |x: f64, y: f64, open: &mut Option<(f64, f64)>| {
            *open = Some(match *open {
                Some((start, _)) => (start, y),
                None => (x, y),
            });
        };
        if fa >= 0.0 && fb >= 0.0 && fa + fb >= reach {
            close(&mut open, out);
        } else if fa < 0.0 && fb < 0.0 && -(fa + fb) >= reach {
            bury(a, b, &mut open);
        } else if reach <= min || len + 2 > stack.len() {
            match (fa >= 0.0, fb >= 0.0) {
                (true, true) => close(&mut open, out),
                (false, false) => bury(a, b, &mut open),
                (false, true) => {
                    let c = crossing(f, a, fa, b, fb);
                    bury(a, c, &mut open);
                    close(&mut open, out);
                }
                (true, false) => {
                    let c = crossing(f, b, fb, a, fa);
                    close(&mut open, out);
                    bury(c, b, &mut open);
                }
            }
        } else if (fa >= 0.0) != (fb >= 0.0) && fa.abs().max(fb.abs()) >= 0.25 * reach {
            // A clear sign change: one crossing is all the Lipschitz bound leaves room for
            // near the larger end, so solve for it and classify the two sides separately.
            let c = if fa < 0.0 {
                crossing(f, a, fa, b, fb)
            } else {
                crossing(f, b, fb, a, fa)
            };
            let fc = f(c);
            stack[len] = (c, fc, b, fb);
            stack[len + 1] = (a, fa, c, fc);
            len += 2;
            if (c - a).abs() <= f64::EPSILON * (1.0 + a.abs())
                || (b - c).abs() <= f64::EPSILON * (1.0 + b.abs())
            {
                // Degenerate split: fall back to bisection next time round.
                len -= 2;
                let m = 0.5 * (a + b);
                let fm = f(m);
                stack[len] = (m, fm, b, fb);
                stack[len + 1] = (a, fa, m, fm);
                len += 2;
            }
        } else {
            let m = 0.5 * (a + b);
            let fm = f(m);
            stack[len] = (m, fm, b, fb);
            stack[len + 1] = (a, fa, m, fm);
            len += 2;
        }
    }
    close(&mut open, out);
}

/// A small sorted set of disjoint parameter ranges.
#[derive(Copy, Clone, Debug)]
struct Intervals {
    items: [(f64, f64); 8],
    len: usize,
}

impl Intervals {
    fn new(lo: f64, hi: f64) -> Self {
        let mut s = Self::empty();
        s.push(lo, hi);
        s
    }

    fn empty() -> Self {
        Self {
            items: [(0.0, 0.0); 8],
            len: 0,
        }
    }

    fn as_slice(&self) -> &[(f64, f64)] {
        &self.items[..self.len]
    }

    fn is_empty(&self) -> bool {
        self.len == 0
    }

    fn clear(&mut self) {
        self.len = 0;
    }

    /// Appends a range after the existing ones (dropped when full).
    fn push(&mut self, a: f64, b: f64) {
        if self.len < self.items.len() && b >= a {
            self.items[self.len] = (a, b);
            self.len += 1;
        }
    }

    /// Removes the open range `(a, b)`; the end points stay visible.
    fn subtract(&mut self, a: f64, b: f64) {
        let mut out = Self::empty();
        for &(x, y) in self.as_slice() {
            if b <= x || a >= y {
                out.push(x, y);
                continue;
            }
            if a > x {
                out.push(x, a);
            }
            if b < y {
                out.push(b, y);
            }
        }
        *self = out;
    }

    /// Keeps only the parts inside the circular arcs `(lo, hi)` (angles, any unwrapping).
    fn intersect_circular(&mut self, arcs: &[(f64, f64)]) {
        use core::f64::consts::TAU;
        let mut out = Self::empty();
        for &(x, y) in self.as_slice() {
            for &(lo, hi) in arcs {
                // Shift the arc by whole turns to every position overlapping [x, y].
                let k0 = ((x - hi) / TAU).ceil();
                let mut k = k0;
                while lo + k * TAU <= y {
                    let (a, b) = ((lo + k * TAU).max(x), (hi + k * TAU).min(y));
                    if b > a {
                        out.push(a, b);
                    }
                    k += 1.0;
                }
            }
        }
        out.items[..out.len].sort_unstable_by(|p, q| p.0.total_cmp(&q.0));
        *self = out;
    }
}

/// Regula falsi (Illinois variant) for the crossing of `f` between `inside` (`f < 0`) and
/// `outside` (`f ≥ 0`); returns a parameter on the outside (`f ≥ 0`, visible) side.
pub(crate) fn crossing(
    f: &impl Fn(f64) -> f64,
    mut inside: f64,
    mut f_in: f64,
    mut outside: f64,
    f_outside: f64,
) -> f64 {
    // `f_out` is the (possibly halved, Illinois) weight; `f_true` the value at `outside`.
    let (mut f_out, mut f_true) = (f_outside, f_outside);
    let mut side = 0i8;
    for _ in 0..60 {
        if (outside - inside).abs() <= 1e-12 * (1.0 + outside.abs()) || f_true <= 1e-10 {
            break;
        }
        let c = (inside * f_out - outside * f_in) / (f_out - f_in);
        if !(c > inside.min(outside) && c < inside.max(outside)) {
            break;
        }
        let fc = f(c);
        if fc < 0.0 {
            inside = c;
            f_in = fc;
            if side == -1 {
                f_out *= 0.5;
            }
            side = -1;
        } else {
            outside = c;
            f_out = fc;
            f_true = fc;
            if side == 1 {
                f_in *= 0.5;
            }
            side = 1;
        }
    }
    outside
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shape::{Element, Sphere};

    /// Lazy clipping answers exactly as clipping everything up front, on a hand-like model
    /// (31 elements) seen from several directions; so does a silhouette rebuilt in place over
    /// one of another view and tolerance.
    #[test]
    fn lazy_clipping_answers_as_eager_clipping() {
        let t = crate::spheremesh::default_right_hand();
        let mut pose = crate::kinematics::Pose::zeros(&t.skeleton);
        for (name, v) in [
            ("index_mcp_flex", 0.8),
            ("middle_pip_flex", 1.0),
            ("global_rx", 0.5),
        ] {
            pose.set(&t.skeleton, name, v).unwrap();
        }
        let spheres: Vec<Sphere> = crate::spheremesh::PosedSphereMesh::new(&t, &pose).spheres;
        let elements: Vec<Element> = t.elements.iter().map(|e| e.element).collect();
        let g = SphereMeshGeometry::new(&spheres, &elements).unwrap();
        let ball = g.tree.root_ball().unwrap();
        let mut k = 0u32;
        // A deterministic low-discrepancy walk through the model's bounding ball.
        let mut next = || {
            k += 1;
            let f = |a: f64| (f64::from(k) * a).fract() * 2.0 - 1.0;
            ball.center + Vector3::new(f(0.618_034), f(0.754_878), f(0.569_840)) * ball.radius
        };
        // Rebuilt in place for each view after answering (and clipping for) the previous one.
        let mut reused = UnionSilhouette::build_with(&g, ViewBasis::new(Vector3::y()), 0.1, false);
        for v in [Vector3::z(), Vector3::new(0.4, -0.3, 1.0), Vector3::x()] {
            let basis = ViewBasis::new(v.normalize());
            let mut lazy = UnionSilhouette::build(&g, basis, 1e-6);
            let mut eager = UnionSilhouette::build_with(&g, basis, 1e-6, false);
            reused.rebuild(&g, basis, 1e-6);
            assert_eq!(reused.len, lazy.len);
            assert_eq!(reused.first, lazy.first);
            assert!(lazy.pieces[..lazy.len]
                .iter()
                .all(|p| p.n_visible == UNCLIPPED));
            for _ in 0..400 {
                let p = next();
                let e0 = g.project(&p).unwrap().element as usize;
                let a = lazy.nearest(&g, &p, e0, f64::INFINITY);
                let b = eager.nearest(&g, &p, e0, f64::INFINITY);
                let c = reused.nearest(&g, &p, e0, f64::INFINITY);
                assert_eq!(a.map(|x| (x.0, x.1)), b.map(|x| (x.0, x.1)));
                assert_eq!(a.map(|x| x.2.point), b.map(|x| x.2.point));
                assert_eq!(
                    a.map(|x| (x.0.to_bits(), x.1)),
                    c.map(|x| (x.0.to_bits(), x.1))
                );
                assert_eq!(a.map(|x| x.2.point), c.map(|x| x.2.point));
            }
        }
    }

    /// The nearest point of a whole piece (what [`Nearest::scan`] orders the pieces by, and
    /// keeps when it is visible) against the nearest of 401 samples along it.
    #[test]
    fn whole_piece_nearest_point_matches_sampling() {
        use crate::query::silhouette::{element_pieces, MAX_ELEMENT_PIECES};
        let centers = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(30.0, 4.0, -6.0),
            Vector3::new(8.0, 25.0, 3.0),
        ];
        let radii = [9.0, 5.0, 7.0];
        let basis = ViewBasis::new(Vector3::new(0.3, -0.2, 1.0).normalize());
        let mut out = [Piece::Arc {
            sphere: 0,
            lo: 0.0,
            hi: 0.0,
        }; MAX_ELEMENT_PIECES];
        let n = element_pieces(&centers, &radii, &basis, &mut out);
        assert!(n >= 4, "{n} pieces");
        for piece in &out[..n] {
            let (lo, hi) = piece.range();
            let whole = [Span::new(piece, lo, hi)];
            let samples: Vec<Vector3<f64>> = (0..=400)
                .map(|k| {
                    let s = lo + (hi - lo) * f64::from(k) / 400.0;
                    piece.at(&centers, &radii, &basis, s).point
                })
                .collect();
            let step = (0..400)
                .map(|k| (samples[k + 1] - samples[k]).norm())
                .fold(0.0, f64::max);
            // A lattice over a cube around the element, off the sampled points.
            let axis = |k: usize| -35.3 + 12.7 * k as f64;
            for k in 0..343 {
                let p = Vector3::new(axis(k % 7), axis(k / 7 % 7), axis(k / 49) - 5.0);
                let x = nearest_on(piece, &whole, &centers, &radii, &basis, &p).point;
                let on_piece = samples
                    .iter()
                    .map(|s| (x - s).norm())
                    .fold(f64::INFINITY, f64::min);
                assert!(on_piece <= step, "{on_piece} mm off the piece");
                let d = (p - x).norm();
                let brute = samples
                    .iter()
                    .map(|s| (p - s).norm())
                    .fold(f64::INFINITY, f64::min);
                assert!(d <= brute + 1e-9, "{d} > {brute}");
                assert!(brute - d <= step, "{d} far below sampling's {brute}");
            }
        }
    }

    #[test]
    fn stack_footprint_stays_moderate() {
        assert!(core::mem::size_of::<UnionSilhouette>() < 64 * 1024);
    }

    #[test]
    fn intervals_subtract_and_intersect() {
        let mut s = Intervals::new(0.0, 10.0);
        s.subtract(2.0, 3.0);
        s.subtract(5.0, 12.0);
        assert_eq!(s.as_slice(), &[(0.0, 2.0), (3.0, 5.0)]);
        let tau = core::f64::consts::TAU;
        let mut a = Intervals::new(-1.0, 1.0);
        a.intersect_circular(&[(0.5 + tau, 2.0 + tau)]);
        assert_eq!(a.as_slice().len(), 1);
        assert!((a.as_slice()[0].0 - 0.5).abs() < 1e-12 && (a.as_slice()[0].1 - 1.0).abs() < 1e-12);
    }

    #[test]
    fn convex_buried_range_is_found() {
        // f(t) = |t − 0.5| − 0.2: buried on (0.3, 0.7).
        let f = |t: f64| (t - 0.5f64).abs() - 0.2;
        let mut out = Intervals::empty();
        buried_range_convex(&f, 0.0, 1.0, 1.0, &mut out);
        let (a, b) = out.as_slice()[0];
        assert!((a - 0.3).abs() < 1e-9 && (b - 0.7).abs() < 1e-9, "{a} {b}");
        assert!(f(a) >= 0.0 && f(b) >= 0.0);
    }
}
