//! The scene fingerprint checked in the renderer handshake (DESIGN.md §8): BLAKE3 over the
//! settings, the finished geometry and the materials. Everything the renderer and the SMA must
//! agree on goes in (vertex numbering and normals included, since samples are keyed by vertex
//! and side); where the files sit does not (the OBJ path is left out), so a scene exported and
//! reloaded keeps its fingerprint.

use crate::model::{Material, Mesh, Scattering};
use crate::settings::SceneSettings;

const DOMAIN: &[u8] = b"walkthrough scene fingerprint v1";

pub fn fingerprint(settings: &SceneSettings, mesh: &Mesh, materials: &[Material]) -> [u8; 32] {
    let mut h = blake3::Hasher::new();
    h.update(DOMAIN);
    let located_nowhere = SceneSettings {
        obj: String::new(),
        ..settings.clone()
    };
    // Debug of plain data is deterministic and covers every field, including ones added later.
    text(&mut h, &format!("{located_nowhere:?}"));
    count(&mut h, mesh.positions.len());
    for (p, n) in mesh.positions.iter().zip(&mesh.normals) {
        floats(&mut h, &p.to_array());
        floats(&mut h, &n.to_array());
    }
    count(&mut h, mesh.triangles.len());
    for t in &mesh.triangles {
        for i in t.vertices.iter().chain([&t.material]) {
            h.update(&i.to_le_bytes());
        }
    }
    count(&mut h, materials.len());
    for m in materials {
        text(&mut h, &m.name);
        for v in [m.kd, m.ke, m.ks] {
            floats(&mut h, &v.to_array());
        }
        floats(&mut h, &[m.ns]);
        h.update(&m.illum.to_le_bytes());
        h.update(&[match m.scattering {
            Scattering::Diffuse => 0,
            Scattering::Glossy => 1,
            Scattering::Mirror => 2,
        }]);
    }
    *h.finalize().as_bytes()
}

/// Lower-case hex, as `scene info` prints it.
pub fn hex(fingerprint: &[u8; 32]) -> String {
    fingerprint.iter().map(|b| format!("{b:02x}")).collect()
}

fn count(h: &mut blake3::Hasher, n: usize) {
    h.update(&(n as u64).to_le_bytes());
}

fn text(h: &mut blake3::Hasher, s: &str) {
    count(h, s.len());
    h.update(s.as_bytes());
}

fn floats(h: &mut blake3::Hasher, values: &[f32]) {
    for v in values {
        h.update(&v.to_le_bytes());
    }
}
