//! The `meniscus` command line: the program shell (subcommands, panics, Ctrl-C, exit
//! codes). Each subcommand is one module of [`cli`]; all reconstruction logic lives in
//! the library.

mod cli;

use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};
use cli::archive::ArchiveCommand;
use cli::reconstruct::ReconstructArgs;
use cli::Failure;
use std::path::Path;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "meniscus",
    version,
    about = "Surface reconstruction for particle-based fluids (Akinci et al. 2013 pipeline)"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Reconstruct the surface of one particle file or a `{}` sequence of them.
    Reconstruct(Box<ReconstructArgs>),
    /// Inspect, check, extract from or fill a `.mseq` mesh-sequence archive.
    #[command(subcommand)]
    Archive(ArchiveCommand),
}

fn main() -> ExitCode {
    meniscus::tune_allocator();
    let matches = Cli::command()
        .try_get_matches()
        .unwrap_or_else(|e| exit_with_hint(e));
    let cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    // A panic inside a library entry point comes back as an error that is printed once,
    // naming the input; the default hook would print it a first time (kept with
    // RUST_BACKTRACE, for bug reports).
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if !meniscus::error::panic_is_caught() || std::env::var_os("RUST_BACKTRACE").is_some() {
            default_hook(info);
        }
    }));
    // Ctrl-C: the first stops the run at the next tile or stage (temporary files are
    // removed, no partial output is left); a second one exits at once, leaving the
    // temporary files to the next run (which removes those of runs that are gone) and
    // an archive being appended to without its index (the next append writes it).
    let cancel = meniscus::CancelToken::new();
    let handler = cancel.clone();
    let _ = ctrlc::set_handler(move || {
        if handler.cancel() {
            std::process::exit(130);
        }
        eprintln!(
            "\ninterrupted: stopping at the next tile or stage (Ctrl-C again to quit now, \
             leaving temporary files that the next run removes)"
        );
    });
    let result = match cli.command {
        Command::Reconstruct(mut args) => {
            let given = matches
                .subcommand_matches("reconstruct")
                .expect("the reconstruct subcommand");
            cli::reconstruct::run(&mut args, given, &cancel)
        }
        Command::Archive(command) => cli::archive::run(command, &cancel),
    };
    if result.is_err() && cancel.is_cancelled() {
        eprintln!("error: interrupted");
        return ExitCode::from(130);
    }
    report(result)
}

/// Prints a command-line error and exits; an extra argument that is an existing file (a
/// shell glob the shell expanded) gets a hint at the `{}` pattern.
fn exit_with_hint(e: clap::Error) -> ! {
    use clap::error::{ContextKind, ContextValue, ErrorKind};
    let extra = match e.get(ContextKind::InvalidArg) {
        Some(ContextValue::String(arg)) if e.kind() == ErrorKind::UnknownArgument => {
            Some(arg.clone())
        }
        _ => None,
    };
    let Some(extra) = extra.filter(|a| Path::new(a).is_file()) else {
        e.exit()
    };
    let _ = e.print();
    eprintln!(
        "hint: {extra:?} is a file: did the shell expand a glob into several inputs? A sequence is \
         one quoted pattern with {{}} where the frame number goes, e.g. {:?}",
        meniscus::sequence::suggested_pattern(&extra)
    );
    std::process::exit(e.exit_code())
}

fn report(result: Result<(), Failure>) -> ExitCode {
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(Failure::Usage(message)) => {
            eprintln!("error: {message}");
            ExitCode::from(2)
        }
        Err(Failure::Run(message)) => {
            eprintln!("error: {message}");
            ExitCode::FAILURE
        }
    }
}
