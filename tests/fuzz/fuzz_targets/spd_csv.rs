#![no_main]
//! The measured-SPD CSV parser on arbitrary text.

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = prismap_engine::scene::parse_spd_csv(text);
    }
});
