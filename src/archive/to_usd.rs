//! Frames of an archive as USD stages ([`ArchiveReader::extract_stage`]).

use super::ArchiveReader;
use crate::error::{Error, Result};
use crate::io::usd::{write_stage, UsdOptions, UsdStageWriter};
use std::path::{Path, PathBuf};

impl ArchiveReader {
    /// Writes the frames `numbers` (every frame when `None`) as USD (`.usdc`, `.usda`,
    /// `.usd`): into one stage at `output`, each frame at its number's time code, decoded
    /// one at a time (memory of one frame, whatever the count); or, with a `{}` in
    /// `output`, a stage per frame, its `{}` replaced by the frame number, in parallel.
    /// Missing directories are made; every stage is written atomically, complete or
    /// absent (an error or `cancel` leaves no partial stage, and one stage's frames are
    /// all there or none). Returns the stages written, in frame order.
    pub fn extract_stage(
        &self,
        numbers: Option<&[i64]>,
        output: &str,
        options: &UsdOptions,
        cancel: &crate::CancelToken,
    ) -> Result<Vec<PathBuf>> {
        let input = self.path.display().to_string();
        crate::error::guard(
            move || input,
            || self.extract_stage_unguarded(numbers, output, options, cancel),
        )
    }

    fn extract_stage_unguarded(
        &self,
        numbers: Option<&[i64]>,
        output: &str,
        options: &UsdOptions,
        cancel: &crate::CancelToken,
    ) -> Result<Vec<PathBuf>> {
        use rayon::prelude::*;
        options.validate()?;
        let all: Vec<i64> = self.frames.iter().map(|f| f.number).collect();
        let numbers = numbers.unwrap_or(&all);
        crate::io::usd::check_time_codes(Path::new(output), numbers)?;
        let per_frame = crate::sequence::is_pattern(output);
        let paths: Vec<PathBuf> = match per_frame {
            true => numbers
                .iter()
                .map(|n| crate::sequence::substitute(output, &n.to_string()))
                .collect(),
            false => vec![PathBuf::from(output)],
        };
        for dir in paths.iter().filter_map(|p| p.parent()) {
            if !dir.as_os_str().is_empty() {
                std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
            }
        }
        crate::io::tempfiles::remove_output_leftovers(paths.iter().map(PathBuf::as_path));
        if per_frame {
            numbers
                .par_iter()
                .zip(&paths)
                .try_for_each(|(&n, path)| -> Result<()> {
                    cancel.check()?;
                    write_stage(path, n, &self.read_surface(n)?, options).map(|_| ())
                })?;
            return Ok(paths);
        }
        let mut stage = UsdStageWriter::create(&paths[0], options)?;
        for &n in numbers {
            cancel.check()?;
            stage.append_frame(n, &self.read_surface(n)?)?;
        }
        stage.finish()?;
        Ok(paths)
    }
}
