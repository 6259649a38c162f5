//! The seeded batch queries (`project_points_seeded`, `project_points_front_facing_seeded`)
//! return bit for bit what the unseeded ones return, whatever the seeds (none, stale, random,
//! out of range), write the answers' elements back as seeds, and reject non-finite points; the
//! culled plain projection is the exact argmin of Eq. 3.6 (ties to the lower element index).
//! The coherent ones (`project_points_coherent`, `project_points_front_facing_coherent`) do
//! too over a tracker's sequence of poses, while skipping most searches, and so do their
//! `_skipping` forms for the points they do not skip.

mod common;

#[path = "../benches/support/hand_like.rs"]
mod hand_like;
#[path = "../benches/support/rendered.rs"]
mod rendered;

use common::*;
use hand_like::hand_like_geometry;
use hand_model::query::{Coherence, Projection, SphereMeshGeometry, View, NO_SEED};
use hand_model::shape::{Element, Sphere};
use nalgebra::Vector3;
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// Seed vectors to try for `n` points on a model with `elements` elements.
fn seed_sets(rng: &mut ChaCha8Rng, n: usize, elements: usize) -> Vec<Vec<u32>> {
    let far = [elements as u32, elements as u32 + 7, NO_SEED - 1, NO_SEED];
    vec![
        vec![NO_SEED; n],
        vec![0; n],
        (0..n)
            .map(|_| rng.random_range(0..elements as u32))
            .collect(),
        (0..n)
            .map(|_| far[rng.random_range(0..far.len())])
            .collect(),
    ]
}

/// The plain projection by brute force: the element with the smallest `φ_e(p)`, the first one
/// on ties, projected.
fn brute_force(g: &SphereMeshGeometry, p: &Vector3<f64>) -> Option<Projection> {
    let mut best: Option<(usize, f64)> = None;
    for e in 0..g.elements().len() {
        let d = g.phi_element(e, p)?;
        if best.is_none_or(|(_, b)| d < b) {
            best = Some((e, d));
        }
    }
    g.project_on_element(best?.0, p)
}

fn element_of(o: &Option<Projection>) -> u32 {
    o.map_or(NO_SEED, |q| q.element)
}

/// Checks every seeded query on `points` against the unseeded ones (and the plain projection
/// against brute force), with seed vectors from `seed_sets` plus `extra`.
fn check_seeded(
    g: &SphereMeshGeometry,
    points: &[Vector3<f64>],
    views: &[View],
    extra: &[Vec<u32>],
    rng: &mut ChaCha8Rng,
) {
    let n = points.len();
    let mut plain = vec![None; n];
    g.project_points(points, &mut plain);
    for (p, q) in points.iter().zip(&plain) {
        assert_eq!(*q, brute_force(g, p), "culled argmin differs at {p:?}");
        // Seeded searches start from the seed's projection, whose distance must be the
        // element's φ_e bit for bit for the search to be the same.
        for e in 0..g.elements().len() {
            let d = g.project_on_element(e, p).unwrap().distance;
            assert_eq!(d.to_bits(), g.phi_element(e, p).unwrap().to_bits());
        }
    }
    let mut seeds = seed_sets(rng, n, g.elements().len());
    seeds.extend_from_slice(extra);
    let mut out = vec![None; n];
    for initial in &seeds {
        let mut s = initial.clone();
        g.project_points_seeded(points, &mut s, &mut out);
        // Bitwise: `Projection` holds only floats compared with `==`; also compare the bits.
        for (a, b) in out.iter().zip(&plain) {
            assert_eq!(a, b);
            assert_eq!(bits(a), bits(b));
        }
        assert!(s.iter().zip(&out).all(|(s, o)| *s == element_of(o)));
    }
    for view in views {
        let mut unseeded = vec![None; n];
        g.project_points_front_facing(points, view, &mut unseeded);
        for initial in &seeds {
            let mut s = initial.clone();
            g.project_points_front_facing_seeded(points, view, &mut s, &mut out);
            for (a, b) in out.iter().zip(&unseeded) {
                assert_eq!(bits(a), bits(b), "{view:?}");
            }
            assert!(s.iter().zip(&out).all(|(s, o)| *s == element_of(o)));
        }
    }
}

