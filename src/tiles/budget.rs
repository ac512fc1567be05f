//! The memory model of a tiled run: how much a run needs at each phase, and the tile size
//! that fits a budget (`choose_tile_blocks`). The particles cost per particle; the field
//! and the surface cost per block the particles populate and per triangle to come, which
//! the counting pass estimates from the populated blocks on the surface of the fluid
//! ([`SceneShape`]): a splash has far more surface per particle than a resting tank.
//! Calibrated on copies of `dambreak_small` frame 25 (1M to 32M particles,
//! `benches/scale.sh`) and on the same frame thrown into a splash (`tile_scene … splash`):
//! within about 10 % there, above the measured peaks.

use crate::error::{Error, Result};
use crate::grid::{BlockKey, BLOCK_EDGE};
use hashbrown::HashMap;

/// Peak memory of an untiled run (field and marching cubes over the whole frame), bytes
/// per particle: positions, the sorted copy, neighbour lists and indices. With
/// [`FIELD_BYTES_PER_POPULATED_BLOCK`] and [`SURFACE_BYTES_PER_TRIANGLE`] this put the 4M
/// scene at 884 MiB (measured 833) and its splash at 1097 MiB (measured 1054).
pub(crate) const UNTILED_BYTES_PER_PARTICLE: u64 = 56;
/// Field blocks of an untiled run, bytes per populated block: 1.6 blocks of 2 KiB in the
/// narrow band per populated block (1.59 in the 4M scene, 1.58 in its splash).
pub(crate) const FIELD_BYTES_PER_POPULATED_BLOCK: u64 = 3400;
/// Block surfaces and the stitched mesh of an untiled run, bytes per marching-cubes
/// triangle (23 measured on the 4M scene, 26 on its splash).
pub(crate) const SURFACE_BYTES_PER_TRIANGLE: f64 = 25.0;
/// Peak memory of one tile beyond its kernels, bytes per particle it loads (own and
/// ghost): particles, neighbour grid, field blocks, block surfaces and the tile's
/// decimation state, in a scene with [`PARTICLES_PER_SURFACE_BLOCK`]; scaled up where a
/// scene has more surface per particle (its splash: 1.4 × as much surface). Across tiles
/// of 256 to 1024 cells the measured tile peaks grow by 238 B per particle of the densest
/// tile in the 4M scene and by 273 B in its splash, kernels included, over what the
/// earlier tiles produced (2 threads, `--stats`); with the kernels' bytes this puts
/// the tiles 1.5 × above those slopes.
pub(crate) const TILE_BYTES_PER_PARTICLE: u64 = 150;
/// Particles per surface block of the scene [`TILE_BYTES_PER_PARTICLE`] was measured on
/// (50.2 in the 4M scene, 35.6 in its splash).
pub(crate) const PARTICLES_PER_SURFACE_BLOCK: f64 = 50.0;
/// Marching-cubes triangles per populated block on the fluid's surface (one with an
/// unpopulated block among its 26 neighbours): 134 in the 4M scene, 129 in its splash.
pub(crate) const MC_TRIANGLES_PER_SURFACE_BLOCK: f64 = 140.0;
/// Memory of the process before any particle (code, thread stacks, allocator), bytes.
pub(crate) const BASE_BYTES: u64 = 64 << 20;
/// What the tiles leave in memory under the post-processing, beyond the surface (mostly
/// the allocator's free heap, which glibc's trim threshold bounds, and the isolated
/// centres), bytes per particle up to [`POST_TILES_MAX_BYTES`]: 62–94 MiB measured after
/// the 4M scene's tiles.
pub(crate) const POST_TILES_BYTES_PER_PARTICLE: u64 = 24;
/// The most the tiles leave (see [`POST_TILES_BYTES_PER_PARTICLE`]), bytes.
pub(crate) const POST_TILES_MAX_BYTES: u64 = 96 << 20;
/// Bytes per particle of a tile's particles loaded with a payload of `w` floats for the
/// attribute stage, on top of `4·w` (records and rows read back, positions and indices,
/// home half-blocks, the sort order, the sorted copy).
pub(crate) const ATTRIBUTE_TILE_BYTES_PER_PARTICLE: u64 = 76;

/// What the counting pass knows of a frame's surface before any field value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct SceneShape {
    /// Particles in the frame.
    pub particles: u64,
    /// Blocks holding at least one particle.
    pub populated_blocks: u64,
    /// Populated blocks with an unpopulated block among their 26 neighbours.
    pub surface_blocks: u64,
}

