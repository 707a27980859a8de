//! Phantom generation reports one step per z-slice, can be cancelled, and gives with
//! progress the same volume as without, bit for bit.

use volmorph_testkit::progress;
use volmorph_volume::VolumeError;
use volmorph_volume::phantom::{self, Phantom};

#[test]
fn phantoms_report_slices_and_cancel() {
    for ph in [Phantom::Sphere, Phantom::Teapot, Phantom::Tree] {
        let dims = [24, 20, 30];
        let plain = phantom::density(ph, dims).unwrap();
        let with = progress::check(|p| phantom::density_with(ph, dims, p));
        assert_eq!(plain, with, "{}", ph.name());
        let plain = phantom::signed_distance(ph, dims).unwrap();
        let with = progress::check(|p| phantom::signed_distance_with(ph, dims, p));
        let bits = |v: &volmorph_volume::Volume<f32>| {
            v.data().iter().map(|x| x.to_bits()).collect::<Vec<_>>()
        };
        assert_eq!(bits(&plain), bits(&with), "{}", ph.name());
        assert_eq!(
            progress::total_steps(|p| phantom::density_with(ph, dims, p)),
            30
        );
        let e = progress::cancelled(|p| phantom::signed_distance_with(ph, dims, p), 1, 30);
        assert!(matches!(e, VolumeError::Cancelled(_)), "{e}");
    }
}
