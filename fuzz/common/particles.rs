//! The particle readers on one input: the whole-file reader, the streaming positions
//! reader of the format, and the spooled source with every attribute, drained.

use super::{check_error, input_file, scratch_dir};
use meniscus::attributes::AttributeSelection;
use meniscus::io::particles::{
    read_particles, stream_positions, ParticleFormat, ParticleSource, SpooledParticles,
};
use meniscus::CancelToken;

pub fn run(name: &str, format: ParticleFormat, data: &[u8]) {
    let path = input_file(name, data);
    if let Err(e) = read_particles(&path, None) {
        check_error(&path, &e);
    }
    let mut positions = 0usize;
    let mut count = |chunk: &[glam::Vec3]| {
        positions += chunk.len();
        Ok(())
    };
    let streamed = stream_positions(&path, Some(format), &mut count);
    if let Ok(Some(n)) = streamed {
        assert_eq!(n, positions, "the streamed count disagrees with the chunks");
    }
    let spooled = SpooledParticles::from_file(
        &path,
        format,
        &AttributeSelection::All,
        Some(scratch_dir()),
        &CancelToken::new(),
    );
    if let Ok(Some(source)) = spooled {
        let width: usize = source.attribute_layout().iter().map(|a| a.components).sum();
        let mut seen = 0usize;
        let drained = source.visit_chunks(&mut |chunk| {
            assert_eq!(chunk.first, seen);
            assert_eq!(chunk.payload.len(), chunk.positions.len() * width);
            seen += chunk.positions.len();
            Ok(())
        });
        if drained.is_ok() {
            assert_eq!(seen, source.particle_count());
        }
    }
}

/// `.xyz`: the whole-file reader and the memory-mapped source, drained.
pub fn run_xyz(data: &[u8]) {
    run("input.xyz", ParticleFormat::Xyz, data);
    let path = scratch_dir().join("input.xyz");
    if let Ok(source) = meniscus::io::particles::MappedXyz::open(&path) {
        let mut seen = 0usize;
        let drained = source.visit_chunks(&mut |chunk| {
            assert_eq!(chunk.first, seen);
            seen += chunk.positions.len();
            Ok(())
        });
        if drained.is_ok() {
            assert_eq!(seen, source.particle_count());
        }
    }
}
