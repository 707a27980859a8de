//! The PLY, STL and OFF readers give the same mesh, or the same error, whether their input is
//! a slice or a stream refilled a few bytes at a time, of known or unknown size.

use volmorph_testkit::Rng;

use super::input::Input;
use super::ply::{PlyEncoding, PlyProperties, PlyProperty, PlyValues};
use super::{MeshColors, MeshFormat, MeshWriteOptions, off, ply, stl, to_bytes};
use crate::{DVec3, Mesh, MeshError};

type Read = Result<(Mesh, Option<MeshColors>), MeshError>;

/// Triangles and quads, coordinates not `f32`-representable.
fn mixed() -> Mesh {
    let p: Vec<DVec3> = (0..8u32)
        .map(|i| {
            DVec3::new(f64::from(i & 1), f64::from((i >> 1) & 1), f64::from(i >> 2))
                * DVec3::new(0.1, 1.0 / 3.0, -2.0e-7)
                + DVec3::new(1e5, -0.0, 7.25)
        })
        .collect();
    let faces: [&[u32]; 7] = [
        &[0, 2, 3, 1],
        &[4, 5, 7],
        &[4, 7, 6],
        &[0, 1, 5, 4],
        &[2, 6, 7, 3],
        &[0, 4, 6, 2],
        &[1, 3, 7, 5],
    ];
    Mesh::from_polygons(p, faces).unwrap()
}

fn samples() -> Vec<(MeshFormat, Vec<u8>)> {
    let m = mixed();
    let mut out = Vec::new();
    for format in [MeshFormat::Ply, MeshFormat::Stl, MeshFormat::Off] {
        for (binary, big_endian, single_precision) in [
            (false, false, false),
            (true, false, false),
            (true, true, true),
        ] {
            let o = MeshWriteOptions {
                binary,
                big_endian,
                single_precision,
            };
            out.push((format, to_bytes(&m, format, &o).unwrap()));
        }
    }
    // Colours per vertex (uchar, after a float) and per face (float), in every encoding.
    let nv = m.vertex_count();
    let ch: Vec<u8> = (0..nv).map(|i| (i * 37) as u8).collect();
    let dens: Vec<f32> = (0..nv).map(|i| i as f32 * 0.5).collect();
    let fc: Vec<f32> = (0..m.face_count()).map(|i| i as f32 / 8.0).collect();
    let props = PlyProperties {
        vertex: vec![
            PlyProperty {
                name: "density",
                values: PlyValues::F32(&dens),
            },
            PlyProperty {
                name: "red",
                values: PlyValues::U8(&ch),
            },
            PlyProperty {
                name: "green",
                values: PlyValues::U8(&ch),
            },
            PlyProperty {
                name: "blue",
                values: PlyValues::U8(&ch),
            },
        ],
        face: ["red", "green", "blue"]
            .map(|name| PlyProperty {
                name,
                values: PlyValues::F32(&fc),
            })
            .to_vec(),
    };
    for enc in [
        PlyEncoding::Ascii,
        PlyEncoding::BinaryLittleEndian,
        PlyEncoding::BinaryBigEndian,
    ] {
        let mut b = Vec::new();
        ply::write_ply_with_properties(&mut b, &m, enc, false, &props).unwrap();
        out.push((MeshFormat::Ply, b.clone()));
        // Face colours only: the vertex element without lists is read in bulk.
        let only_faces = PlyProperties {
            vertex: Vec::new(),
            face: props.face.clone(),
        };
        b.clear();
        ply::write_ply_with_properties(&mut b, &m, enc, false, &only_faces).unwrap();
        out.push((MeshFormat::Ply, b));
    }
    // Header comments, blank lines and OFF comments.
    let text = String::from_utf8(out[0].1.clone()).unwrap();
    out.push((
        MeshFormat::Ply,
        text.replacen("format", "comment a b c\n\nobj_info x\nformat", 1)
            .into_bytes(),
    ));
    let off = String::from_utf8(out[6].1.clone()).unwrap();
    out.push((
        MeshFormat::Off,
        off.replace('\n', "  # note\n\n").into_bytes(),
    ));
    out
}

fn via<S: super::input::Source>(format: MeshFormat, input: &mut Input<S>) -> Read {
    match format {
        MeshFormat::Ply => ply::read_ply_input(input, true),
        MeshFormat::Stl => stl::read_stl_input(input).map(|m| (m, None)),
        MeshFormat::Off => off::read_off_input(input).map(|m| (m, None)),
        MeshFormat::Obj => unreachable!("OBJ has its own stream reader"),
    }
}

/// Positions as bit patterns (NaN equals itself), faces and colours, or the error message.
type Outcome = Result<(Vec<[u64; 3]>, Vec<Vec<u32>>, Option<MeshColors>), String>;

