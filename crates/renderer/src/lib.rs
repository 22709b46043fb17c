//! The renderer: a point-oriented path-tracing service answering object-space shading requests
//! (DESIGN.md §2, §7), plus per-pixel reference images (DESIGN.md §10).
//!
//! - [`world`]: a scene prepared for tracing ([`bvh`], [`lights`], [`material`], [`offset`]);
//! - `wide_bvh`, `wide_traversal`, `packet_traversal`: the BVH's queries over eight-wide nodes,
//!   one ray at a time or a packet of coherent rays at a time;
//! - [`estimator`]: path tracing with next-event estimation, one path at a time or as ray
//!   streams (`wavefront`), the first bounces of a point's paths stratified (`strata`);
//! - [`point`]: shading points from (triangle, barycentrics, side), hidden-point relocation;
//! - `ray_order`: ray streams regrouped by direction octant and origin before tracing;
//! - [`shade`]: points and batches at a quality, deterministic per (seed, index);
//! - [`direct_tile`]: a camera's direct light per pixel, one tile and pass at a time;
//! - [`service`]: the TCP server of the renderer link;
//! - [`reference`] and [`image_files`]: reference images (EXR + tone-mapped PNG), and the one EXR
//!   reader; [`features`]: the albedo and normal images a denoiser takes beside a reference;
//! - [`vector_level`]: the CPU's vector instructions the ray queries use, chosen at run time;
//!   [`subnormals`]: tiny floats flushed to zero on the tracing threads;
//! - [`cli`]: `renderer serve` and `renderer reference`, the only module that parses arguments.

pub(crate) mod bvh;
pub mod cli;
pub(crate) mod counters;
pub mod direct_tile;
pub mod estimator;
pub mod features;
pub mod image_files;
pub(crate) mod lights;
pub(crate) mod material;
pub(crate) mod offset;
#[cfg(target_arch = "x86_64")]
pub(crate) mod packet_traversal;
pub mod point;
pub(crate) mod ray_order;
pub mod reference;
pub mod sampling;
pub mod service;
pub(crate) mod shade;
pub(crate) mod strata;
pub(crate) mod subnormals;
pub(crate) mod texture_lod;
pub mod vector_level;
pub(crate) mod wavefront;
#[cfg(target_arch = "x86_64")]
pub(crate) mod wide_bvh;
#[cfg(target_arch = "x86_64")]
pub(crate) mod wide_traversal;
pub mod world;

pub use counters::{RayCounts, RayKind};
pub use shade::{Shaded, shade_batch, shade_point};
pub use strata::FirstBounce;
pub use world::World;

/// What the launcher's benchmarks measure inside the renderer (the `bench` feature): the tracer's
/// BVH against a naive one, and hidden-point relocation.
#[cfg(feature = "bench")]
pub mod internals {
    pub use crate::bvh::{SceneBvh, Traversal};
    pub use crate::ray_order::RayOrder;
}
