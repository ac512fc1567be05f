//! Census for a narrow band (issue 35): how many blocks of the default field are wholly
//! inside (every vertex negative) or deep (inside, with their 26 neighbours inside too),
//! and how well a half-block occupancy test predicts deep blocks before any field value
//! is known: a block counts as predicted deep when every half-block within `D` halves of
//! its own holds at least `m` particles.
//!
//! `cargo run --release --example band_census -- frame.xyz RADIUS`
//!
//! Measured 2026-11-27 (blocks of 8 cells of 1 r): frame 25 16.7 % inside, 2.9 % deep;
//! the 168k splash 13.5 % / 0.9 %; the calm 4M scene (96 copies of frame 25) 18.2 % /
//! 3.1 %; double dam break 9 none. The test with D = 2 predicts 6 % of the blocks deep,
//! half of them wrongly (not deep; on the splash some not even inside).
use glam::Vec3;
use hashbrown::{HashMap, HashSet};
use meniscus::field::compute_field;
use meniscus::grid::{BlockKey, BLOCK_EDGE};
use meniscus::pipeline::ReconstructOptions;
use std::path::Path;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let r: f32 = args[1].parse().unwrap();
    let particles = meniscus::io::particles::read_particles(Path::new(&args[0]), None).unwrap();
    let positions: Vec<Vec3> = particles.positions.clone();
    let options = ReconstructOptions::new(r);
    let t = std::time::Instant::now();
    let (field, _) = compute_field(&positions, &options.field).unwrap();
    eprintln!(
        "field {:.1} s, {} blocks",
        t.elapsed().as_secs_f64(),
        field.block_count()
    );
    let inside: HashSet<BlockKey> = field
        .blocks()
        .filter(|(_, v)| v.iter().all(|&x| x < 0.0))
        .map(|(k, _)| *k)
        .collect();
    let around = |k: &BlockKey, d: i32| {
        let mut out = vec![];
        for z in -d..=d {
            for y in -d..=d {
                for x in -d..=d {
                    out.push([k[0] + x, k[1] + y, k[2] + z]);
                }
            }
        }
        out
    };
    let deep: HashSet<BlockKey> = inside
        .iter()
        .filter(|k| around(k, 1).iter().all(|n| inside.contains(n)))
        .copied()
        .collect();
    // Occupancy of half-blocks (edge 4 cells of h = cell_size * r).
    let h = options.field.cell_size_world();
    let half =
        |p: Vec3| [0, 1, 2].map(|a| (p[a] as f64 / h / (BLOCK_EDGE / 2) as f64).floor() as i32);
    let mut occ: HashMap<BlockKey, u32> = HashMap::new();
    for p in &positions {
        *occ.entry(half(*p)).or_default() += 1;
    }
    let total = field.block_count();
    println!("blocks {total}, all-inside {} ({:.1} %), deep (inside with all 26 neighbours inside) {} ({:.1} %)",
        inside.len(), 100.0 * inside.len() as f64 / total as f64, deep.len(), 100.0 * deep.len() as f64 / total as f64);
    for d in [2, 3, 4, 5] {
        for m in [1u32, 2] {
            // Block b is predicted deep when every half-block within d halves of its two
            // halves per axis holds at least m particles.
            let predicted: Vec<BlockKey> = field
                .blocks()
                .map(|(k, _)| *k)
                .filter(|k| {
                    let lo = [0, 1, 2].map(|a| 2 * k[a] - d);
                    let hi = [0, 1, 2].map(|a| 2 * k[a] + 1 + d);
                    (lo[2]..=hi[2]).all(|z| {
                        (lo[1]..=hi[1]).all(|y| {
                            (lo[0]..=hi[0]).all(|x| occ.get(&[x, y, z]).copied().unwrap_or(0) >= m)
                        })
                    })
                })
                .collect();
            let wrong = predicted.iter().filter(|k| !inside.contains(*k)).count();
            let wrong_deep = predicted.iter().filter(|k| !deep.contains(*k)).count();
            println!("D={d} halves, m={m}: predicted deep {} ({:.1} % of blocks), not all-inside {wrong}, not deep {wrong_deep}",
                predicted.len(), 100.0 * predicted.len() as f64 / total as f64);
        }
    }
}
