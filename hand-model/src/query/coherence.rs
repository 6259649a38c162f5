//! Temporal coherence of the closest-point search across re-posings: a tracker re-projects the
//! same ~2500 sensor points on a slightly moved model every solver iteration (§3.3.1), and the
//! element that won a point's argmin (Eq. 3.6) usually wins it again, by a clear margin.
//!
//! The signed distance of an element is `φ_e(p) = min_λ ‖p − Σ λᵢ cᵢ‖ − Σ λᵢ rᵢ` over a fixed
//! set of barycentric weights `λ` (the closed forms of Fig. 3.7 evaluate exactly this minimum),
//! so moving the element's spheres by `Δcᵢ` and changing their radii by `Δrᵢ` changes `φ_e(p)` by
//! at most its motion `δ_e = maxᵢ (‖Δcᵢ‖ + |Δrᵢ|)`, and moving `p` changes it by at most `‖Δp‖`.
//! Say that after the last call every element but the winner `e*` was at least `m` from `p`
//! (the *margin*), and let `M = m − ‖Δp‖`. Now an element whose bounding ball is farther than
//! `M` is farther than `M`, and any other element `e` is at least `M − δ_e` away; so every
//! element but `e*` is at least `m' = M − max δ_e` away, the maximum taken over the elements
//! whose balls are within `M` (the cheap vectorised ball test of the search). When `φ_{e*}(p)`
//! is below `m'`, `e*` is the argmin again without evaluating any other element, and `m'` is
//! the new margin. Taking the motion per element matters: a bending finger moves its tip by
//! several millimetres per solver iteration while the palm and the other fingers barely move.
//!
//! A margin equal to the minimum would expire at the first motion, so the searches that set it
//! evaluate every element within [`MARGIN_GAP`] of the minimum (see
//! [`SphereMeshGeometry::search`]): the margin is then the second smallest distance, capped at
//! the minimum plus the gap. The answers are bit for bit those of the plain search.
//!
//! Points near the seam of two elements (adjacent palm wedges, a joint between phalanges) have
//! a second element within a hair of the minimum, and any motion at all spent a margin set by
//! it: most of the searches that followed found the same element again. So a search also names
//! that nearest other element within the gap (the *runner* of `SphereMeshGeometry::search`);
//! the margin bounds every element but the winner and the runner (the third smallest distance,
//! capped), and the keep test evaluates the runner exactly (one element instead of a search).
//! In the online bench this cut the full searches by a third (≈ 7 000 → 4 800 a frame, 92 %
//! of them still finding the same element). The runner's distance is remembered too, as a
//! lower bound that its own motion and the point's wear down: it is evaluated again only
//! when that bound no longer clears the winner.
//!
//! The keep test bounds the other elements' motion in three tiers, cheapest first: the largest
//! motion of all of them; the largest motion of the element's neighbours (precomputed per
//! element once per call, for points near their element: `Coherence::near_motions`); and the
//! per-point ball test of the elements within reach (`SphereMeshGeometry::motion_within`).

use super::geometry::SphereMeshGeometry;
use super::union_silhouette::UnionSilhouette;
use super::{is_usable, Projection, NO_SEED};
use crate::shape::{Element, Sphere};
use nalgebra::Vector3;

/// How far beyond the minimum (mm) a full search looks for the margin: a wider gap costs more
/// element evaluations per full search and saves more searches afterwards. Within one tracked
/// frame the model moves a few millimetres in total over the solver iterations.
pub(super) const MARGIN_GAP: f64 = 4.0;

/// The neighbourhood of an element for the keep test's middle tier: a point at most
/// `NEAR_DISTANCE` (mm) outside its element whose spent margin `reach` is at most `NEAR_REACH`
/// can only have within reach the elements whose bounding balls come within
/// `NEAR_DISTANCE + NEAR_REACH` of its element's ball (see [`Coherence::near_motions`]).
const NEAR_DISTANCE: f64 = 4.0;
const NEAR_REACH: f64 = 8.0;

/// Relative rounding allowance of a margin per use: the margins, distances and motions compared
/// are computed in floating point, each to ~1e-15 of the coordinates' magnitude.
const ROUNDING: f64 = 1e-9;

