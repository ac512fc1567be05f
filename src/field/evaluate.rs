//! The block loop shared by both kernels of the field: every candidate block evaluated in
//! parallel into one contiguous array, the blocks no particle reaches dropped, and the
//! run-time choice between the portable and the AVX2 copy of a kernel's block code.
//!
//! A kernel ([`super::isotropic`], [`super::anisotropic`]) implements [`BlockEvaluator`]:
//! its block code, written once with `#[inline(always)]`, is compiled twice here — as is,
//! and inside a function with AVX2 and FMA enabled, picked at run time on x86-64 CPUs that
//! have them (one row of eight vertices is then one vector instruction instead of two).
//! The products that are fused are written as `mul_add` (one rounding, in hardware or in
//! libm) and Rust never contracts any other `a * b + c`, so both copies round identically
//! and give bit-identical fields (each kernel's tests compare them).

use super::{FieldOptions, FieldStats};
use crate::grid::{zeroed_blocks, BlockKey, BlockValues, SparseField, BLOCK_EDGE, BLOCK_VOLUME};
use rayon::prelude::*;

/// Row length: one block row of vertices along x.
pub(super) const ROW: usize = BLOCK_EDGE as usize;
/// Rows of vertices in a block.
pub(super) const ROWS: usize = BLOCK_VOLUME / ROW;

/// One kernel's evaluation of a block.
pub(super) trait BlockEvaluator: Sync {
    /// Per-thread scratch.
    type Scratch: Send;
    /// Fresh scratch for one thread.
    fn scratch(&self) -> Self::Scratch;
    /// Accumulates and finalises the block `key` into `values`; the number of its
    /// vertices in the band, or `None` when no particle reaches it. Must be
    /// `#[inline(always)]`, so that the AVX2 copy compiles it with AVX2.
    fn evaluate_block(
        &self,
        key: BlockKey,
        scratch: &mut Self::Scratch,
        values: &mut BlockValues,
    ) -> Option<usize>;
}

/// Evaluates every candidate block into one contiguous array with `evaluator` (`simd`:
/// the AVX2 copy may be used), then compacts away the candidates no particle reaches:
/// the field and its figures (`particles` entered the field).
pub(super) fn evaluate_blocks<E: BlockEvaluator>(
    evaluator: &E,
    candidates: &[BlockKey],
    particles: usize,
    options: &FieldOptions,
    simd: bool,
) -> (SparseField, FieldStats) {
    let mut values: Vec<BlockValues> = zeroed_blocks(candidates.len());
    let in_band: Vec<Option<usize>> = candidates
        .par_iter()
        .zip(values.par_iter_mut())
        .map_init(
            || evaluator.scratch(),
            |scratch, (&key, out)| evaluate(evaluator, key, scratch, out, simd),
        )
        .collect();
    let mut stats = FieldStats {
        particles,
        ..FieldStats::default()
    };
    let mut kept = 0;
    let mut keys = Vec::with_capacity(candidates.len());
    for (slot, (key, n)) in candidates.iter().zip(&in_band).enumerate() {
        if let Some(n) = n {
            stats.vertices_in_band += n;
            if slot != kept {
                // A move, not a swap: the block left behind is dropped.
                values.copy_within(slot..=slot, kept);
            }
            keys.push(*key);
            kept += 1;
        }
    }
    values.truncate(kept);
    values.shrink_to_fit();
    stats.blocks = kept;
    let field = SparseField::from_parts(
        options.cell_size_world(),
        options.outside_value(),
        &keys,
        values,
    );
    stats.block_bytes = field.memory_bytes();
    (field, stats)
}

/// One block, with the AVX2 copy of the kernel when `simd` and the CPU has it.
#[inline]
fn evaluate<E: BlockEvaluator>(
    evaluator: &E,
    key: BlockKey,
    scratch: &mut E::Scratch,
    values: &mut BlockValues,
    simd: bool,
) -> Option<usize> {
    #[cfg(target_arch = "x86_64")]
    if simd
        && std::arch::is_x86_feature_detected!("avx2")
        && std::arch::is_x86_feature_detected!("fma")
    {
        // SAFETY: the CPU supports the features the function is compiled for.
        return unsafe { evaluate_avx2(evaluator, key, scratch, values) };
    }
    let _ = simd;
    evaluator.evaluate_block(key, scratch, values)
}

/// The kernel's block code compiled with AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn evaluate_avx2<E: BlockEvaluator>(
    evaluator: &E,
    key: BlockKey,
    scratch: &mut E::Scratch,
    values: &mut BlockValues,
) -> Option<usize> {
    evaluator.evaluate_block(key, scratch, values)
}
