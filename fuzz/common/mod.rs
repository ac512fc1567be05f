//! What every fuzz target shares: the input written to a file under `/dev/shm` (the
//! readers take paths), and the checks made on what a reader returns.

#![allow(dead_code)]

pub mod mesh;
pub mod particles;

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// A directory of this process under `/dev/shm` (memory-backed), made once; falls back to
/// the system's temporary directory when `/dev/shm` is missing.
pub fn scratch_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let base = if Path::new("/dev/shm").is_dir() {
            PathBuf::from("/dev/shm")
        } else {
            std::env::temp_dir()
        };
        let dir = base.join(format!("meniscus-fuzz-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("scratch directory");
        dir
    })
}

/// Writes `data` to `name` in the scratch directory (replacing the previous input) and
/// returns its path.
pub fn input_file(name: &str, data: &[u8]) -> PathBuf {
    let path = scratch_dir().join(name);
    std::fs::write(&path, data).expect("write the fuzz input");
    path
}

/// A reader's error must name the input file (the errors are typed and say where).
pub fn check_error(path: &Path, e: &meniscus::Error) {
    let name = path.file_name().unwrap().to_str().unwrap();
    let message = e.to_string();
    assert!(
        message.contains(name),
        "the error does not name the input file: {message}"
    );
}