/// The per-point memory of [`SphereMeshGeometry::project_points_coherent`] and
/// [`SphereMeshGeometry::project_points_front_facing_coherent`] between calls: the winning
/// element of each point's last search and how far every other element was, with the spheres
/// and points that held for; also the storage of the front-facing calls' object-space
/// silhouette, rebuilt in place per call. Build it empty with [`Coherence::default`]; the calls
/// size it and allocate nothing once it has held as many points and spheres (and, for the
/// front-facing calls, once one of them has needed a silhouette).
///
/// The state only saves work: whatever it holds (another model, other points, stale
/// answers), the projections are bit for bit those of
/// [`project_points`](SphereMeshGeometry::project_points).
#[derive(Clone, Debug, Default)]
pub struct Coherence {
    tracks: Vec<Track>,
    /// The spheres and elements of the last call.
    spheres: Vec<Sphere>,
    elements: Vec<Element>,
    /// Per element its motion `δ_e` since the last call (+∞ after a change of model).
    motions: Vec<f64>,
    /// Per element, the largest motion of the other elements whose bounding balls come within
    /// `NEAR_DISTANCE + NEAR_REACH` of its own (at the current spheres): a point near the
    /// element (at most `NEAR_DISTANCE` outside it, so within that much of its ball) has no
    /// other element within `NEAR_REACH` of it. A bound between the largest motion of all
    /// other elements and the per-point ball test, looked up instead of tested.
    near_motions: Vec<f64>,
    /// Per culling block of the geometry, the largest motion of its elements and the block,
    /// largest first (see [`SphereMeshGeometry::motion_within`]).
    block_motions: Vec<(f64, usize)>,
    /// How many points of the last call kept their element without a search.
    kept: usize,
    /// The image pixel of each track's point when the tracks were carried by pixel
    /// ([`Coherence::carry_to_pixels`]); empty otherwise.
    pixels: Vec<u32>,
    /// Scratch of the carry: per image pixel, 1 + the index of the old track there (0: none);
    /// all zero between carries.
    by_pixel: Vec<u32>,
    /// Scratch of the carry: the new tracks.
    carried: Vec<Track>,
    /// The object-space silhouette of the front-facing calls, rebuilt in place per call
    /// (allocated by the first call that needs one).
    pub(super) silhouette: Option<Box<UnionSilhouette>>,
}

/// One point's memory.
#[derive(Copy, Clone, Debug, PartialEq)]
struct Track {
    /// The plain argmin element of the last call ([`NO_SEED`] for none).
    element: u32,
    /// The runner-up of the last search ([`NO_SEED`] for none): evaluated exactly by the keep
    /// test instead of being bounded by the margin.
    runner: u32,
    /// A lower bound of the runner's `φ_e(point)` at the last call's spheres: the runner is
    /// evaluated again only when this less its motion and the point's no longer clears the
    /// winner.
    runner_margin: f64,
    /// A lower bound of `φ_e(point)` over every element `e` but `element` and `runner` at the
    /// last call's spheres.
    margin: f64,
    /// The point the margin is for.
    point: Vector3<f64>,
}

/// The 8 pixels around a pixel, the 4 edge neighbours (nearer) first, each group in row order.
const NEIGHBOURS: [(isize, isize); 8] = [
    (0, -1),
    (-1, 0),
    (1, 0),
    (0, 1),
    (-1, -1),
    (1, -1),
    (-1, 1),
    (1, 1),
];

impl Track {
    const NONE: Self = Self {
        element: NO_SEED,
        runner: NO_SEED,
        runner_margin: f64::NEG_INFINITY,
        margin: f64::NEG_INFINITY,
        point: Vector3::new(0.0, 0.0, 0.0),
    };

    /// Carries the memory of a point that a call skipped over the model's motion in that call:
    /// the margin less the largest motion of any element (which bounds the winner's and the
    /// runner's motion too), the runner's bound less the runner's own motion. The next call
    /// subtracts its own motions as usual, so the bounds stay lower bounds. An unbounded
    /// motion (another model) forgets the point.
    fn wear(&mut self, motions: &Motions<'_>) {
        let all = motions.largest.1;
        let runner = motions
            .per_element
            .get(self.runner as usize)
            .copied()
            .unwrap_or(0.0);
        if !(all.is_finite() && runner.is_finite()) {
            *self = Self::NONE;
            return;
        }
        self.margin -= all;
        self.runner_margin -= runner;
    }
}

