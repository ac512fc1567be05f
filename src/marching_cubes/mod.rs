//! Marching cubes (Lorensen & Cline 1987) on the sparse lattice, with a face-consistent
//! ambiguity rule.
//!
//! **Input:** a [`SparseField`] (negative inside). **Output:** a [`TriMesh`] whose vertices
//! sit on lattice edges with a sign change, counter-clockwise seen from outside.
//!
//! * A vertex is *inside* when its value is `< 0`.
//! * Ambiguous faces are resolved with the asymptotic decider (Nielson & Hamann 1991): the
//!   inside corners are connected when the bilinear interpolant's saddle value
//!   `(v00·v11 − v10·v01) / (v00 + v11 − v10 − v01)` is negative. It reads only the face's
//!   four values in a canonical order, so both cubes of a face agree; see `marching_cubes/table.rs` for why
//!   this yields a closed, consistently oriented 2-manifold for every field in which the
//!   region with values `< 0` is bounded.
//! * Every mesh vertex is identified by its global lattice edge (lower endpoint + axis) and
//!   computed once, by the block owning the lower endpoint, from the two endpoint values
//!   only (the rare loops that need a centre vertex, see `table.rs`, key it by their cell): `t = v_lo / (v_lo − v_hi)`, clamped to `[2⁻¹⁰, 1 − 2⁻¹⁰]` so that vertices of
//!   distinct edges never coincide.
//! * Output order: blocks in ascending (z, y, x), vertices by owned edge within a block,
//!   triangles by cell. It depends only on the field, never on the thread count.

mod table;

use crate::grid::BlockRange;
use crate::grid::{local_index, BlockKey, BlockValues, SparseField, BLOCK_EDGE};
use crate::mesh::TriMesh;
use glam::{DVec3, Vec3};
use hashbrown::HashMap;
use rayon::prelude::*;

/// What marching cubes produced.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct MarchingCubesStats {
    /// Blocks whose cells were visited.
    pub blocks_visited: usize,
    /// Output vertices.
    pub vertices: usize,
    /// Output triangles.
    pub triangles: usize,
}

const E: i32 = BLOCK_EDGE;
const CUBE: usize = ((E + 1) * (E + 1) * (E + 1)) as usize;
/// Lower clamp of the edge parameter.
const T_MIN: f64 = 1.0 / 1024.0;

/// A reference to a mesh vertex: the owning block (offset bits x, y, z from the referring
/// block) and the vertex's id in that block (`local vertex index · 3 + axis` for edge
/// vertices, from `CENTER_ID_BASE` for cell-centre vertices); or, with [`OWN_INDEX`] set,
/// the position of a vertex of the referring block itself in its `owned` list (what
/// [`march_block`] makes of every reference to its own vertices).
type EdgeRef = u32;

/// Flag of an [`EdgeRef`] already resolved to an index into the block's own vertices.
const OWN_INDEX: EdgeRef = 1 << 31;

/// Ids a block's vertices can have: edge ids, then four centre ids per cell.
const VERTEX_IDS: usize = CENTER_ID_BASE as usize + 4 * (E * E * E) as usize;

fn edge_ref(owner_offset: u32, local_edge: u32) -> EdgeRef {
    (owner_offset << 16) | local_edge
}

/// The marching-cubes output of one block: the vertices it owns and its triangles, which
/// may refer to vertices owned by its +x/+y/+z neighbours. Joined by [`stitch`].
pub(crate) struct BlockSurface {
    key: BlockKey,
    /// Owned vertex ids, ascending, and their positions.
    owned: Vec<(u16, Vec3)>,
    triangles: Vec<[EdgeRef; 3]>,
}

impl BlockSurface {
    /// Bytes held (for memory accounting).
    pub fn memory_bytes(&self) -> usize {
        self.owned.capacity() * 16 + self.triangles.capacity() * 12 + 64
    }
}

/// Bytes per triangle while block surfaces are stitched into one mesh: the block surfaces
/// (≈ 20 B per triangle) and the stitched mesh (≈ 18 B) exist together.
pub(crate) const STITCH_BYTES_PER_TRIANGLE: f64 = 38.0;