impl SceneShape {
    /// The shape of the particles counted per home block.
    pub(crate) fn of(block_counts: &HashMap<BlockKey, u64>) -> SceneShape {
        let surface_blocks = block_counts
            .keys()
            .filter(|b| {
                (-1..=1).any(|dz| {
                    (-1..=1).any(|dy| {
                        (-1..=1).any(|dx| {
                            !block_counts.contains_key(&[b[0] + dx, b[1] + dy, b[2] + dz])
                        })
                    })
                })
            })
            .count() as u64;
        SceneShape {
            particles: block_counts.values().sum(),
            populated_blocks: block_counts.len() as u64,
            surface_blocks,
        }
    }

    /// Marching-cubes triangles to expect.
    pub(crate) fn marching_cubes_triangles(&self) -> f64 {
        self.surface_blocks as f64 * MC_TRIANGLES_PER_SURFACE_BLOCK
    }

    /// Peak memory of field and marching cubes over the whole frame at once, bytes.
    fn untiled_bytes(&self) -> u64 {
        BASE_BYTES
            + self.particles * UNTILED_BYTES_PER_PARTICLE
            + self.populated_blocks * FIELD_BYTES_PER_POPULATED_BLOCK
            + (self.marching_cubes_triangles() * SURFACE_BYTES_PER_TRIANGLE) as u64
    }
}

/// Memory the surface needs after the tiles (the post-processing's peak), per
/// marching-cubes triangle, and the stage whose peak it is (the pipeline adds up its
/// stages' own figures: [`crate::pipeline::ReconstructOptions`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct OutputCost {
    /// Bytes per marching-cubes triangle.
    pub(crate) bytes_per_triangle: f64,
    /// What would lower the peak, as the message advises it ("fewer subdivision steps").
    pub(crate) advice: &'static str,
}

impl OutputCost {
    /// No memory after the tiles (for tests of the tiles alone).
    #[cfg(test)]
    pub(crate) const NONE: OutputCost = OutputCost {
        bytes_per_triangle: 0.0,
        advice: "",
    };
}

/// What a run will hold, from the particles counted per home block: the estimates of
/// the module docs for an untiled run, one tile, and a tiled run.
struct Model<'a> {
    block_counts: &'a HashMap<BlockKey, u64>,
    /// Lowest block any tile processes.
    origin: BlockKey,
    /// Blocks a particle reaches.
    reach: i32,
    shape: SceneShape,
    /// After the tiles: the process and the post-processing's peak, bytes.
    output: u64,
    /// During the tiles: the process and what the tiles have produced so far (decimated
    /// pieces, or the raw block surfaces), bytes.
    produced: u64,
    /// Payload bytes per particle (4 per float).
    payload: u64,
    /// Bytes per particle the kernels add.
    kernel_bytes_per_particle: u64,
    /// The field blocks that particles larger than the reference radius reach (or their
    /// count): [`LARGE_SUPPORT_BYTES_PER_BLOCK`] each, all of them in the untiled run,
    /// those of the fullest tile in a tiled one.
    large: &'a std::result::Result<Vec<BlockKey>, u64>,
}