impl Coherence {
    /// How many points of the last call kept their previous element without a search (a
    /// measure of the saved work).
    pub fn kept(&self) -> usize {
        self.kept
    }

    /// Forgets every point (the next call searches them all in full).
    pub fn clear(&mut self) {
        self.pixels.clear();
        self.tracks.clear();
        self.spheres.clear();
        self.elements.clear();
        self.motions.clear();
        self.kept = 0;
    }

    /// Hands the memory of the last call's points over to the points of a new frame, matched by
    /// image pixel: `pixels[i]` is the linear pixel index (`v · width + u`, `u < width`,
    /// `v < height`) of the new `i`-th point, and it inherits the track of the old point at the
    /// same pixel or, failing that, at the nearest of the 8 pixels around it (the first in row
    /// order among equals). The old points' pixels are those of the previous carry; without
    /// one (the state was filled after [`Coherence::clear`] or never carried) every track is
    /// forgotten. Points with a pixel outside the image inherit nothing.
    ///
    /// Any inherited track is sound: its margin is reduced by how far the new point lies from
    /// the old one and by the motion of the model since (module docs), so the next call's
    /// projections are bit for bit the plain ones whatever the match; a close match (the same
    /// surface point seen again one frame later) only lets more points skip their search in
    /// the first solver iteration of the frame, which otherwise searches every point. Allocates
    /// nothing once the state has held as many points and an image as large.
    pub fn carry_to_pixels(&mut self, pixels: &[u32], width: u32, height: u32) {
        let (w, h) = (width as usize, height as usize);
        let size = w * h;
        let valid = self.pixels.len() == self.tracks.len()
            && self.pixels.iter().all(|&k| (k as usize) < size);
        self.carried.clear();
        if valid && !self.pixels.is_empty() {
            if self.by_pixel.len() < size {
                self.by_pixel.resize(size, 0);
            }
            for (i, &k) in self.pixels.iter().enumerate() {
                // A repeated pixel keeps its first point.
                let slot = &mut self.by_pixel[k as usize];
                if *slot == 0 {
                    *slot = i as u32 + 1;
                }
            }
            let by_pixel = &self.by_pixel;
            let tracks = &self.tracks;
            let at = |u: isize, v: isize| -> Option<Track> {
                if u < 0 || v < 0 || u as usize >= w || v as usize >= h {
                    return None;
                }
                let i = by_pixel[v as usize * w + u as usize];
                (i != 0).then(|| tracks[i as usize - 1])
            };
            self.carried.extend(pixels.iter().map(|&k| {
                let k = k as usize;
                if k >= size {
                    return Track::NONE;
                }
                let (u, v) = ((k % w) as isize, (k / w) as isize);
                at(u, v)
                    .or_else(|| NEIGHBOURS.iter().find_map(|&(du, dv)| at(u + du, v + dv)))
                    .unwrap_or(Track::NONE)
            }));
            for &k in &self.pixels {
                self.by_pixel[k as usize] = 0;
            }
        } else {
            self.carried.resize(pixels.len(), Track::NONE);
        }
        std::mem::swap(&mut self.tracks, &mut self.carried);
        self.pixels.clear();
        self.pixels.extend_from_slice(pixels);
    }

    /// Sizes the state for `n` points, sets each element's motion since the last call (+∞ for
    /// another model: other elements or another sphere count) and makes the model the reference
    /// of the next call.
    fn begin(&mut self, spheres: &[Sphere], elements: &[Element], n: usize) {
        self.tracks.resize(n, Track::NONE);
        self.kept = 0;
        let same = self.spheres.len() == spheres.len() && self.elements == elements;
        self.motions.clear();
        self.motions.extend(elements.iter().map(|el| {
            el.spheres()
                .iter()
                .map(|&i| {
                    let i = i as usize;
                    match (self.spheres.get(i), spheres.get(i)) {
                        (Some(a), Some(b)) if same => {
                            (a.center - b.center).norm() + (a.radius - b.radius).abs()
                        }
                        _ => f64::INFINITY,
                    }
                })
                .fold(0.0, f64::max)
        }));
        self.spheres.clear();
        self.spheres.extend_from_slice(spheres);
        self.elements.clear();
        self.elements.extend_from_slice(elements);
    }
}