/// Extracts the zero level set of `field` as a triangle mesh.
pub fn extract_surface(field: &SparseField) -> (TriMesh, MarchingCubesStats) {
    stitch(march_blocks(field, None))
}

/// Marches the cells of every block within `range` (all when `None`) whose cells can
/// touch a negative vertex. `field` must hold every block of `range` grown by one block
/// upwards. Results are sorted by block key in (z, y, x) order.
pub(crate) fn march_blocks(field: &SparseField, range: Option<BlockRange>) -> Vec<BlockSurface> {
    // Blocks to visit: the block itself or one of its +x/+y/+z neighbours holds a negative
    // value.
    // (Found in parallel, then sorted and deduplicated.)
    let mut keys: Vec<BlockKey> = field
        .keys_of_negative_blocks()
        .into_par_iter()
        .flat_map_iter(|key| {
            (0..8).map(move |o| {
                [
                    key[0] - (o & 1),
                    key[1] - ((o >> 1) & 1),
                    key[2] - ((o >> 2) & 1),
                ]
            })
        })
        .filter(|&k| range.is_none_or(|r| r.contains(k)))
        .collect();
    keys.par_sort_unstable_by_key(|k| [k[2], k[1], k[0]]);
    keys.dedup();
    keys.shrink_to_fit();
    keys.par_iter()
        .map_init(
            || {
                (
                    vec![0.0f32; CUBE],
                    vec![0u16; VERTEX_IDS],
                    [0u64; EDGE_ID_WORDS],
                )
            },
            |(cube, slots, owned_edges), &key| march_block(field, key, cube, slots, owned_edges),
        )
        .collect()
}

/// Joins block surfaces (from one or many tiles) into one mesh. Vertices are numbered in
/// (z, y, x) block order, then by id within the block, whatever order the blocks come in,
/// so the result is the same however the blocks were grouped into tiles.
pub(crate) fn stitch(mut surfaces: Vec<BlockSurface>) -> (TriMesh, MarchingCubesStats) {
    surfaces.sort_unstable_by_key(|s| [s.key[2], s.key[1], s.key[0]]);
    let (base, index_of) = number_blocks(&surfaces);
    // Every block fills its own slices of the output, in parallel, in place.
    let mut triangles = vec![[0u32; 3]; surfaces.iter().map(|s| s.triangles.len()).sum()];
    let mut positions = vec![Vec3::ZERO; *base.last().unwrap() as usize];
    let triangle_slices =
        split_by_lengths(&mut triangles, surfaces.iter().map(|s| s.triangles.len()));
    let position_slices = split_by_lengths(&mut positions, surfaces.iter().map(|s| s.owned.len()));
    surfaces
        .par_iter()
        .zip(triangle_slices)
        .zip(position_slices)
        .for_each(|((s, triangles), positions)| {
            let owners = owner_table(&index_of, s.key);
            for (out, t) in triangles.iter_mut().zip(&s.triangles) {
                *out = t.map(|r| resolve(&surfaces, &owners, &base, r));
            }
            for (out, e) in positions.iter_mut().zip(&s.owned) {
                *out = e.1;
            }
        });
    let stats = MarchingCubesStats {
        blocks_visited: surfaces.len(),
        vertices: positions.len(),
        triangles: triangles.len(),
    };
    (
        TriMesh {
            positions,
            triangles,
            normals: Vec::new(),
            attributes: Vec::new(),
        },
        stats,
    )
}

/// `items` cut into consecutive slices of the given lengths (which must add up to at
/// most its length).
fn split_by_lengths<T>(mut items: &mut [T], lengths: impl Iterator<Item = usize>) -> Vec<&mut [T]> {
    lengths
        .map(|n| {
            let (head, tail) = std::mem::take(&mut items).split_at_mut(n);
            items = tail;
            head
        })
        .collect()
}

