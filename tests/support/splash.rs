//! A violent splash made from a calm frame, deterministically: a smooth displacement
//! field, strongest at the top of the fluid, stretches it into sheets and filaments, and
//! one particle in twenty is thrown up to 12 r away as spray. Shared by
//! `examples/tile_scene.rs` (its `splash` argument) and the containment tests.

use glam::Vec3;

/// Stretches the fluid into sheets and filaments and throws spray (see the module docs).
pub fn splash(positions: &mut [Vec3]) {
    let (lo, hi) = positions.iter().fold(
        (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
        |(l, h), p| (l.min(*p), h.max(*p)),
    );
    let extent = hi - lo;
    let spacing = spacing(positions);
    let mut state = 0x9e37_79b9_7f4a_7c15_u64;
    let mut random = move || {
        // splitmix64
        state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 11) as f32 / (1u64 << 53) as f32
    };
    let wave = 2.0 * std::f32::consts::PI / (0.35 * extent.max_element());
    let amplitude = 0.12 * extent.max_element();
    for p in positions.iter_mut() {
        let height = ((p.y - lo.y) / extent.y.max(f32::MIN_POSITIVE)).clamp(0.0, 1.0);
        let w = height * height * (3.0 - 2.0 * height);
        let d = Vec3::new(
            (wave * (p.y + 0.7 * p.z) + 1.0).sin(),
            (wave * (p.x - 0.4 * p.z) + 2.0).sin().abs(),
            (wave * (p.x + p.y) + 3.0).sin(),
        );
        *p += amplitude * w * d;
        if random() < 0.05 {
            let kick = Vec3::new(random() - 0.5, random(), random() - 0.5);
            *p += kick.normalize_or_zero() * (12.0 * 0.5 * spacing * random());
        }
    }
}

/// Median distance to the nearest other particle, sampled (the rest spacing 2r).
fn spacing(positions: &[Vec3]) -> f32 {
    let stride = (positions.len() / 200).max(1);
    let mut d: Vec<f32> = positions
        .iter()
        .step_by(stride)
        .map(|p| {
            positions
                .iter()
                .map(|q| p.distance(*q))
                .filter(|d| *d > 0.0)
                .fold(f32::MAX, f32::min)
        })
        .collect();
    d.sort_by(f32::total_cmp);
    d[d.len() / 2]
}
