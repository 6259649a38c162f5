//! Bounding balls of element hulls, used to cull elements in the model-wide argmin of Eq. 3.6.
//!
//! For any set `E` inside a ball `B(C, R)`, the signed distance satisfies
//! `φ_E(p) ≥ ‖p − C‖ − R`, outside (distance to a superset) and inside (depth in a subset) alike,
//! so an element whose bound is not below the best distance found so far can be skipped.

use super::point_pill::{PillFrame, PillShape};
use super::point_wedge::WedgeFrame;
use nalgebra::Vector3;

/// Relative slack added to bounding radii so that rounding never makes a bound exceed the exact
/// distance it is compared with.
const SLACK: f64 = 1e-9;

/// A ball `B(center, radius)` containing an element (thesis §3.3.1: per-element culling of the
/// brute-force argmin of Eq. 3.6).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct BoundingBall {
    /// Center.
    pub center: Vector3<f64>,
    /// Radius (≥ the farthest surface point's distance from the center).
    pub radius: f64,
}

impl BoundingBall {
    /// The smallest ball containing two balls (what bounds a pill exactly).
    pub(crate) fn of_two(c0: &Vector3<f64>, r0: f64, c1: &Vector3<f64>, r1: f64) -> Self {
        let d = c1 - c0;
        let len = d.norm();
        if r0 >= len + r1 {
            return Self::slack(*c0, r0);
        }
        if r1 >= len + r0 {
            return Self::slack(*c1, r1);
        }
        // len > 0 here, otherwise one of the branches above applies.
        let radius = 0.5 * (len + r0 + r1);
        let center = c0 + d * ((radius - r0) / len);
        Self::slack(center, radius)
    }

    fn slack(center: Vector3<f64>, radius: f64) -> Self {
        let scale = radius + center.abs().max();
        Self {
            center,
            radius: radius + SLACK * scale,
        }
    }

    fn contains(&self, c: &Vector3<f64>, r: f64) -> bool {
        (c - self.center).norm() + r <= self.radius
    }

    /// Bound of a pill: the smallest ball containing its two spheres.
    pub(crate) fn of_pill(f: &PillFrame) -> Self {
        match f.shape {
            PillShape::Ball { which } => Self::slack(f.centers[which], f.radii[which]),
            PillShape::Cone { .. } => {
                Self::of_two(&f.centers[0], f.radii[0], &f.centers[1], f.radii[1])
            }
        }
    }

    /// Bound of a wedge: the smallest of the pairwise balls that contain the third sphere, the
    /// circumcenter ball and the centroid ball (not always the minimal enclosing ball of the
    /// three spheres, but close and cheap).
    pub(crate) fn of_wedge(f: &WedgeFrame) -> Self {
        let c = &f.centers;
        let r = &f.radii;
        let mut best: Option<Self> = None;
        let mut consider = |b: Self| {
            if best.is_none_or(|x| b.radius < x.radius) {
                best = Some(b);
            }
        };
        for (i, j, k) in [(0, 1, 2), (1, 2, 0), (2, 0, 1)] {
            let b = Self::of_two(&c[i], r[i], &c[j], r[j]);
            if b.contains(&c[k], r[k]) {
                consider(b);
            }
        }
        let enclosing = |center: Vector3<f64>| {
            let radius = (0..3)
                .map(|i| (c[i] - center).norm() + r[i])
                .fold(0.0, f64::max);
            Self::slack(center, radius)
        };
        if let Some(cc) = circumcenter(&c[0], &c[1], &c[2]) {
            consider(enclosing(cc));
        }
        consider(enclosing((c[0] + c[1] + c[2]) / 3.0));
        // `consider` was called at least once (the centroid ball).
        best.unwrap_or_else(|| enclosing(c[0]))
    }
}

/// Circumcenter of a non-degenerate triangle.
fn circumcenter(a: &Vector3<f64>, b: &Vector3<f64>, c: &Vector3<f64>) -> Option<Vector3<f64>> {
    let ab = b - a;
    let ac = c - a;
    let n = ab.cross(&ac);
    let n2 = n.norm_squared();
    if n2 <= 1e-20 * ab.norm_squared() * ac.norm_squared() || n2 == 0.0 {
        return None;
    }
    let offset = (n.cross(&ab) * ac.norm_squared() + ac.cross(&n) * ab.norm_squared()) / (2.0 * n2);
    Some(a + offset)
}

/// Elements per block of [`BallBlocks`]: one mask per block, two SSE (or one AVX) vectors wide.
pub(crate) const BLOCK: usize = 8;

/// Element index of a padding lane in [`BallBlocks::element`].
pub(crate) const PADDING: u32 = u32::MAX;

/// The elements' bounding balls as `f32` structure-of-arrays blocks, for a vectorised first
/// culling pass: one block of [`BLOCK`] balls is tested against a query at once, and only the
/// survivors go through the exact `f64` test.
///
/// - Blocks group elements that are close in space (the leaf order of the bounding-ball tree),
///   and each block has a ball containing its elements' balls, so a query usually dismisses
///   most blocks with one test. The culled argmin does not depend on the order in which
///   elements are evaluated, so the lane order is free.
/// - In `f32`, coordinates of a hand 400 mm from the camera would carry 3·10⁻⁵ mm of rounding,
///   so they are stored relative to `origin` (the center of the model's bounding ball), and the
///   tests are widened by a margin far above the rounding: the pass only ever keeps more
///   elements than the exact test, never fewer.
#[derive(Clone, Debug, Default)]
pub(crate) struct BallBlocks {
    origin: Vector3<f64>,
    /// `max (‖C − origin‖_∞ + R)` over the element and block balls: with the query's offset,
    /// it bounds every magnitude entering the tests, hence their rounding.
    extent: f64,
    /// The element of each lane (block `k`, lane `l` at `k·BLOCK + l`), [`PADDING`] for none.
    element: Vec<u32>,
    /// Per block: x, y, z of the centers relative to `origin`, and the radii. Padding lanes have
    /// radius −∞ and never survive.
    blocks: Vec<[[f32; BLOCK]; 4]>,
    /// Per block: a ball `[x, y, z, R]` (relative to `origin`) containing its elements' balls.
    block_balls: Vec<[f32; 4]>,
}

