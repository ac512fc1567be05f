//! Mesh reader, glTF: `read_mesh` on a `.glb` file (the reader detects binary or JSON
//! glTF by content, so one extension covers both).
//!
//! The reader catches the panics the `gltf` crate raises on some malformed documents (an
//! error, not a crash), but libfuzzer-sys's panic hook aborts before any unwinding. So
//! this target installs a hook that only remembers the last panic, and aborts itself when
//! a panic escapes `read_mesh`: a caught `gltf` panic is not a finding, any other is.
#![no_main]

#[path = "../common/mod.rs"]
mod common;

use libfuzzer_sys::fuzz_target;
use std::sync::{Mutex, Once};

static LAST_PANIC: Mutex<String> = Mutex::new(String::new());

fuzz_target!(|data: &[u8]| {
    static HOOK: Once = Once::new();
    HOOK.call_once(|| {
        std::panic::set_hook(Box::new(|info| {
            let message = format!("{info}\n{}", std::backtrace::Backtrace::force_capture());
            *LAST_PANIC.lock().unwrap_or_else(|e| e.into_inner()) = message;
        }));
    });
    if std::panic::catch_unwind(|| common::mesh::run("input.glb", data)).is_err() {
        let message = LAST_PANIC.lock().unwrap_or_else(|e| e.into_inner()).clone();
        eprintln!("panic escaped read_mesh: {message}");
        std::process::abort();
    }
});
