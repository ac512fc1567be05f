//! Typed errors of the library: one variant family per stage, each saying what was wrong
//! with which input.

use std::panic::AssertUnwindSafe;
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Result alias of the library.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Every error the library can return.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// An operating-system I/O error on a named file.
    #[error("{path}: {source}")]
    Io {
        /// The file being read or written.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A particle or mesh file whose content is malformed.
    #[error("{path}: {location}: {message}")]
    Parse {
        /// The file being read.
        path: PathBuf,
        /// Where in the file: "line 12", "byte offset 4096", "header".
        location: String,
        /// What was wrong.
        message: String,
    },
    /// A file whose format is not known or not supported.
    #[error("{path}: {message}")]
    UnsupportedFormat {
        /// The file.
        path: PathBuf,
        /// What is not supported and what is.
        message: String,
    },
    /// An option with a value that cannot work.
    #[error("invalid {option}: {message}")]
    InvalidOption {
        /// The option's name in the library: the field of its options struct
        /// (`particle_radius`; two names with a `/` when their combination is wrong;
        /// `input`, `output` for the paths a job is given). The command line shows it as
        /// its flag (`--particle-radius`).
        option: &'static str,
        /// Why the value is rejected.
        message: String,
    },
    /// The spill file of a tiled run could not be created, written or read.
    #[error("spill file {path}: {source} (another temporary directory may have room)")]
    Spill {
        /// The temporary directory or file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The memory budget cannot hold what the run needs.
    #[error("memory budget of {budget_mib} MiB is too small: {message}")]
    MemoryBudget {
        /// The budget, MiB.
        budget_mib: u64,
        /// What does not fit, and what would.
        message: String,
    },
    /// The run was interrupted (Ctrl-C); nothing was written.
    #[error("interrupted")]
    Interrupted,
    /// A point attribute that is missing, malformed or not finite.
    #[error("{path}: attribute {attribute:?}: {message}")]
    Attribute {
        /// The input.
        path: PathBuf,
        /// The attribute's name.
        attribute: String,
        /// What was wrong.
        message: String,
    },
    /// A particle whose position the lattice cannot hold: not finite, or more than 2^23
    /// cells from the origin for the cell size the particle radius gives.
    #[error("{}{message}", path.as_ref().map(|p| format!("{}: ", p.display())).unwrap_or_default())]
    ParticleOutOfRange {
        /// The input, when the particles came from a file.
        path: Option<PathBuf>,
        /// Which particle, where, and why.
        message: String,
    },
    /// Frames a run would add to an archive that already holds them (refused before the
    /// archive is touched; [`crate::job::JobOptions::skip_existing`] skips them instead).
    #[error("{}: already holds {}", path.display(), held_frames(frames, *planned))]
    FramesExist {
        /// The archive.
        path: PathBuf,
        /// The frames of the run it holds, in the run's order.
        frames: Vec<i64>,
        /// How many frames the run has.
        planned: usize,
    },
    /// A bug: the library panicked while working on `input`. The panic was caught at the
    /// public entry point so that the caller gets an error, not an abort.
    #[error("{input}: internal error (a bug in meniscus, please report it): {message}")]
    Internal {
        /// The file (or "particles in memory", "archive ...") being worked on.
        input: String,
        /// The panic's message.
        message: String,
    },
    /// A directory without the free space a temporary or spill file is about to take;
    /// found before writing it.
    #[error("{path}: not enough free space for {what}: {needed} bytes needed ({:.1} MiB), {available} bytes free ({:.1} MiB)", *needed as f64 / 1048576.0, *available as f64 / 1048576.0)]
    NoSpace {
        /// The directory.
        path: PathBuf,
        /// What was to be written there ("the spooled particles of frame.bgeo.gz").
        what: String,
        /// Bytes the file would take.
        needed: u64,
        /// Bytes free for this user.
        available: u64,
    },
    /// A given particle radius refused before any work ([`crate::radius::check_radius`]):
    /// so small that most of the fluid's particles would have no neighbour within the
    /// kernel's reach (each meshed as a sphere of its own), or so large that the surface
    /// would swell into one blob. Says both radii and, in `force`, how to run anyway.
    #[error("{}", implausible_radius(path, *given, *estimate, origin, problem, force))]
    ImplausibleRadius {
        /// The input whose particles were measured.
        path: PathBuf,
        /// The radius given, world units.
        given: f32,
        /// The radius the particles imply, world units (see `origin`).
        estimate: f32,
        /// Where `estimate` comes from.
        origin: crate::radius::RadiusSource,
        /// What a run with `given` would do.
        problem: crate::radius::RadiusProblem,
        /// How the caller runs with `given` anyway, in its own terms (a flag, a keyword,
        /// a check box); the message ends with it.
        force: String,
    },
    /// A particle radius attribute ([`crate::radius::ParticleRadii`]) that is not one
    /// finite number > 0 per particle.
    #[error("{}: radius attribute {attribute:?}{}: {message}", path.display(), particle.map(|i| format!(", particle {i}")).unwrap_or_default())]
    InvalidRadius {
        /// The input.
        path: PathBuf,
        /// The attribute's name.
        attribute: String,
        /// The first particle (input index) with a bad radius; `None` when the
        /// attribute as a whole is wrong (its length or components).
        particle: Option<usize>,
        /// What was wrong.
        message: String,
    },
    /// The input holds no particles.
    #[error("{path}: the file holds no particles")]
    EmptyInput {
        /// The file.
        path: PathBuf,
    },
}

/// `a / b` to three significant digits.
/// The message of [`Error::ImplausibleRadius`]: the same words in every front end, which
/// differ only in `force`.
fn implausible_radius(
    path: &std::path::Path,
    given: f32,
    estimate: f32,
    origin: &crate::radius::RadiusSource,
    problem: &crate::radius::RadiusProblem,
    force: &str,
) -> String {
    format!(
        "{}: a particle radius of {given:?} is refused: it is {} × the {estimate:?} {origin}, and {problem}; give about {estimate:?}, or {force} to run with {given:?} anyway",
        path.display(),
        ratio(given, estimate)
    )
}

fn ratio(a: f32, b: f32) -> String {
    let x = a / b;
    if (0.01..1000.0).contains(&x) {
        format!("{x:.3}")
    } else {
        format!("{x:.2e}")
    }
}

impl Error {
    /// Wraps an I/O error with the path it concerns.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }

    /// A parse error at a location of a file.
    pub fn parse(
        path: impl Into<PathBuf>,
        location: impl Into<String>,
        message: impl Into<String>,
    ) -> Self {
        Error::Parse {
            path: path.into(),
            location: location.into(),
            message: message.into(),
        }
    }
}

/// How many [`guard`]s are running, in any thread.
static GUARDS: AtomicUsize = AtomicUsize::new(0);

/// True while a public entry point is running under `guard`: a panic now becomes an
/// [`Error::Internal`] the caller will report, so a panic hook may stay silent (the CLI's
/// does, to print the message once).
pub fn panic_is_caught() -> bool {
    GUARDS.load(Ordering::Relaxed) > 0
}

/// Runs a public entry point; a panic in it (or in the rayon tasks it waits for) becomes
/// [`Error::Internal`] naming `input`.
pub(crate) fn guard<T>(input: impl FnOnce() -> String, f: impl FnOnce() -> Result<T>) -> Result<T> {
    struct Count;
    impl Drop for Count {
        fn drop(&mut self) {
            GUARDS.fetch_sub(1, Ordering::Relaxed);
        }
    }
    GUARDS.fetch_add(1, Ordering::Relaxed);
    let _count = Count;
    match std::panic::catch_unwind(AssertUnwindSafe(f)) {
        Ok(result) => result,
        Err(payload) => {
            let message = if let Some(s) = payload.downcast_ref::<&str>() {
                (*s).to_string()
            } else if let Some(s) = payload.downcast_ref::<String>() {
                s.clone()
            } else {
                "panic without a message".to_string()
            };
            Err(Error::Internal {
                input: input(),
                message,
            })
        }
    }
}

/// "frame 3", "frames 1, 6 and 13 (all 3 frames of this run)"; the first ten of a long
/// list.
fn held_frames(frames: &[i64], planned: usize) -> String {
    const SHOWN: usize = 10;
    let names: Vec<String> = frames.iter().take(SHOWN).map(|n| n.to_string()).collect();
    let list = match names.split_last() {
        // The count follows.
        _ if frames.len() > SHOWN => format!("{}, …", names.join(", ")),
        Some((last, rest)) if !rest.is_empty() => format!("{} and {last}", rest.join(", ")),
        _ => names.join(""),
    };
    let noun = if frames.len() == 1 { "frame" } else { "frames" };
    let of = if frames.len() == planned && planned > 1 {
        format!(" (all {planned} frames of this run)")
    } else if planned > frames.len() {
        format!(" ({} of the {planned} frames of this run)", frames.len())
    } else {
        String::new()
    };
    format!("{noun} {list}{of}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_exist_names_the_frames_it_holds() {
        let e = |frames: Vec<i64>, planned| {
            Error::FramesExist {
                path: "run.mseq".into(),
                frames,
                planned,
            }
            .to_string()
        };
        assert_eq!(e(vec![0], 1), "run.mseq: already holds frame 0");
        assert_eq!(
            e(vec![1, 6, 13], 3),
            "run.mseq: already holds frames 1, 6 and 13 (all 3 frames of this run)"
        );
        assert_eq!(
            e(vec![6], 3),
            "run.mseq: already holds frame 6 (1 of the 3 frames of this run)"
        );
        let long = e((0..25).collect(), 30);
        assert!(
            long.ends_with(
                "frames 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, … (25 of the 30 frames of this run)"
            ),
            "{long}"
        );
        assert!(!long.contains("--"), "names no flag: {long}");
    }
}
