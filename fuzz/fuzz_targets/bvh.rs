//! The BVH reader on any text, and what a parsed clip is used for at once (rate, rest and posed
//! joint positions): a clip or an error, never a panic.
#![no_main]
use garmentbake::io::bvh::Bvh;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(bvh) = Bvh::parse(text, "fuzz.bvh") {
        let _ = (bvh.fps(), bvh.duration());
        let _ = bvh.world_rest_positions();
        if bvh.frame_count() > 0 {
            let _ = bvh.world_pose(bvh.frame_count() - 1);
        }
        let _ = bvh.capture();
    }
});
