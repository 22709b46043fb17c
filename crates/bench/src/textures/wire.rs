//! What a texture costs on the viewer link (DESIGN.md §5, "Parts, and textures"; §8): the bytes
//! of an insert of real leaves of `bracara-textured`, their material and coordinates made by the
//! SMA's own code (`ShadingCache::leaf_surface`), textured diffuse triangles beside untextured
//! ones, and beside the same triangles without a material and coordinates, as triangles were
//! sent before textures.

use std::sync::Arc;

use protocol::Side;
use protocol::frame::encode;
use protocol::viewer_link::{CornerShading, DirectShare, ShownTriangle, SmaToViewer};
use sma::cache::ShadingCache;
use sma::mesh::{MeshParams, SubdivisionMesh};
use sma::visible_set::shown_id;

pub(super) const SCENE: &str = "bracara-textured";

/// Red splits of every leaf before the insert: the SMA sends refined leaves, whose ids and
/// coordinate ranges are those of a refined mesh.
pub(super) const REFINEMENTS: usize = 2;

/// Triangles per insert, as the SMA's syncs send them at most.
const BATCH: usize = 10_000;

/// Bytes per triangle of an insert before triangles carried a material and texture
/// coordinates (protocol version 10): the textured triangle's budget is 1.25 times it.
pub(super) const BEFORE_TEXTURES: f64 = 77.0;
pub(super) const TARGET: f64 = 1.25 * BEFORE_TEXTURES;

/// Bytes per triangle on the wire.
pub(super) struct WireBytes {
    /// Triangles of a textured material, and their bytes each.
    pub textured: (usize, f64),
    /// Triangles of an untextured material (a material index, zero coordinates).
    pub untextured: (usize, f64),
    /// The textured triangles less their material and coordinates: the wire before textures.
    pub textured_bare: f64,
}

pub(super) fn measure() -> anyhow::Result<WireBytes> {
    let scene = Arc::new(scene::load(SCENE)?);
    let mut mesh = SubdivisionMesh::new(&scene.mesh, MeshParams::default());
    for _ in 0..REFINEMENTS {
        let leaves: Vec<_> = mesh.leaves().collect();
        mesh.refine(&leaves, &|_| false);
    }
    let cache = ShadingCache::new(usize::MAX).with_albedos_of(Arc::clone(&scene));
    let (mut textured, mut untextured) = (Vec::new(), Vec::new());
    for leaf in mesh.leaves() {
        let (material, texcoords) = cache.leaf_surface(&mesh, leaf);
        let positions = mesh.leaf_positions(leaf).map(|p| p.to_array());
        let triangle = ShownTriangle {
            id: shown_id(leaf, Side::Front),
            positions,
            material,
            texcoords,
            shading: lit(positions),
        };
        match scene.materials.get(usize::from(material)) {
            Some(m) if m.diffuse_map.is_some() => textured.push(triangle),
            _ => untextured.push(triangle),
        }
    }
    anyhow::ensure!(
        !textured.is_empty() && !untextured.is_empty(),
        "{SCENE} has {} textured and {} untextured leaves",
        textured.len(),
        untextured.len()
    );
    let surface_bytes = textured
        .iter()
        .map(|t| Ok(encode(&(t.material, t.texcoords))?.len()))
        .sum::<anyhow::Result<usize>>()?;
    let textured_bytes = insert_bytes(&textured)?;
    Ok(WireBytes {
        textured: (textured.len(), per_triangle(textured_bytes, &textured)),
        untextured: (
            untextured.len(),
            per_triangle(insert_bytes(&untextured)?, &untextured),
        ),
        textured_bare: per_triangle(textured_bytes - surface_bytes, &textured),
    })
}

/// A diffuse leaf's shading as the SMA sends it: illumination and its direct share per corner
/// (full-width floats and bytes whatever their values), no view-dependent part.
fn lit(positions: [[f32; 3]; 3]) -> CornerShading {
    CornerShading {
        illumination: positions
            .map(|[x, y, z]| [0.5 + 0.1 * x.sin(), 0.4 + 0.1 * y.cos(), 0.3 + 0.01 * z]),
        direct_share: positions.map(|p| DirectShare((p[0].abs() * 37.0) as u8)),
        view_dependent: None,
    }
}

/// Bytes of `triangles` sent as inserts of [`BATCH`] triangles.
fn insert_bytes(triangles: &[ShownTriangle]) -> anyhow::Result<usize> {
    triangles
        .chunks(BATCH)
        .map(|chunk| {
            let insert = SmaToViewer::Insert {
                triangles: chunk.to_vec(),
            };
            Ok(encode(&insert)?.len())
        })
        .sum()
}

fn per_triangle(bytes: usize, triangles: &[ShownTriangle]) -> f64 {
    bytes as f64 / triangles.len() as f64
}
