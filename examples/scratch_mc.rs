use glam::Vec3;
use meniscus::{field, marching_cubes, mesh};
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
    let t = std::time::Instant::now();
    let mut opts = field::FieldOptions::new(r);
    opts.particle_coverage = std::env::var("COV")
        .map(|v| v.parse().unwrap())
        .unwrap_or(0.0);
    let (f, fs) = field::compute_field(&pts, &opts).unwrap();
    let t1 = t.elapsed();
    let (m, ms) = marching_cubes::extract_surface(&f);
    let t2 = t.elapsed();
    let rep = mesh::validate(&m);
    println!(
        "{fs:?}\n{ms:?}\nfield {:?} mc {:?}\n{rep:?}\nvolume {}",
        t1,
        t2 - t1,
        m.signed_volume()
    );
    if args.len() > 3 {
        let mut s = String::new();
        s += &format!("ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n", m.positions.len(), m.triangles.len());
        for p in &m.positions {
            s += &format!("{} {} {}\n", p.x, p.y, p.z);
        }
        for t in &m.triangles {
            s += &format!("3 {} {} {}\n", t[0], t[1], t[2]);
        }
        std::fs::write(&args[3], s).unwrap();
    }
}
