//! volmorph-render: the picture layer shared by volmorph's renderers — slice pictures,
//! mesh pictures, ray-cast images of F-rep shapes and NURBS volumes, Jacobian maps and
//! registration overlays — with one set of camera presets and one shading model.
//!
//! * [`RgbaImage`] / [`ScalarImage`] — pixel buffers, row-major with **row 0 at the top**;
//!   straight-alpha compositing with [`blend_over`].
//! * [`Window`] — window/level intensity mapping ([`Window::auto`]: the automatic window);
//!   [`Colormap`] — grey, hot, viridis, turbo and Moreland's cool-warm as 256-entry tables; [`render_scalar`] / [`ScalarStyle`] turn an
//!   f32 field into colour (NaN colour, diverging centre).
//! * [`write_animation`] — animated PNG or GIF by extension ([`animation`]).
//! * [`write_png_rgba`], [`write_png_rgb`], [`write_png_grey8`], [`write_png_grey16`] (atomic
//!   writes) and [`read_png`] (any PNG to RGBA8).
//! * [`Camera`] — pinhole and orthographic projections with pixel-centre rays and their
//!   inverse [`Camera::project`], framed on a box by [`Camera::frame`]; [`Ray`] and [`Aabb`]
//!   with slab intersection.
//! * [`Orbit`] — the camera presets: azimuth/elevation about a y or z up axis, named views
//!   (front, side, top, iso, anatomical), turntables; [`view_camera`] for any direction.
//! * [`Shading`] — the one shading model (Blinn–Phong, light in the camera frame, linear
//!   light); [`shading`] also holds the sRGB conversions every renderer uses.
//! * [`draw`] — lines, markers and rectangles for handle overlays.
//! * [`render_triangles`] — z-buffered, shaded pictures of triangle meshes ([`ShadeStyle`]);
//!   [`render_mesh`] / [`write_mesh_png`] for a [`volmorph_mesh::Mesh`] with its colours,
//!   through [`Orbit::mesh_camera`].
//! * [`render_slice`] — pictures of volume slices ([`SliceStyle`]): physical aspect, a
//!   readable default size ([`slice_picture_size`]), bilinear resampling, and orientation
//!   labels ([`OrientationLabels`]).
//! * [`annotate`] — the built-in bitmap font and the R/L/A/P/S/I orientation labels.
//!
//! Geometry is f64 ([`glam::DVec3`]); image values are f32; colours are 8-bit sRGB-coded.

pub mod animation;
pub mod annotate;
mod camera;
mod colormap;
pub mod cubecut;
pub mod deformed;
pub mod draw;
pub mod dvr;
mod error;
mod geometry;
mod image;
pub mod mesh_picture;
pub mod octree;
pub mod picture;
mod png_file;
pub mod quality;
mod raster;
pub mod shading;
mod slice_picture;
pub mod transfer;
pub mod view;
mod window;

pub use animation::{
    ANIMATION_EXTENSIONS, AnimationFormat, UNWRITABLE_ANIMATION_EXTENSIONS, check_animation_output,
    check_frames_folder, write_animation, write_gif,
};
pub use annotate::OrientationLabels;
pub use camera::{BOX_FILL, Camera, FIT_MARGIN, Framing, Projection};
pub use colormap::{Colormap, LUT_SIZE, Lut, ScalarStyle, render_scalar, render_scalar_with};
pub use cubecut::{CutMethod, ProxyBox, ProxyGeometry, Slicing};
pub use deformed::DeformedView;
pub use dvr::{ClipPlane, DvrOptions, DvrRenderer, DvrVolume, RenderMode};
pub use error::RenderError;
pub use geometry::{Aabb, Ray};
pub use image::{
    MAX_IMAGE_PIXELS, RgbaImage, ScalarImage, blend_over, finite_range, luma709, psnr,
};
pub use mesh_picture::{render_mesh, write_mesh_png};
pub use picture::{
    CameraKind, ComparePictures, PictureMode, PictureSpec, TransferChoice, VolumePictures,
};
pub use png_file::{
    MAX_APNG_FRAMES, PNG_EXTENSIONS, check_png, decode_png, encode_png_rgba, read_png, write_apng,
    write_png_grey8, write_png_grey16, write_png_rgb, write_png_rgba,
};
pub use quality::{QUALITY_UNITS_ACROSS, QualityOptions, render_quality};
pub use raster::{
    MAX_SUPERSAMPLE, ShadeStyle, SurfaceColors, render_triangles, render_triangles_with_colors,
};
pub use shading::{Lighting, Shading};
pub use slice_picture::{
    DEFAULT_LONG_SIDE, Interpolation, MAX_SLICE_SIDE, PixelAspect, SliceSize, SliceStyle,
    render_slice, slice_picture_size,
};
pub use transfer::{TransferFunction, TransferPreset};
pub use view::{DEFAULT_FOV_Y, Orbit, UpAxis, view_camera};
pub use window::{AUTO_WINDOW_PERCENTILES, Window};
