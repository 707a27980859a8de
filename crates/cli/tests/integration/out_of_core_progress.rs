//! The out-of-core warp behind `volmorph warp A.ome.zarr B.ome.zarr`: with progress it writes
//! the same store as the in-memory pull-back; cancelled, it leaves no output store.

use volmorph_deform::Affine;
use volmorph_io::Counter;
use volmorph_volume::{AnyVolume, Geometry, Volume};
use volmorph_volume_io::omezarr::{OmeZarrReader, OmeZarrWriter, ZarrWriteOptions};
use volmorph_warp::WarpError;
use volmorph_warp::chunked::warp_chunked_with;
use volmorph_warp::pullback::{ResampleOptions, resample_any};

fn run(
    reader: &OmeZarrReader,
    out: &std::path::Path,
    map: &Affine,
    progress: &dyn volmorph_io::Progress,
) -> Result<OmeZarrWriter, WarpError> {
    let options = ZarrWriteOptions {
        chunk: [8, 8, 8],
        ..ZarrWriteOptions::default()
    };
    let writer =
        OmeZarrWriter::create(out, reader.geometry(), reader.voxel_type(), &options).unwrap();
    let chunks = writer.chunk_boxes();
    warp_chunked_with(
        map,
        reader.geometry(),
        reader.geometry(),
        &chunks,
        &ResampleOptions::default(),
        |b| reader.read_box(b).map_err(WarpError::from),
        |b, v| writer.write_chunk(b, &v).map_err(WarpError::from),
        progress,
    )?;
    Ok(writer)
}

#[test]
fn cancelled_out_of_core_warp_leaves_no_store() {
    let dir = tempfile::tempdir().unwrap();
    let g = Geometry::new([30, 26, 22]);
    let v = Volume::<u16>::from_fn(g, |i, j, k| (i * 3 + j * 5 + k * 7) as u16).unwrap();
    let input = dir.path().join("in.ome.zarr");
    volmorph_volume_io::write(&input, &AnyVolume::from(v.clone())).unwrap();
    let reader = OmeZarrReader::open(&input).unwrap();
    let map = Affine {
        matrix: glam::DMat3::from_rotation_z(0.1),
        offset: glam::DVec3::new(1.5, -0.5, 0.25),
    };
    let out = dir.path().join("out.ome.zarr");

    let stop = Counter::cancel_after(1);
    let e = run(&reader, &out, &map, &stop).map(drop).unwrap_err();
    assert!(matches!(e, WarpError::Cancelled(_)), "{e}");
    assert!(!out.exists(), "a cancelled warp left {}", out.display());

    let count = Counter::new();
    run(&reader, &out, &map, &count).unwrap().finish().unwrap();
    assert_eq!(count.steps(), count.announced());
    let written = volmorph_volume_io::read(&out).unwrap();
    let full = resample_any(&AnyVolume::from(v), &map, &g, &ResampleOptions::default()).unwrap();
    assert_eq!(written, full);
}
