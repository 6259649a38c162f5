//! A hand-like sphere-mesh for benchmarks and tests, shared by `benches/projection.rs` and the
//! `tests/query_*.rs` files (included with `#[path]`).
//!
//! The numbers are the rest pose of the hmodel "anastasia" template as tabulated in
//! `shared/reference/ANCHOR-FACTS.md` §2.6 (38 spheres, 30 elements: 16 pills and 14 wedges;
//! model frame, mm, fingers along +y, about 185 mm from wrist to middle fingertip), rounded to
//! 1 µm. Swap `hand_like_geometry` for the workspace's default template once it exists.

use hand_model::shape::{Element, Sphere};
use nalgebra::Vector3;

/// Sphere centers (x, y, z) and radii, mm.
const SPHERES: [[f64; 4]; 38] = [
    [-39.192, 104.429, -2.033, 4.180],
    [-36.422, 92.180, 0.547, 4.772],
    [-30.159, 74.244, 2.802, 6.226],
    [-18.101, 44.887, 6.898, 7.846],
    [-15.961, 123.394, 3.965, 4.850],
    [-15.499, 110.035, 6.476, 5.012],
    [-11.982, 86.452, 8.150, 6.971],
    [-5.933, 49.105, 10.799, 7.268],
    [3.942, 132.349, 12.379, 5.584],
    [5.236, 116.502, 12.871, 5.676],
    [7.451, 93.353, 12.058, 7.643],
    [8.132, 52.893, 10.546, 7.688],
    [36.583, 120.305, 8.224, 5.174],
    [33.698, 107.802, 8.022, 5.853],
    [30.999, 87.409, 6.976, 7.553],
    [25.396, 50.819, 5.287, 8.441],
    [58.849, 61.889, -28.382, 7.031],
    [52.332, 50.044, -24.625, 7.308],
    [36.349, 27.673, -17.367, 10.312],
    [9.726, 3.872, -7.160, 15.683],
    [-17.933, 38.572, 3.262, 8.985],
    [-6.554, 42.595, 6.321, 10.217],
    [5.558, 45.021, 6.948, 10.726],
    [23.937, 45.629, 3.482, 9.505],
    [28.597, 41.231, 1.305, 4.763],
    [0.000, 0.000, 0.000, 13.624],
    [-10.008, 1.014, 0.437, 13.419],
    [7.311, 3.093, -0.049, 13.299],
    [-25.232, 60.867, 0.066, 1.753],
    [-7.663, 66.684, 5.106, 2.812],
    [7.453, 68.134, 6.365, 3.158],
    [24.194, 64.374, 0.365, 1.296],
    [62.867, 67.174, -30.287, 4.992],
    [29.198, 25.354, -9.295, 6.604],
    [9.740, -4.058, 0.000, 12.986],
    [-6.493, -4.058, 0.000, 12.986],
    [4.058, -48.699, 0.000, 15.421],
    [-4.058, -48.699, 0.000, 15.421],
];

/// Fingers: 3 pills each (+ the thumb tip pill); palm, membrane, thumb-fold and wrist wedges.
const ELEMENTS: [&[u32]; 30] = [
    &[1, 0],
    &[2, 1],
    &[3, 2],
    &[5, 4],
    &[6, 5],
    &[7, 6],
    &[9, 8],
    &[10, 9],
    &[11, 10],
    &[13, 12],
    &[14, 13],
    &[15, 14],
    &[17, 16],
    &[18, 17],
    &[19, 18, 33],
    &[26, 21, 20],
    &[25, 26, 21],
    &[25, 22, 21],
    &[25, 27, 22],
    &[27, 22, 23],
    &[20, 29, 28],
    &[21, 20, 29],
    &[21, 30, 29],
    &[22, 21, 30],
    &[22, 23, 30],
    &[23, 30, 31],
    &[19, 33, 24],
    &[16, 32],
    &[36, 35, 34],
    &[36, 37, 35],
];

/// The spheres and elements of a hand-like sphere-mesh (see the module docs).
pub fn hand_like_geometry() -> (Vec<Sphere>, Vec<Element>) {
    let spheres = SPHERES
        .iter()
        .map(|[x, y, z, r]| Sphere::new(Vector3::new(*x, *y, *z), *r))
        .collect();
    let elements = ELEMENTS
        .iter()
        .map(|ids| match ids {
            [a, b] => Element::Pill([*a, *b]),
            [a, b, c] => Element::Wedge([*a, *b, *c]),
            _ => unreachable!("elements have two or three spheres"),
        })
        .collect();
    (spheres, elements)
}
