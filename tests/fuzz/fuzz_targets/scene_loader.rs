#![no_main]
//! The glTF loader on arbitrary bytes: it must return Ok or an error, never crash.
//!
//! The `gltf` crate itself panics on some malformed files (e.g. gltf-json 1.4.1,
//! mesh.rs:151: a POSITION accessor index out of range during validation); the loader's
//! `catch_unwind` backstop turns those into errors, and `tests/fuzz/regressions/` keeps
//! the inputs as regression tests. A silent panic hook lets the fuzzer explore past
//! them: a panic that escapes `load_from_slice` still aborts the run and is reported.

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    static HOOK: std::sync::Once = std::sync::Once::new();
    HOOK.call_once(|| std::panic::set_hook(Box::new(|_| {})));
    let result = std::panic::catch_unwind(|| prismap_engine::scene::load_from_slice(data, "fuzz.gltf", None));
    assert!(result.is_ok(), "a panic escaped the loader");
});
