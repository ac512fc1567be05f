//! Raw `.xyz`: no header, `N` records of three little-endian f32 (12 bytes each). Read
//! through [`MappedXyz`], a window at a time; never streamed or spooled (it is mapped as
//! it is).

use super::{MappedXyz, ParticleCodec, ParticleSource, Particles, StreamSink};
use crate::error::Result;
use crate::io::atomic::write_atomically;
use std::io::Write;
use std::path::Path;

/// The `.xyz` format.
pub(super) struct Xyz;

impl ParticleCodec for Xyz {
    fn read(&self, path: &Path) -> Result<Particles> {
        let file = MappedXyz::open(path)?;
        let mut positions = Vec::with_capacity(file.particle_count());
        file.visit_chunks(&mut |chunk| {
            positions.extend_from_slice(chunk.positions);
            Ok(())
        })?;
        Ok(Particles {
            positions,
            attributes: Vec::new(),
        })
    }

    /// `Ok(None)`: [`MappedXyz`] maps the file as it is.
    fn stream(&self, _path: &Path, _sink: &mut dyn StreamSink) -> Result<Option<usize>> {
        Ok(None)
    }

    fn write(&self, path: &Path, particles: &Particles) -> Result<()> {
        write_atomically(path, |w| {
            for p in &particles.positions {
                for v in p.to_array() {
                    w.write_all(&v.to_le_bytes())?;
                }
            }
            Ok(())
        })
        .map(|_| ())
    }
}
