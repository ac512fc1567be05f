use glam::Vec3;
use meniscus::pipeline;
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let bytes = std::fs::read(&args[1]).unwrap();
    let r: f32 = args[2].parse().unwrap();
    let pts: Vec<Vec3> = bytes
        .chunks_exact(12)
        .map(|c| {
            Vec3::new(
                f32::from_le_bytes(c[0..4].try_into().unwrap()),
                f32::from_le_bytes(c[4..8].try_into().unwrap()),
                f32::from_le_bytes(c[8..12].try_into().unwrap()),
            )
        })
        .collect();
    drop(bytes);
    let mut opts = pipeline::ReconstructOptions::new(r);
    if std::env::var("NOCOV").is_ok() {
        opts.field.particle_coverage = 0.0;
    }
    if std::env::var("NOISO").is_ok() {
        opts.isolated_sphere_level = None;
    }
    if args.len() > 3 {
        opts.tiles.tile_size_cells = Some(args[3].parse().unwrap());
    }
    let t = std::time::Instant::now();
    let (s, st) = pipeline::reconstruct(&pts, &opts).unwrap();
    println!(
        "{} tris, {:?} {:?} total {:?}",
        s.fluid.triangle_count(),
        st.tiles,
        st.field,
        t.elapsed()
    );
    print!("{}", st.table());
}