impl SphereMeshGeometry {
    /// [`project_points`](Self::project_points) (Eq. 3.6) for a tracker that re-projects the
    /// same data points every solver iteration: a point whose previous element is still nearer
    /// than the previous margin, less the model's and the point's motion since, keeps it without
    /// a search (module docs of `coherence.rs`); the others are searched from their previous
    /// element. `out` is bit for bit what `project_points` returns, whatever `state` holds.
    /// Allocates nothing once `state` has held as many points.
    ///
    /// # Panics
    /// If `out.len() != points.len()`.
    #[track_caller]
    pub fn project_points_coherent(
        &self,
        points: &[Vector3<f64>],
        state: &mut Coherence,
        out: &mut [Option<Projection>],
    ) {
        self.coherent_batch(points, None, state, out);
    }

    /// [`project_points_coherent`](Self::project_points_coherent) for the points whose `skip`
    /// entry is false alone: `out[i]` of a skipped point is left as it is, and its memory is
    /// worn down by the model's motion since the last call (every margin less the largest
    /// element motion), so that it stays sound for a later call that projects the point. A
    /// tracker skips the points whose correspondence another rule already settled (the
    /// sphere-mesh tracker's along-ray registration). The projected points' `out` is bit for
    /// bit what [`project_points`](Self::project_points) returns, whatever `state` holds.
    ///
    /// # Panics
    /// If `out` or `skip` is not as long as `points`.
    #[track_caller]
    pub fn project_points_coherent_skipping(
        &self,
        points: &[Vector3<f64>],
        skip: &[bool],
        state: &mut Coherence,
        out: &mut [Option<Projection>],
    ) {
        assert_eq!(points.len(), skip.len(), "one skip flag per point");
        self.coherent_batch(points, Some(skip), state, out);
    }

    /// The coherent projection of the points not skipped (all of them for `None`).
    #[track_caller]
    pub(super) fn coherent_batch(
        &self,
        points: &[Vector3<f64>],
        skip: Option<&[bool]>,
        state: &mut Coherence,
        out: &mut [Option<Projection>],
    ) {
        assert_eq!(points.len(), out.len(), "one output slot per point");
        state.begin(&self.spheres, &self.elements, points.len());
        self.order_block_motions(&state.motions, &mut state.block_motions);
        self.near_motions(&state.motions, &mut state.near_motions);
        let motions = Motions::new(&state.motions, &state.near_motions, &state.block_motions);
        let mut kept = 0;
        for (i, ((p, o), track)) in points
            .iter()
            .zip(out.iter_mut())
            .zip(&mut state.tracks)
            .enumerate()
        {
            if skip.is_some_and(|s| s[i]) {
                track.wear(&motions);
            } else {
                kept += usize::from(self.project_tracked(p, track, &motions, o));
            }
        }
        state.kept = kept;
    }

    /// Fills `near` with each element's [`Coherence::near_motions`] entry given the elements'
    /// `motions` (as many).
    fn near_motions(&self, motions: &[f64], near: &mut Vec<f64>) {
        near.clear();
        near.resize(motions.len(), 0.0);
        for (a, ball_a) in self.bounds.iter().enumerate() {
            for (b, ball_b) in self.bounds.iter().enumerate().skip(a + 1) {
                let reach = ball_a.radius + ball_b.radius + NEAR_DISTANCE + NEAR_REACH;
                let scale = reach + ball_a.center.abs().max() + ball_b.center.abs().max();
                let reach = reach + ROUNDING * scale;
                if (ball_a.center - ball_b.center).norm_squared() <= reach * reach {
                    near[a] = near[a].max(motions[b]);
                    near[b] = near[b].max(motions[a]);
                }
            }
        }
    }

