//! A scene's viewpoint as the camera a viewer would send for it, for tests that run passes
//! without a viewer.

use protocol::types::Viewpoint;
use protocol::viewer_link::Camera;

/// The camera of `vp` at `width` × `height`, sequence number 1.
pub fn camera(vp: &scene::ViewpointSetting, width: u32, height: u32) -> Camera {
    let viewpoint = Viewpoint {
        name: vp.name.clone(),
        eye: vp.eye,
        target: vp.target,
        up: vp.up,
        fov_y_deg: vp.fov_y_deg,
    };
    Camera::from_viewpoint(&viewpoint, 1, width, height)
}