/// Every float of a projection as bits (so that −0 and 0 differ), with its indices.
fn bits(o: &Option<Projection>) -> Option<(Vec<u64>, [u32; 3], u32)> {
    o.map(|q| {
        let floats = q
            .point
            .iter()
            .chain(&q.normal)
            .chain(&q.skeleton_point)
            .chain(&q.weights)
            .chain([&q.distance]);
        (floats.map(|x| x.to_bits()).collect(), q.spheres, q.element)
    })
}

#[test]
fn seeded_queries_on_rendered_hands_equal_unseeded() {
    let mut rng = rng(31);
    let views = [
        View::Orthographic(Vector3::z()),
        View::Perspective {
            camera_center: Vector3::zeros(),
        },
    ];
    for scene in rendered::rendered_scenes() {
        let g = SphereMeshGeometry::new(&scene.spheres, &scene.elements).unwrap();
        let previous = SphereMeshGeometry::new(&scene.previous, &scene.elements).unwrap();
        for points in [&scene.points, &scene.noisy] {
            // Stale seeds: the answers at the previous pose.
            let mut stale = vec![NO_SEED; points.len()];
            let mut out = vec![None; points.len()];
            previous.project_points_seeded(points, &mut stale, &mut out);
            check_seeded(&g, points, &views, &[stale], &mut rng);
        }
    }
}

#[test]
fn seeded_queries_on_random_points_equal_unseeded() {
    let (spheres, elements) = hand_like_geometry();
    let g = SphereMeshGeometry::new(&spheres, &elements).unwrap();
    let mut rng = rng(32);
    let refs: Vec<&Sphere> = spheres.iter().collect();
    let mut points: Vec<Vector3<f64>> = (0..1500)
        .map(|_| random_point_near(&mut rng, &refs, 20.0))
        .collect();
    // Points on sphere surfaces and at centers (ties between elements sharing spheres).
    for s in &spheres {
        points.push(s.center);
        points.push(s.center + random_unit(&mut rng) * s.radius);
    }
    let views = [
        View::Orthographic(Vector3::z()),
        View::Orthographic(Vector3::new(0.3, -0.2, 1.0)),
        View::Perspective {
            camera_center: Vector3::new(0.0, 50.0, -400.0),
        },
    ];
    check_seeded(&g, &points, &views, &[], &mut rng);
}

#[test]
fn seeded_queries_on_random_meshes_equal_unseeded() {
    let mut rng = rng(33);
    // Up to 70 elements: more than one culling block, and past the lazily clipped silhouette's
    // element limit (64).
    for (k, n_elements) in [1, 2, 9, 31, 40, 70].into_iter().enumerate() {
        let offset = Vector3::new(0.0, 0.0, 400.0 * (k % 2) as f64);
        let spheres: Vec<Sphere> = (0..30)
            .map(|_| {
                let s = random_sphere(&mut rng, 40.0, 10.0);
                Sphere::new(s.center + offset, s.radius)
            })
            .collect();
        let elements: Vec<Element> = (0..n_elements)
            .map(|_| {
                let ids: [u32; 3] = std::array::from_fn(|_| rng.random_range(0..30u32));
                if rng.random_bool(0.5) {
                    Element::Pill([ids[0], ids[1]])
                } else {
                    Element::Wedge(ids)
                }
            })
            .collect();
        let g = SphereMeshGeometry::new(&spheres, &elements).unwrap();
        let refs: Vec<&Sphere> = spheres.iter().collect();
        let points: Vec<Vector3<f64>> = (0..300)
            .map(|_| random_point_near(&mut rng, &refs, 10.0))
            .collect();
        let views = [
            View::Orthographic(random_unit(&mut rng)),
            View::Perspective {
                camera_center: offset + random_unit(&mut rng) * 300.0,
            },
        ];
        check_seeded(&g, &points, &views, &[], &mut rng);
    }
}

