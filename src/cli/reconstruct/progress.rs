//! What `meniscus reconstruct` shows while and after it runs: the progress bar, each
//! finished frame's lines (`--json-progress`, errors, warnings, the stage table), the
//! summary, the `--stats` JSON and the exit status of failed frames.

use super::ReconstructArgs;
use crate::cli::Failure;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use meniscus::job::{peak_rss_bytes, run_frames, FrameReport, FrameStatus, JobOptions};
use meniscus::pipeline::ReconstructOptions;
use std::path::PathBuf;

/// The progress bar of `frames` frames on stderr (hidden with `--quiet`).
fn progress_bar(args: &ReconstructArgs, frames: usize) -> ProgressBar {
    if args.quiet {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::with_draw_target(Some(frames as u64), ProgressDrawTarget::stderr());
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} frames  {msg}",
        )
        .expect("valid template"),
    );
    bar.enable_steady_tick(std::time::Duration::from_millis(120));
    bar
}

/// Runs the frames of `plan` behind a progress bar, printing what each finished frame
/// calls for: its `--json-progress` line, its error (with `--keep-going`), warnings, and
/// the stage table of a single frame.
pub(super) fn run_with_progress(
    args: &ReconstructArgs,
    plan: &[(meniscus::sequence::Frame, PathBuf)],
    options: &ReconstructOptions,
    job: &JobOptions,
) -> meniscus::Result<Vec<FrameReport>> {
    let bar = progress_bar(args, plan.len());
    let mut warned = false;
    let result = run_frames(
        plan,
        options,
        job,
        &mut |_, frame| bar.set_prefix(frame.input.display().to_string()),
        &mut |stage| bar.set_message(stage.to_string()),
        &mut |report: &FrameReport| {
            bar.inc(1);
            if args.json_progress {
                println!("{}", report.progress_line());
            }
            if args.keep_going {
                if let Some(error) = &report.error {
                    bar.suspend(|| eprintln!("error: frame {}: {error}", report.frame));
                }
            }
            if !warned && !report.dropped_attributes.is_empty() {
                warned = true;
                bar.suspend(|| {
                    eprintln!(
                        "warning: {} cannot hold point attributes; not written: {}",
                        report.output.display(),
                        report.dropped_attributes.join(", ")
                    )
                });
            }
            let contained = report.reconstruction.containment.as_ref();
            if let Some(left) = contained.map(|c| c.remaining).filter(|&n| n > 0) {
                bar.suspend(|| {
                    eprintln!(
                        "warning: {}: {left} particle centres stay less than the keep-inside \
                         depth under the surface (where it is folded or thinner than \
                         containment can tell its side)",
                        report.input.display()
                    )
                });
            }
            if !args.quiet && plan.len() == 1 && report.error.is_none() && !report.skipped {
                bar.suspend(|| eprint!("{}", report.reconstruction.table()));
            }
        },
    );
    bar.finish_and_clear();
    result
}

/// Writes the `--stats` JSON: the options, every frame's report, the run's time and peak
/// memory.
pub(super) fn write_stats(
    path: &std::path::Path,
    options: &ReconstructOptions,
    reports: &[FrameReport],
    total: f64,
) -> Result<(), Failure> {
    let json = serde_json::json!({
        "options": options,
        "frames": reports,
        "total_seconds": total,
        "peak_rss_bytes": peak_rss_bytes(),
    });
    let text = serde_json::to_string_pretty(&json).map_err(|e| Failure::Run(e.to_string()))?;
    std::fs::write(path, text).map_err(|e| Failure::from(meniscus::Error::io(path, e)))
}

/// Fails the run when any frame failed (with `--keep-going`), naming them.
pub(super) fn check_failed(reports: &[FrameReport]) -> Result<(), Failure> {
    let failed: Vec<&FrameReport> = reports
        .iter()
        .filter(|r| r.status == FrameStatus::Failed)
        .collect();
    if failed.is_empty() {
        return Ok(());
    }
    let numbers: Vec<String> = failed.iter().map(|r| r.frame.to_string()).collect();
    Err(Failure::Run(format!(
        "{} of {} frames failed (frame{} {}); the others were written",
        failed.len(),
        reports.len(),
        if failed.len() == 1 { "" } else { "s" },
        numbers.join(", ")
    )))
}

/// The run's summary line: frames, time, triangles, where they went (`output` as given
/// to `-o`) and peak memory.
pub(super) fn summarize(reports: &[FrameReport], total: f64, output: &str) {
    let count = |s| reports.iter().filter(|r| r.status == s).count();
    let (done, skipped, failed) = (
        count(FrameStatus::Done),
        count(FrameStatus::Skipped),
        count(FrameStatus::Failed),
    );
    let triangles: usize = reports.iter().map(|r| r.triangles()).sum();
    eprintln!(
        "{} frame(s) reconstructed{}{} in {:.2} s, {} triangles written to {}, peak memory {}",
        done,
        if skipped > 0 {
            format!(", {skipped} skipped")
        } else {
            String::new()
        },
        if failed > 0 {
            format!(", {failed} failed")
        } else {
            String::new()
        },
        total,
        triangles,
        output,
        peak_rss_bytes()
            .map(|b| format!("{:.1} MiB", b as f64 / (1 << 20) as f64))
            .unwrap_or_else(|| "unknown".into()),
    );
}
