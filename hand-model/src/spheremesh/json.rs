//! The versioned JSON template format (placeholder constants; the reader/writer lives here).

/// The `format` tag of sphere-mesh template files.
pub const TEMPLATE_FORMAT: &str = "hands.spheremesh";
/// The current version of the template format.
pub const TEMPLATE_VERSION: u32 = 1;