/// The vertex numbering of `surfaces` in their order: the first index of each block's
/// owned vertices (plus the total at the end), and each block's position in the list.
fn number_blocks(surfaces: &[BlockSurface]) -> (Vec<u32>, HashMap<BlockKey, usize>) {
    let mut base = Vec::with_capacity(surfaces.len() + 1);
    base.push(0u32);
    for s in surfaces {
        base.push(base.last().unwrap() + s.owned.len() as u32);
    }
    let index_of = surfaces
        .iter()
        .enumerate()
        .map(|(i, s)| (s.key, i))
        .collect();
    (base, index_of)
}

/// For the triangles of block `key`: the position in the list of each block its vertex
/// references can point to (the block itself and its +x/+y/+z neighbours, by offset
/// bits), looked up once per block instead of once per reference.
fn owner_table(index_of: &HashMap<BlockKey, usize>, key: BlockKey) -> [Option<usize>; 8] {
    std::array::from_fn(|o| index_of.get(&upper_neighbour(key, o)).copied())
}

/// Block `key` moved by +1 along the axes whose bits are set in `offset` (x = 1, y = 2,
/// z = 4): the blocks whose values and vertices a block's cells use.
fn upper_neighbour(key: BlockKey, offset: usize) -> BlockKey {
    [0, 1, 2].map(|a| key[a] + ((offset >> a) & 1) as i32)
}

/// The index of the vertex `r` of a triangle of a block whose [`owner_table`] is
/// `owners`, in a numbering where block `surfaces[i]`'s owned vertices start at `base[i]`.
fn resolve(
    surfaces: &[BlockSurface],
    owners: &[Option<usize>; 8],
    base: &[u32],
    r: EdgeRef,
) -> u32 {
    if r & OWN_INDEX != 0 {
        let bi = owners[0].expect("a block's own surface is in the list");
        return base[bi] + (r & 0xffff);
    }
    let bi = owners[(r >> 16) as usize].expect("the owner of a crossed edge is always marched");
    let local = (r & 0xffff) as u16;
    let pos = surfaces[bi]
        .owned
        .binary_search_by_key(&local, |e| e.0)
        .expect("the owner of a crossed edge always creates its vertex");
    base[bi] + pos as u32
}

/// The triangles of the blocks in `own`, with every vertex they use, as one mesh, and for
/// each vertex whether it lies on the border of `own` (a lattice edge of a cell outside
/// `own`, so other tiles' triangles may use it too) and, if so, its global key.
///
/// `surfaces` must hold the blocks of `own` and of the layer of blocks just above it (the
/// owners of the vertices on the upper faces of `own`). Vertices are numbered in block
/// order like [`stitch`]; a vertex's position depends only on its edge's two end values,
/// so a seam vertex has the same position in every tile that uses it.
pub(crate) fn stitch_range(surfaces: &[BlockSurface], own: BlockRange) -> RangeMesh {
    let (base, index_of) = number_blocks(surfaces);
    let total = *base.last().unwrap() as usize;
    let mut triangles: Vec<[u32; 3]> = Vec::new();
    for s in surfaces.iter().filter(|s| own.contains(s.key)) {
        let owners = owner_table(&index_of, s.key);
        triangles.extend(
            s.triangles
                .iter()
                .map(|t| t.map(|r| resolve(surfaces, &owners, &base, r))),
        );
    }
    // Keep the referenced vertices only, in block order.
    let mut new_index = vec![u32::MAX; total];
    for t in &triangles {
        for &v in t {
            new_index[v as usize] = 0;
        }
    }
    let (lo, hi) = (own.lo.map(|c| c * E), own.hi.map(|c| (c + 1) * E));
    let mut positions = Vec::new();
    let mut seam_keys = Vec::new();
    for (bi, s) in surfaces.iter().enumerate() {
        for (k, &(id, p)) in s.owned.iter().enumerate() {
            let g = base[bi] as usize + k;
            if new_index[g] == u32::MAX {
                continue;
            }
            new_index[g] = positions.len() as u32;
            positions.push(p);
            let id32 = id as u32;
            let on_seam = id32 < CENTER_ID_BASE && {
                let l = (id32 / 3) as i32;
                let axis = (id32 % 3) as usize;
                let corner = [l % E, (l / E) % E, l / (E * E)];
                (0..3).any(|b| {
                    let g = s.key[b] * E + corner[b];
                    b != axis && (g <= lo[b] || g >= hi[b])
                })
            };
            seam_keys.push(on_seam.then_some((s.key, id)));
        }
    }
    for t in &mut triangles {
        for v in t.iter_mut() {
            *v = new_index[*v as usize];
        }
    }
    RangeMesh {
        mesh: TriMesh {
            positions,
            triangles,
            normals: Vec::new(),
            attributes: Vec::new(),
        },
        seam_keys,
    }
}