impl Model<'_> {
    /// Peak of an untiled run. A payload costs the particles kept in memory to the
    /// attribute stage (12 bytes of position and 4 per float, and one sorted copy).
    fn untiled(&self) -> u64 {
        let particles = self.shape.particles;
        let kept = if self.payload > 0 {
            12 + 2 * self.payload
        } else {
            0
        };
        (self.shape.untiled_bytes()
            + self.large_bytes(None)
            + particles * self.kernel_bytes_per_particle)
            .max(self.output)
            + particles * kept
    }

    /// Exact particle count of the fullest zone 2 of tiles of `t` blocks: every populated
    /// block adds its count to each tile whose zone 2 holds it. Zone 2 of a tile reaches
    /// 2·reach + 1 blocks below its own blocks and 2·reach + 2 above (see the module
    /// docs).
    fn densest_zone(&self, t: i32) -> u64 {
        let (below, above) = (2 * self.reach + 1, 2 * self.reach + 2);
        let origin = self.origin;
        let mut zone: HashMap<BlockKey, u64> = HashMap::new();
        for (b, n) in self.block_counts {
            let lo = [0, 1, 2].map(|a| (b[a] - origin[a] - above).div_euclid(t));
            let hi = [0, 1, 2].map(|a| (b[a] - origin[a] + below).div_euclid(t));
            for tz in lo[2]..=hi[2] {
                for ty in lo[1]..=hi[1] {
                    for tx in lo[0]..=hi[0] {
                        *zone.entry([tx, ty, tz]).or_default() += n;
                    }
                }
            }
        }
        zone.values().copied().max().unwrap_or(0)
    }

    /// Peak of the densest tile of `t` blocks, scaled up where the scene has more surface
    /// per particle than the one [`TILE_BYTES_PER_PARTICLE`] was measured on.
    fn tile(&self, t: i32) -> u64 {
        let surface_factor = (self.shape.surface_blocks as f64 * PARTICLES_PER_SURFACE_BLOCK
            / self.shape.particles.max(1) as f64)
            .max(1.0);
        let per_particle = (TILE_BYTES_PER_PARTICLE as f64 * surface_factor) as u64
            + self.kernel_bytes_per_particle;
        self.densest_zone(t) * per_particle + self.large_bytes(Some(t))
    }

    /// Bytes of the large particles' blocks: all of them (`None`), or those of the tile
    /// of `t` blocks that holds the most (with the tiles' field ring of one block).
    fn large_bytes(&self, t: Option<i32>) -> u64 {
        let blocks = match (self.large, t) {
            (Err(count), _) => *count,
            (Ok(blocks), None) => blocks.len() as u64,
            (Ok(blocks), Some(t)) => {
                let mut per_tile: HashMap<BlockKey, u64> = HashMap::new();
                for b in blocks {
                    let lo = [0, 1, 2].map(|a| (b[a] - self.origin[a] - 1).div_euclid(t));
                    let hi = [0, 1, 2].map(|a| (b[a] - self.origin[a] + 1).div_euclid(t));
                    for tz in lo[2]..=hi[2] {
                        for ty in lo[1]..=hi[1] {
                            for tx in lo[0]..=hi[0] {
                                *per_tile.entry([tx, ty, tz]).or_default() += 1;
                            }
                        }
                    }
                }
                per_tile.values().copied().max().unwrap_or(0)
            }
        };
        blocks * LARGE_SUPPORT_BYTES_PER_BLOCK
    }

    /// Peak of a tiled run: the tiles over what they produced, or the surface after them
    /// with the attribute stage's tile (the densest tile's particles loaded with their
    /// payload).
    fn tiled(&self, t: i32) -> u64 {
        let attribute_tile = if self.payload > 0 {
            self.densest_zone(t) * (ATTRIBUTE_TILE_BYTES_PER_PARTICLE + 2 * self.payload)
        } else {
            0
        };
        (self.tile(t) + self.produced).max(self.output + attribute_tile)
    }
}

/// MiB, rounded up.
fn mib(bytes: u64) -> u64 {
    bytes.div_ceil(1 << 20)
}

/// How the memory budget cuts a frame.
pub(super) struct BudgetInput<'a> {
    /// Particles per home block.
    pub block_counts: &'a HashMap<BlockKey, u64>,
    /// Lowest block any tile processes.
    pub origin: BlockKey,
    /// Blocks a particle reaches.
    pub reach: i32,
    /// The post-processing's memory per marching-cubes triangle.
    pub output_cost: OutputCost,
    /// Floats of payload per particle.
    pub payload_width: usize,
    /// Bytes per particle the kernels add.
    pub kernel_bytes_per_particle: u64,
    /// Whether the tiles decimate their pieces (else the raw surface accumulates).
    pub decimated_in_tiles: bool,
    /// Whether the particles carry their own radii: a column of 4 bytes per particle held
    /// for the whole run, and 8 more per particle of a tile (its ratios, and those of the
    /// field's particles).
    pub radius_column: bool,
    /// The field blocks that particles larger than the reference radius reach
    /// ([`large_support_blocks`]), or their count when it passed the cap.
    pub large_support_blocks: std::result::Result<Vec<BlockKey>, u64>,
}

/// Bytes per field block that a large particle's support adds: the block's values
/// (2 KiB) and its share of the candidate lists and surfaces. A lone particle 40 × r
/// (support 41³ = 68 921 blocks, 6 cells of h = r per block reach) peaked at 177 MiB,
/// 2.7 KB per block of its support.
pub(crate) const LARGE_SUPPORT_BYTES_PER_BLOCK: u64 = 2700;

