//! Decodes every frame of an `.mseq` archive many times and prints the best and median
//! throughput: a quick way to profile the decoder (`perf record`) without criterion.
//!
//! `cargo run --release --example decode_archive -- run.mseq [rounds]`

use meniscus::archive::ArchiveReader;
use std::path::Path;
use std::time::Instant;

fn main() {
    meniscus::tune_allocator();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(input) = args.first() else {
        eprintln!("usage: decode_archive RUN.mseq [rounds]");
        std::process::exit(2);
    };
    let rounds: usize = args
        .get(1)
        .map_or(50, |s| s.parse().expect("a round count"));
    let reader = ArchiveReader::open(Path::new(input)).expect("readable archive");
    let numbers: Vec<i64> = reader.frames().iter().map(|f| f.number).collect();
    let triangles: u64 = reader.frames().iter().map(|f| f.triangles as u64).sum();
    let mut times = Vec::with_capacity(rounds);
    for _ in 0..rounds {
        let start = Instant::now();
        for &n in &numbers {
            std::hint::black_box(reader.read_geometry(n).expect("decodable frame"));
        }
        times.push(start.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    let (best, median) = (times[0], times[times.len() / 2]);
    println!(
        "{} frames, {triangles} triangles: best {:.2} ms ({:.1} M triangles/s), median {:.2} ms ({:.1} M triangles/s)",
        numbers.len(),
        best * 1e3,
        triangles as f64 / best / 1e6,
        median * 1e3,
        triangles as f64 / median / 1e6
    );
}