/// Global identity of a mesh vertex: its owning block and its id there.
pub(crate) type VertexKey = (BlockKey, u16);

/// A piece of the marching-cubes mesh cut along block borders ([`stitch_range`]).
pub(crate) struct RangeMesh {
    /// The triangles of the range and the vertices they use.
    pub mesh: TriMesh,
    /// Per vertex: the global key when the vertex lies on the range's border (other
    /// ranges may use it), `None` inside.
    pub seam_keys: Vec<Option<VertexKey>>,
}

/// First local id of cell-centre vertices (after the `8³ · 3` edge ids): cell `n`'s
/// `k`-th centred loop has id `CENTER_ID_BASE + 4n + k`.
const CENTER_ID_BASE: u32 = (E * E * E * 3) as u32;
/// Words of the bit set of a block's own edge ids (`< CENTER_ID_BASE`).
const EDGE_ID_WORDS: usize = (CENTER_ID_BASE as usize).div_ceil(64);

/// World position of the vertex on the lattice edge from cube-local `corner` along `axis`.
fn edge_position(cube: &[f32], key: BlockKey, corner: [i32; 3], axis: usize, h: f64) -> DVec3 {
    let mut hi = corner;
    hi[axis] += 1;
    let v0 = cube[cube_index(corner[0], corner[1], corner[2])] as f64;
    let v1 = cube[cube_index(hi[0], hi[1], hi[2])] as f64;
    let t = (v0 / (v0 - v1)).clamp(T_MIN, 1.0 - T_MIN);
    let mut g = [0, 1, 2].map(|i| (key[i] * E + corner[i]) as f64);
    g[axis] += t;
    DVec3::new(g[0] * h, g[1] * h, g[2] * h)
}

#[inline]
fn cube_index(a: i32, b: i32, c: i32) -> usize {
    ((c * (E + 1) + b) * (E + 1) + a) as usize
}

/// Per row of cells `(b, c)` of the gathered `cube` (index `c·E + b`): the inside bits of
/// the four vertex rows around it, in corner order (y, then z; bit `a` of a row is vertex
/// `a`), and the bits of its cells with a sign change. `None` when every value has the
/// same sign. A few bit operations per row of cells instead of eight loads per cell.
#[inline(always)]
fn cell_rows(cube: &[f32]) -> Option<[([u16; 4], u16); (E * E) as usize]> {
    let mut signs = [0u16; (E as usize + 1) * (E as usize + 1)];
    for (row, bits) in cube.chunks_exact(E as usize + 1).zip(signs.iter_mut()) {
        *bits = row
            .iter()
            .enumerate()
            .fold(0, |m, (a, &v)| m | ((v < 0.0) as u16) << a);
    }
    const FULL_ROW: u16 = (1 << (E + 1)) - 1;
    if signs.iter().all(|&m| m == 0) || signs.iter().all(|&m| m == FULL_ROW) {
        return None;
    }
    let row_signs = |b: i32, c: i32| signs[(c * (E + 1) + b) as usize];
    Some(std::array::from_fn(|n| {
        let (b, c) = (n as i32 % E, n as i32 / E);
        let rows = [
            row_signs(b, c),
            row_signs(b + 1, c),
            row_signs(b, c + 1),
            row_signs(b + 1, c + 1),
        ];
        // Cell `a` has an inside corner when bit a or a + 1 of the rows' union is set, and
        // only inside corners when both bits of their intersection are.
        let any = rows[0] | rows[1] | rows[2] | rows[3];
        let all = rows[0] & rows[1] & rows[2] & rows[3];
        (rows, (any | any >> 1) & !(all & all >> 1) & ((1 << E) - 1))
    }))
}

