//! One module per subcommand.

pub mod bench;
pub mod convert;
pub mod demo;
pub mod drag;
pub mod ffd;
pub mod frep;
pub mod handles;
pub mod info;
pub mod isosurface;
pub mod lattice;
pub mod map;
pub mod mesh;
pub mod mls2d;
pub mod nurbs;
pub mod nurbs_trace;
pub mod phantom;
pub mod picture;
pub mod project;
pub mod register;
pub mod render;
pub mod sculpt;
pub mod slice;
pub mod studio;
pub mod warp;