fn outcome(r: &Read) -> Outcome {
    match r {
        Ok((m, c)) => Ok((
            m.positions()
                .iter()
                .map(|p| p.to_array().map(f64::to_bits))
                .collect(),
            m.faces().map(<[u32]>::to_vec).collect(),
            c.clone(),
        )),
        Err(e) => Err(e.to_string()),
    }
}

/// The slice reader and stream readers with refills of each of `chunks` bytes agree on
/// `bytes`, the stream's size known or not.
fn check(format: MeshFormat, bytes: &[u8], chunks: &[usize]) {
    let whole = via(format, &mut Input::slice(bytes, format));
    for &chunk in chunks {
        for len in [Some(bytes.len() as u64), None] {
            let mut input = Input::reader_with_chunk(bytes, len, format, String::new(), chunk);
            let streamed = via(format, &mut input);
            // A binary STL header declaring more triangles than the budget can index is
            // refused before reading when the size is unknown; with the size known the
            // truncation is reported first.
            if len.is_none()
                && format == MeshFormat::Stl
                && matches!(
                    streamed,
                    Err(MeshError::Io(volmorph_io::IoError::Budget { .. }))
                )
                && whole
                    .as_ref()
                    .is_err_and(|e| e.to_string().contains("triangles, needing"))
            {
                continue;
            }
            assert_eq!(
                outcome(&whole),
                outcome(&streamed),
                "{format} input of {} bytes, chunk {chunk}, size {len:?}:\n{}",
                bytes.len(),
                String::from_utf8_lossy(&bytes[..bytes.len().min(400)])
            );
        }
    }
}

#[test]
fn slice_and_stream_readers_agree_on_truncated_and_mutated_input() {
    let mut rng = Rng::new(0x5eed_57e4);
    for (format, bytes) in samples() {
        check(format, &bytes, &[1, 2, 7, 4096]);
        for cut in 0..bytes.len() {
            check(format, &bytes[..cut], &[3]);
        }
        for _ in 0..200 {
            let mut b = bytes.clone();
            for _ in 0..1 + rng.index(4) {
                let i = rng.index(b.len());
                b[i] = match rng.index(5) {
                    0 => rng.next_u64() as u8,
                    1 => b'9',
                    2 => 0xff,
                    3 => b'\n',
                    _ => b' ',
                };
            }
            check(format, &b, &[1, 5]);
        }
    }
}

/// Inputs whose data straddles refills in every way the readers handle: long lines and
/// words, comments across the window, binary items and face lists larger than a refill.
#[test]
fn long_items_straddle_refills() {
    // A polygon of 40 000 corners: its binary index list and its text lines exceed a refill.
    let n = 40_000u32;
    let p: Vec<DVec3> = (0..n)
        .map(|i| {
            let a = f64::from(i) / f64::from(n) * std::f64::consts::TAU;
            DVec3::new(a.cos(), a.sin(), 0.0)
        })
        .collect();
    let face: Vec<u32> = (0..n).collect();
    let m = Mesh::from_polygons(p, [face.as_slice()]).unwrap();
    for format in [MeshFormat::Ply, MeshFormat::Off] {
        for binary in [false, true] {
            let o = MeshWriteOptions {
                binary,
                ..MeshWriteOptions::default()
            };
            let bytes = to_bytes(&m, format, &o).unwrap();
            check(format, &bytes, &[4093, super::input::CHUNK]);
            let back = via(format, &mut Input::slice(&bytes, format)).unwrap().0;
            assert_eq!(back, m);
        }
    }
    // A bad index near the end of a long binary list in a stream: reported once the list is
    // whole, and the truncation instead when it is not.
    let mut bytes = to_bytes(&m, MeshFormat::Ply, &MeshWriteOptions::default()).unwrap();
    let k = bytes.len() - 8;
    bytes[k..k + 4].copy_from_slice(&(n as i32).to_le_bytes());
    check(MeshFormat::Ply, &bytes, &[4093]);
    check(MeshFormat::Ply, &bytes[..bytes.len() - 2], &[4093]);
    // A comment line longer than a refill, in PLY's header and in OFF.
    let long = "z".repeat(100_000);
    let ply_text =
        String::from_utf8(to_bytes(&mixed(), MeshFormat::Ply, &MeshWriteOptions::ascii()).unwrap())
            .unwrap()
            .replacen("format", &format!("comment {long}\nformat"), 1);
    check(MeshFormat::Ply, ply_text.as_bytes(), &[4093, 65536]);
    let off_text =
        String::from_utf8(to_bytes(&mixed(), MeshFormat::Off, &MeshWriteOptions::ascii()).unwrap())
            .unwrap()
            .replacen('\n', &format!(" # {long}\n"), 3);
    check(MeshFormat::Off, off_text.as_bytes(), &[4093, 65536]);
}
