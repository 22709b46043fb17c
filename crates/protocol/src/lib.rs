//! Wire protocol of the walkthrough system (DESIGN.md §8).
//!
//! Three processes meet only over TCP: renderers answer shading requests from the SMA, and viewers
//! exchange cameras and triangles with it. This crate is a leaf: it defines its own plain types for
//! what travels and depends on none of the project's crates but `conventions` (the camera).
//!
//! - [`frame`]: length-delimited frames carrying postcard payloads, with a maximum size;
//! - [`handshake`]: magic, protocol version, role and (renderer link) scene fingerprint;
//! - [`renderer_link`] and [`viewer_link`]: the messages of each link;
//! - [`admission`]: what a port allows a peer before its handshake, and how many it serves;
//! - [`liveness`]: heartbeats, silence and frame timeouts: when a peer counts as lost;
//! - [`connection`]: a typed message reader and writer over any byte stream;
//! - [`error`]: every way a peer can go wrong, as a value, never a panic;
//! - [`camera`]: the wire's camera in the system's camera convention;
//! - [`direct_tile`]: a resting view's direct light per pixel, in tiles, on both links;
//! - [`texture`]: materials, textures and texture coordinates, for the albedo per pixel.
//!
//! ```
//! use protocol::frame::{decode, encode};
//! use protocol::viewer_link::{SmaToViewer, ShownTriangle};
//! let msg = SmaToViewer::Insert {
//!     triangles: vec![ShownTriangle {
//!         id: 7,
//!         positions: [[0.0; 3]; 3],
//!         material: 0,
//!         texcoords: Default::default(),
//!         shading: Default::default(),
//!     }],
//! };
//! let bytes = encode(&msg).unwrap();
//! assert_eq!(decode::<SmaToViewer>(&bytes).unwrap(), msg);
//! ```

pub mod admission;
mod camera;
pub mod connection;
pub mod direct_tile;
mod error;
pub mod frame;
pub mod handshake;
pub mod liveness;
mod preallocated;
pub mod renderer_link;
pub mod texture;
pub mod types;
mod variant_count;
pub mod viewer_link;

pub use connection::{MessageReader, MessageWriter, split_tcp};
pub use error::ProtocolError;
pub use frame::WireMessage;
pub use handshake::{Hello, HelloReply, PROTOCOL_VERSION, Role};
pub use types::{Fingerprint, PartEstimate, Rgb, SampleParts, SceneIdentity, Side, Vec3f};
