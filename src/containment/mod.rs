//! Containment: every non-isolated particle centre at least a given depth under the
//! surface, whatever decimation and Loop subdivision did to it.
//!
//! **Why.** The raw marching-cubes surface of the field (with its particle-coverage
//! balls) leaves no centre outside. Decimation and Loop both move the surface inwards
//! where it is strongly curved: decimation collapses thin sheets, filament tips and
//! coverage balls past their centres, and Loop pulls the coarse convex parts of the
//! decimated mesh further in (a vertex of valence 6 moves 3/8 of the way to the mean of
//! its neighbours). On a violent splash a few centres per hundred thousand end up outside
//! or just under the surface; on calm frames none do.
//!
//! **What.** After decimation and before subdivision, the surface *as one Loop step
//! will make it* (whether the pipeline subdivides or the `.mseq` decoder does) is
//! measured against every non-isolated centre near it. A centre less than
//! [`ContainmentOptions::min_depth`] under it (or outside it) pushes the control triangle
//! under its nearest surface point outwards along the surface normal there, by what is
//! missing (1.4 times that when Loop will average the push out over the neighbours).
//! Pushes are combined per control vertex by taking the largest, and halved around any
//! control triangle they would turn by more than about 75°, so they never fold the
//! surface. The watched centres (those within r of being too shallow) whose nearest
//! surface lay where the pushes reach are measured again, against the one-step surface
//! recomputed around them, for at most [`ContainmentOptions::max_rounds`] rounds. A
//! push of more than r may bring a centre nobody watched too close: then every centre
//! within `depth + r` of the surface the pushes moved is measured again too (on a 4M
//! violent splash, 128k centres instead of 4M in the second round, and a few dozen in
//! the later ones; measuring them all again took 2.4 s a round). Only control vertices move: the
//! topology does not change, so a closed 2-manifold stays one, and subdivision then runs
//! on the moved control mesh as always. With two or more steps the surface is measured
//! after the first (the later ones move it far less: the edges halve each step).
//!
//! **Measure.** The one-step surface is never built as a mesh: its points (Loop's vertex
//! point of every control vertex, the edge points of every control triangle's sides) are
//! computed from the control mesh, and its triangles are the four children of each
//! control triangle. When nothing subdivides (the steady surface) the surface is the
//! control mesh itself: a triangle is cut at its edge midpoints only where a side is
//! long enough that a centre near it could be far from all its corners, the others are
//! measured whole, their corners their only points (on the steady surface's fine mesh
//! that is a seventh of the points and a quarter of the triangles: containment took
//! 40 ms instead of 85 on dam break frame 25 and 19 s instead of 32 on the 4M splash,
//! the output the same to 1e-5 r). It is not even computed for the whole mesh at once:
//! the centres are
//! measured in slabs across the scene, each against the one-step surface of the control
//! triangles it can reach (`slabs`; [`ContainmentOptions::chunk_triangles`] per slab),
//! so the stage's memory beyond the control mesh follows the slab and stays far under
//! the subdivision's peak. A centre's nearest points are looked up in a cell hash of
//! them (cells of `2r`, the 2 × 2 × 2 cells nearest the centre: every point within r of
//! it); a centre with none there is deep inside or isolated. A centre
//! deep under the tangent plane of its nearest point (normal from the control mesh),
//! deeper than the depth plus `0.15 r` plus `l²/2r` for a point `l` aside (what a surface
//! curved to a radius of r or more can lose against its tangent plane), is taken at that
//! depth. Otherwise its nearest point is measured exactly on the children of the control
//! triangles around the control triangle of its nearest point, and its side is that of
//! the angle-weighted pseudo-normal of the nearest feature (face, edge or vertex;
//! Bærentzen and Aanæs 2005).
//!
//! **Order.** Every centre is measured on its own and the pushes are combined per vertex
//! by taking the largest (ties: the lowest particle index), so the result depends neither
//! on the thread count nor on the order in which the particles are visited (tiles, spill
//! cells).
//!
//! **Cost**: on the first round one cell look-up per particle, and about a microsecond
//! for each of the quarter of them near the surface; figures in
//! `docs/performance-log.md`.

