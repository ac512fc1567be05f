//! Attribute streams of a frame: the fluid surface's per-vertex attributes and the
//! spheres' per-instance attributes, quantized with their own error bound.
//!
//! A record whose header flags [`HAS_ATTRIBUTES`] holds
//!
//! ```text
//! payload    := u32(descriptor length) descriptor u32(CRC-32 of descriptor)
//!               u64(geometry length) geometry attributes
//! descriptor := f64(error bound) varint(count)
//!               count × (u8(target) varint(components) varint(name length) name)
//! geometry   := the payload of the same frame without attributes (zstd)
//! attributes := zstd(count × (varint(length) stream))
//! stream     := per component, per item in order: zigzag varint(q − previous q)
//! ```
//!
//! `target` is 0 for the fluid's control vertices, in the order the geometry decodes them
//! (before subdivision), 1 for the sphere instances in the order of their centres. Each
//! value is `q × step` with `q` an integer, `step = 2 × error bound`; the previous `q`
//! starts at 0 for each component. The descriptor is read when the archive is opened
//! (names and bound for [`super::FrameInfo`]), hence its own checksum; the payload's
//! checksum covers all of it.

use super::codec::{decompress, get_varint, put_varint, unzigzag, zigzag};
use crate::mesh::Attribute;

/// Record flag: the payload carries attribute streams.
pub(crate) const HAS_ATTRIBUTES: u32 = 1;
/// Most components of one attribute.
pub(crate) const MAX_COMPONENTS: usize = 64;
/// Largest `|value| / step`: integers up to it are exact in f64, and their differences
/// do not overflow.
const MAX_QUANTUM: f64 = (1u64 << 52) as f64;

/// What an attribute is attached to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum AttributeTarget {
    /// One item per vertex of the fluid surface.
    FluidVertices,
    /// One item per sphere instance.
    SphereInstances,
}

/// One stored attribute, as [`super::FrameInfo`] lists it.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct AttributeInfo {
    /// Name (`velocity`, `density`, ...).
    pub name: String,
    /// Components per item.
    pub components: usize,
    /// Fluid vertices or sphere instances.
    pub target: AttributeTarget,
}

/// The descriptor of a frame's attribute streams.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Descriptor {
    pub(crate) error_bound: f64,
    pub(crate) attributes: Vec<AttributeInfo>,
}

/// The parts of a payload that carries attributes.
pub(crate) struct Sections<'a> {
    pub(crate) descriptor: Descriptor,
    pub(crate) geometry: &'a [u8],
    pub(crate) streams: &'a [u8],
}

fn take<'a>(bytes: &'a [u8], pos: &mut usize, n: usize) -> Option<&'a [u8]> {
    let s = bytes.get(*pos..pos.checked_add(n)?)?;
    *pos += n;
    Some(s)
}

/// Splits a payload flagged [`HAS_ATTRIBUTES`] into descriptor, geometry and attribute
/// streams.
pub(crate) fn split(payload: &[u8]) -> Result<Sections<'_>, String> {
    let pos = &mut 0usize;
    let descriptor = read_descriptor(payload, pos)?;
    let len = take(payload, pos, 8).ok_or("geometry length missing")?;
    let len = u64::from_le_bytes(len.try_into().expect("8 bytes"));
    let geometry = usize::try_from(len)
        .ok()
        .and_then(|n| take(payload, pos, n))
        .ok_or("geometry cut off")?;
    Ok(Sections {
        descriptor,
        geometry,
        streams: &payload[*pos..],
    })
}

