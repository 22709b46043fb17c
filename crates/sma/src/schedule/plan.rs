//! From one viewer's visible set to what must still be shaded (DESIGN.md §3 step 5, §5, §7):
//! every visible sample's needs, each on a rung of the quality ladder (`ladder`) and with its
//! urgency, for the request queue (`requests`) to order and batch. What the viewer is shown of
//! the same set is `targets`.

use glam::Vec3;
use protocol::Side;
use protocol::renderer_link::{Quality, SampleKey, ShadePoint};
use scene::Scene;

use super::ladder::Qualities;
use super::need::{Need, Urgency};
use super::pending::PendingRefinement;
use super::viewers::Viewer;
use crate::cache::ShadingCache;
use crate::config::ScheduleConfig;
use crate::mesh::SubdivisionMesh;
use crate::sample::DisplayMap;
use crate::visibility::LeafView;

/// What planning holds for the whole run: the quality ladder, how far a view-dependent sample's
/// eye may move, and which base triangles have a view-dependent material.
#[derive(Clone, Debug)]
pub struct PlanRules {
    pub qualities: Qualities,
    pub aging: Aging,
    /// Per base triangle.
    pub view_dependent: Vec<bool>,
}

impl PlanRules {
    pub fn new(config: &ScheduleConfig, scene: &Scene) -> PlanRules {
        let quality = scene.settings.quality;
        let full = Quality {
            paths: quality.paths,
            bounces: config.bounces.or(quality.bounces),
        };
        let qualities = if config.ladder {
            Qualities::new(full, config.max_paths, config.early_rung)
        } else {
            Qualities::fixed(full)
        };
        PlanRules {
            qualities,
            aging: Aging {
                max_angle_rad: config.view_angle_deg.to_radians(),
            },
            view_dependent: (0..scene.mesh.triangles.len())
                .map(|t| scene.material_of(t).is_view_dependent())
                .collect(),
        }
    }
}

/// When and how a viewer's visible samples get more paths.
#[derive(Clone, Copy, Debug)]
pub struct MorePaths {
    /// L_white of the viewer's tone map.
    pub l_white: f32,
    /// A sample whose displayed standard error is below this needs no more paths...
    pub threshold: f32,
    /// ...but may still get them, last of all, while refinement runs (`Urgency::Polish`).
    pub polish: bool,
}

impl MorePaths {
    /// Every shown view gets more paths where its noise shows, below every other need: they
    /// keep the renderers busy between refinement rounds and passes (DESIGN.md §3, §5). While
    /// its criterion still refines, its quieter samples too, last of all (`Urgency::Polish`).
    /// Without the quality ladder (the thesis's fixed-quality samples) none.
    pub fn for_viewer(config: &ScheduleConfig, viewer: &Viewer) -> Option<MorePaths> {
        if !config.ladder {
            return None;
        }
        Some(MorePaths {
            l_white: viewer.last_l_white?,
            threshold: config.display_error,
            polish: config.refine && !viewer.criterion_dry,
        })
    }
}

/// How far a view-dependent sample's eye may move, as the angle seen from the vertex, before
/// the sample is retaken (DESIGN.md §5).
#[derive(Clone, Copy, Debug)]
pub struct Aging {
    pub max_angle_rad: f32,
}

impl Aging {
    pub fn is_stale(&self, vertex: Vec3, sample_eye: Option<Vec3>, eye: Vec3) -> bool {
        sample_eye.is_none_or(|old| (old - vertex).angle_between(eye - vertex) > self.max_angle_rad)
    }
}

/// Everything a viewer's visible leaves still need.
pub struct NeedsInput<'a> {
    pub view: &'a LeafView,
    pub eye: Vec3,
    pub pending: &'a PendingRefinement,
    pub mesh: &'a SubdivisionMesh,
    pub cache: &'a ShadingCache,
    pub rules: &'a PlanRules,
    /// Set once the viewer has a tone map: its noisy samples get more paths (lowest urgency).
    pub more_paths: Option<MorePaths>,
    /// Where on the image, in pixels, the next steps of a walking viewer look (`ahead::focus`);
    /// None: the image's centre.
    pub focus: Option<(f32, f32)>,
}