#[test]
fn seeded_queries_reject_non_finite_points_and_check_lengths() {
    let (spheres, elements) = hand_like_geometry();
    let g = SphereMeshGeometry::new(&spheres, &elements).unwrap();
    let points = [
        Vector3::new(0.0, -60.0, 380.0),
        Vector3::new(f64::NAN, 0.0, 400.0),
        Vector3::new(0.0, f64::INFINITY, 400.0),
        Vector3::new(0.0, 0.0, 1e300),
    ];
    let mut out = vec![None; points.len()];
    let view = View::Orthographic(Vector3::z());
    let mut seeds = vec![3; points.len()];
    g.project_points_seeded(&points, &mut seeds, &mut out);
    assert!(out[0].is_some() && out[1..].iter().all(Option::is_none));
    assert_eq!(seeds[1..], [NO_SEED; 3]);
    let mut seeds = vec![3; points.len()];
    g.project_points_front_facing_seeded(&points, &view, &mut seeds, &mut out);
    assert!(out[0].is_some() && out[1..].iter().all(Option::is_none));
    assert_eq!(seeds[1..], [NO_SEED; 3]);
    // An invalid view answers nothing.
    g.project_points_front_facing_seeded(
        &points,
        &View::Orthographic(Vector3::zeros()),
        &mut seeds,
        &mut out,
    );
    assert!(out.iter().all(Option::is_none) && seeds == [NO_SEED; 4]);

    let short = std::panic::catch_unwind(|| {
        let mut seeds = vec![NO_SEED; 2];
        let mut out = vec![None; points.len()];
        g.project_points_seeded(&points, &mut seeds, &mut out);
    });
    assert!(
        short.is_err(),
        "a seed slice of the wrong length is refused"
    );
}

/// `a + (b − a)·t` for every sphere.
fn blend(a: &[Sphere], b: &[Sphere], t: f64) -> Vec<Sphere> {
    a.iter()
        .zip(b)
        .map(|(a, b)| {
            Sphere::new(
                a.center.lerp(&b.center, t),
                a.radius + (b.radius - a.radius) * t,
            )
        })
        .collect()
}

/// Over a tracker's sequence of calls — small steps from the previous pose to the current one
/// (shrinking like solver iterations), a reshape (radii), noisy points, then a jump back and a
/// plain-projection call in between — the coherent queries answer bit for bit what the plain
/// and front-facing ones answer on the same geometry (which equal brute force, above), and
/// most points of the smallest step keep their element without a search.
#[test]
fn coherent_queries_on_a_tracked_sequence_equal_fresh_ones() {
    let view = View::Perspective {
        camera_center: Vector3::zeros(),
    };
    for scene in rendered::rendered_scenes() {
        let n = scene.points.len();
        let steps = tracked_steps(&scene);
        for front_facing in [false, true] {
            let mut state = Coherence::default();
            let mut g = SphereMeshGeometry::new(&scene.spheres, &scene.elements).unwrap();
            let (mut out, mut fresh) = (vec![None; n], vec![None; n]);
            let mut kept = Vec::new();
            for (spheres, points) in &steps {
                g.update(spheres).unwrap();
                if front_facing {
                    g.project_points_front_facing_coherent(points, &view, &mut state, &mut out);
                    g.project_points_front_facing(points, &view, &mut fresh);
                } else {
                    g.project_points_coherent(points, &mut state, &mut out);
                    g.project_points(points, &mut fresh);
                }
                for (a, b) in out.iter().zip(&fresh) {
                    assert_eq!(bits(a), bits(b), "{} {front_facing}", scene.name);
                }
                kept.push(state.kept());
            }
            // The first call searches everything; the smallest step mostly keeps.
            assert_eq!(kept[0], 0);
            assert!(kept[4] > n / 2, "{} {kept:?}", scene.name);
        }
    }
}

