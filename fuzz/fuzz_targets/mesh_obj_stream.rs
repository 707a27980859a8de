//! Fuzz the streaming OBJ reader (used for files and gzip streams): any byte stream must
//! give a mesh or an error, and the same mesh as the in-memory reader.
#![no_main]
use libfuzzer_sys::fuzz_target;
fuzz_target!(|data: &[u8]| {
    // The budget every reader checks sizes against, below libFuzzer's -rss_limit_mb.
    volmorph_io::set_memory_limit(512 << 20);
    let mut r = std::io::BufReader::with_capacity(7, data);
    let streamed = volmorph_mesh::format::obj::read_obj_stream(&mut r);
    let whole = volmorph_mesh::read_obj_bytes(data);
    if let (Ok(a), Ok(b)) = (&streamed, &whole) {
        assert_eq!(a, b, "streamed and in-memory OBJ readers disagree");
    }
});
