//! Depth-peel sculpting of closed meshes (McPhail, chapter 3).

mod cells;
mod collapse;
mod cut;
mod dexel;
mod document;
mod error;
mod exact;
mod grid;
mod interval;
mod peel;
mod smooth;
mod stitch;
mod store;
mod tool;
mod view;

pub use dexel::{BitVolume, TriDexel};
pub use document::{
    ChangedRegion, DEFAULT_MARGIN, DEFAULT_MAX_DABS, Edit, EditRecord, EditStats, EditTimings,
    SculptDocument, SculptOptions,
};
pub use error::SculptError;
pub use exact::FRACTION_BITS;
pub use grid::{GRID_OFFSET, Grid, IndexBox, MAX_GRID_POINTS, MIN_GRID_POINTS, transverse};
pub use interval::{Op, combine, inside_at, is_clean};
pub use peel::{
    Crossing, DepthPeelImage, MAX_VIEW_PIXELS, PerspectiveView, TriangleSoup, depth_peel_axis,
    depth_peel_perspective,
};
pub use smooth::{MAX_KERNEL, SmoothRegion};
pub use tool::{CONVEXITY_TOLERANCE, Pose, Tool, closed_soup, resample_stroke};
pub use view::FrozenView;
