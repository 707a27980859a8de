//! Median times of reading a dragon-sized mesh (a triangulated torus with 435 600 vertices and
//! 871 200 triangles) in every format: from a plain file and from a gzip file through
//! [`read`], and from bytes in memory through [`read_bytes`]. Further mesh files named on the
//! command line are timed through [`read`] too.
//!
//! Run with `cargo run --release -p volmorph-mesh --features examples --example
//! mesh_read_timing -- [repetitions] [mesh files…]` (7 repetitions by default).

use std::io::Write;
use std::path::Path;
use std::time::Instant;

use flate2::Compression;
use flate2::write::GzEncoder;
use volmorph_mesh::{DVec3, Mesh, MeshFormat, MeshWriteOptions, read, read_bytes, to_bytes};

fn torus(n: u32, m: u32) -> Mesh {
    let mut p = Vec::with_capacity((n * m) as usize);
    for i in 0..n {
        for j in 0..m {
            let u = f64::from(i) / f64::from(n) * std::f64::consts::TAU;
            let v = f64::from(j) / f64::from(m) * std::f64::consts::TAU;
            let r = 0.08 + 0.03 * v.cos();
            // Round to f32 like a scanned model stored with `property float`.
            p.push(
                DVec3::new(r * u.cos(), r * u.sin(), 0.03 * v.sin())
                    .as_vec3()
                    .as_dvec3(),
            );
        }
    }
    let id = |i: u32, j: u32| (i % n) * m + (j % m);
    let mut tris = Vec::with_capacity(2 * (n * m) as usize);
    for i in 0..n {
        for j in 0..m {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            tris.push([a, b, c]);
            tris.push([a, c, d]);
        }
    }
    Mesh::from_triangles(p, &tris).expect("valid torus")
}

/// Median and minimum of `reps` runs of `f`, in milliseconds.
fn median_ms<T>(reps: usize, mut f: impl FnMut() -> T) -> (f64, f64) {
    let mut t: Vec<f64> = (0..reps)
        .map(|_| {
            let s = Instant::now();
            std::hint::black_box(f());
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    (t[t.len() / 2], t[0])
}

fn report(label: &str, source: &str, (median, min): (f64, f64)) {
    println!("{label:<34} {source:<7} median {median:>8.1} ms   min {min:>8.1} ms");
}

fn main() {
    let mut args = std::env::args().skip(1);
    let reps: usize = args
        .next()
        .map_or(7, |s| s.parse().expect("repetitions: a number"))
        .max(1);
    let extra: Vec<String> = args.collect();
    let mesh = torus(660, 660);
    println!(
        "mesh: {} vertices, {} triangles; {reps} repetitions",
        mesh.vertex_count(),
        mesh.face_count()
    );
    let dir = tempfile::tempdir().expect("temporary folder");
    let cases = [
        (MeshFormat::Ply, "binary LE PLY, double", true, false),
        (MeshFormat::Ply, "binary LE PLY, float", true, true),
        (MeshFormat::Ply, "ASCII PLY, double", false, false),
        (MeshFormat::Stl, "binary STL", true, false),
        (MeshFormat::Stl, "ASCII STL", false, false),
        (MeshFormat::Off, "OFF", false, false),
        (MeshFormat::Obj, "OBJ", false, false),
    ];
    for (k, (format, label, binary, single_precision)) in cases.into_iter().enumerate() {
        let o = MeshWriteOptions {
            binary,
            big_endian: false,
            single_precision,
        };
        let bytes = to_bytes(&mesh, format, &o).expect("write");
        let plain = dir.path().join(format!("m{k}.{}", format.extension()));
        std::fs::write(&plain, &bytes).expect("write file");
        let mut enc = GzEncoder::new(Vec::new(), Compression::default());
        enc.write_all(&bytes).expect("compress");
        let gz_bytes = enc.finish().expect("compress");
        let gz = dir.path().join(format!("m{k}.{}.gz", format.extension()));
        std::fs::write(&gz, &gz_bytes).expect("write file");
        println!(
            "{label}: {:.1} MB, {:.1} MB gzipped",
            bytes.len() as f64 / 1e6,
            gz_bytes.len() as f64 / 1e6
        );
        let faces = mesh.face_count();
        report(
            label,
            "file",
            median_ms(reps, || {
                assert_eq!(read(&plain).expect("read").face_count(), faces);
            }),
        );
        report(
            label,
            "gzip",
            median_ms(reps, || {
                assert_eq!(read(&gz).expect("read").face_count(), faces);
            }),
        );
        report(
            label,
            "memory",
            median_ms(reps, || {
                assert_eq!(
                    read_bytes(&bytes, format).expect("read").face_count(),
                    faces
                );
            }),
        );
    }
    for name in extra {
        let p = Path::new(&name);
        let m = read(p).expect("read");
        println!(
            "{name}: {} vertices, {} faces",
            m.vertex_count(),
            m.face_count()
        );
        report(&name, "file", median_ms(reps, || read(p).expect("read")));
    }
}
