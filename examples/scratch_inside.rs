use glam::Vec3;
use meniscus::{mesh, pipeline};
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
    let mut opts = pipeline::ReconstructOptions::new(r);
    opts.field.particle_coverage = std::env::var("COV")
        .map(|v| v.parse().unwrap())
        .unwrap_or(0.0);
    let (s, st) = pipeline::reconstruct(&pts, &opts).unwrap();
    let (fluid, iso) = pipeline::split_isolated(&pts, 4.0 * r);
    let t = mesh::InsideTest::new(&s.fluid, 2.0 * r);
    let out: Vec<usize> = (0..fluid.len())
        .filter(|&i| !t.contains(fluid[i]))
        .collect();
    println!(
        "{}: tris {} iso {} outside {} {:?}",
        args[1],
        s.fluid.triangle_count(),
        iso.len(),
        out.len(),
        &out[..out.len().min(5)]
    );
    print!("{}", st.table());
}