/// Marches the 8³ cells whose lower corner lies in block `key`; `cube`, `slots` and
/// `owned_edges` are scratch ((E+1)³ values, one entry per vertex id, a bit per edge id
/// of the block's own edge vertices).
fn march_block(
    field: &SparseField,
    key: BlockKey,
    cube: &mut [f32],
    slots: &mut [u16],
    owned_edges: &mut [u64; EDGE_ID_WORDS],
) -> BlockSurface {
    gather_cube(field, key, cube);
    let Some(cell_rows) = cell_rows(cube) else {
        // All outside or all inside (most blocks of the band): no cell changes sign.
        return BlockSurface {
            key,
            owned: Vec::new(),
            triangles: Vec::new(),
        };
    };
    let (mut triangles, centers) = march_cells(cube, &cell_rows, key, field.cell_size, owned_edges);
    let owned = owned_vertices(cube, key, field.cell_size, owned_edges, centers);
    // References to the block's own vertices become their positions in `owned` (the
    // stitcher then looks up only the references into neighbour blocks).
    for (k, &(id, _)) in owned.iter().enumerate() {
        slots[id as usize] = k as u16;
    }
    for r in triangles.iter_mut().flatten() {
        if *r >> 16 == 0 {
            *r = OWN_INDEX | slots[*r as usize] as u32;
        }
    }
    BlockSurface {
        key,
        owned,
        triangles,
    }
}

/// Gathers the (E+1)³ values of block `key`'s cells into `cube`: this block plus the
/// +x/+y/+z neighbours' first layers, row by row (eight values of a block row, then the
/// first of the +x neighbour's).
fn gather_cube(field: &SparseField, key: BlockKey, cube: &mut [f32]) {
    let neighbours: [Option<&BlockValues>; 8] =
        std::array::from_fn(|o| field.block(&upper_neighbour(key, o)));
    let outside = field.outside_value;
    for c in 0..=E {
        for b in 0..=E {
            let o = (((b / E) << 1) | ((c / E) << 2)) as usize;
            let src = local_index(0, b % E, c % E);
            let start = cube_index(0, b, c);
            let row = &mut cube[start..start + E as usize + 1];
            match neighbours[o] {
                Some(block) => row[..E as usize].copy_from_slice(&block[src..src + E as usize]),
                None => row[..E as usize].fill(outside),
            }
            row[E as usize] = neighbours[o | 1].map_or(outside, |block| block[src]);
        }
    }
}

