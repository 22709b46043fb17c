//! The key record of a cache file: what must match for its samples and subdivision to mean the
//! same in this SMA (DESIGN.md §5, "keyed by the scene fingerprint and what a sample means").

use protocol::renderer_link::Quality;
use serde::{Deserialize, Serialize};

use crate::mesh::{MeshParams, NeighbourRule};

/// The layout of the records (`record`) and of a stored sample. Raised whenever either changes,
/// or what a sample holds does (its parts, as answered: direct and indirect illumination,
/// view-dependent radiance), so an old file is refused rather than misread.
pub const FORMAT_VERSION: u32 = 3;

/// Everything a store is keyed by. The format version is stored apart from it (`store`), so a
/// file of another version is told as such even where its key no longer decodes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StoreKey {
    /// The scene's fingerprint (geometry, materials, textures: `scene::fingerprint`).
    pub scene: [u8; 32],
    /// The mesh settings that shape subdivision: replaying a record's splits under others would
    /// give another mesh (`MeshParams`).
    pub mesh: MeshKey,
    /// What a stored sample means.
    pub samples: SampleMeaning,
}

/// `MeshParams` as stored: the floats by their bits, so equal means bit-equal.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct MeshKey {
    pub min_edge_length_bits: u32,
    pub weld_tolerance_rel_bits: u32,
    /// `true`: the thesis's neighbour rule; `false`: red–green.
    pub thesis_neighbour_rule: bool,
}

impl MeshKey {
    pub fn of(params: &MeshParams) -> MeshKey {
        MeshKey {
            min_edge_length_bits: params.min_edge_length.to_bits(),
            weld_tolerance_rel_bits: params.weld_tolerance_rel.to_bits(),
            thesis_neighbour_rule: params.neighbour_rule == NeighbourRule::Thesis,
        }
    }
}

/// What a sample is an estimate of: samples on the quality ladder, or the thesis's
/// fixed-quality ones, at the scene's quality (paths and bounce depth, DESIGN.md §7).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct SampleMeaning {
    pub ladder: bool,
    pub paths: u32,
    pub bounces: Option<u32>,
}

impl SampleMeaning {
    pub fn new(ladder: bool, full: Quality) -> SampleMeaning {
        SampleMeaning {
            ladder,
            paths: full.paths,
            bounces: full.bounces,
        }
    }
}

impl StoreKey {
    /// A key of default mesh settings and samples of 64 paths at 2 bounces, for a scene whose
    /// fingerprint is `scene` repeated: the fixture of the store's tests and benchmark.
    #[cfg(any(test, feature = "testing"))]
    pub fn of_test_scene(scene: u8) -> StoreKey {
        StoreKey {
            scene: [scene; 32],
            mesh: MeshKey::of(&MeshParams::default()),
            samples: SampleMeaning::new(
                true,
                Quality {
                    paths: 64,
                    bounces: Some(2),
                },
            ),
        }
    }

    /// Why a stored key does not fit this one, in words for the warning; None when it does.
    pub fn mismatch(&self, stored: &StoreKey) -> Option<String> {
        if stored.scene != self.scene {
            Some(format!(
                "it belongs to another scene (fingerprint {}, this scene's is {})",
                scene::fingerprint_hex(&stored.scene),
                scene::fingerprint_hex(&self.scene)
            ))
        } else if stored.mesh != self.mesh {
            Some(format!(
                "its mesh settings differ ({:?}, this SMA's are {:?})",
                stored.mesh, self.mesh
            ))
        } else if stored.samples != self.samples {
            Some(format!(
                "its samples mean something else ({:?}, this SMA's are {:?})",
                stored.samples, self.samples
            ))
        } else {
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key() -> StoreKey {
        StoreKey::of_test_scene(7)
    }

    #[test]
    fn each_part_of_the_key_is_named_when_it_differs() {
        let ours = key();
        assert_eq!(ours.mismatch(&key()), None);
        let mut other = key();
        other.scene[0] = 8;
        assert!(ours.mismatch(&other).unwrap().contains("another scene"));
        let mut other = key();
        other.mesh.thesis_neighbour_rule = true;
        assert!(ours.mismatch(&other).unwrap().contains("mesh settings"));
        let mut other = key();
        other.samples.ladder = false;
        assert!(ours.mismatch(&other).unwrap().contains("samples mean"));
    }
}
