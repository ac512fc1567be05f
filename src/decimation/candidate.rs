//! The record of an edge collapse candidate, declared before the code that produces it
//! (`state`: the candidates of a pass; `placement`: their costs) and the code that
//! consumes it (`collapse`: the attempt; the walks in `mod.rs`), as meshoptimizer
//! declares its `Collapse`: none of them imports another for it.

/// An edge collapse candidate of one pass, with the cost computed when it was costed:
/// still valid when it is taken, since a collapse is taken only while neither end has
/// moved in the pass. Where the merged vertex goes is computed again when the collapse
/// is tried (the same function of the same state, so the same point): 24 bytes instead
/// of 48 for every candidate of every pass, against one placement per attempt.
#[derive(Clone, Copy)]
pub(super) struct Candidate {
    /// Squared RMS distance of the collapse, `Q(p) / area` (unit-box units).
    pub(super) cost: f64,
    pub(super) u: u32,
    pub(super) v: u32,
    /// The triangle whose side `u → v` the candidate came from (the next pass finds the
    /// candidate again by it, to reuse its cost).
    pub(super) triangle: u32,
    /// [`Mark::NONE`], [`Mark::DECIDED`] by the parallel walk in this pass, or the clock
    /// of the state when the collapse was last refused.
    pub(super) mark: u32,
}

/// Values of [`Candidate::mark`] besides a refusal's clock.
pub(super) struct Mark;

impl Mark {
    /// Never refused (clocks start at 1).
    pub(super) const NONE: u32 = 0;
    /// Decided by the parallel walk of this pass.
    pub(super) const DECIDED: u32 = u32::MAX;
}

impl Candidate {
    /// The edge `u → v` of `triangle`, not costed yet.
    pub(super) fn edge(triangle: u32, u: u32, v: u32) -> Candidate {
        Candidate {
            cost: 0.0,
            u,
            v,
            triangle,
            mark: Mark::NONE,
        }
    }

    /// The candidate as the next pass takes it over (its cost, placement and refusal
    /// kept; a decision of this pass's parallel walk forgotten).
    pub(super) fn carried(&self) -> Candidate {
        let mark = if self.mark == Mark::DECIDED {
            Mark::NONE
        } else {
            self.mark
        };
        Candidate { mark, ..*self }
    }
}