/// Every visible sample's needs. A vertex is met once per leaf around it (about six on a
/// closed mesh), and the re-plan keeps, per sample and quality, the need first in queue order,
/// that is the largest priority; so the leaves are gathered per sample first (largest priority,
/// largest leaf, whether a refining leaf and a settled one hold it), and each sample's needs
/// are made once.
pub fn needs(input: &NeedsInput) -> Vec<Need> {
    let visible = &input.view.visible;
    let (w, h) = (visible.width as f32, visible.height as f32);
    let (fx, fy) = input.focus.unwrap_or((0.5 * w, 0.5 * h));
    // Per sample, its place in `gathered`, by vertex and side: dense, as vertex ids are.
    let mut place = vec![u32::MAX; 2 * input.mesh.vertex_count()];
    let mut gathered: Vec<(SampleKey, Gathered)> = Vec::new();
    for (v, &(cx, cy)) in visible.leaves.iter().zip(&input.view.centroids) {
        // On-screen size, weighted toward the focus (1 there; at rest, the centre, and 1/3 in a
        // corner): what the next steps still see first (DESIGN.md §3 step 9).
        let (dx, dy) = ((cx - fx) / (0.5 * w), (cy - fy) / (0.5 * h));
        let priority = v.pixels as f32 / (1.0 + dx * dx + dy * dy);
        let refining = input.pending.group_of(v.leaf).is_some();
        for vertex in input.mesh.node(v.leaf).vertices {
            let key = SampleKey {
                vertex,
                side: v.side,
            };
            let at = &mut place[2 * vertex as usize + usize::from(v.side == Side::Back)];
            if *at == u32::MAX {
                *at = gathered.len() as u32;
                gathered.push((key, Gathered::default()));
            }
            gathered[*at as usize].1.add(priority, v.pixels, refining);
        }
    }
    let display = input.more_paths.map(|m| DisplayMap::new(m.l_white));
    let mut out = Vec::with_capacity(gathered.len());
    for (key, g) in gathered {
        for (refining, priority) in [(false, g.settled), (true, g.refining)] {
            if let Some(priority) = priority {
                need_key(input, key, refining, priority, &mut out);
            }
        }
        if let (Some(more), Some(display)) = (&input.more_paths, &display) {
            more_paths(input, more, display, key, g.pixels, &mut out);
        }
    }
    out
}

/// What the visible leaves around one sample ask of it.
#[derive(Clone, Copy, Debug, Default)]
struct Gathered {
    /// The largest priority among leaves not being refined, and among those being refined.
    settled: Option<f32>,
    refining: Option<f32>,
    /// The largest leaf's pixels.
    pixels: u32,
}

impl Gathered {
    fn add(&mut self, priority: f32, pixels: u32, refining: bool) {
        let slot = if refining {
            &mut self.refining
        } else {
            &mut self.settled
        };
        *slot = Some(slot.map_or(priority, |p| p.max(priority)));
        self.pixels = self.pixels.max(pixels);
    }
}

fn need_key(
    input: &NeedsInput,
    key: SampleKey,
    refining: bool,
    priority: f32,
    out: &mut Vec<Need>,
) {
    if input.cache.is_failed(key) {
        return;
    }
    let mv = input.mesh.vertex(key.vertex);
    let view_dependent = input
        .rules
        .view_dependent
        .get(mv.base_triangle as usize)
        .copied()
        .unwrap_or(false);
    let point = ShadePoint {
        key,
        base_triangle: mv.base_triangle,
        bary: mv.bary,
        side: key.side,
        eye: view_dependent.then(|| input.eye.to_array()),
    };
    let qualities = &input.rules.qualities;
    let mut push = |(quality, target), urgency, new_eye| {
        out.push(Need {
            point,
            quality,
            target,
            urgency,
            priority,
            new_eye,
        });
    };
    let early = (qualities.early, qualities.early);
    match input.cache.get_seen_from(key, Some(input.eye)) {
        None if refining => push(early, Urgency::Refinement, false),
        None => {
            push((qualities.first, qualities.first), Urgency::Missing, false);
            // Without a cheaper first sample (a fixed quality) the first is the upgrade.
            if qualities.first != qualities.early {
                push(early, Urgency::Better, false);
            }
        }
        // An early-rung sample's paths up to the scene's quality come as a top-up
        // (`more_paths`), which refinement does not wait for: were they `Better`, every round's new
        // vertices would wait for them before the next round (`turns::refinement_candidate`),
        // and the rounds would cost the scene's quality again.
        Some(s) if s.quality.rank() < qualities.full.rank() => {
            let top_up = s.quality.bounces == qualities.full.bounces;
            if !(top_up && input.more_paths.is_some()) {
                push(qualities.upgrade(s.quality), Urgency::Better, false);
            }
        }
        Some(s)
            if s.view_dependent && input.rules.aging.is_stale(mv.position, s.eye, input.eye) =>
        {
            push(early, Urgency::Better, true);
        }
        Some(_) => {}
    }
}

