//! Fuzz the studio's wire format as a page's messages reach it: any bytes must decode to a
//! frame or give an error naming what is wrong (never a panic, a hang or an unbounded
//! allocation), a frame must re-encode to bytes that decode to the same frame, and a decoded
//! header must give a command (scene command or sculpt stroke) or a set-up, or an error.
#![no_main]

use libfuzzer_sys::fuzz_target;
use volmorph_scene::setup::Setup;
use volmorph_studio::command_json::{MAX_SCULPT_POINTS, parse, sculpt};
use volmorph_studio::protocol::{Frame, MAX_CLIENT_FRAME};

fuzz_target!(|data: &[u8]| {
    volmorph_io::set_memory_limit(512 << 20);
    if let Ok(f) = Frame::decode(data) {
        let bytes = f.encode();
        // Re-encoding may lengthen the header (numbers are written in full), past the limit.
        if bytes.len() <= MAX_CLIENT_FRAME {
            check_round_trip(&f, &bytes);
        }
        check_header(&f.header);
    }
    // The same bytes as a bare header (most inputs are not framed).
    if let Ok(h) = serde_json::from_slice::<serde_json::Value>(data) {
        check_header(&h);
    }
});

fn check_header(h: &serde_json::Value) {
    match sculpt(h) {
        Ok(Some(r)) => {
            assert!((1..=MAX_SCULPT_POINTS).contains(&r.points.len()));
            assert!(r.points.iter().all(|p| p.is_finite()));
            assert!(r.size.is_finite() && r.size > 0.0);
        }
        Ok(None) => {
            let _ = parse(h);
        }
        Err(e) => assert!(!e.0.is_empty()),
    }
    let _ = serde_json::from_value::<Setup>(h.clone());
}

fn check_round_trip(f: &Frame, bytes: &[u8]) {
    let again = Frame::decode(bytes).expect("an encoded frame within the limit decodes");
    assert_eq!(again.kind, f.kind);
    assert_eq!(again.request, f.request);
    assert_eq!(again.header, f.header);
    assert_eq!(again.payload, f.payload);
}
