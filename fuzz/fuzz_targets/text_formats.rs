//! Fuzz the text formats: camera.json, ground-truth/track lines, template JSON, htrack .calib.
#![no_main]
use std::path::Path;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let p = Path::new("fuzz");
    let _ = sensor_io::io::parse_camera_json(text, p);
    let _ = serde_json::from_str::<sensor_io::record::HandRecord>(text);
    let _ = hand_model::spheremesh::SphereMeshTemplate::from_json_str(text, p);
    let _ = hand_model::cylinder::parse_htrack_calib(text, p);
});