/// The triangles of every cell with a sign change (vertex references: owner block and
/// local id) and the centre vertices of loops triangulated around one; marks the
/// block's own edge vertices in `owned_edges`.
fn march_cells(
    cube: &[f32],
    cell_rows: &[([u16; 4], u16)],
    key: BlockKey,
    h: f64,
    owned_edges: &mut [u64; EDGE_ID_WORDS],
) -> (Vec<[u32; 3]>, Vec<(u16, Vec3)>) {
    // Two triangles per cell with a sign change on average (4M scene: 2.00), reserved
    // at once so that most blocks' lists are never grown by copying.
    let mixed_cells: usize = cell_rows.iter().map(|r| r.1.count_ones() as usize).sum();
    let table = table::table();
    let edges = table::cube_edges();
    let mut triangles = Vec::with_capacity(2 * mixed_cells);
    owned_edges.fill(0);
    let mut centers: Vec<(u16, Vec3)> = Vec::new();
    let corner_offset = |k: u8| ((k & 1) as i32, ((k >> 1) & 1) as i32, ((k >> 2) & 1) as i32);
    for c in 0..E {
        for b in 0..E {
            let (rows, mut mixed) = cell_rows[(c * E + b) as usize];
            while mixed != 0 {
                let a = mixed.trailing_zeros() as i32;
                mixed &= mixed - 1;
                // Corner k = x + 2y + 4z is inside when bit a + x of row (y, z) is.
                let case = rows.iter().enumerate().fold(0u8, |case, (yz, &m)| {
                    case | (((m >> a) & 3) as u8) << (2 * yz)
                });
                let mut values = [0.0f32; 8];
                for k in 0..8u8 {
                    let (x, y, z) = corner_offset(k);
                    values[k as usize] = cube[cube_index(a + x, b + y, c + z)];
                }
                let entry = table.entry(case, connected_faces(case, &values));
                let edge_key = |e: u8| {
                    let edge = edges[e as usize];
                    let (x, y, z) = corner_offset(edge.lo);
                    ((a + x, b + y, c + z), edge.axis as usize)
                };
                let cell = local_index(a, b, c) as u32;
                for (n, lp) in entry.centered_loops.iter().enumerate() {
                    let sum = lp.iter().fold(DVec3::ZERO, |acc, &e| {
                        let ((ga, gb, gc), axis) = edge_key(e);
                        acc + edge_position(cube, key, [ga, gb, gc], axis, h)
                    });
                    let id = CENTER_ID_BASE + cell * 4 + n as u32;
                    centers.push((id as u16, (sum / lp.len() as f64).as_vec3()));
                }
                for tri in &entry.triangles {
                    triangles.push(tri.map(|p| {
                        if p >= table::CENTER {
                            return edge_ref(
                                0,
                                CENTER_ID_BASE + cell * 4 + (p - table::CENTER) as u32,
                            );
                        }
                        let ((ga, gb, gc), axis) = edge_key(p);
                        let owner = ((ga / E) | ((gb / E) << 1) | ((gc / E) << 2)) as u32;
                        let local = (local_index(ga % E, gb % E, gc % E) * 3 + axis) as u32;
                        if owner == 0 {
                            owned_edges[local as usize / 64] |= 1 << (local % 64);
                        }
                        edge_ref(owner, local)
                    }));
                }
            }
        }
    }
    (triangles, centers)
}

/// The faces of a cell of `case` whose inside corners meet (asymptotic decider), as a
/// bit per face: the saddle of the bilinear interpolant, where the two diagonals'
/// regions meet, is negative.
fn connected_faces(case: u8, values: &[f32; 8]) -> u8 {
    let mut connect = 0u8;
    for face in 0..6 {
        if table::face_is_ambiguous(case, face) {
            let [p, q, r, s] = table::face_corners(face).map(|k| values[k as usize]);
            let saddle = (p * r - q * s) / (p + r - q - s);
            if saddle < 0.0 {
                connect |= 1 << face;
            }
        }
    }
    connect
}

/// The block's own vertices: edge ids (< `CENTER_ID_BASE`) first, in ascending order
/// from the bit set, then the centres in cell order: ascending ids.
fn owned_vertices(
    cube: &[f32],
    key: BlockKey,
    h: f64,
    owned_edges: &[u64; EDGE_ID_WORDS],
    centers: Vec<(u16, Vec3)>,
) -> Vec<(u16, Vec3)> {
    let owned_count: u32 = owned_edges.iter().map(|bits| bits.count_ones()).sum();
    let mut owned: Vec<(u16, Vec3)> = Vec::with_capacity(owned_count as usize + centers.len());
    let ids = owned_edges.iter().enumerate().flat_map(|(word, &bits)| {
        let mut bits = bits;
        std::iter::from_fn(move || {
            (bits != 0).then(|| {
                let bit = bits.trailing_zeros();
                bits &= bits - 1;
                (word * 64) as u16 + bit as u16
            })
        })
    });
    owned.extend(ids.map(|id| {
        let l = (id / 3) as i32;
        let corner = [l % E, (l / E) % E, l / (E * E)];
        (
            id,
            edge_position(cube, key, corner, (id % 3) as usize, h).as_vec3(),
        )
    }));
    owned.extend(centers);
    owned
}
