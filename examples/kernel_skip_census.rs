//! Census for issue 52's "kernels only for particles within reach of a narrow-band
//! vertex": with the field already known (an oracle no real run has before its kernels),
//! which lattice values can change the output, and which particles' kernels reach none of
//! them.
//!
//! A vertex value is *needed* when it is a corner of a cell marching cubes triangulates
//! (corners of both signs in the final field) or a corner of the cell of a particle the
//! coverage test finds uncovered (raw field interpolated above `−r/4`). Every other
//! stored value only has to stay negative. A particle is *skippable* when its ellipsoid
//! (`s² < 1`, the kernel's support) contains no needed vertex. The figures are the ceiling
//! of any exact skip: kernels of skippable particles, and kernel-vertex pairs at values
//! that are not needed (the field's work there).
//!
//! `cargo run --release --example kernel_skip_census -- frame.xyz RADIUS [still|steady]`
//!
//! Measured 2026-12-02 (session 18 of `docs/performance-log.md`): skippable kernels 50.5 %
//! (frame 25, still), 51.6 % (steady), 46.9 % and 46.2 % (4M splash); pairs at values
//! not needed 81–87 %. No test known before the kernels finds those values.
use glam::Vec3;
use hashbrown::HashMap;
use meniscus::field::{compute_field, compute_kernels};
use meniscus::grid::{split_coordinate, BlockKey, BLOCK_EDGE};
use meniscus::pipeline::ReconstructOptions;
use rayon::prelude::*;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

/// Needed vertices, a bit per vertex of each block.
struct Needed {
    bits: HashMap<BlockKey, [AtomicU64; 8]>,
}