/// Reads the descriptor at the start of a payload (and checks its checksum).
pub(crate) fn read_descriptor(payload: &[u8], pos: &mut usize) -> Result<Descriptor, String> {
    let len = take(payload, pos, 4).ok_or("attribute descriptor missing")?;
    let len = u32::from_le_bytes(len.try_into().expect("4 bytes")) as usize;
    let bytes = take(payload, pos, len).ok_or("attribute descriptor cut off")?;
    let crc = take(payload, pos, 4).ok_or("attribute descriptor cut off")?;
    if u32::from_le_bytes(crc.try_into().expect("4 bytes")) != crc32fast::hash(bytes) {
        return Err("attribute descriptor checksum mismatch".into());
    }
    let p = &mut 0usize;
    let bound = take(bytes, p, 8).ok_or("attribute error bound missing")?;
    let error_bound = f64::from_le_bytes(bound.try_into().expect("8 bytes"));
    if !(error_bound.is_finite() && error_bound > 0.0 && 2.0 * error_bound <= f32::MAX as f64) {
        return Err(format!(
            "attribute error bound {error_bound} is not a positive finite bound"
        ));
    }
    // Each attribute takes at least three bytes.
    let count = get_varint(bytes, p).ok_or("attribute count missing")?;
    if count > (bytes.len() / 3) as u64 {
        return Err(format!("attribute count {count} exceeds the descriptor"));
    }
    let mut attributes = Vec::with_capacity(count as usize);
    for i in 0..count {
        let target = match take(bytes, p, 1).ok_or("attribute target missing")?[0] {
            0 => AttributeTarget::FluidVertices,
            1 => AttributeTarget::SphereInstances,
            t => return Err(format!("attribute {i}: unknown target {t}")),
        };
        let components = get_varint(bytes, p).ok_or("attribute components missing")?;
        if components == 0 || components > MAX_COMPONENTS as u64 {
            return Err(format!("attribute {i}: {components} components"));
        }
        let name_len = get_varint(bytes, p).ok_or("attribute name missing")?;
        let name = usize::try_from(name_len)
            .ok()
            .and_then(|n| take(bytes, p, n))
            .ok_or("attribute name cut off")?;
        let name = String::from_utf8(name.to_vec())
            .map_err(|_| format!("attribute {i}: name is not UTF-8"))?;
        attributes.push(AttributeInfo {
            name,
            components: components as usize,
            target,
        });
    }
    if *p != bytes.len() {
        return Err("trailing bytes after the attribute descriptor".into());
    }
    Ok(Descriptor {
        error_bound,
        attributes,
    })
}

/// Checks that `attributes` hold `items` items each, quantizable with `step`.
pub(crate) fn check(
    attributes: &[Attribute],
    items: usize,
    what: &str,
    step: f64,
) -> Result<(), String> {
    for a in attributes {
        if a.components == 0 || a.components > MAX_COMPONENTS {
            return Err(format!(
                "attribute {:?}: {} components (1 to {MAX_COMPONENTS})",
                a.name, a.components
            ));
        }
        if a.values.len() != a.components * items {
            return Err(format!(
                "attribute {:?}: {} values for {items} {what} of {} components",
                a.name,
                a.values.len(),
                a.components
            ));
        }
        if let Some(v) = a
            .values
            .iter()
            .find(|v| !(v.is_finite() && (**v as f64 / step).abs() <= MAX_QUANTUM))
        {
            return Err(format!(
                "attribute {:?}: value {v} is not finite or too large for the attribute error bound",
                a.name
            ));
        }
    }
    Ok(())
}

/// One attribute's stream: the items `order` names (all items in order when `None`).
fn encode_stream(a: &Attribute, order: Option<&[u32]>, step: f64, out: &mut Vec<u8>) {
    let k = a.components;
    let items = order.map_or(a.len(), |o| o.len());
    for c in 0..k {
        let mut previous = 0i64;
        for i in 0..items {
            let item = order.map_or(i, |o| o[i] as usize);
            let q = (a.values[item * k + c] as f64 / step).round() as i64;
            put_varint(out, zigzag(q - previous));
            previous = q;
        }
    }
}

