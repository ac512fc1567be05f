//! ParaView collection reader (`.pvd`): `sequence::collection_frames`, and
//! `sequence::choose` on the collection with the default choice (which must give the
//! same frames). The empty files `frame_0.vtu` … `frame_3.vtu` beside the input are the
//! datasets an entry may name, so that a collection can be read to the end; their
//! content is not read.
#![no_main]

#[path = "../common/mod.rs"]
mod common;

use libfuzzer_sys::fuzz_target;
use meniscus::sequence::{choose, collection_frames, FrameChoice};
use std::sync::Once;

fuzz_target!(|data: &[u8]| {
    static DATASETS: Once = Once::new();
    DATASETS.call_once(|| {
        for k in 0..4 {
            common::input_file(&format!("frame_{k}.vtu"), b"");
        }
    });
    let path = common::input_file("input.pvd", data);
    let frames = collection_frames(&path);
    match &frames {
        Ok(frames) => {
            assert!(!frames.is_empty(), "a collection without frames is Ok");
            for (k, f) in frames.iter().enumerate() {
                assert_eq!(f.number, k as i64);
                assert_eq!(f.label, k.to_string());
                assert!(f.input.is_file(), "{} is not a file", f.input.display());
            }
            let timed = frames.iter().filter(|f| f.time.is_some()).count();
            assert!(
                timed == 0 || timed == frames.len(),
                "timesteps on some frames only"
            );
            for w in frames.windows(2) {
                if let (Some(a), Some(b)) = (w[0].time, w[1].time) {
                    assert!(a.is_finite() && b.is_finite() && a < b, "times {a}, {b}");
                }
            }
        }
        Err(e) => common::check_error(&path, e),
    }
    let chosen = choose(path.to_str().unwrap(), &FrameChoice::default());
    match (&frames, &chosen) {
        (Ok(a), Ok(b)) => assert_eq!(a, b, "choose disagrees with collection_frames"),
        (Err(_), Err(e)) => common::check_error(&path, e),
        _ => panic!("choose: {chosen:?}, collection_frames: {frames:?}"),
    }
});
