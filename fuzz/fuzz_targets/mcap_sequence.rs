//! Fuzz the streaming MCAP sequence reader through a file (its public entry point).
#![no_main]
use libfuzzer_sys::fuzz_target;
use sensor_io::io::{McapReader, SequenceReader};

fuzz_target!(|data: &[u8]| {
    let path = std::env::temp_dir().join(format!("hands-fuzz-{}.mcap", std::process::id()));
    if std::fs::write(&path, data).is_err() {
        return;
    }
    if let Ok(mut r) = McapReader::open(&path) {
        for _ in 0..64 {
            match r.next_frame() {
                Some(Ok(_)) => {}
                _ => break,
            }
        }
    }
});
