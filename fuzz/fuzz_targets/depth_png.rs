//! Fuzz the 16-bit depth PNG reader: any bytes give a depth image or an error, never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = sensor_io::io::decode_depth_png(data, std::path::Path::new("fuzz.png"));
});