/// The calls of [`coherent_queries_on_a_tracked_sequence_equal_fresh_ones`]: the model and the
/// points of each.
fn tracked_steps(scene: &rendered::RenderedScene) -> Vec<(Vec<Sphere>, &[Vector3<f64>])> {
    let mut steps: Vec<(Vec<Sphere>, &[Vector3<f64>])> = [0.0, 0.5, 0.8, 0.95, 1.0]
        .iter()
        .map(|&t| (blend(&scene.previous, &scene.spheres, t), &scene.points[..]))
        .collect();
    let grown: Vec<Sphere> = scene
        .spheres
        .iter()
        .enumerate()
        .map(|(i, s)| Sphere::new(s.center, s.radius + 0.2 * (i % 3) as f64))
        .collect();
    steps.push((grown.clone(), &scene.points));
    steps.push((grown, &scene.noisy));
    steps.push((scene.previous.clone(), &scene.noisy));
    steps
}

/// The same sequence with some points skipped by each call (a different third each time, and
/// half of them for three calls in a row): the points projected are answered bit for bit as
/// fresh, the skipped ones' slots are left as they were, and the worn memory of a point skipped
/// for several calls still lets most points of the smallest step keep their element.
#[test]
fn coherent_queries_skipping_points_equal_fresh_ones() {
    let view = View::Perspective {
        camera_center: Vector3::zeros(),
    };
    for scene in rendered::rendered_scenes() {
        let n = scene.points.len();
        for front_facing in [false, true] {
            let mut state = Coherence::default();
            let mut g = SphereMeshGeometry::new(&scene.spheres, &scene.elements).unwrap();
            let mut fresh = vec![None; n];
            let mut kept = Vec::new();
            for (k, (spheres, points)) in tracked_steps(&scene).iter().enumerate() {
                let skip: Vec<bool> = (0..n)
                    .map(|i| k > 0 && (i % 3 == k % 3 || (2..5).contains(&k) && i % 2 == 0))
                    .collect();
                g.update(spheres).unwrap();
                if front_facing {
                    g.project_points_front_facing(points, &view, &mut fresh);
                } else {
                    g.project_points(points, &mut fresh);
                }
                let sentinel = fresh
                    .iter()
                    .flatten()
                    .next()
                    .map(|q| Projection { element: 999, ..*q });
                let mut out = vec![sentinel; n];
                if front_facing {
                    g.project_points_front_facing_coherent_skipping(
                        points, &skip, &view, &mut state, &mut out,
                    );
                } else {
                    g.project_points_coherent_skipping(points, &skip, &mut state, &mut out);
                }
                for ((a, b), &s) in out.iter().zip(&fresh).zip(&skip) {
                    let expected = if s { &sentinel } else { b };
                    assert_eq!(bits(a), bits(expected), "{} {front_facing}", scene.name);
                }
                let projected = skip.iter().filter(|&&s| !s).count();
                kept.push((state.kept(), projected));
            }
            assert!(kept[4].0 > kept[4].1 / 2, "{} {kept:?}", scene.name);
        }
    }
}

/// A coherent state filled on other points and another model (more spheres) still gives the
/// plain answers, and non-finite points are answered `None` and forgotten.
#[test]
fn coherent_queries_ignore_a_foreign_state() {
    let (spheres, elements) = hand_like_geometry();
    let g = SphereMeshGeometry::new(&spheres, &elements).unwrap();
    let mut rng = rng(34);
    let refs: Vec<&Sphere> = spheres.iter().collect();
    let mut points: Vec<Vector3<f64>> = (0..400)
        .map(|_| random_point_near(&mut rng, &refs, 15.0))
        .collect();
    let mut state = Coherence::default();
    let mut out = vec![None; points.len()];
    g.project_points_coherent(&points, &mut state, &mut out);
    // Other points (shuffled, moved) on a model with one more sphere.
    points.reverse();
    points
        .iter_mut()
        .step_by(2)
        .for_each(|p| *p += random_vector(&mut rng, 5.0));
    points[7] = Vector3::new(f64::NAN, 0.0, 0.0);
    let mut more = spheres.clone();
    more.push(Sphere::new(Vector3::new(0.0, 0.0, 500.0), 3.0));
    let other = SphereMeshGeometry::new(&more, &elements).unwrap();
    for g in [&other, &g] {
        let mut fresh = vec![None; points.len()];
        g.project_points(&points, &mut fresh);
        g.project_points_coherent(&points, &mut state, &mut out);
        for (a, b) in out.iter().zip(&fresh) {
            assert_eq!(bits(a), bits(b));
        }
        assert!(out[7].is_none());
    }
}

