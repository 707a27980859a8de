//! Fuzz the assembly of a DICOM series from a folder (sorting along the slice normal, the
//! checks of spacing, orientation, size and type across slices, rescale per slice): the fuzz
//! input is cut into up to three files (each given the `DICM` preamble when it lacks one),
//! written into a folder and read as one series. Any bytes must give a volume or an error,
//! never a panic, a hang or an allocation beyond the memory budget.
#![no_main]
use libfuzzer_sys::fuzz_target;

/// The cut points are read from the input's first two bytes (in units of 16 bytes).
const UNIT: usize = 16;

fn with_preamble(data: &[u8]) -> Vec<u8> {
    let mut file = Vec::with_capacity(data.len() + 132);
    if data.len() < 132 || &data[128..132] != b"DICM" {
        file.extend_from_slice(&[0u8; 128]);
        file.extend_from_slice(b"DICM");
    }
    file.extend_from_slice(data);
    file
}

fuzz_target!(|data: &[u8]| {
    volmorph_io::set_memory_limit(512 << 20);
    let [a, b, rest @ ..] = data else {
        return;
    };
    let first = (usize::from(*a) * UNIT).min(rest.len());
    let second = (first + usize::from(*b) * UNIT).min(rest.len());
    let parts = [&rest[..first], &rest[first..second], &rest[second..]];
    let Ok(dir) = tempfile::tempdir() else {
        return;
    };
    for (i, part) in parts.iter().enumerate().filter(|(_, p)| !p.is_empty()) {
        std::fs::write(dir.path().join(format!("{i}.dcm")), with_preamble(part))
            .expect("scratch file");
    }
    let _ = volmorph_volume_io::read(dir.path());
});