mod centres;
mod measure;
mod rounds;
mod slabs;
mod surface;

use crate::cancel::CancelToken;
use crate::error::Result;
use crate::mesh::TriMesh;
use glam::Vec3;
pub(crate) use rounds::contain_centres;

/// Options of [`contain`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[non_exhaustive]
pub struct ContainmentOptions {
    /// Least depth of a particle centre under the output surface, multiples of the particle
    /// radius r. Default 0.25.
    pub min_depth: f32,
    /// Rounds of measuring and pushing at most. Default 4.
    pub max_rounds: u32,
    /// Control triangles measured at once, about: the surface is measured in slabs of
    /// that many, so that the stage's memory follows the slab rather than the whole
    /// surface. `None`: from the memory budget (an eighth of it per slab, see
    /// [`Self::slab_triangles`]), slabs of [`UNBUDGETED_SLAB_TRIANGLES`] without a budget.
    /// The output does not depend on it. Default `None`.
    #[serde(default)]
    pub chunk_triangles: Option<usize>,
}

/// Peak working set of the containment stage, bytes per decimated (control) triangle,
/// everything after the tiles included: the control mesh, its vertex → triangle lists
/// and normals, the slab tables, one slab's one-step Loop surface and cell hash, the
/// centres watched. Measured on the 32M scene under a 2 GiB budget: 1315 MiB at the stage
/// (17.2 M control triangles, 17 slabs), 70 bytes per triangle over the process and the
/// tiles' leftovers; 80 kept as margin. (Before the slabs, 2026-11-26: 2685 MiB, 154 B.)
/// Below the subdivision's, so the stage never sets a run's estimate.
pub(crate) const BYTES_PER_INPUT_TRIANGLE: f64 = 80.0;

/// Control triangles per slab without a memory budget: 2²², about 400 MB of slab (96 B
/// per control triangle of it). The default surface of a 4M-particle splash (3.5 M
/// control triangles) is measured whole; the steady surface's fine mesh of the same
/// scene (32 M triangles, not decimated) in eight slabs, where measuring it whole
/// peaked at 4.3 GiB.
pub const UNBUDGETED_SLAB_TRIANGLES: usize = 1 << 22;

/// Working set of a slab, bytes per control triangle in it: its triangle and vertex
/// lists, the one-step surface's points (3.5 per triangle), their cell hash and what
/// building it takes.
const SLAB_BYTES_PER_TRIANGLE: u64 = 96;

impl ContainmentOptions {
    /// Every centre at least `min_depth` (multiples of `r`) deep, the other options
    /// default.
    pub fn depth(min_depth: f32) -> Self {
        ContainmentOptions {
            min_depth,
            ..Default::default()
        }
    }

    /// Checks the depth: in `[0, 1]`, multiples of `r`.
    pub fn validate(&self) -> crate::Result<()> {
        let d = self.min_depth;
        if !(d.is_finite() && (0.0..=1.0).contains(&d)) {
            return Err(crate::Error::InvalidOption {
                option: "containment.min_depth",
                message: format!("takes a depth in [0, 1] (multiples of r), got {d}"),
            });
        }
        Ok(())
    }

    /// Control triangles per slab under a memory budget of `budget` bytes (`None`: no
    /// limit): [`Self::chunk_triangles`] when given, else as many as an eighth of the
    /// budget holds, at least 2¹⁸; [`UNBUDGETED_SLAB_TRIANGLES`] without a budget.
    pub fn slab_triangles(&self, budget: Option<u64>) -> usize {
        match (self.chunk_triangles, budget) {
            (Some(n), _) => n.max(1),
            (None, Some(b)) => ((b / 8 / SLAB_BYTES_PER_TRIANGLE) as usize).max(1 << 18),
            (None, None) => UNBUDGETED_SLAB_TRIANGLES,
        }
    }
}

impl Default for ContainmentOptions {
    fn default() -> Self {
        ContainmentOptions {
            min_depth: 0.25,
            max_rounds: 4,
            chunk_triangles: None,
        }
    }
}

