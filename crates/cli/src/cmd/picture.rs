//! Picture options shared by the commands that draw: the picture size. Cameras, framing,
//! shading and mesh pictures are `volmorph_render`'s ([`volmorph_render::Orbit::mesh_camera`],
//! [`volmorph_render::write_mesh_png`]).

/// Parse a picture size `WIDTHxHEIGHT` (e.g. `800x600`) or one number for a square.
///
/// # Errors
/// As [`crate::args::size`].
pub fn size(s: &str) -> anyhow::Result<(u32, u32)> {
    crate::args::size(s)
}
