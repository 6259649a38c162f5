//! The sphere-mesh hand model of thesis Ch. 3: a template (skeleton + spheres attached to bones +
//! pill/wedge elements), its posing, the honline shape vector β and the file formats.

mod default;
mod import_hmodel;
mod json;
pub(crate) use json::write_atomic;
mod posed;
mod shape_params;
mod template;

pub use default::default_right_hand;
pub use import_hmodel::{
    detect_hmodel_variant, export_hmodel_dir, import_hmodel_dir, pose_from_honline_theta,
    HmodelVariant, HONLINE_THETA_DOFS, PILL_SENTINEL,
};
pub use json::{TEMPLATE_FORMAT, TEMPLATE_VERSION};
pub use posed::PosedSphereMesh;
pub use shape_params::{ShapeBasis, ShapeEffect, ShapeKind, ShapeParam};
pub use template::{Attachment, ElementDef, SphereDef, SphereMeshTemplate};
