//! volmorph-render: the picture layer shared by volmorph's renderers — slice pictures,
//! ray-cast images of deformed volumes, F-rep shapes and NURBS volumes, Jacobian maps and
//! registration overlays.
//!
//! * [`RgbaImage`] / [`ScalarImage`] — pixel buffers, row-major with **row 0 at the top**;
//!   straight-alpha compositing with [`blend_over`].
//! * [`Window`] — window/level intensity mapping; [`Colormap`] — grey, hot, viridis, turbo
//!   and Moreland's cool-warm as 256-entry tables; [`render_scalar`] / [`ScalarStyle`] turn an
//!   f32 field into colour (NaN colour, diverging centre).
//! * [`write_png_rgba`], [`write_png_rgb`], [`write_png_grey8`], [`write_png_grey16`] (atomic
//!   writes) and [`read_png`] (any PNG to RGBA8).
//! * [`Camera`] — pinhole and orthographic projections with pixel-centre rays and their
//!   inverse [`Camera::project`]; [`Ray`] and [`Aabb`] with slab intersection.
//! * [`draw`] — lines, markers and rectangles for handle overlays.
//! * [`render_triangles`] — z-buffered, shaded pictures of triangle meshes ([`ShadeStyle`]).
//!
//! Geometry is f64 ([`glam::DVec3`]); image values are f32; colours are 8-bit sRGB-coded.
//! The crate receives plain 2-D fields and knows nothing of volumes.

mod camera;
mod colormap;
pub mod draw;
mod error;
mod geometry;
mod image;
mod png_file;
mod raster;
mod window;

pub use camera::{Camera, FIT_MARGIN, Projection};
pub use colormap::{Colormap, LUT_SIZE, Lut, ScalarStyle, render_scalar, render_scalar_with};
pub use error::RenderError;
pub use geometry::{Aabb, Ray};
pub use image::{MAX_IMAGE_PIXELS, RgbaImage, ScalarImage, blend_over, finite_range, luma709};
pub use png_file::{
    decode_png, encode_png_rgba, read_png, write_png_grey8, write_png_grey16, write_png_rgb,
    write_png_rgba,
};
pub use raster::{MAX_SUPERSAMPLE, ShadeStyle, render_triangles};
pub use window::Window;
