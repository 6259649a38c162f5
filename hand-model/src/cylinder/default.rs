//! The project's default right-hand cylinder template (thesis §2.2, Fig. 4.10).
//!
//! Authored here, in the frames of `DESIGN.md` (origin at the wrist end of the palm, +y toward
//! the fingertips, palm facing −z, thumb toward −x). The proportions — segment lengths, radii
//! and thicknesses, and the positions of the thumb base and of the four finger bases — are those
//! of the metric model that the htrack default calibration produces (ANCHOR-FACTS §3, "Resulting
//! metric model", computed from OpenGP/htrack `tracker/Calibration/default.calib`), mirrored to a
//! right hand and rounded to 0.01 mm. The directions are our own: straight fingers fanned by a
//! few degrees, and a thumb metacarpal pointing radially, distally and slightly palmward.
//!
//! Bone frames follow the sphere-mesh default template: local +y along the bone, local +z toward
//! the palm, so a positive rotation about local +x flexes toward the palm and a positive rotation
//! about local −z abducts toward the thumb side.

use std::path::Path;

use nalgebra::{Matrix3, Vector3};

use super::model::{build_hand, CylinderModel, DigitSpec, HandSpec, SegmentShape};
use crate::keypoints::Handedness;
use crate::math::{axis_angle, Rigid3};

/// Palm segment `[length, r1, r2, r1y, r2y]` (mm).
const PALM: SegmentShape = [56.27, 29.22, 33.76, 8.77, 8.77];

/// Per digit (thumb, pinky, ring, middle, index): base position in the model frame (mm), splay
/// about the palm normal (rad, positive toward the thumb; unused for the thumb) and the three
/// segments `[length, r1, r2, r1y, r2y]`.
type DigitRow = ([f64; 3], f64, [SegmentShape; 3]);

const DIGIT_TABLE: [DigitRow; 5] = [
    (
        [-16.23, 8.12, -8.12],
        0.0,
        [
            [32.47, 11.04, 6.49, 11.04, 6.49],
            [19.48, 6.49, 5.84, 6.49, 5.84],
            [12.99, 5.84, 5.19, 5.84, 5.19],
        ],
    ),
    (
        [24.35, 64.93, 0.0],
        -0.25,
        [
            [24.35, 6.49, 5.84, 6.49, 5.84],
            [14.61, 5.84, 5.19, 5.84, 5.19],
            [9.74, 5.19, 5.19, 5.19, 5.19],
        ],
    ),
    (
        [8.12, 64.93, 0.0],
        -0.12,
        [
            [30.84, 6.49, 5.84, 6.49, 5.84],
            [18.51, 5.84, 5.19, 5.84, 5.19],
            [12.34, 5.19, 5.19, 5.19, 5.19],
        ],
    ),
    (
        [-8.12, 64.93, 0.0],
        0.0,
        [
            [32.47, 6.49, 5.84, 6.49, 5.84],
            [19.48, 5.84, 5.19, 5.84, 5.19],
            [12.99, 5.19, 5.19, 5.19, 5.19],
        ],
    ),
    (
        [-24.35, 64.93, 0.0],
        0.10,
        [
            [30.84, 6.49, 5.84, 6.49, 5.84],
            [18.51, 5.84, 5.19, 5.84, 5.19],
            [12.34, 5.19, 5.19, 5.19, 5.19],
        ],
    ),
];

/// Thumb metacarpal direction (model frame, normalized at use): radial, distal, slightly palmar.
const THUMB_DIR: [f64; 3] = [-0.66, 0.72, -0.22];
/// Direction toward which the thumb flexes (orthogonalized against [`THUMB_DIR`] at use).
const THUMB_PALMAR: [f64; 3] = [0.7, 0.0, -0.7];

/// Local frame with +y along `dir` and +z toward `palmar` (orthogonalized), x = y × z.
fn frame(dir: Vector3<f64>, palmar: Vector3<f64>) -> Matrix3<f64> {
    let y = dir.normalize();
    let z = (palmar - y * palmar.dot(&y)).normalize();
    Matrix3::from_columns(&[y.cross(&z), y, z])
}

/// The default right-hand cylinder model: 16 segments (palm, then thumb, pinky, ring, middle,
/// index — htrack's segment order), 26 DOFs named as in [`super::CYLINDER_DOF_NAMES`].
pub fn default_right_hand_cylinders() -> CylinderModel {
    let source = Path::new("<default cylinder template>");
    // Palm frame: local y = model y, local z palmar (model −z), local x = model −x.
    let palm_rot = Matrix3::from_columns(&[-Vector3::x(), Vector3::y(), -Vector3::z()]);
    let palm = Rigid3::from_rotation(palm_rot);
    let digits: [DigitSpec; 5] = std::array::from_fn(|d| {
        let (base, splay, shapes) = DIGIT_TABLE[d];
        // Row 0 is the thumb.
        let global_rot = if d == 0 {
            frame(Vector3::from(THUMB_DIR), Vector3::from(THUMB_PALMAR))
        } else {
            axis_angle(&Vector3::z(), splay) * palm_rot
        };
        let global = Rigid3::new(global_rot, Vector3::from(base));
        DigitSpec {
            rests: [
                palm.inverse().compose(&global),
                Rigid3::from_translation(Vector3::new(0.0, shapes[0][0], 0.0)),
                Rigid3::from_translation(Vector3::new(0.0, shapes[1][0], 0.0)),
            ],
            shapes,
        }
    });
    let spec = HandSpec {
        name: "hands default right hand (cylinders)".into(),
        handedness: Handedness::Right,
        palm_rest: palm,
        palm: PALM,
        digits,
        flex_axis: Vector3::x(),
        abd_axis: -Vector3::z(),
    };
    build_hand(spec, source).expect("the embedded default cylinder template is valid")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_template_is_a_right_hand() {
        let m = default_right_hand_cylinders();
        assert_eq!(m.segments.len(), 16);
        assert_eq!(m.skeleton.num_dofs(), 26);
        let posed = m.rest_posed();
        let kp = m.keypoints(&posed);
        // Thumb toward −x, palm facing −z: thumb CMC at −x, index MCP at −x, pinky at +x.
        assert!(kp[1].x < 0.0 && kp[5].x < kp[17].x);
        assert!(kp[1].z < 0.0);
    }
}
