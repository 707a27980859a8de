//! Picture deformation reports one step per row of grid quads, can be cancelled, and gives
//! with progress the same picture as without, bit for bit.

use glam::DVec3;
use volmorph_deform::DeformError;
use volmorph_handles::HandleSet;
use volmorph_handles::mls2d::{
    Mls2dKind, warp_picture, warp_picture_tps, warp_picture_tps_with, warp_picture_with,
};
use volmorph_testkit::progress;

fn set() -> HandleSet {
    let pairs = [
        ([10.0, 10.0], [12.0, 9.0]),
        ([80.0, 12.0], [78.0, 15.0]),
        ([45.0, 40.0], [50.0, 36.0]),
        ([12.0, 70.0], [10.0, 72.0]),
        ([85.0, 68.0], [83.0, 66.0]),
    ];
    HandleSet {
        dim: 2,
        points: pairs
            .iter()
            .map(|(a, b)| (DVec3::new(a[0], a[1], 0.0), DVec3::new(b[0], b[1], 0.0)))
            .collect(),
        segments: Vec::new(),
        frames: Vec::new(),
    }
}

#[test]
fn picture_warps_report_quad_rows_and_cancel() {
    let (w, h) = (96u32, 80u32);
    let px: Vec<[u8; 4]> = (0..w * h)
        .map(|n| [(n % 251) as u8, (n / 7 % 253) as u8, (n / 96) as u8, 255])
        .collect();
    let s = set();
    let grid = 24;
    let plain = warp_picture(w, h, &px, &s, Mls2dKind::Rigid, 1.0, grid).unwrap();
    let with =
        progress::check(|p| warp_picture_with(w, h, &px, &s, Mls2dKind::Rigid, 1.0, grid, p));
    assert_eq!(plain, with);
    assert_eq!(
        progress::total_steps(|p| warp_picture_with(
            w,
            h,
            &px,
            &s,
            Mls2dKind::Affine,
            1.0,
            grid,
            p
        )),
        (grid - 1) as u64
    );
    let plain = warp_picture_tps(w, h, &px, &s, grid).unwrap();
    let with = progress::check(|p| warp_picture_tps_with(w, h, &px, &s, grid, p));
    assert_eq!(plain, with);
    let e = progress::cancelled(|p| warp_picture_tps_with(w, h, &px, &s, grid, p), 1, 23);
    assert!(matches!(e, DeformError::Cancelled(_)), "{e}");
}
