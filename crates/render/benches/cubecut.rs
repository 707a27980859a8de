//! Cube cutting (McPhail ch. 2): proxy-polygon generation time for 64–1024 view-aligned
//! slices by the table-driven sweep, Rezk-Salama and Kolb's per-vertex method and clipping,
//! on a single cube, on the octree-culled teapot at 256³ (a largely empty volume, as the
//! thesis' Fig. 2.9) and on the octree-culled cranium CT under the CT bone preset (when the
//! file is present: `VOLMORPH_BENCH_CT`, or `../shared/data/volumes/cranium_ct.nii.gz` from
//! the workspace root; the group is skipped otherwise). Target: 256 slices over the
//! octree-culled 256³ volume in at most 2 ms.
//!
//! `cargo bench -p volmorph-render --bench cubecut`

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use glam::{DMat3, DVec3};
use volmorph_render::cubecut::cut_box;
use volmorph_render::{
    CutMethod, DvrOptions, DvrRenderer, DvrVolume, ProxyBox, ProxyGeometry, Slicing,
    TransferFunction, TransferPreset,
};
use volmorph_volume::AnyVolume;
use volmorph_volume::phantom::{Phantom, density};

const SLICES: [usize; 5] = [64, 128, 256, 512, 1024];
const METHODS: [(CutMethod, &str); 3] = [
    (CutMethod::Sweep, "sweep"),
    (CutMethod::Rsk, "rsk"),
    (CutMethod::Clip, "clip"),
];

/// An oblique view direction (no symmetry to exploit).
fn forward() -> DVec3 {
    DVec3::new(0.31, -0.52, 0.79)
}

fn single_cube(c: &mut Criterion) {
    let bx = ProxyBox {
        origin: DVec3::ZERO,
        axes: DMat3::IDENTITY,
        tex_origin: DVec3::ZERO,
        tex_size: DVec3::ONE,
    };
    let mut g = c.benchmark_group("cubecut_single_cube");
    let mut out = ProxyGeometry::default();
    for n in SLICES {
        let slicing = Slicing::across(forward(), &bx.corners(), n).expect("slicing");
        g.throughput(Throughput::Elements(n as u64));
        for (method, name) in METHODS {
            g.bench_with_input(BenchmarkId::new(name, n), &slicing, |b, s| {
                b.iter(|| {
                    out.clear();
                    cut_box(black_box(&bx), s, method, &mut out);
                    out.polygons.len()
                });
            });
        }
    }
    g.finish();
}

fn octree_culled(c: &mut Criterion) {
    let teapot = density(Phantom::Teapot, [256; 3]).expect("phantom");
    let dv = DvrVolume::new(&AnyVolume::from(teapot)).expect("prepare");
    let tf = TransferFunction::parse("0:0,0,0,0; 126:0,0,0,0; 127:1,1,1,0.5; 255:1,1,1,1")
        .expect("transfer function");
    culled(c, "cubecut_teapot256_culled", &dv, tf);
}

fn ct_culled(c: &mut Criterion) {
    let path = std::env::var_os("VOLMORPH_BENCH_CT").map_or_else(
        || {
            std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../../shared/data/volumes/cranium_ct.nii.gz")
        },
        std::path::PathBuf::from,
    );
    if !path.is_file() {
        eprintln!("cubecut_ct_culled skipped: no CT at {}", path.display());
        return;
    }
    let volume = volmorph_volume_io::read(&path).expect("CT volume");
    let dv = DvrVolume::new(&volume).expect("prepare");
    let tf = TransferPreset::CtBone
        .build(dv.value_range())
        .expect("transfer function");
    culled(c, "cubecut_ct_culled", &dv, tf);
}

/// Proxy geometry of the octree nodes of `dv` visible under `tf`, per method and slice count.
fn culled(c: &mut Criterion, name: &str, dv: &DvrVolume, tf: TransferFunction) {
    let r = DvrRenderer::new(dv, DvrOptions::new(tf)).expect("renderer");
    // Octree level 2: nodes of 16³ cells, the thesis' depth 4 on a 256³ volume.
    let level = 2;
    let mut g = c.benchmark_group(name);
    g.sample_size(30);
    let mut out = ProxyGeometry::default();
    for n in SLICES {
        let slicing =
            Slicing::across(forward(), &dv.geometry().corner_points(), n).expect("slicing");
        g.throughput(Throughput::Elements(n as u64));
        for (method, name) in METHODS {
            g.bench_with_input(BenchmarkId::new(name, n), &slicing, |b, s| {
                b.iter(|| {
                    r.proxy_geometry_into(s, level, method, &mut out)
                        .expect("level exists");
                    out.polygons.len()
                });
            });
        }
    }
    g.finish();
}

criterion_group!(benches, single_cube, octree_culled, ct_culled);
criterion_main!(benches);
