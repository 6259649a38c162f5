//! The sphere-mesh hand model of thesis Ch. 3: a template (skeleton + spheres attached to bones +
//! pill/wedge elements), its posing, the honline shape vector β and the file formats.

mod default;
mod json;
mod posed;
mod shape_params;
mod template;

pub use default::default_right_hand;
pub use json::{TEMPLATE_FORMAT, TEMPLATE_VERSION};
pub use posed::PosedSphereMesh;
pub use shape_params::{ShapeBasis, ShapeEffect, ShapeKind, ShapeParam};
pub use template::{Attachment, ElementDef, SphereDef, SphereMeshTemplate};
