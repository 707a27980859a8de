//! volmorph-ffd: free-form deformation of polygon meshes.
mod error;
pub mod interp;
pub mod polygon;

pub use error::FfdError;
pub mod accurate;
pub mod baseline;
pub mod frame;
pub mod shapes;
pub mod step;
pub mod subdivide;
pub mod tessellate;
