//! Volume file I/O throughput: read and write a 256³ `f32` volume (64 MiB) as NIfTI-1, plain
//! (`.nii`) and gzip-compressed (`.nii.gz`, level 6), in a temporary directory.
//!
//! Compare the medians with the tools' own floor on the same files, e.g.
//! `cat x.nii > /dev/null`, `gzip -6 -c x.nii > /dev/null`, `gunzip -c x.nii.gz > /dev/null`:
//! reading should be limited by the disk (plain) or by inflate (gzip), not by volmorph.
//! Set `VOLMORPH_BENCH_KEEP=<dir>` to write the benchmark files there and keep them.

use std::hint::black_box;
use std::path::PathBuf;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use volmorph_volume::{AnyVolume, DVec3, Geometry, Volume};
use volmorph_volume_io::{self as format, WriteOptions};

const N: usize = 256;

/// CT-like content: integral values from a smooth field plus a little hashed noise, so gzip
/// sees a realistic (not trivial, not random) stream.
fn phantom() -> AnyVolume {
    let g = Geometry::new([N, N, N])
        .with_spacing(DVec3::new(0.75, 0.75, 1.5))
        .with_origin(DVec3::new(-102.0, -102.0, -190.0));
    let v = Volume::from_fn(g, |i, j, k| {
        let (x, y, z) = (
            i as f32 / N as f32 - 0.5,
            j as f32 / N as f32 - 0.5,
            k as f32 / N as f32 - 0.5,
        );
        let r2 = x * x + y * y + z * z;
        let body = if r2 < 0.16 {
            40.0 + 900.0 * (x * 9.0).sin() * (y * 7.0).cos()
        } else {
            -1000.0
        };
        let h =
            (i.wrapping_mul(73_856_093) ^ j.wrapping_mul(19_349_663) ^ k.wrapping_mul(83_492_791))
                % 31;
        (body + h as f32).round()
    })
    .expect("valid geometry");
    v.into()
}

fn bench(c: &mut Criterion) {
    let tmp = tempfile::tempdir().expect("temp dir");
    let dir: PathBuf = std::env::var_os("VOLMORPH_BENCH_KEEP")
        .map_or_else(|| tmp.path().to_path_buf(), PathBuf::from);
    let vol = phantom();
    let bytes = vol.as_bytes().len() as u64;
    let opts = WriteOptions {
        compress: false,
        level: 6,
    };

    let mut g = c.benchmark_group("nifti_256cubed_f32");
    g.sample_size(10);
    g.throughput(Throughput::Bytes(bytes));
    for ext in ["nii", "nii.gz"] {
        let path = dir.join(format!("bench.{ext}"));
        g.bench_function(format!("write .{ext}"), |b| {
            b.iter(|| format::write_with(black_box(&path), &vol, &opts).expect("write"));
        });
        format::write_with(&path, &vol, &opts).expect("write");
        g.bench_function(format!("read .{ext}"), |b| {
            b.iter(|| black_box(format::read(black_box(&path)).expect("read")));
        });
        let back = format::read(&path).expect("read");
        assert!(back.as_bytes() == vol.as_bytes() && back.geometry() == vol.geometry());
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