/// The next rung for a cached sample whose noise is still visible (or, to polish, any below the
/// cap): priority is the displayed standard error times the pixels of the leaf, so paths go where
/// they lower the displayed error most.
fn more_paths(
    input: &NeedsInput,
    more: &MorePaths,
    display: &DisplayMap,
    key: SampleKey,
    pixels: u32,
    out: &mut Vec<Need>,
) {
    let Some(sample) = input.cache.get_seen_from(key, Some(input.eye)) else {
        return;
    };
    let error = sample.estimate().displayed(display).standard_error;
    // Below the scene's quality (an early-rung sample) it gets its paths whatever its noise
    // shows: a variance read from a quarter of the paths may miss what is rare.
    let below_scene_quality = sample.quality.rank() < input.rules.qualities.full.rank();
    // Nor is a quiet variance believed before the first rung above it (`Qualities::trusts`).
    let untrusted = !input.rules.qualities.trusts(sample.quality);
    let urgency = if below_scene_quality {
        Urgency::TopUp
    } else if error > more.threshold || untrusted {
        Urgency::Paths
    } else if more.polish {
        Urgency::Polish
    } else {
        return;
    };
    let Some((quality, target)) = input.rules.qualities.next_rung(sample.quality) else {
        return;
    };
    let mv = input.mesh.vertex(key.vertex);
    out.push(Need {
        point: ShadePoint {
            key,
            base_triangle: mv.base_triangle,
            bary: mv.bary,
            side: key.side,
            eye: sample.eye.map(|e| e.to_array()),
        },
        quality,
        target,
        urgency,
        priority: if below_scene_quality || untrusted {
            error.max(more.threshold)
        } else {
            error
        } * pixels as f32,
        new_eye: false,
    });
}

#[cfg(test)]
mod tests {
    use std::collections::HashSet;

    use super::*;
    use crate::cache::CachedSample;
    use crate::mesh::NodeId;
    use crate::visible_set::{VisibleLeaf, VisibleSet};
    use protocol::SampleParts;

    /// The interactive preset's ladder up to 1024 paths, for `bases` diffuse base triangles.
    fn rules(bases: usize) -> PlanRules {
        PlanRules {
            qualities: Qualities::new(Quality::INTERACTIVE, 1024, true),
            aging: Aging { max_angle_rad: 0.1 },
            view_dependent: vec![false; bases],
        }
    }

    /// The needs of one visible triangle whose three samples are at the scene's quality with
    /// `luminance_variance` over their paths.
    fn needs_of_one_leaf(luminance_variance: f32, more: MorePaths) -> Vec<Need> {
        needs_of_one_leaf_at(Quality::INTERACTIVE, luminance_variance, Some(more))
    }

    /// As [`needs_of_one_leaf`], the samples at `quality`.
    fn needs_of_one_leaf_at(
        quality: Quality,
        luminance_variance: f32,
        more: Option<MorePaths>,
    ) -> Vec<Need> {
        needs_of_one_leaf_with(&rules(2), Some(quality), luminance_variance, more)
    }