/// A query point prepared for [`BallBlocks::survivors`].
#[derive(Copy, Clone, Debug)]
pub(crate) struct BlockQuery {
    p: [f32; 3],
    /// Widening of the tests: a relative 10⁻⁵ of the magnitudes involved, about ten times the
    /// worst `f32` rounding of a distance and of `best + R`.
    margin_scale: f64,
}

impl BallBlocks {
    /// Blocks for `balls`, with the lanes in the order `order` (every element once); sized
    /// once, refreshed by [`refit`](Self::refit) without allocating.
    pub(crate) fn new(
        balls: &[BoundingBall],
        order: impl Iterator<Item = u32>,
        origin: Vector3<f64>,
    ) -> Self {
        let n_blocks = balls.len().div_ceil(BLOCK);
        let mut element: Vec<u32> = order.collect();
        debug_assert_eq!(element.len(), balls.len());
        element.resize(n_blocks * BLOCK, PADDING);
        let mut b = Self {
            element,
            blocks: vec![[[0.0; BLOCK]; 4]; n_blocks],
            block_balls: vec![[0.0; 4]; n_blocks],
            ..Self::default()
        };
        b.refit(balls, origin);
        b
    }

    /// Stores `balls` (same count as at construction) relative to `origin`.
    pub(crate) fn refit(&mut self, balls: &[BoundingBall], origin: Vector3<f64>) {
        self.origin = origin;
        self.extent = 0.0;
        let lanes = self.element.chunks(BLOCK);
        for ((block, block_ball), ids) in
            self.blocks.iter_mut().zip(&mut self.block_balls).zip(lanes)
        {
            let mut all: Option<BoundingBall> = None;
            for (lane, &e) in ids.iter().enumerate() {
                let (c, r) = match balls.get(e as usize) {
                    Some(ball) => {
                        all = Some(all.map_or(*ball, |a| {
                            BoundingBall::of_two(&a.center, a.radius, &ball.center, ball.radius)
                        }));
                        (ball.center - origin, ball.radius)
                    }
                    None => (Vector3::zeros(), f64::NEG_INFINITY),
                };
                block[0][lane] = c.x as f32;
                block[1][lane] = c.y as f32;
                block[2][lane] = c.z as f32;
                block[3][lane] = r as f32;
            }
            let all = all.unwrap_or(BoundingBall {
                center: origin,
                radius: f64::NEG_INFINITY,
            });
            let c = all.center - origin;
            *block_ball = [c.x as f32, c.y as f32, c.z as f32, all.radius as f32];
        }
        for ball in balls.iter().map(|b| (b.center - origin, b.radius)) {
            self.extent = self.extent.max(ball.0.abs().max() + ball.1);
        }
        for b in &self.block_balls {
            let c = Vector3::new(b[0], b[1], b[2]).map(f64::from);
            self.extent = self.extent.max(c.abs().max() + f64::from(b[3]));
        }
    }

    /// Number of blocks.
    pub(crate) fn len(&self) -> usize {
        self.blocks.len()
    }

    /// The elements of the lanes of block `block` ([`PADDING`] for none).
    #[inline]
    pub(crate) fn elements(&self, block: usize) -> &[u32] {
        &self.element[block * BLOCK..(block + 1) * BLOCK]
    }

    /// Prepares the query point `p`.
    #[inline]
    pub(crate) fn query(&self, p: &Vector3<f64>) -> BlockQuery {
        let rel = p - self.origin;
        BlockQuery {
            p: [rel.x as f32, rel.y as f32, rel.z as f32],
            margin_scale: 1e-5 * (rel.abs().max() + self.extent),
        }
    }

    /// Bit `l` set for every lane `l` of block `block` whose ball may satisfy
    /// `‖p − C‖ − R ≤ best`: a superset of the elements that the exact test keeps. Overflow to
    /// infinities or NaN (coordinates near `f32::MAX`) keeps the lane.
    // The negated comparisons keep a lane whose test is NaN: culling must never drop the
    // true answer, so an incomparable bound counts as "may be closer".
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    #[inline(always)]
    pub(crate) fn survivors(&self, q: &BlockQuery, block: usize, best: f64) -> u32 {
        let reach = (best + q.margin_scale + 1e-5 * best.abs()) as f32;
        let culled = |x: f32, y: f32, z: f32, r: f32| {
            let (dx, dy, dz) = (q.p[0] - x, q.p[1] - y, q.p[2] - z);
            let t = reach + r;
            (t <= 0.0) | (dx * dx + dy * dy + dz * dz > t * t)
        };
        let [bx, by, bz, br] = self.block_balls[block];
        if culled(bx, by, bz, br) {
            return 0;
        }
        let [x, y, z, r] = &self.blocks[block];
        // Written lane-wise into an array of bits (not as a running mask) so that it compiles to
        // packed compares on baseline x86-64.
        let mut bits = [0u32; BLOCK];
        for (lane, bit) in bits.iter_mut().enumerate() {
            *bit = if culled(x[lane], y[lane], z[lane], r[lane]) {
                0
            } else {
                1 << lane
            };
        }
        bits.iter().fold(0, |mask, bit| mask | bit)
    }
}