    /// Fills `order` with the largest motion of each culling block's elements and the block,
    /// largest first (padding lanes name no element).
    fn order_block_motions(&self, motions: &[f64], order: &mut Vec<(f64, usize)>) {
        order.clear();
        order.extend((0..self.blocks.len()).map(|block| {
            let lanes = self.blocks.elements(block).iter();
            let largest = lanes
                .filter_map(|&e| motions.get(e as usize))
                .fold(0.0, |a: f64, &b| a.max(b));
            (largest, block)
        }));
        order.sort_unstable_by(|a, b| b.0.total_cmp(&a.0));
    }

    /// The plain projection of `p` into `out` given its memory `track` and the elements'
    /// `motions` since `track` was set; updates `track` and says whether the search was
    /// skipped.
    #[inline]
    fn project_tracked(
        &self,
        p: &Vector3<f64>,
        track: &mut Track,
        motions: &Motions<'_>,
        out: &mut Option<Projection>,
    ) -> bool {
        if !is_usable(p) {
            *track = Track::NONE;
            *out = None;
            return false;
        }
        let seed = track.element as usize;
        let (first, pr) = match self.frames.get(seed) {
            Some(frame) => (seed, frame.project(p)),
            None => {
                let Some(guess) = self.tree.guess(p) else {
                    *out = None;
                    return false;
                };
                (guess, self.frames[guess].project(p))
            }
        };
        if first == seed {
            let moved = (p - track.point).norm();
            let slack = ROUNDING * (1.0 + p.abs().max() + track.margin.abs());
            let reach = track.margin - moved - slack;
            // The largest motion of all the other elements first: in the late solver iterations
            // it is small enough, and cheaper than the ball test. Without any motion the margin
            // would be `reach`: below the distance the ball test cannot help.
            let cheap = reach - motions.largest_without(seed);
            let margin = if pr.distance < cheap {
                cheap
            } else if pr.distance < reach {
                // The element's neighbourhood next, when the point is near enough to it.
                let near = reach - motions.near[seed];
                if pr.distance < near && pr.distance <= NEAR_DISTANCE && reach <= NEAR_REACH {
                    near
                } else {
                    reach - self.motion_within(p, reach, seed, motions, pr.distance)
                }
            } else {
                reach
            };
            let runner_margin = (pr.distance < margin)
                .then(|| self.runner_margin(track, seed, p, moved, motions, pr.distance))
                .flatten();
            if let Some(runner_margin) = runner_margin {
                *track = Track {
                    margin,
                    runner_margin,
                    point: *p,
                    ..*track
                };
                *out = Some(self.globalize(seed, pr));
                return true;
            }
        }
        let search = self.search(p, first, pr.distance, MARGIN_GAP);
        let (e, _) = search.nearest;
        *track = Track {
            element: e as u32,
            runner: search.runner.map_or(NO_SEED, |(r, _)| r as u32),
            runner_margin: search.runner.map_or(f64::NEG_INFINITY, |(_, d)| d),
            margin: search.margin,
            point: *p,
        };
        let pr = if e == first {
            pr
        } else {
            self.frames[e].project(p)
        };
        *out = Some(self.globalize(e, pr));
        false
    }

    /// Whether the point `p`, `moved` away from `track.point`, keeps element `seed` at
    /// `distance` against the track's runner (if any; ties go to the lower index): the new lower
    /// bound of the runner's distance if so. The old bound less the runner's motion and the
    /// point's usually clears `distance`; otherwise the runner is evaluated.
    #[inline]
    fn runner_margin(
        &self,
        track: &Track,
        seed: usize,
        p: &Vector3<f64>,
        moved: f64,
        motions: &Motions<'_>,
        distance: f64,
    ) -> Option<f64> {
        let runner = track.runner as usize;
        let Some(frame) = self.frames.get(runner) else {
            return Some(f64::NEG_INFINITY);
        };
        let slack = ROUNDING * (1.0 + p.abs().max() + track.runner_margin.abs());
        let bound = track.runner_margin - moved - motions.per_element[runner] - slack;
        if distance < bound {
            return Some(bound);
        }
        let d = frame.distance_below(p, distance);
        (d > distance || (d == distance && runner > seed)).then_some(d)
    }

