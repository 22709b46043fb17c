//! What the viewer says at the start of every SMA session, window or headless: the SMA knows
//! nothing of a viewer that (re)connects, so the camera, the criterion and the pause state are all
//! sent again.

use protocol::types::Viewpoint;
use protocol::viewer_link::{SceneInfo, ViewerToSma};

/// The viewpoint named `name`, or the scene's first when no name is given; `Ok(None)` when the
/// scene has none.
pub fn pick_viewpoint(scene: &SceneInfo, name: Option<&str>) -> anyhow::Result<Option<Viewpoint>> {
    match name {
        Some(name) => scene
            .viewpoints
            .iter()
            .find(|vp| vp.name == name)
            .cloned()
            .map(Some)
            .ok_or_else(|| {
                let known: Vec<&str> = scene.viewpoints.iter().map(|vp| vp.name.as_str()).collect();
                anyhow::anyhow!(
                    "scene {:?} has no view {name:?} (it has {known:?})",
                    scene.name
                )
            }),
        None => Ok(scene.viewpoints.first().cloned()),
    }
}

/// The refinement preferences to restate after the camera.
pub fn preferences(criterion: Option<&str>, paused: bool) -> Vec<ViewerToSma> {
    let mut msgs: Vec<ViewerToSma> = criterion
        .map(|name| ViewerToSma::SetCriterion {
            name: name.to_string(),
        })
        .into_iter()
        .collect();
    if paused {
        msgs.push(ViewerToSma::Pause);
    }
    msgs
}

/// The criterion after `current` in the SMA's list (wrapping), for the window's switch key.
pub fn next_criterion(scene: &SceneInfo, current: Option<&str>) -> Option<String> {
    let list = &scene.criteria;
    let at = current.and_then(|c| list.iter().position(|n| n == c));
    let next = at.map_or(0, |i| (i + 1) % list.len().max(1));
    list.get(next).cloned()
}

#[cfg(test)]
mod tests {
    use protocol::types::Bounds;

    use super::*;

    fn scene() -> SceneInfo {
        let vp = |name: &str| Viewpoint {
            name: name.into(),
            eye: [0.0; 3],
            target: [0.0, 0.0, -1.0],
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 60.0,
        };
        SceneInfo {
            name: "s".into(),
            fingerprint: [0; 32],
            bounds: Bounds {
                min: [0.0; 3],
                max: [1.0; 3],
            },
            viewpoints: vec![vp("MC"), vp("VT")],
            criteria: vec!["nld_os".into(), "rnd".into()],
            sky: Default::default(),
            quality: protocol::renderer_link::Quality {
                paths: 64,
                bounces: Some(2),
            },
            textures: false,
            materials: vec![],
            texture_table: vec![],
        }
    }

    #[test]
    fn viewpoints_by_name_or_first_and_unknown_names_are_errors() {
        let s = scene();
        assert_eq!(pick_viewpoint(&s, Some("VT")).unwrap().unwrap().name, "VT");
        assert_eq!(pick_viewpoint(&s, None).unwrap().unwrap().name, "MC");
        let e = pick_viewpoint(&s, Some("XX")).unwrap_err().to_string();
        assert!(e.contains("XX") && e.contains("MC"), "{e}");
    }

    #[test]
    fn criteria_cycle_and_preferences_follow_the_flags() {
        let s = scene();
        assert_eq!(next_criterion(&s, Some("nld_os")).as_deref(), Some("rnd"));
        assert_eq!(next_criterion(&s, Some("rnd")).as_deref(), Some("nld_os"));
        assert_eq!(next_criterion(&s, None).as_deref(), Some("nld_os"));
        let empty = SceneInfo {
            criteria: vec![],
            ..s
        };
        assert_eq!(next_criterion(&empty, Some("rnd")), None);
        assert_eq!(
            preferences(Some("rnd"), true),
            vec![
                ViewerToSma::SetCriterion { name: "rnd".into() },
                ViewerToSma::Pause
            ]
        );
        assert!(preferences(None, false).is_empty());
    }
}
