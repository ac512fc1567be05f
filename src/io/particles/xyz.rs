//! Raw `.xyz`: no header, `N` records of three little-endian f32 (12 bytes each).

use super::ParticleSource;
use super::Particles;
use crate::error::Result;
use crate::io::atomic::write_atomically;
use std::io::Write;
use std::path::Path;

pub(super) fn read(path: &Path) -> Result<Particles> {
    let file = super::MappedXyz::open(path)?;
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

pub(super) fn write(path: &Path, particles: &Particles) -> Result<()> {
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