/// The payload of a frame with attributes (checked with [`check`]): `geometry` is the
/// frame's payload without them, `order` the fluid's control vertices in decoding order
/// (indices into `fluid`'s items), `spheres` the per-instance attributes of the stored
/// instances.
pub(crate) fn encode_payload(
    error_bound: f64,
    fluid: &[Attribute],
    order: &[u32],
    spheres: &[Attribute],
    geometry: &[u8],
    zstd_level: i32,
) -> std::io::Result<Vec<u8>> {
    let step = 2.0 * error_bound;
    let mut descriptor = Vec::new();
    descriptor.extend_from_slice(&error_bound.to_le_bytes());
    put_varint(&mut descriptor, (fluid.len() + spheres.len()) as u64);
    let mut raw = Vec::new();
    let mut stream = Vec::new();
    let all = fluid
        .iter()
        .map(|a| (a, 0u8, Some(order)))
        .chain(spheres.iter().map(|a| (a, 1u8, None)));
    for (a, target, order) in all {
        descriptor.push(target);
        put_varint(&mut descriptor, a.components as u64);
        put_varint(&mut descriptor, a.name.len() as u64);
        descriptor.extend_from_slice(a.name.as_bytes());
        stream.clear();
        encode_stream(a, order, step, &mut stream);
        put_varint(&mut raw, stream.len() as u64);
        raw.extend_from_slice(&stream);
    }
    let streams = zstd::bulk::compress(&raw, zstd_level)?;
    let mut payload = Vec::with_capacity(descriptor.len() + geometry.len() + streams.len() + 16);
    payload.extend_from_slice(&(descriptor.len() as u32).to_le_bytes());
    payload.extend_from_slice(&descriptor);
    payload.extend_from_slice(&crc32fast::hash(&descriptor).to_le_bytes());
    payload.extend_from_slice(&(geometry.len() as u64).to_le_bytes());
    payload.extend_from_slice(geometry);
    payload.extend_from_slice(&streams);
    Ok(payload)
}