/// The blocks within reach of the home blocks of `large` (home block → how many blocks
/// its largest particle reaches, more than a particle of the reference radius does): the
/// union of the cubes of `2k + 1` blocks about each. Counted by separable dilation (per
/// reach, along x, then y, then z), so a cluster of large particles costs their union,
/// not the sum of their cubes. `Err(cap + 1)` once the count passes `cap` (the budget
/// refuses it then, and the blocks are not listed).
pub(crate) fn large_support_blocks(
    large: &HashMap<BlockKey, i32>,
    cap: u64,
) -> std::result::Result<Vec<BlockKey>, u64> {
    use hashbrown::HashSet;
    let over = cap.saturating_add(1);
    let mut reaches: Vec<i32> = large.values().copied().collect();
    reaches.sort_unstable();
    reaches.dedup();
    let mut union: HashSet<BlockKey> = HashSet::new();
    for k in reaches {
        let mut set: HashSet<BlockKey> = large
            .iter()
            .filter(|(_, &r)| r == k)
            .map(|(b, _)| *b)
            .collect();
        for axis in 0..3 {
            let mut grown: HashSet<BlockKey> = HashSet::with_capacity(set.len());
            for b in &set {
                for d in -k..=k {
                    let mut c = *b;
                    c[axis] += d;
                    grown.insert(c);
                }
                if (grown.len() + union.len()) as u64 > over.saturating_mul(2) {
                    return Err(over);
                }
            }
            set = grown;
        }
        union.extend(set);
    }
    if union.len() as u64 > cap {
        return Err(over);
    }
    Ok(union.into_iter().collect())
}

/// Bytes per particle of a radius column held for the run.
const RADIUS_COLUMN_BYTES: u64 = 4;
/// Bytes per particle of a tile that particles of several sizes add.
const RADIUS_TILE_BYTES: u64 = 8;

/// Picks the tile edge in blocks (`None`: one tile) and estimates the run's peak memory;
/// refuses, before any work, a budget that the surface after the tiles or the smallest
/// tile cannot fit.
pub(super) fn choose_tile_blocks(
    input: &BudgetInput,
    options: &super::TileOptions,
) -> Result<(Option<i32>, u64)> {
    let shape = SceneShape::of(input.block_counts);
    let triangles = shape.marching_cubes_triangles();
    let particles = shape.particles;
    let column = if input.radius_column {
        RADIUS_COLUMN_BYTES * particles
    } else {
        0
    };
    let tile_radii = if input.radius_column {
        RADIUS_TILE_BYTES
    } else {
        0
    };
    let model = Model {
        large: &input.large_support_blocks,
        block_counts: input.block_counts,
        origin: input.origin,
        reach: input.reach,
        shape,
        output: BASE_BYTES
            + column
            + (particles * POST_TILES_BYTES_PER_PARTICLE).min(POST_TILES_MAX_BYTES)
            + (triangles * input.output_cost.bytes_per_triangle) as u64,
        produced: BASE_BYTES
            + column
            + (triangles
                * if input.decimated_in_tiles {
                    0.2 * crate::mesh::MESH_BYTES_PER_TRIANGLE
                } else {
                    20.0
                }) as u64,
        payload: 4 * input.payload_width as u64,
        kernel_bytes_per_particle: input.kernel_bytes_per_particle
            + tile_radii
            + if input.radius_column {
                RADIUS_COLUMN_BYTES
            } else {
                0
            },
    };
    if let Some(budget) = options.memory_budget_bytes {
        if model.output > budget {
            return Err(Error::MemoryBudget {
                budget_mib: mib(budget),
                message: format!(
                    "the process and the surface of {particles} particles (≈ {:.1} M triangles from marching cubes) need ≈ {} MiB after the tiles (post-processing): a larger budget would fit; {} would lower it",
                    triangles / 1e6,
                    mib(model.output),
                    input.output_cost.advice
                ),
            });
        }
    }
    match (options.tile_size_cells, options.memory_budget_bytes) {
        (Some(cells), budget) => given_tile_size(&model, cells, budget),
        (None, None) => Ok((None, model.untiled())),
        (None, Some(budget)) => largest_tile_under(&model, budget),
    }
}

