//! A bounding-ball hierarchy over the elements of a sphere-mesh, used to guess the element
//! nearest to a query point before the culled argmin of Eq. 3.6 (the thesis evaluates all 30
//! elements per point on the GPU; one CPU core needs a good first bound to skip most of them).
//!
//! The tree topology is built once from the elements' bounding balls in the construction pose
//! (median splits along the widest axis) and only refitted when the model is re-posed: an
//! articulated hand keeps each finger's elements together, so the grouping stays meaningful while
//! the balls stay valid for any pose.

use super::bounding::BoundingBall;
use nalgebra::Vector3;

#[derive(Copy, Clone, Debug, PartialEq)]
enum Children {
    /// A leaf holding one element.
    Leaf(u32),
    /// An inner node with two children (node indices, both smaller than the parent's).
    Inner(u32, u32),
}

#[derive(Copy, Clone, Debug, PartialEq)]
struct Node {
    center: Vector3<f64>,
    radius: f64,
    children: Children,
}

/// The hierarchy. Nodes are stored children-first, so a forward sweep refits it.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct ElementTree {
    nodes: Vec<Node>,
}

impl ElementTree {
    /// Builds the topology from the elements' current bounding balls and fits it.
    pub(crate) fn build(balls: &[BoundingBall]) -> Self {
        let mut tree = Self {
            nodes: Vec::with_capacity(2 * balls.len()),
        };
        if !balls.is_empty() {
            let mut ids: Vec<u32> = (0..balls.len() as u32).collect();
            tree.split(balls, &mut ids);
        }
        tree.refit(balls);
        tree
    }

    fn split(&mut self, balls: &[BoundingBall], ids: &mut [u32]) -> u32 {
        if let [e] = ids {
            return self.push(Children::Leaf(*e));
        }
        let mut lo = Vector3::repeat(f64::INFINITY);
        let mut hi = Vector3::repeat(f64::NEG_INFINITY);
        for &e in ids.iter() {
            lo = lo.inf(&balls[e as usize].center);
            hi = hi.sup(&balls[e as usize].center);
        }
        let axis = (hi - lo).imax();
        ids.sort_unstable_by(|a, b| {
            balls[*a as usize].center[axis].total_cmp(&balls[*b as usize].center[axis])
        });
        let (left, right) = ids.split_at_mut(ids.len() / 2);
        let a = self.split(balls, left);
        let b = self.split(balls, right);
        self.push(Children::Inner(a, b))
    }

    fn push(&mut self, children: Children) -> u32 {
        self.nodes.push(Node {
            center: Vector3::zeros(),
            radius: 0.0,
            children,
        });
        (self.nodes.len() - 1) as u32
    }

    /// Refits every node to the elements' new bounding balls (same count as at build time).
    /// Allocates nothing.
    pub(crate) fn refit(&mut self, balls: &[BoundingBall]) {
        for i in 0..self.nodes.len() {
            let ball = match self.nodes[i].children {
                Children::Leaf(e) => balls[e as usize],
                Children::Inner(a, b) => {
                    let (a, b) = (&self.nodes[a as usize], &self.nodes[b as usize]);
                    BoundingBall::of_two(&a.center, a.radius, &b.center, b.radius)
                }
            };
            let node = &mut self.nodes[i];
            node.center = ball.center;
            node.radius = ball.radius;
        }
    }

    /// The ball containing the whole model (the root's), `None` for an empty tree.
    pub(crate) fn root_ball(&self) -> Option<BoundingBall> {
        self.nodes.last().map(|n| BoundingBall {
            center: n.center,
            radius: n.radius,
        })
    }

    /// The elements in leaf storage order: a left-to-right walk of the tree, so elements that
    /// are close in the order are close in space.
    pub(crate) fn leaf_order(&self) -> impl Iterator<Item = u32> + '_ {
        self.nodes.iter().filter_map(|n| match n.children {
            Children::Leaf(e) => Some(e),
            Children::Inner(..) => None,
        })
    }

    /// Greedy descent to one leaf, always into the child with the smaller power
    /// `‖p − C‖² − R²`: a cheap guess of the element nearest to `p`. `None` for an empty tree.
    #[inline]
    pub(crate) fn guess(&self, p: &Vector3<f64>) -> Option<usize> {
        let mut node = self.nodes.last()?;
        loop {
            match node.children {
                Children::Leaf(e) => return Some(e as usize),
                Children::Inner(a, b) => {
                    let (na, nb) = (&self.nodes[a as usize], &self.nodes[b as usize]);
                    let pa = (p - na.center).norm_squared() - na.radius * na.radius;
                    let pb = (p - nb.center).norm_squared() - nb.radius * nb.radius;
                    node = if pa <= pb { na } else { nb };
                }
            }
        }
    }
}
