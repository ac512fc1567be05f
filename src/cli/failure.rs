//! How a command fails: a usage error (exit 2) or a failed run (exit 1), and the flag
//! that names a library option.

/// Why a command failed: what it prints and its exit code.
pub(crate) enum Failure {
    /// An option or argument that cannot work (exit 2, as clap's own usage errors).
    Usage(String),
    /// A file, its content, or the run itself (exit 1).
    Run(String),
}

impl Failure {
    /// An option the user gave, with a value that cannot work.
    pub(crate) fn option(option: &str, message: impl std::fmt::Display) -> Self {
        Failure::Usage(format!("invalid option {option}: {message}"))
    }
}

impl From<meniscus::Error> for Failure {
    fn from(e: meniscus::Error) -> Self {
        match e {
            meniscus::Error::InvalidOption { option, message } => {
                Failure::option(&flag(option), message)
            }
            e => Failure::Run(e.to_string()),
        }
    }
}

/// The flag of a library option name (`particle_radius` → `--particle-radius`,
/// `t_low/t_high` → `--t-low/--t-high`, `input` → `INPUT`).
fn flag(option: &str) -> String {
    option
        .split('/')
        .map(|name| match name {
            "input" => "INPUT".to_string(),
            name => format!("--{}", name.replace('_', "-")),
        })
        .collect::<Vec<_>>()
        .join("/")
}