    /// The largest motion of the elements other than `skip` whose bounding balls may come
    /// within `reach` of `p` (the widened `f32` test of the search: a superset of them); 0 when
    /// none, +∞ for an infinite `reach` bound that keeps them all. Blocks whose elements all
    /// moved less than the largest motion found so far cannot change it and are not tested
    /// (largest first). The caller keeps `skip` only if `distance < reach − motion`: once that
    /// fails the value is not needed and the scan stops early with a motion that fails it too.
    #[inline]
    fn motion_within(
        &self,
        p: &Vector3<f64>,
        reach: f64,
        skip: usize,
        motions: &Motions<'_>,
        distance: f64,
    ) -> f64 {
        if !reach.is_finite() {
            return f64::INFINITY;
        }
        let query = self.blocks.query(p);
        let mut worst: f64 = 0.0;
        for &(block_motion, block) in motions.blocks {
            if block_motion <= worst {
                break;
            }
            let mut mask = self.blocks.survivors(&query, block, reach);
            let lanes = self.blocks.elements(block);
            while mask != 0 {
                let e = lanes[mask.trailing_zeros() as usize] as usize;
                mask &= mask - 1;
                // A padding lane (kept only on overflow) names no element and bounds nothing.
                if let Some(&m) = motions.per_element.get(e).filter(|_| e != skip) {
                    worst = worst.max(m);
                }
            }
            if distance >= reach - worst {
                return worst;
            }
        }
        worst
    }
}

/// The elements' motions since the last call of [`SphereMeshGeometry::project_points_coherent`],
/// summarised for the keep test of `project_tracked`.
struct Motions<'a> {
    /// Per element its motion `δ_e`.
    per_element: &'a [f64],
    /// Per element the largest motion of its neighbours ([`Coherence::near_motions`]).
    near: &'a [f64],
    /// The element that moved most and its motion.
    largest: (usize, f64),
    /// The largest motion of the other elements.
    second: f64,
    /// Per culling block the largest motion of its elements and the block, largest first.
    blocks: &'a [(f64, usize)],
}

impl<'a> Motions<'a> {
    fn new(per_element: &'a [f64], near: &'a [f64], blocks: &'a [(f64, usize)]) -> Self {
        let mut largest = (usize::MAX, 0.0);
        let mut second: f64 = 0.0;
        for (e, &m) in per_element.iter().enumerate() {
            if m > largest.1 {
                second = largest.1;
                largest = (e, m);
            } else {
                second = second.max(m);
            }
        }
        Self {
            per_element,
            near,
            largest,
            second,
            blocks,
        }
    }