/// Decodes the attribute streams of a frame whose geometry decoded to `fluid_items`
/// control vertices and `instances` sphere instances: the fluid's attributes (one item
/// per control vertex, in decoding order) and the spheres'.
pub(crate) fn decode_streams(
    descriptor: &Descriptor,
    streams: &[u8],
    fluid_items: usize,
    instances: usize,
) -> Result<(Vec<Attribute>, Vec<Attribute>), String> {
    let items = |t: AttributeTarget| match t {
        AttributeTarget::FluidVertices => fluid_items,
        AttributeTarget::SphereInstances => instances,
    };
    // At most a 10-byte varint per value plus each stream's length: the counts come from
    // the decoded geometry, the components are bounded by the descriptor.
    let capacity = descriptor
        .attributes
        .iter()
        .map(|a| (a.components * 10).saturating_mul(items(a.target)) + 10)
        .fold(64usize, usize::saturating_add);
    if zstd::zstd_safe::get_frame_content_size(streams)
        .ok()
        .flatten()
        .is_none()
    {
        return Err("attribute streams: zstd frame without its content size".into());
    }
    let raw = decompress(streams, capacity).map_err(|e| format!("attribute streams: {e}"))?;
    let step = 2.0 * descriptor.error_bound;
    let pos = &mut 0usize;
    let (mut fluid, mut spheres) = (Vec::new(), Vec::new());
    for a in &descriptor.attributes {
        let n = items(a.target);
        let len = get_varint(&raw, pos)
            .ok_or_else(|| format!("attribute {:?}: stream length missing", a.name))?;
        let stream = usize::try_from(len)
            .ok()
            .and_then(|l| take(&raw, pos, l))
            .ok_or_else(|| format!("attribute {:?}: stream cut off", a.name))?;
        let k = a.components;
        // Every value takes at least one byte.
        if stream.len() < n * k {
            return Err(format!(
                "attribute {:?}: stream of {} bytes cannot hold {n} items",
                a.name,
                stream.len()
            ));
        }
        let mut values = vec![0f32; n * k];
        let p = &mut 0usize;
        for c in 0..k {
            let mut q = 0i64;
            for i in 0..n {
                let d = get_varint(stream, p)
                    .ok_or_else(|| format!("attribute {:?}: stream ends early", a.name))?;
                q = q.wrapping_add(unzigzag(d));
                values[i * k + c] = (q as f64 * step) as f32;
            }
        }
        if *p != stream.len() {
            return Err(format!(
                "attribute {:?}: stream holds more than {n} items",
                a.name
            ));
        }
        let attribute = Attribute {
            name: a.name.clone(),
            components: k,
            values,
        };
        match a.target {
            AttributeTarget::FluidVertices => fluid.push(attribute),
            AttributeTarget::SphereInstances => spheres.push(attribute),
        }
    }
    if *pos != raw.len() {
        return Err("trailing bytes after the attribute streams".into());
    }
    Ok((fluid, spheres))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> (Vec<Attribute>, Vec<Attribute>) {
        let fluid = vec![Attribute {
            name: "velocity".into(),
            components: 3,
            values: (0..300).map(|i| (i as f32 * 0.37).sin() * 3.0).collect(),
        }];
        let spheres = vec![Attribute {
            name: "density".into(),
            components: 1,
            values: vec![1000.0, 998.5, 1001.25],
        }];
        (fluid, spheres)
    }

    #[test]
    fn streams_round_trip_in_the_given_order() {
        let (fluid, spheres) = sample();
        let order: Vec<u32> = (0..100).rev().collect();
        let payload = encode_payload(1e-3, &fluid, &order, &spheres, b"geometry", 3).unwrap();
        let s = split(&payload).unwrap();
        assert_eq!(s.geometry, b"geometry");
        assert_eq!(s.descriptor.error_bound, 1e-3);
        let (f, sp) = decode_streams(&s.descriptor, s.streams, 100, 3).unwrap();
        for i in 0..100 {
            for c in 0..3 {
                let want = fluid[0].item(99 - i)[c];
                assert!((f[0].item(i)[c] - want).abs() <= 1e-3 + 1e-6);
            }
        }
        assert_eq!(sp[0].values, [1000.0, 998.5, 1001.25]);
        // Counts that disagree with the streams are errors.
        assert!(decode_streams(&s.descriptor, s.streams, 99, 3).is_err());
        assert!(decode_streams(&s.descriptor, s.streams, 100, 4).is_err());
    }

    #[test]
    fn damaged_sections_are_errors_not_panics() {
        let (fluid, spheres) = sample();
        let order: Vec<u32> = (0..100).collect();
        let payload = encode_payload(1e-3, &fluid, &order, &spheres, b"geometry", 3).unwrap();
        for i in 0..payload.len() {
            for delta in [1u8, 0x80, 0xff] {
                let mut bad = payload.clone();
                bad[i] = bad[i].wrapping_add(delta);
                if let Ok(s) = split(&bad) {
                    let _ = decode_streams(&s.descriptor, s.streams, 100, 3);
                }
            }
        }
        for cut in 0..payload.len() {
            if let Ok(s) = split(&payload[..cut]) {
                assert!(decode_streams(&s.descriptor, s.streams, 100, 3).is_err());
            }
        }
        // Valid zstd frames around hostile content: huge lengths, values that overflow.
        let descriptor = split(&payload).unwrap().descriptor;
        let mut huge = Vec::new();
        put_varint(&mut huge, u64::MAX);
        let mut overflow = Vec::new();
        put_varint(&mut overflow, 600);
        for _ in 0..300 {
            put_varint(&mut overflow, u64::MAX);
        }
        put_varint(&mut overflow, 3);
        overflow.extend([0, 0, 0]);
        for raw in [huge, overflow, vec![0x80; 20]] {
            let streams = zstd::bulk::compress(&raw, 1).unwrap();
            let _ = decode_streams(&descriptor, &streams, 100, 3);
        }
    }
}