impl Needed {
    fn mark(&self, g: [i32; 3]) {
        let (b, l): (Vec<i32>, Vec<i32>) = g.iter().map(|&c| split_coordinate(c)).unzip();
        if let Some(words) = self.bits.get(&[b[0], b[1], b[2]]) {
            let i = (l[0] + BLOCK_EDGE * (l[1] + BLOCK_EDGE * l[2])) as usize;
            words[i / 64].fetch_or(1 << (i % 64), Ordering::Relaxed);
        }
    }
    fn get(&self, g: [i32; 3]) -> bool {
        let (b, l): (Vec<i32>, Vec<i32>) = g.iter().map(|&c| split_coordinate(c)).unzip();
        match self.bits.get(&[b[0], b[1], b[2]]) {
            Some(words) => {
                let i = (l[0] + BLOCK_EDGE * (l[1] + BLOCK_EDGE * l[2])) as usize;
                words[i / 64].load(Ordering::Relaxed) >> (i % 64) & 1 == 1
            }
            None => false,
        }
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let r: f32 = args[1].parse().unwrap();
    let preset = args.get(2).map_or("still", |s| s.as_str());
    let options = match preset {
        "steady" => ReconstructOptions::steady(r),
        _ => ReconstructOptions::new(r),
    };
    let particles = meniscus::io::particles::read_particles(Path::new(&args[0]), None).unwrap();
    let all: Vec<Vec3> = particles.positions.clone();
    drop(particles);
    let big_r = options.field.influence_radius_world() as f32;
    let lonely = isolated(&all, big_r);
    let positions: Vec<Vec3> = all
        .iter()
        .zip(&lonely)
        .filter(|(_, &l)| !l)
        .map(|(p, _)| *p)
        .collect();
    drop(all);
    let t = Instant::now();
    let (field, _) = compute_field(&positions, &options.field).unwrap();
    let mut raw_options = options.field.clone();
    raw_options.particle_coverage = 0.0;
    raw_options.iso_offset = 0.0;
    let (raw, _) = compute_field(&positions, &raw_options).unwrap();
    eprintln!(
        "fields {:.1} s, {} blocks",
        t.elapsed().as_secs_f64(),
        field.block_count()
    );
    let h = field.cell_size;
    let needed = Needed {
        bits: field
            .blocks()
            .map(|(k, _)| (*k, std::array::from_fn(|_| AtomicU64::new(0))))
            .collect(),
    };
    // Corners of the cells with corners of both signs.
    let keys: Vec<BlockKey> = field.blocks().map(|(k, _)| *k).collect();
    keys.par_iter().for_each(|k| {
        for c in 0..BLOCK_EDGE {
            for b in 0..BLOCK_EDGE {
                for a in 0..BLOCK_EDGE {
                    let g = [
                        k[0] * BLOCK_EDGE + a,
                        k[1] * BLOCK_EDGE + b,
                        k[2] * BLOCK_EDGE + c,
                    ];
                    let corners: Vec<[i32; 3]> = (0..8)
                        .map(|n| [g[0] + (n & 1), g[1] + (n >> 1 & 1), g[2] + (n >> 2 & 1)])
                        .collect();
                    let inside = corners
                        .iter()
                        .filter(|v| field.value(v[0], v[1], v[2]) < 0.0)
                        .count();
                    if inside != 0 && inside != 8 {
                        corners.iter().for_each(|v| needed.mark(*v));
                    }
                }
            }
        }
    });
    let mixed_needed: usize = count(&needed);
    // Corners of the cells of uncovered particles.
    let uncovered = positions
        .par_iter()
        .filter(|p| {
            let g = p.as_dvec3() / h;
            let base = [g.x.floor(), g.y.floor(), g.z.floor()];
            let mut value = 0.0;
            for n in 0..8 {
                let o = [n & 1, n >> 1 & 1, n >> 2 & 1];
                let v = [0, 1, 2].map(|a| base[a] as i32 + o[a]);
                let w: f64 = (0..3)
                    .map(|a| {
                        let t = g[a] - base[a];
                        if o[a] == 1 {
                            t
                        } else {
                            1.0 - t
                        }
                    })
                    .product();
                value += w * raw.value(v[0], v[1], v[2]) as f64;
            }
            if value > -0.25 * r as f64 {
                for n in 0..8 {
                    let o = [n & 1, n >> 1 & 1, n >> 2 & 1];
                    needed.mark([0, 1, 2].map(|a| base[a] as i32 + o[a]));
                }
                true
            } else {
                false
            }
        })
        .count();
    drop(raw);
    let band: usize = field
        .blocks()
        .map(|(_, v)| v.iter().filter(|&&x| x != field.outside_value).count())
        .sum();
    let needed_vertices = count(&needed);
    let blocks_needed = needed
        .bits
        .values()
        .filter(|w| w.iter().any(|x| x.load(Ordering::Relaxed) != 0))
        .count();
    drop(field);
    let t = Instant::now();
    let (kernels, _) = compute_kernels(&positions, &options.field).unwrap();
    eprintln!("kernels {:.1} s", t.elapsed().as_secs_f64());
    // Per kernel: (pairs at needed vertices, pairs at other vertices).
    let pairs: Vec<(u64, u64)> = kernels
        .par_iter()
        .map(|k| {
            let m = k.quadratic_form(h);
            let e = k.half_extents(h);
            let c = k.centre.as_dvec3() / h;
            let lo = [0, 1, 2].map(|a| (c[a] - e[a]).ceil() as i32);
            let hi = [0, 1, 2].map(|a| (c[a] + e[a]).floor() as i32);
            let (mut yes, mut no) = (0, 0);
            for z in lo[2]..=hi[2] {
                for y in lo[1]..=hi[1] {
                    for x in lo[0]..=hi[0] {
                        let d = [x as f64 - c[0], y as f64 - c[1], z as f64 - c[2]];
                        let s2 = m[0] * d[0] * d[0]
                            + 2.0 * m[1] * d[0] * d[1]
                            + 2.0 * m[2] * d[0] * d[2]
                            + m[3] * d[1] * d[1]
                            + 2.0 * m[4] * d[1] * d[2]
                            + m[5] * d[2] * d[2];
                        if s2 < 1.0 {
                            if needed.get([x, y, z]) {
                                yes += 1;
                            } else {
                                no += 1;
                            }
                        }
                    }
                }
            }
            (yes, no)
        })
        .collect();
    let skippable = pairs.iter().filter(|p| p.0 == 0).count();
    let (yes, no) = pairs
        .iter()
        .fold((0u64, 0u64), |a, p| (a.0 + p.0, a.1 + p.1));
    let pct = |a: f64, b: f64| 100.0 * a / b;
    println!(
        "{preset}: {} field particles, {} uncovered; {} blocks, {} with a needed vertex ({:.1} %); \
         band vertices {band}, needed {needed_vertices} ({:.1} %; {mixed_needed} of them corners of triangulated cells); \
         skippable kernels {skippable} ({:.2} %); kernel-vertex pairs at unneeded vertices {:.1} %",
        positions.len(),
        uncovered,
        keys.len(),
        blocks_needed,
        pct(blocks_needed as f64, keys.len() as f64),
        pct(needed_vertices as f64, band as f64),
        pct(skippable as f64, positions.len() as f64),
        pct(no as f64, (yes + no) as f64),
    );
}

fn count(needed: &Needed) -> usize {
    needed
        .bits
        .values()
        .map(|w| {
            w.iter()
                .map(|x| x.load(Ordering::Relaxed).count_ones() as usize)
                .sum::<usize>()
        })
        .sum()
}

/// Particles with no other strictly within `radius` (the pipeline's isolation test).
fn isolated(positions: &[Vec3], radius: f32) -> Vec<bool> {
    let cell = |p: Vec3| (p / radius).floor().as_ivec3();
    let mut grid: HashMap<glam::IVec3, Vec<u32>> = HashMap::new();
    for (i, p) in positions.iter().enumerate() {
        grid.entry(cell(*p)).or_default().push(i as u32);
    }
    let r2 = radius * radius;
    positions
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let c = cell(*p);
            for dz in -1..=1 {
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        if let Some(list) = grid.get(&(c + glam::IVec3::new(dx, dy, dz))) {
                            if list.iter().any(|&j| {
                                j as usize != i
                                    && (positions[j as usize] - *p).length_squared() < r2
                            }) {
                                return false;
                            }
                        }
                    }
                }
            }
            true
        })
        .collect()
}