    /// As [`needs_of_one_leaf`], under `rules`, the samples at `quality` (None: not cached).
    fn needs_of_one_leaf_with(
        rules: &PlanRules,
        quality: Option<Quality>,
        luminance_variance: f32,
        more: Option<MorePaths>,
    ) -> Vec<Need> {
        let mesh = SubdivisionMesh::new(&crate::mesh::grid_mesh(1), Default::default());
        let mut cache = ShadingCache::new(1 << 20);
        for vertex in mesh
            .node(0)
            .vertices
            .into_iter()
            .filter(|_| quality.is_some())
        {
            let quality = quality.expect("filtered");
            let key = SampleKey {
                vertex,
                side: Side::Front,
            };
            cache.insert(
                key,
                CachedSample {
                    parts: SampleParts::direct_only([0.2; 3], luminance_variance),
                    quality,
                    view_dependent: false,
                    eye: None,
                    last_seen: 0,
                },
            );
        }
        let view = LeafView {
            visible: VisibleSet {
                leaves: vec![VisibleLeaf {
                    leaf: 0,
                    side: Side::Front,
                    pixels: 100,
                }],
                width: 64,
                height: 64,
            },
            centroids: vec![(32.0, 32.0)],
            ..Default::default()
        };
        needs(&NeedsInput {
            view: &view,
            eye: Vec3::new(0.5, 0.5, 2.0),
            pending: &PendingRefinement::default(),
            mesh: &mesh,
            cache: &cache,
            rules,
            more_paths: more,
            focus: None,
        })
    }

    /// A vertex shared by several leaves gets one need per quality, as the largest leaf
    /// around it asks (the re-plan would keep no other), whatever order the leaves come in.
    #[test]
    fn a_shared_vertex_gets_one_need_per_quality_with_its_largest_leafs_priority() {
        let mesh = SubdivisionMesh::new(&crate::mesh::grid_mesh(3), Default::default());
        let leaves: Vec<VisibleLeaf> = (0..mesh.base_count() as NodeId)
            .map(|leaf| VisibleLeaf {
                leaf,
                side: Side::Front,
                pixels: 10 + 7 * ((leaf * 5) % 11),
            })
            .collect();
        let view = LeafView {
            centroids: vec![(32.0, 32.0); leaves.len()],
            visible: VisibleSet {
                leaves: leaves.clone(),
                width: 64,
                height: 64,
            },
            ..Default::default()
        };
        let cache = ShadingCache::new(1 << 20);
        let needs = needs(&NeedsInput {
            view: &view,
            eye: Vec3::new(1.5, 1.5, 4.0),
            pending: &PendingRefinement::default(),
            mesh: &mesh,
            cache: &cache,
            rules: &rules(mesh.base_count()),
            more_paths: None,
            focus: None,
        });
        let mut seen = HashSet::new();
        for need in &needs {
            assert!(
                seen.insert((need.point.key, need.target.rank())),
                "one need per sample and quality: {need:?}"
            );
            // Centred leaves: the priority is the pixels.
            let largest = leaves
                .iter()
                .filter(|l| mesh.node(l.leaf).vertices.contains(&need.point.key.vertex))
                .map(|l| l.pixels)
                .max()
                .expect("the vertex is on a visible leaf");
            assert_eq!(need.priority, largest as f32, "{need:?}");
        }
        // 16 vertices, each missing: a direct-light sample and an early-rung one.
        assert_eq!(needs.len(), 2 * 16);
    }

    /// A walking viewer's focus (`ahead`) orders equal leaves: the one near it first; without
    /// one, leaves at the same distance from the centre are equal.
    #[test]
    fn the_leaf_nearer_the_focus_comes_first() {
        let mesh = SubdivisionMesh::new(&crate::mesh::grid_mesh(3), Default::default());
        let (left, right) = (0, mesh.base_count() as NodeId - 1);
        let view = LeafView {
            centroids: vec![(10.0, 32.0), (54.0, 32.0)],
            visible: VisibleSet {
                leaves: [left, right]
                    .map(|leaf| VisibleLeaf {
                        leaf,
                        side: Side::Front,
                        pixels: 50,
                    })
                    .to_vec(),
                width: 64,
                height: 64,
            },
            ..Default::default()
        };
        let cache = ShadingCache::new(1 << 20);
        let priority_of = |focus, leaf: NodeId| {
            let needs = needs(&NeedsInput {
                view: &view,
                eye: Vec3::new(1.5, 1.5, 4.0),
                pending: &PendingRefinement::default(),
                mesh: &mesh,
                cache: &cache,
                rules: &rules(mesh.base_count()),
                more_paths: None,
                focus,
            });
            let on_leaf = |n: &&Need| mesh.node(leaf).vertices.contains(&n.point.key.vertex);
            needs.iter().find(on_leaf).expect("a need").priority
        };
        assert_eq!(priority_of(None, left), priority_of(None, right));
        let turning_right = Some((64.0, 32.0));
        assert!(priority_of(turning_right, right) > 2.0 * priority_of(turning_right, left));
    }