/// Tiles of `cells` cells, checked against the budget when there is one.
fn given_tile_size(model: &Model, cells: u32, budget: Option<u64>) -> Result<(Option<i32>, u64)> {
    let t = (cells.max(1) as i32 + BLOCK_EDGE - 1) / BLOCK_EDGE;
    let estimate = model.tiled(t);
    match budget {
        Some(budget) if estimate > budget => Err(Error::MemoryBudget {
            budget_mib: mib(budget),
            message: format!(
                "tiles of {cells} cells need ≈ {} MiB (densest tile ≈ {} MiB, the process and the surface so far ≈ {} MiB): smaller tiles or a larger budget would fit",
                mib(estimate),
                mib(model.tile(t)),
                mib(model.produced)
            ),
        }),
        _ => Ok((Some(t), estimate)),
    }
}

/// Tile edges a budget chooses from, in blocks, largest first: powers of two and the
/// halfway steps between them (fewer tiles do less work again on their borders).
const TILE_BLOCKS: [i32; 14] = [128, 96, 64, 48, 32, 24, 16, 12, 8, 6, 4, 3, 2, 1];

/// One tile if the run fits `budget` untiled, else the largest tile of [`TILE_BLOCKS`]
/// that does.
fn largest_tile_under(model: &Model, budget: u64) -> Result<(Option<i32>, u64)> {
    let untiled = model.untiled();
    if untiled <= budget {
        return Ok((None, untiled));
    }
    let mut smallest = 0;
    for t in TILE_BLOCKS {
        let estimate = model.tiled(t);
        smallest = estimate;
        if estimate <= budget {
            return Ok((Some(t), estimate));
        }
    }
    Err(Error::MemoryBudget {
        budget_mib: mib(budget),
        message: format!(
            "even one-block tiles need ≈ {} MiB for {} particles (the process and the surface so far ≈ {} MiB)",
            mib(smallest),
            model.shape.particles,
            mib(model.produced)
        ),
    })
}

/// Parses a memory size: a number (digits, optionally a fraction) with an optional
/// unit. Plain digits are bytes (`B` may be written); `KiB`, `MiB`, `GiB`, `TiB` are
/// powers of two (2^10 … 2^40 bytes), `kB`, `MB`, `GB`, `TB` powers of ten (10^3 …
/// 10^12). Units are read regardless of case, spaces before them are allowed. A bare `k`,
/// `m`, `g` or `t` could mean either and is refused with both readings offered.
pub fn parse_memory_size(text: &str) -> std::result::Result<u64, String> {
    let t = text.trim();
    let split = t
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(t.len());
    let (number, unit) = t.split_at(split);
    let unit = unit.trim();
    let value: f64 = number.parse().map_err(|_| {
        format!("{text:?} is not a size like 512MiB, 2GiB (powers of 2) or 2GB (powers of 10)")
    })?;
    let scale: f64 = match unit.to_ascii_lowercase().as_str() {
        "" | "b" => 1.0,
        "kib" => 1024.0,
        "mib" => (1u64 << 20) as f64,
        "gib" => (1u64 << 30) as f64,
        "tib" => (1u64 << 40) as f64,
        "kb" => 1e3,
        "mb" => 1e6,
        "gb" => 1e9,
        "tb" => 1e12,
        "k" | "m" | "g" | "t" => {
            let prefix = unit.to_ascii_uppercase();
            let (binary, decimal) = match prefix.as_str() {
                "K" => (10, 3),
                "M" => (20, 6),
                "G" => (30, 9),
                _ => (40, 12),
            };
            // The SI prefix of 10^3 is a lower-case k.
            let si = if prefix == "K" { "k" } else { prefix.as_str() };
            return Err(format!(
                "{text:?} is ambiguous: write {number}{prefix}iB (2^{binary} bytes) or {number}{si}B (10^{decimal} bytes)"
            ));
        }
        _ => {
            return Err(format!(
                "unknown size unit {unit:?} in {text:?}: use KiB, MiB, GiB, TiB (powers of 2) or kB, MB, GB, TB (powers of 10)"
            ))
        }
    };
    let bytes = value * scale;
    if !(bytes >= 1.0 && bytes < u64::MAX as f64) {
        return Err(format!("{text:?} is not a positive size"));
    }
    Ok(bytes as u64)
}

