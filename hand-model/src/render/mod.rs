//! Rendering and export of sphere-meshes (thesis §3.3.2 "Rendering", Fig. 3.3, Fig. 3.4).
//!
//! - [`raycast`]: exact first hit of a ray with pills, wedges and whole models;
//! - [`depth`]: a tiled CPU depth renderer (depth, element id and normal per pixel);
//! - [`mesh`]: a watertight triangle mesh of the model surface, with [`obj`] and [`glb`] writers;
//! - [`preview`]: a shaded PNG preview that frames the hand.
//!
//! Everything takes posed spheres (e.g. [`PosedSphereMesh::spheres`](crate::spheremesh::PosedSphereMesh))
//! and a list of [`Element`](crate::shape::Element)s whose indices refer to them.

mod atomic;
mod coverage;
pub mod depth;
pub mod glb;
pub mod mesh;
pub mod obj;
mod pixels;
mod prepared;
pub mod preview;
pub mod raycast;
#[cfg(test)]
mod testutil;

pub use depth::{render_depth, DepthRender, DepthRenderer, Intrinsics, PixelHit, NO_ELEMENT};
pub use mesh::{extract_mesh, MeshOptions, TriMesh};
pub use pixels::{KeptPixels, PixelRuns};
pub use prepared::PreparedElement;
pub use raycast::{
    cast_ray, cast_ray_element, cast_ray_pill, cast_ray_wedge, Ray, RayHit, SurfaceHit,
};
