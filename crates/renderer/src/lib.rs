//! The renderer: a point-oriented path-tracing service answering object-space shading requests
//! (DESIGN.md §2, §7), plus per-pixel reference images (DESIGN.md §10).
//!
//! - [`world`]: a scene prepared for tracing ([`bvh`], [`lights`], [`material`], [`offset`]);
//! - [`estimator`]: path tracing with next-event estimation;
//! - [`point`]: shading points from (triangle, barycentrics, side), hidden-point relocation;
//! - [`shade`]: points and batches at a quality, deterministic per (seed, index);
//! - [`service`]: the TCP server of the renderer link;
//! - [`reference`] and [`tonemap`]: reference images (EXR + tone-mapped PNG);
//! - [`cli`]: `renderer serve` and `renderer reference`, the only module that parses arguments.

pub mod bvh;
pub mod cli;
pub mod counters;
pub mod estimator;
pub mod lights;
pub mod material;
pub mod offset;
pub mod point;
pub mod reference;
pub mod sampling;
pub mod service;
pub mod shade;
pub mod tonemap;
pub mod world;

pub use counters::{RayCounts, RayKind};
pub use shade::{Shaded, shade_batch, shade_point};
pub use world::World;
