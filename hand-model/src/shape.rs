//! Sphere-mesh shapes as plain data (thesis §3.1): spheres and the pill / wedge elements that
//! are the convex hulls of two or three of them.
//!
//! Shapes carry no query code; the closest-point, implicit-function and front-facing queries
//! live in [`crate::query`].

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// A sphere `B(x | c, r) = ‖x − c‖² − r²` (Eq. 3.2) in some frame (mm).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Sphere {
    /// Center `c` (mm).
    pub center: Vector3<f64>,
    /// Radius `r` (mm, ≥ 0).
    pub radius: f64,
}

impl Sphere {
    /// A sphere from its center and radius.
    pub fn new(center: Vector3<f64>, radius: f64) -> Self {
        Self { center, radius }
    }
}

/// One element `E^e` of a sphere-mesh skeleton: the convex hull of two spheres (a *pill*) or of
/// three spheres (a *wedge*), with linearly interpolated radii (Eq. 3.1, Fig. 3.3).
///
/// Indices refer to the sphere list of the model that owns the element.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Element {
    /// Convex hull of two spheres (a tapered capsule, "convsegment" in hmodel).
    Pill([u32; 2]),
    /// Convex hull of three spheres ("convtriangle" in hmodel).
    Wedge([u32; 3]),
}

impl Element {
    /// The sphere indices of the element (2 or 3 of them).
    pub fn spheres(&self) -> &[u32] {
        match self {
            Element::Pill(s) => s,
            Element::Wedge(s) => s,
        }
    }
}
