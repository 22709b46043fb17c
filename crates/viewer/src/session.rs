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
