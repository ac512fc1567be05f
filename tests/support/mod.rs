//! Helpers the integration tests share. Each `tests/*.rs` is a crate of its own and
//! includes this module with `mod support;`: the shipped datasets, the `meniscus`
//! binary, thread pools, directories, deterministic random generators and mutations, the
//! splash generator ([`splash`]), the archive tests' frames and meshes ([`archive`]) and
//! the USD output's particle sequence ([`particle_sequence`]).

// Every test crate compiles all of it and uses only some.
#![allow(dead_code)]

pub mod archive;
pub mod flicker;
pub mod particle_sequence;
pub mod splash;

use glam::Vec3;
use meniscus::io::particles::read_particles;
use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::time::{Duration, Instant};

/// The shipped dataset file `rel` (a path under `datasets/`).
pub fn dataset(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("datasets")
        .join(rel)
}

/// The particle positions of dataset `rel`, through the library's reader.
pub fn positions(rel: &str) -> Vec<Vec3> {
    read_particles(&dataset(rel), None).unwrap().positions
}

/// The positions of the binary `.xyz` dataset `rel` (three little-endian `f32`s per
/// particle), read without the library.
pub fn xyz(rel: &str) -> Vec<Vec3> {
    std::fs::read(dataset(rel))
        .unwrap()
        .chunks_exact(12)
        .map(|c| {
            let f = |k: usize| f32::from_le_bytes(c[4 * k..4 * k + 4].try_into().unwrap());
            Vec3::new(f(0), f(1), f(2))
        })
        .collect()
}

/// The eleven shipped simulation frames (`dambreak_small` and `double_dambreak`) with
/// their particle radii.
pub fn shipped_frames() -> Vec<(String, f32)> {
    [1, 9, 17, 25, 31, 45]
        .iter()
        .map(|k| (format!("dambreak_small/ParticleData_Fluid_{k}.xyz"), 0.012))
        .chain(
            [1, 6, 9, 13, 20]
                .iter()
                .map(|k| (format!("double_dambreak/ParticleData_Fluid_{k}.xyz"), 0.025)),
        )
        .collect()
}

/// The VTK-written VTK XML fixtures (`tests/data/vtk_xml/dd9_*.vtu|vtp`, the first 40
/// particles of double dam break frame 9), sorted by name.
pub fn vtk_xml_fixtures() -> Vec<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/vtk_xml");
    let mut names: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            let name = p.file_name().unwrap().to_str().unwrap();
            name.starts_with("dd9_") && (name.ends_with(".vtu") || name.ends_with(".vtp"))
        })
        .collect();
    names.sort();
    names
}

/// The `meniscus` binary of this build.
pub fn meniscus() -> Command {
    Command::new(env!("CARGO_BIN_EXE_meniscus"))
}

/// Runs `meniscus ARGS`: success and stderr.
pub fn run(args: &[&str]) -> (bool, String) {
    let out = meniscus().args(args).output().unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Sends Ctrl-C (`SIGINT`) to `child` once a file appears in `temp` (its spill file),
/// failing if none does within a minute or the run ends first.
pub fn interrupt_once_spilled(child: &mut Child, temp: &Path) {
    let clock = Instant::now();
    while names_in(temp).is_empty() {
        assert!(
            clock.elapsed() < Duration::from_secs(60),
            "no spill file appeared"
        );
        assert!(child.try_wait().unwrap().is_none(), "the run ended early");
        std::thread::sleep(Duration::from_millis(5));
    }
    std::thread::sleep(Duration::from_millis(100));
    let status = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
}

/// Runs `f` in a thread pool of `threads` threads.
pub fn in_pool<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

/// A temporary directory with an empty directory `temp` in it (for `--temp-dir`):
/// the directory (removed when dropped) and the path of `temp`.
pub fn dir_with_temp() -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let temp = dir.path().join("temp");
    std::fs::create_dir(&temp).unwrap();
    (dir, temp)
}

/// The names of the entries of `dir`, sorted.
pub fn names_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// A deterministic generator (xorshift), so that every run mutates the same way.
pub struct Rng(pub u64);