    /// The thesis profile's fixed quality: a missing sample's one need is the scene's quality
    /// preset, and a sample at it needs nothing more, however noisy.
    #[test]
    fn without_the_ladder_a_sample_gets_the_scene_quality_at_once_and_nothing_more() {
        use crate::config::{Profile, SmaConfig};
        let scene = scene::load("cornell").expect("the built-in Cornell box");
        let config = SmaConfig::of_profile(Profile::Thesis);
        let rules = PlanRules::new(&config.schedule, &scene);
        let preset = Quality {
            paths: scene.settings.quality.paths,
            bounces: scene.settings.quality.bounces,
        };
        let missing = needs_of_one_leaf_with(&rules, None, 0.0, None);
        assert_eq!(missing.len(), 3, "one need per sample: {missing:?}");
        assert!(
            missing.iter().all(|n| n.urgency == Urgency::Missing
                && n.quality == preset
                && n.target == preset)
        );
        let noisy = MorePaths {
            l_white: 1.0,
            threshold: 1.0 / 255.0,
            polish: true,
        };
        for more in [None, Some(noisy)] {
            let needs = needs_of_one_leaf_with(&rules, Some(preset), 4.0, more);
            assert!(needs.is_empty(), "{needs:?}");
        }
        // The ladder of today, for contrast: a direct-light sample first.
        let today = PlanRules::new(&SmaConfig::default().schedule, &scene);
        let first = needs_of_one_leaf_with(&today, None, 0.0, None);
        assert!(first.iter().any(|n| n.quality == Quality::DIRECT));
    }

    #[test]
    fn early_samples_are_topped_up_below_refinement_once_there_is_a_tone_map() {
        let early = Quality {
            paths: 16,
            bounces: Some(2),
        };
        let more = MorePaths {
            l_white: 1.0,
            threshold: 1.0 / 255.0,
            polish: false,
        };
        // Quiet or not, an early sample is brought to the scene's 64 paths, as a top-up.
        for variance in [1e-6, 4.0] {
            let needs = needs_of_one_leaf_at(early, variance, Some(more));
            assert_eq!(needs.len(), 3);
            assert!(needs.iter().all(|n| n.urgency == Urgency::TopUp
                && n.quality.paths == 48
                && n.target == Quality::INTERACTIVE));
        }
        // Before the viewer has a tone map it is an upgrade like any other.
        let needs = needs_of_one_leaf_at(early, 4.0, None);
        assert!(
            needs
                .iter()
                .all(|n| n.urgency == Urgency::Better && n.quality.paths == 48)
        );
    }

    #[test]
    fn quiet_samples_are_polished_only_while_refinement_runs() {
        let more = |polish| MorePaths {
            l_white: 1.0,
            threshold: 1.0 / 255.0,
            polish,
        };
        let urgencies = |variance, polish| -> Vec<Urgency> {
            needs_of_one_leaf(variance, more(polish))
                .iter()
                .map(|n| n.urgency)
                .collect()
        };
        // 64 paths: a variance of 4 shows (displayed error far above a step); 1e-6 does not, but
        // is not believed before the first rung above the scene's quality.
        assert_eq!(urgencies(4.0, false), [Urgency::Paths; 3]);
        assert_eq!(urgencies(4.0, true), [Urgency::Paths; 3]);
        assert_eq!(urgencies(1e-6, false), [Urgency::Paths; 3]);
        let first_rung = needs_of_one_leaf(1e-6, more(false));
        assert!(
            first_rung
                .iter()
                .all(|n| n.target.paths == 256 && n.quality.paths == 192)
        );
        let trusted = |variance, polish| -> Vec<Urgency> {
            let at = Quality {
                paths: 256,
                bounces: Quality::INTERACTIVE.bounces,
            };
            needs_of_one_leaf_at(at, variance, Some(more(polish)))
                .iter()
                .map(|n| n.urgency)
                .collect()
        };
        assert_eq!(trusted(1e-6, false), []);
        assert_eq!(trusted(1e-6, true), [Urgency::Polish; 3]);
        assert_eq!(trusted(400.0, false), [Urgency::Paths; 3]);
    }
}
