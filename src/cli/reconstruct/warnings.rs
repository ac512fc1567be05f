//! The warnings of `meniscus reconstruct` about options the chosen output makes
//! pointless.

use super::ReconstructArgs;
use clap::parser::ValueSource;
use clap::ArgMatches;
use meniscus::attributes::AttributeSelection;
use meniscus::io::particles::ParticleFormat;
use meniscus::job::output_profile;
use meniscus::settings::Decimation;
use std::path::PathBuf;

/// Options the user gave that the chosen output makes pointless, each with the reason;
/// the run proceeds without them.
pub(crate) fn ineffective_options(
    args: &ReconstructArgs,
    given: &ArgMatches,
    plan: &[(meniscus::sequence::Frame, PathBuf)],
    attributes: &AttributeSelection,
) -> Vec<String> {
    let given = |id: &str| given.value_source(id) == Some(ValueSource::CommandLine);
    let profile = output_profile(plan);
    let output = &args.output;
    let mut warnings = Vec::new();
    // Raw .xyz holds no attributes (a list of names is an error when it is read).
    let raw_positions = args
        .input_format
        .or_else(|| {
            let (frame, _) = plan.first()?;
            ParticleFormat::from_path(&frame.input).ok()
        })
        .is_some_and(|f| f == ParticleFormat::Xyz);
    if raw_positions && *attributes == AttributeSelection::All {
        warnings.push("--attributes all has no effect: raw .xyz input holds positions only".into());
    }
    if !profile.quantized {
        for (id, option) in [
            ("error_bound", "--error-bound"),
            ("attribute_error_bound", "--attribute-error-bound"),
        ] {
            if given(id) {
                warnings.push(format!(
                    "{option} has no effect: it quantizes a .mseq archive, and {output:?} is not one"
                ));
            }
        }
    } else if given("attribute_error_bound") {
        if *attributes == AttributeSelection::None {
            warnings.push(
                "--attribute-error-bound has no effect: --attributes none carries no attributes"
                    .into(),
            );
        } else if raw_positions {
            warnings.push(
                "--attribute-error-bound has no effect: raw .xyz input holds positions only".into(),
            );
        }
    }
    if given("no_normals") && !profile.normals {
        warnings.push(format!(
            "--no-normals has no effect: {output:?} stores no normals (they are computed when frames are extracted)"
        ));
    }
    // An error bound of world units given as multiples of r (as it once was).
    if let (true, Some(bound)) = (profile.quantized, args.error_bound) {
        let r = args.radius as f64;
        if bound > 0.1 * r {
            warnings.push(format!(
                "--error-bound is in world units: {bound} is {:.3} × the particle radius (default {} = {} r)",
                bound / r,
                meniscus::archive::default_error_bound(args.radius),
                meniscus::archive::DEFAULT_ERROR_BOUND_RADII
            ));
        }
    }
    if given("fps") {
        match profile.animated {
            true if plan.len() == 1 && !profile.stage_metadata => warnings.push(format!(
                "--fps has no effect: {output:?} holds a single frame, which does not play"
            )),
            true => {}
            false => warnings.push(format!(
                "--fps has no effect: only a {{}} sequence written into one .glb/.gltf, or a USD stage, is animated, and {output:?} is neither"
            )),
        }
    }
    for (id, option) in [
        ("up_axis", "--up-axis"),
        ("meters_per_unit", "--meters-per-unit"),
    ] {
        if given(id) && !profile.stage_metadata {
            warnings.push(format!(
                "{option} has no effect: it is recorded in a USD stage (.usdc, .usda, .usd), and {output:?} is not one"
            ));
        }
    }
    if given("usd_droplets") && !profile.stage_metadata {
        warnings.push(format!(
            "--usd-droplets has no effect: it says how a USD stage (.usdc, .usda, .usd) holds the isolated particles, and {output:?} is not one"
        ));
    }
    if given("skip_existing") && profile.written_whole {
        warnings.push(format!(
            "--skip-existing has no effect: {output:?} holds the whole sequence and is written whole"
        ));
    }
    let single_file = plan.len() == 1 && plan[0].0.label.is_empty();
    if given("keep_going") && single_file {
        warnings.push(
            "--keep-going has no effect: a single file has no other frames to go on with".into(),
        );
    }
    if given("normal_smoothing") {
        if !profile.normals {
            warnings.push(format!(
                "--normal-smoothing has no effect: {output:?} stores no normals (they are computed when frames are extracted)"
            ));
        } else if args.no_normals {
            warnings.push("--normal-smoothing has no effect: --no-normals writes none".into());
        }
    }
    let smooth = args
        .smooth
        .unwrap_or_else(|| super::preset(args).settings(1.0).smooth);
    for (id, option) in [
        ("smooth_method", "--smooth-method"),
        ("smooth_max_inward", "--smooth-max-inward"),
        ("smooth_feature_angle", "--smooth-feature-angle"),
    ] {
        if given(id) && smooth == 0 {
            warnings.push(format!(
                "{option} has no effect: smoothing is off (0 steps)"
            ));
        }
    }
    if let (true, Some(decimate)) = (given("decimate_error"), &args.decimate) {
        if decimate.parse() == Ok(Decimation::Off) {
            warnings.push(format!(
                "--decimate-error has no effect: decimation is off (--decimate {decimate})"
            ));
        }
    }
    warnings
}
