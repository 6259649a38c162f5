//! Fuzz the streaming MCAP sequence reader through a file (its public entry point).
#![no_main]
use libfuzzer_sys::fuzz_target;
use sensor_io::io::{McapReader, SequenceReader};

fuzz_target!(|data: &[u8]| {
    // The reader turns panics of the third-party decoder into errors with `catch_unwind`;
    // libfuzzer-sys's hook would abort before that, so use a silent hook. Panics escaping the
    // reader still abort (libfuzzer-sys catches the unwind and aborts).
    static QUIET: std::sync::Once = std::sync::Once::new();
    QUIET.call_once(|| std::panic::set_hook(Box::new(|_| {})));
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
