//! The PC2 and MDD readers on any bytes: frames or an error, never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = exporters::pc2::read(data);
    let _ = exporters::mdd::read(data);
});
