//! The OBJ reader on any bytes: a mesh or an error, never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // As read_obj reads a file: lossy UTF-8.
    let _ = garmentbake::io::obj::parse_obj(&String::from_utf8_lossy(data), "fuzz.obj");
});