    /// The largest motion of the elements other than `e`: a point's own element does not
    /// bound how near the others came (a fingertip point's element moves most).
    #[inline]
    fn largest_without(&self, e: usize) -> f64 {
        if e == self.largest.0 {
            self.second
        } else {
            self.largest.1
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A chain of `n` pills along x, sphere `i` at `x = 10 i`.
    fn chain(n: usize) -> (Vec<Sphere>, Vec<Element>) {
        let spheres = (0..=n)
            .map(|i| Sphere::new(Vector3::new(10.0 * i as f64, 0.0, 0.0), 3.0))
            .collect();
        let elements = (0..n as u32).map(|i| Element::Pill([i, i + 1])).collect();
        (spheres, elements)
    }

    #[test]
    fn largest_motion_without_an_element() {
        let m = Motions::new(&[1.0, 5.0, 3.0, 5.0], &[], &[]);
        assert_eq!(m.largest_without(1), 5.0); // the tie at element 3
        let m = Motions::new(&[1.0, 5.0, 3.0], &[], &[]);
        assert_eq!((m.largest_without(1), m.largest_without(0)), (3.0, 5.0));
        let m = Motions::new(&[f64::INFINITY, f64::INFINITY], &[], &[]);
        assert_eq!(m.largest_without(0), f64::INFINITY);
        let m = Motions::new(&[0.0, 0.0], &[], &[]);
        assert_eq!((m.largest_without(0), m.largest_without(1)), (0.0, 0.0));
    }

    #[test]
    fn block_motions_are_the_lane_maxima_largest_first() {
        let (spheres, elements) = chain(20);
        let g = SphereMeshGeometry::new(&spheres, &elements).unwrap();
        let motions: Vec<f64> = (0..elements.len()).map(|e| (e * 7 % 11) as f64).collect();
        let mut order = Vec::new();
        g.order_block_motions(&motions, &mut order);
        let mut blocks: Vec<usize> = order.iter().map(|&(_, b)| b).collect();
        blocks.sort_unstable();
        assert_eq!(blocks, (0..g.blocks.len()).collect::<Vec<_>>());
        assert!(order.windows(2).all(|w| w[0].0 >= w[1].0));
        for &(m, b) in &order {
            let lanes = g.blocks.elements(b).iter();
            let expected = lanes
                .filter_map(|&e| motions.get(e as usize))
                .fold(0.0, |a: f64, &x| a.max(x));
            assert_eq!(m, expected);
        }
    }

    /// A pill of the chain (balls of radius 8 mm, 10 mm apart) has the pills within
    /// 8 + 8 + 12 mm of its ball center as neighbours: two on each side.
    #[test]
    fn near_motions_are_the_largest_motions_of_the_neighbours() {
        let (spheres, elements) = chain(20);
        let g = SphereMeshGeometry::new(&spheres, &elements).unwrap();
        let motions: Vec<f64> = (0..elements.len()).map(|e| e as f64).collect();
        let mut near = Vec::new();
        g.near_motions(&motions, &mut near);
        assert_eq!(near[0], 2.0);
        assert_eq!(near[10], 12.0);
        assert_eq!(near[19], 18.0);
        let mut motions = vec![0.0; elements.len()];
        motions[15] = 3.0;
        g.near_motions(&motions, &mut near);
        let expected: Vec<f64> = (0..20)
            .map(|e| {
                if e != 15 && (13..=17).contains(&e) {
                    3.0
                } else {
                    0.0
                }
            })
            .collect();
        assert_eq!(near, expected);
    }

    /// Points at the joints of a chain are as near to both pills there: the search names the
    /// other pill as the runner, and a small motion of the whole chain, which would spend a
    /// margin set by the runner at once, keeps every point's element (evaluating the runner).
    #[test]
    fn points_at_a_seam_keep_their_element_through_a_runner() {
        let (mut spheres, elements) = chain(20);
        let mut g = SphereMeshGeometry::new(&spheres, &elements).unwrap();
        let points: Vec<Vector3<f64>> = (1..20)
            .map(|i| Vector3::new(10.0 * i as f64 + 0.01, 5.0, 0.0))
            .collect();
        let mut state = Coherence::default();
        let (mut out, mut fresh) = (vec![None; points.len()], vec![None; points.len()]);
        g.project_points_coherent(&points, &mut state, &mut out);
        assert!(state.tracks.iter().all(|t| t.runner != NO_SEED));
        for _ in 0..3 {
            for s in &mut spheres {
                s.center.z += 0.5;
            }
            g.update(&spheres).unwrap();
            g.project_points_coherent(&points, &mut state, &mut out);
            g.project_points(&points, &mut fresh);
            assert_eq!(out, fresh);
            assert_eq!(state.kept(), points.len());
        }
    }

    /// One end of the chain swings (a bending fingertip) while the rest stays: the points of
    /// the still elements keep them, and every answer is the fresh one.
    #[test]
    fn a_swinging_end_keeps_the_still_elements_points() {
        let (mut spheres, elements) = chain(20);
        let mut g = SphereMeshGeometry::new(&spheres, &elements).unwrap();
        let points: Vec<Vector3<f64>> = (0..400)
            .map(|i| {
                let t = i as f64 * 0.5;
                Vector3::new(t, 4.0 + (i % 5) as f64, (i % 3) as f64 - 1.0)
            })
            .collect();
        let mut state = Coherence::default();
        let (mut out, mut fresh) = (vec![None; points.len()], vec![None; points.len()]);
        g.project_points_coherent(&points, &mut state, &mut out);
        for step in 1..6 {
            spheres[20].center.y += 2.0 * step as f64;
            g.update(&spheres).unwrap();
            g.project_points_coherent(&points, &mut state, &mut out);
            g.project_points(&points, &mut fresh);
            assert_eq!(out, fresh);
            assert!(state.kept() > points.len() * 3 / 4, "{}", state.kept());
        }
    }
}
