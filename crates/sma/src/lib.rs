//! The Shading Management Agent (DESIGN.md §2–§6): the brain of the system.
//!
//! Core (testable without GPU or network):
//! - [`mesh`]: the hierarchical subdivision mesh (red–green refinement, coarsening, §4.2);
//! - [`cache`]: the object-space vertex shading cache (§5);
//! - [`visible_set`]: the visible set V_t keyed by (leaf, side);
//! - [`nld`]: the NLD metric (eq. 4.3);
//! - [`criteria`]: refinement criteria, one file each behind one trait (§4.3);
//! - [`cache_file`]: the mesh and the cache kept on disk between runs (§5, persistence).
//! - [`indirect_filter`]: the object-space filter of the samples' indirect part (§5).
//!
//! Service:
//! - [`visibility`]: GPU ID-buffer passes with wgpu, headless (§3 steps 2–3);
//! - [`pool`]: the renderer pool;
//! - [`viewer_link`]: accepted viewers;
//! - [`schedule`]: the event loop tying them together;
//! - [`config`]: the SMA's configuration, plain values;
//! - [`server`]: the listener, and starting/stopping a whole SMA (also in-process, for tests);
//! - [`clock`]: waiting on an optional instant, for the schedule's loop and the pool;
//! - [`cli`]: the command line, the only module that parses arguments.
//!
//! The `testing` feature exposes the fixtures of the core's own tests to the launcher's
//! benchmarks and to the tests of the whole system: `mesh::grid_mesh`, `criteria::synthetic` (the
//! synthetic scenes behind the criterion defaults) and `visibility::coverage` (the pixels a set of
//! triangles covers). The SMA's own tests enable it through their dev-dependency on this crate.

pub mod cache;
pub mod cache_file;
pub mod criteria;
pub mod indirect_filter;
pub mod mesh;
pub(crate) mod nld;
pub(crate) mod sample;
pub mod visible_set;

pub mod cli;
pub(crate) mod clock;
pub mod config;
pub(crate) mod direct_tiles;
pub(crate) mod pool;
pub(crate) mod schedule;
pub mod server;
pub(crate) mod viewer_link;
pub mod visibility;
