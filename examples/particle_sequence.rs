//! Writes the 3-frame particle sequence of the USD checks (frames 1, 2 and 4, attributes
//! of 1 to 4 components; see `tests/support/particle_sequence.rs`) into OUT_DIR and prints
//! its `{}` pattern.
//!
//! `cargo run --release --example particle_sequence -- OUT_DIR`

#[path = "../tests/support/particle_sequence.rs"]
mod particle_sequence;

fn main() {
    let Some(dir) = std::env::args().nth(1) else {
        eprintln!("usage: particle_sequence OUT_DIR");
        std::process::exit(2);
    };
    let dir = std::path::PathBuf::from(dir);
    std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    println!("{}", particle_sequence::write_particle_sequence(&dir));
}
