//! Raw `.xyz`: no header, `N` records of three little-endian f32 (12 bytes each).

use super::Particles;
use crate::error::{Error, Result};
use crate::io::atomic::write_atomically;
use glam::Vec3;
use std::io::Write;
use std::path::Path;

pub(super) fn read(path: &Path) -> Result<Particles> {
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
    if len == 0 {
        return Err(Error::EmptyInput {
            path: path.to_path_buf(),
        });
    }
    if len % 12 != 0 {
        return Err(Error::parse(
            path,
            format!("byte offset {}", len - len % 12),
            format!(
                "file size {len} is not a multiple of 12 (x, y, z as f32): truncated or not .xyz"
            ),
        ));
    }
    // SAFETY: the map is read-only and dropped before returning; a concurrent truncation
    // of the file by another process is outside what any reader can defend against.
    let map = unsafe { memmap2::Mmap::map(&file) }.map_err(|e| Error::io(path, e))?;
    let positions = map
        .chunks_exact(12)
        .map(|c| {
            let f = |k: usize| f32::from_le_bytes([c[k], c[k + 1], c[k + 2], c[k + 3]]);
            Vec3::new(f(0), f(4), f(8))
        })
        .collect();
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