/// What [`contain`] did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct ContainmentStats {
    /// Centres with a surface vertex within r or so (see the module docs), measured in
    /// the first round.
    pub near_centres: usize,
    /// Centres less than the depth under the surface in the first round (outside included).
    pub too_shallow: usize,
    /// Of those, centres outside the surface.
    pub outside: usize,
    /// Control vertices moved, summed over the rounds.
    pub moved_vertices: usize,
    /// Rounds of measuring (1 when nothing had to move).
    pub rounds: u32,
    /// Centres measured again after the first round, summed over the rounds (a full
    /// round counts every centre it visits).
    pub remeasured: usize,
    /// Centres still less than the depth under the surface after the last round (the
    /// folded ones not included).
    pub remaining: usize,
    /// Centres measured outside by more than the surface can have moved off them (see
    /// `farthest_outside` of the pipeline's input), or, where that bound holds, measured
    /// outside again, no closer, after a push: their side was read through a fold of the
    /// surface (they are inside it), and a push would raise a spike over them. Not
    /// pushed. Always 0 on a decimated surface (no bound).
    pub folded: usize,
    /// Seconds spent computing the one-step surface it measures (points and cells).
    pub surface_seconds: f64,
    /// Slabs the surface was measured in, in the first round (see
    /// [`ContainmentOptions::chunk_triangles`]).
    pub slabs: u32,
}

/// What [`Centres::visit_between`] calls on each chunk: positions and their particle
/// indices.
pub(crate) type VisitChunk<'a> = dyn FnMut(&[Vec3], &[u32]) -> Result<()> + 'a;

/// Where the centres come from: visited in chunks of positions with their particle
/// indices (any order, any chunking).
pub(crate) trait Centres {
    /// Calls `visit` on chunks that hold every centre whose coordinate `axis` lies from
    /// `lo` to `hi`, and maybe others.
    fn visit_between(
        &self,
        axis: usize,
        lo: f32,
        hi: f32,
        visit: &mut VisitChunk<'_>,
    ) -> Result<()>;
}

impl Centres for [Vec3] {
    fn visit_between(&self, _: usize, _: f32, _: f32, visit: &mut VisitChunk<'_>) -> Result<()> {
        let indices: Vec<u32> = (0..self.len() as u32).collect();
        visit(self, &indices)
    }
}

/// Moves the vertices of `control` (a closed surface, world units) so that every centre
/// of `centres` that lies near it ends at least `options.min_depth · particle_radius`
/// under the surface `control` becomes after `levels` Loop subdivision steps (measured
/// after one step; see the module docs); returns what was done.
pub fn contain(
    control: &mut TriMesh,
    levels: u32,
    centres: &[Vec3],
    particle_radius: f32,
    options: &ContainmentOptions,
) -> ContainmentStats {
    let input = ContainmentInput {
        sizes: None,
        farthest_outside: None,
        levels,
        centres,
        isolated: &[],
        particle_radius,
        slab_triangles: options.slab_triangles(None),
    };
    contain_centres(control, &input, options, &CancelToken::new())
        .expect("centres in memory cannot fail")
}

/// What [`contain_centres`] measures the surface against.
pub(crate) struct ContainmentInput<'a, C: Centres + ?Sized> {
    /// Loop steps the surface will get (here or by whoever decodes it): the surface is
    /// measured as one step makes it.
    pub levels: u32,
    /// The particle centres.
    pub centres: &'a C,
    /// Centres skipped: the isolated particles, which have spheres of their own.
    pub isolated: &'a [Vec3],
    /// How far outside the surface a centre can really be, world units, when the
    /// surface is one that enclosed every centre moved off them by at most that much
    /// (the marching-cubes surface, whose coverage balls enclose every centre, after
    /// smoothing: its inward bound, or its largest vertex move without one): a centre
    /// measured farther outside was read through a fold. `None`: no such bound
    /// (decimation moved the surface).
    pub farthest_outside: Option<f32>,
    /// Particle radius `r`, world units.
    pub particle_radius: f32,
    /// The particles' own radii by input index, when they have several sizes: each
    /// centre's depth is `min_depth` times its own radius.
    pub sizes: Option<crate::field::Sizes<'a>>,
    /// Control triangles per slab, about ([`ContainmentOptions::slab_triangles`]).
    pub slab_triangles: usize,
}