/// Half the memory the system reports available (`MemAvailable`, Linux), the CLI's default
/// budget; `None` where it cannot be read.
pub fn default_memory_budget() -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024 / 2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tiles::TileOptions;

    /// `n`³ populated blocks of `per_block` particles each, spaced `gap` blocks apart.
    fn lattice(n: i32, gap: i32, per_block: u64) -> HashMap<BlockKey, u64> {
        let mut counts = HashMap::new();
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    counts.insert([x * gap, y * gap, z * gap], per_block);
                }
            }
        }
        counts
    }

    #[test]
    fn surface_blocks_are_the_populated_blocks_with_an_empty_neighbour() {
        let solid = SceneShape::of(&lattice(6, 1, 10));
        assert_eq!(solid.particles, 2160);
        assert_eq!(solid.populated_blocks, 216);
        assert_eq!(solid.surface_blocks, 216 - 4 * 4 * 4);
        // Blocks touching only along an edge or a corner still count as neighbours.
        let mut diagonal = HashMap::new();
        diagonal.insert([0, 0, 0], 1);
        diagonal.insert([1, 1, 1], 1);
        assert_eq!(SceneShape::of(&diagonal).surface_blocks, 2);
        let spray = SceneShape::of(&lattice(6, 2, 10));
        assert_eq!(spray.surface_blocks, 216);
        assert!(spray.marching_cubes_triangles() > solid.marching_cubes_triangles());
    }

    #[test]
    fn a_scene_with_more_surface_per_particle_is_planned_with_more_memory() {
        // The same particles as one solid body and as spray: the spray has every block on
        // its surface, so it needs more memory untiled and is tiled under a budget the
        // body runs untiled in.
        let body = lattice(24, 1, 64);
        let spray = lattice(24, 3, 64);
        // Decimation by 0.8, nothing after it: the decimated mesh.
        let output = OutputCost {
            bytes_per_triangle: 0.2 * crate::mesh::MESH_BYTES_PER_TRIANGLE,
            advice: "more decimation",
        };
        let plan = |counts: &HashMap<BlockKey, u64>, budget: Option<u64>| {
            let options = TileOptions {
                memory_budget_bytes: budget,
                ..TileOptions::default()
            };
            let input = BudgetInput {
                block_counts: counts,
                origin: super::super::plan::tile_origin(counts, 1),
                reach: 1,
                output_cost: output,
                payload_width: 0,
                kernel_bytes_per_particle: 0,
                decimated_in_tiles: true,
                radius_column: false,
                large_support_blocks: Ok(Vec::new()),
            };
            choose_tile_blocks(&input, &options)
        };
        let (body_tiles, body_bytes) = plan(&body, None).unwrap();
        let (spray_tiles, spray_bytes) = plan(&spray, None).unwrap();
        assert_eq!((body_tiles, spray_tiles), (None, None));
        assert!(spray_bytes > body_bytes + body_bytes / 10);
        let between = (body_bytes + spray_bytes) / 2;
        let (body_tiles, body_estimate) = plan(&body, Some(between)).unwrap();
        assert_eq!(body_tiles, None);
        assert!(body_estimate <= between);
        let (spray_tiles, spray_estimate) = plan(&spray, Some(between)).unwrap();
        assert!(
            spray_tiles.is_some(),
            "the spray is tiled under {between} bytes"
        );
        assert!(spray_estimate <= between);
    }

    /// Large particles' supports count as the union of their cubes (a cluster costs
    /// about one cube, not one per particle), and a budget below them is refused.
    #[test]
    fn large_particles_count_the_union_of_their_supports() {
        let one: HashMap<BlockKey, i32> = [([0, 0, 0], 5)].into_iter().collect();
        assert_eq!(
            large_support_blocks(&one, u64::MAX).unwrap().len(),
            11 * 11 * 11
        );
        let cluster: HashMap<BlockKey, i32> = [([0, 0, 0], 5), ([1, 0, 0], 5), ([0, 1, 0], 3)]
            .into_iter()
            .collect();
        assert_eq!(
            large_support_blocks(&cluster, u64::MAX).unwrap().len(),
            12 * 11 * 11
        );
        assert_eq!(large_support_blocks(&one, 1000), Err(1001));
        let counts: HashMap<BlockKey, u64> = [([0, 0, 0], 3)].into_iter().collect();
        let input = |large| BudgetInput {
            block_counts: &counts,
            origin: [-7, -7, -7],
            reach: 6,
            output_cost: OutputCost::NONE,
            payload_width: 0,
            kernel_bytes_per_particle: 0,
            decimated_in_tiles: true,
            radius_column: true,
            large_support_blocks: large,
        };
        let blocks = large_support_blocks(&one, u64::MAX);
        let support = 1331 * LARGE_SUPPORT_BYTES_PER_BLOCK;
        assert!(1001 * LARGE_SUPPORT_BYTES_PER_BLOCK > support / 2);
        let (_, alone) =
            choose_tile_blocks(&input(Ok(Vec::new())), &TileOptions::default()).unwrap();
        let (_, with) =
            choose_tile_blocks(&input(blocks.clone()), &TileOptions::default()).unwrap();
        assert_eq!(with, alone + support);
        let tight = TileOptions {
            memory_budget_bytes: Some(alone + support / 2),
            ..TileOptions::default()
        };
        // Tiles hold the blocks of the support that fall in them: the run is tiled.
        let (tiles, estimate) = choose_tile_blocks(&input(blocks), &tight).unwrap();
        assert!(tiles.is_some() && estimate <= alone + support / 2);
        // Past the cap every tile is counted the whole support, and refused.
        let err = choose_tile_blocks(&input(Err(1001)), &tight).unwrap_err();
        assert!(matches!(err, Error::MemoryBudget { .. }), "{err}");
    }

    #[test]
    fn binary_units_are_powers_of_two() {
        assert_eq!(parse_memory_size("512MiB"), Ok(512 << 20));
        assert_eq!(parse_memory_size("2GiB"), Ok(2 << 30));
        assert_eq!(parse_memory_size("2 gib"), Ok(2 << 30));
        assert_eq!(parse_memory_size("1.5GiB"), Ok(3 << 29));
        assert_eq!(parse_memory_size("64KiB"), Ok(64 << 10));
        assert_eq!(parse_memory_size("1TiB"), Ok(1 << 40));
    }

    #[test]
    fn decimal_units_are_powers_of_ten() {
        assert_eq!(parse_memory_size("2GB"), Ok(2_000_000_000));
        assert_eq!(parse_memory_size("512MB"), Ok(512_000_000));
        assert_eq!(parse_memory_size("64kB"), Ok(64_000));
        assert_eq!(parse_memory_size("64KB"), Ok(64_000));
        assert_eq!(parse_memory_size("1TB"), Ok(1_000_000_000_000));
        assert_eq!(parse_memory_size("0.5 GB"), Ok(500_000_000));
    }

    #[test]
    fn plain_digits_are_bytes() {
        assert_eq!(parse_memory_size("1073741824"), Ok(1 << 30));
        assert_eq!(parse_memory_size("4096B"), Ok(4096));
        assert_eq!(parse_memory_size(" 100 "), Ok(100));
    }

    #[test]
    fn a_bare_prefix_is_ambiguous_and_offers_both_readings() {
        assert_eq!(
            parse_memory_size("2g").unwrap_err(),
            "\"2g\" is ambiguous: write 2GiB (2^30 bytes) or 2GB (10^9 bytes)"
        );
        assert_eq!(
            parse_memory_size("2G").unwrap_err(),
            "\"2G\" is ambiguous: write 2GiB (2^30 bytes) or 2GB (10^9 bytes)"
        );
        assert_eq!(
            parse_memory_size("512m").unwrap_err(),
            "\"512m\" is ambiguous: write 512MiB (2^20 bytes) or 512MB (10^6 bytes)"
        );
        assert_eq!(
            parse_memory_size("512M").unwrap_err(),
            "\"512M\" is ambiguous: write 512MiB (2^20 bytes) or 512MB (10^6 bytes)"
        );
        assert!(parse_memory_size("64k")
            .unwrap_err()
            .contains("64KiB (2^10 bytes) or 64kB (10^3 bytes)"));
        assert!(parse_memory_size("1t").unwrap_err().contains("1TiB"));
    }

    #[test]
    fn junk_units_and_values_are_refused() {
        let e = parse_memory_size("2 furlongs").unwrap_err();
        assert!(
            e.contains("unknown size unit \"furlongs\"") && e.contains("GiB"),
            "{e}"
        );
        assert!(parse_memory_size("2GiBs").is_err());
        assert!(parse_memory_size("GiB").unwrap_err().contains("not a size"));
        assert!(parse_memory_size("").is_err());
        assert!(parse_memory_size("-2GiB").is_err());
        assert!(parse_memory_size("0")
            .unwrap_err()
            .contains("not a positive size"));
        assert!(parse_memory_size("0.1").is_err());
        assert!(parse_memory_size("1.2.3GiB").is_err());
        assert!(parse_memory_size("100000000TiB").is_err());
    }
}
