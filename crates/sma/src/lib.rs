//! The Shading Management Agent (DESIGN.md §2–§6): the brain of the system.
//!
//! Core (a library, testable without GPU or network):
//! - [`mesh`]: the hierarchical subdivision mesh (red–green refinement, coarsening, §4.2);
//! - [`cache`]: the object-space vertex shading cache (§5);
//! - [`visible`]: the visible set V_t keyed by (leaf, side);
//! - [`nld`]: the NLD metric (eq. 4.3) and NLD_MM (eq. 4.4);
//! - [`criteria`]: refinement criteria, one file each behind one trait (§4.3).
//!
//! Service:
//! - [`visibility`]: GPU ID-buffer passes with wgpu, headless (§3 steps 2–3);
//! - [`pool`]: the renderer pool;
//! - [`viewer_link`]: accepted viewers;
//! - [`schedule`]: the event loop tying them together;
//! - [`server`]: the listener, and starting/stopping a whole SMA (also in-process, for tests);
//! - [`cli`]: the command line;
//! - [`probe`]: a scripted protocol viewer that checks the SMA's updates (tests, benchmarks);
//! - [`service_bench`]: the service's figures for BENCHMARKS.md.

pub mod bench;
pub mod cache;
pub mod criteria;
pub mod mesh;
pub mod nld;
pub mod visible;

pub mod cli;
pub mod pool;
pub mod probe;
pub mod schedule;
pub mod server;
pub mod service_bench;
pub mod viewer_link;
pub mod visibility;