/// The memory carried from one frame's points to the next frame's by pixel
/// (`Coherence::carry_to_pixels`: the same pixel, else an adjacent one) gives the plain and
/// front-facing answers bit for bit, whatever the match — the same points in another order, a
/// point moved to an adjacent pixel, noisy points, pixels without an old point, a pixel
/// outside the image, a repeated pixel, a carry without pixels before it — and lets a good
/// part of the next frame's first call keep their element when their surface barely moved.
#[test]
fn coherence_carried_by_pixels_equals_fresh_queries() {
    let view = View::Perspective {
        camera_center: Vector3::zeros(),
    };
    let width = 64u32;
    for scene in rendered::rendered_scenes() {
        let n = scene.points.len();
        let height = (8 * n as u32 + 3 * width) / width + 2;
        // Frame A: point i at pixel 3i.
        let pixels_a: Vec<u32> = (0..n as u32).map(|i| 3 * i).collect();
        // Frame B: the same points reversed (pixel-matched, not index-matched), every 7th one
        // moved to the adjacent pixel (3i + 1), every 11th one noisy at a pixel with no old
        // point at or next to it (beyond frame A's rows), one outside the image and two
        // sharing a pixel.
        let mut points_b = scene.points.clone();
        let mut pixels_b = pixels_a.clone();
        for i in 0..n {
            if i % 7 == 3 {
                pixels_b[i] += 1;
            }
            if i % 11 == 5 {
                points_b[i] = scene.noisy[i];
                pixels_b[i] = 3 * (n as u32) + 2 * width + 5 * i as u32;
            }
        }
        pixels_b[0] = width * height + 9;
        pixels_b[2] = pixels_b[1];
        points_b.reverse();
        pixels_b.reverse();
        let moved = blend(&scene.previous, &scene.spheres, 0.3);
        for front_facing in [false, true] {
            let project = |g: &SphereMeshGeometry,
                           points: &[Vector3<f64>],
                           state: &mut Coherence,
                           out: &mut Vec<Option<Projection>>| {
                let mut fresh = vec![None; points.len()];
                if front_facing {
                    g.project_points_front_facing_coherent(points, &view, state, out);
                    g.project_points_front_facing(points, &view, &mut fresh);
                } else {
                    g.project_points_coherent(points, state, out);
                    g.project_points(points, &mut fresh);
                }
                for (a, b) in out.iter().zip(&fresh) {
                    assert_eq!(bits(a), bits(b), "{} {front_facing}", scene.name);
                }
                state.kept()
            };
            let mut g = SphereMeshGeometry::new(&scene.previous, &scene.elements).unwrap();
            let mut out = vec![None; n];
            let mut state = Coherence::default();
            // Filled without a carry: the first carry forgets it.
            project(&g, &scene.noisy, &mut state, &mut out);
            state.carry_to_pixels(&pixels_a, width, height);
            assert_eq!(project(&g, &scene.points, &mut state, &mut out), 0);
            for t in [0.05, 0.1] {
                g.update(&blend(&scene.previous, &scene.spheres, t))
                    .unwrap();
                project(&g, &scene.points, &mut state, &mut out);
            }
            // The next frame, the model moved on.
            g.update(&moved).unwrap();
            let mut plain = state.clone();
            plain.clear();
            let cold = project(&g, &points_b, &mut plain, &mut out);
            state.carry_to_pixels(&pixels_b, width, height);
            let carried = project(&g, &points_b, &mut state, &mut out);
            assert_eq!(cold, 0);
            assert!(
                carried > n / 5,
                "{} {front_facing}: {carried} of {n}",
                scene.name
            );
            // Carried on once more, to frame A's pixels and points.
            state.carry_to_pixels(&pixels_a, width, height);
            g.update(&scene.spheres).unwrap();
            project(&g, &scene.points, &mut state, &mut out);
        }
    }
}