impl Rng {
    pub fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }

    /// A number in `0..n` (0 when `n` is 0).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// A deterministic linear congruential generator (Knuth's MMIX constants) of numbers in
/// `[0, 1)`.
pub struct Lcg(pub u64);

impl Lcg {
    fn step(&mut self) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        self.0
    }

    /// The next number, with 53 random bits.
    pub fn next_f64(&mut self) -> f64 {
        ((self.step() >> 11) as f64) / ((1u64 << 53) as f64)
    }

    /// The next number, with 24 random bits.
    pub fn next_f32(&mut self) -> f32 {
        ((self.step() >> 40) as f32) / ((1u64 << 24) as f32)
    }
}

/// A mutated copy of `base`: a few flipped bits, a truncation, a byte replaced, or a run
/// of ASCII digits replaced by one of the `huge` numbers; a file without digits is left
/// to `no_digits` in that last case.
pub fn mutate(
    rng: &mut Rng,
    base: &[u8],
    huge: &[&str],
    no_digits: impl FnOnce(&mut Rng, &mut Vec<u8>),
) -> Vec<u8> {
    let mut b = base.to_vec();
    match rng.below(4) {
        0 => {
            for _ in 0..1 + rng.below(4) {
                let i = rng.below(b.len());
                b[i] ^= 1 << rng.below(8);
            }
        }
        1 => b.truncate(rng.below(b.len())),
        2 => {
            let i = rng.below(b.len());
            b[i] = rng.next() as u8;
        }
        _ => {
            let digits: Vec<usize> = (0..b.len()).filter(|&i| b[i].is_ascii_digit()).collect();
            if !digits.is_empty() {
                let start = digits[rng.below(digits.len())];
                let end = (start..b.len())
                    .find(|&i| !b[i].is_ascii_digit())
                    .unwrap_or(b.len());
                let huge = huge[rng.below(huge.len())];
                b.splice(start..end, huge.bytes());
            } else {
                no_digits(rng, &mut b);
            }
        }
    }
    b
}

/// Runs `read` on the mutated file `name` (of content `bytes`) of round `round`; if it
/// panics, keeps the file in the temporary directory and fails naming it.
pub fn without_panic<T>(
    round: usize,
    name: &str,
    bytes: &[u8],
    read: impl FnOnce() -> T + std::panic::UnwindSafe,
) -> T {
    match std::panic::catch_unwind(read) {
        Ok(result) => result,
        Err(_) => {
            let keep = std::env::temp_dir().join(format!("meniscus-crash-{round}-{name}"));
            std::fs::write(&keep, bytes).unwrap();
            panic!(
                "round {round}: reading a mutated {name} panicked (kept as {})",
                keep.display()
            );
        }
    }
}

/// Splits `positions` into (particles with another particle strictly closer than
/// `radius`, isolated particle centres), both in input order: an oracle of the
/// pipeline's isolation, by a plain hash of cubic cells of edge `radius`.
pub fn split_isolated(positions: &[Vec3], radius: f32) -> (Vec<Vec3>, Vec<Vec3>) {
    let cell = |p: Vec3| (p / radius).floor().as_ivec3();
    let mut cells: std::collections::HashMap<glam::IVec3, Vec<usize>> = Default::default();
    for (i, p) in positions.iter().enumerate() {
        cells.entry(cell(*p)).or_default().push(i);
    }
    let r2 = radius * radius;
    let lonely = |i: usize| {
        let c = cell(positions[i]);
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let near = cells.get(&(c + glam::IVec3::new(dx, dy, dz)));
                    for &j in near.into_iter().flatten() {
                        if j != i && (positions[j] - positions[i]).length_squared() < r2 {
                            return false;
                        }
                    }
                }
            }
        }
        true
    };
    let (alone, kept): (Vec<usize>, Vec<usize>) = (0..positions.len()).partition(|&i| lonely(i));
    let pick = |ids: Vec<usize>| ids.into_iter().map(|i| positions[i]).collect();
    (pick(kept), pick(alone))
}
