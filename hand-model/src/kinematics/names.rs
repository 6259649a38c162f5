//! The DOF names shared by every model of the workspace (DESIGN.md "Pose and shape"): output
//! files name their DOFs, so the same joint has the same name in every model.

/// The six global DOFs (translation in mm, XYZ Euler rotation in rad), pose-vector order.
pub const GLOBAL_DOFS: [&str; 6] = [
    "global_tx",
    "global_ty",
    "global_tz",
    "global_rx",
    "global_ry",
    "global_rz",
];

/// The two wrist DOFs of the sphere-mesh model.
pub const WRIST_DOFS: [&str; 2] = ["wrist_abd", "wrist_flex"];

/// The 20 digit articulations (thesis §2.2): per digit (thumb, index, middle, ring, pinky) the
/// abduction then three flexions, positive toward the palm.
pub const DIGIT_DOFS: [&str; 20] = [
    "thumb_cmc_abd",
    "thumb_cmc_flex",
    "thumb_mcp_flex",
    "thumb_ip_flex",
    "index_mcp_abd",
    "index_mcp_flex",
    "index_pip_flex",
    "index_dip_flex",
    "middle_mcp_abd",
    "middle_mcp_flex",
    "middle_pip_flex",
    "middle_dip_flex",
    "ring_mcp_abd",
    "ring_mcp_flex",
    "ring_pip_flex",
    "ring_dip_flex",
    "pinky_mcp_abd",
    "pinky_mcp_flex",
    "pinky_pip_flex",
    "pinky_dip_flex",
];

/// Concatenate two name lists at compile time (`N` must equal `A + B`).
pub const fn concat_names<const A: usize, const B: usize, const N: usize>(
    a: [&'static str; A],
    b: [&'static str; B],
) -> [&'static str; N] {
    assert!(A + B == N, "N must equal A + B");
    let mut out = [""; N];
    let mut i = 0;
    while i < A {
        out[i] = a[i];
        i += 1;
    }
    while i < N {
        out[i] = b[i - A];
        i += 1;
    }
    out
}
