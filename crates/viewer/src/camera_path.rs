//! A scripted walk: keyframes of eye, target and field of view in time, interpolated linearly.
//!
//! File format, one keyframe a line, `#` starts a comment:
//! ```text
//! # time_s  eye_x eye_y eye_z   target_x target_y target_z   [fov_y_deg]
//! 0.0       0 1.6 8             0 1.6 0
//! 4.0       3 1.6 6             0 1.2 0                      50
//! ```
//! Times must increase. A missing field of view keeps the previous keyframe's (the first one's
//! defaults to the starting view's). Up is +Y.

use anyhow::{Context, bail};
use glam::Vec3;
use protocol::types::Viewpoint;

#[derive(Clone, Debug, PartialEq)]
pub struct Keyframe {
    pub time_s: f32,
    pub eye: Vec3,
    pub target: Vec3,
    pub fov_y_deg: f32,
}

#[derive(Clone, Debug, PartialEq)]
pub struct CameraPath {
    keys: Vec<Keyframe>,
}

impl CameraPath {
    pub fn parse(text: &str, default_fov: f32) -> anyhow::Result<CameraPath> {
        let mut keys: Vec<Keyframe> = Vec::new();
        for (n, line) in text.lines().enumerate() {
            let line = line.split('#').next().unwrap_or("").trim();
            if line.is_empty() {
                continue;
            }
            let fields = line
                .split_whitespace()
                .map(str::parse::<f32>)
                .collect::<Result<Vec<_>, _>>()
                .with_context(|| format!("line {}: not a number", n + 1))?;
            let fov = keys.last().map_or(default_fov, |k| k.fov_y_deg);
            let key = match fields[..] {
                [t, ex, ey, ez, tx, ty, tz] => keyframe(t, [ex, ey, ez], [tx, ty, tz], fov),
                [t, ex, ey, ez, tx, ty, tz, f] => keyframe(t, [ex, ey, ez], [tx, ty, tz], f),
                _ => bail!(
                    "line {}: expected 7 or 8 numbers, found {}",
                    n + 1,
                    fields.len()
                ),
            };
            if keys.last().is_some_and(|k| k.time_s >= key.time_s) {
                bail!("line {}: times must increase", n + 1);
            }
            if !(key.fov_y_deg > 0.0 && key.fov_y_deg < 180.0) {
                bail!("line {}: field of view must lie in (0, 180) degrees", n + 1);
            }
            keys.push(key);
        }
        if keys.is_empty() {
            bail!("a camera path needs at least one keyframe");
        }
        Ok(CameraPath { keys })
    }

    /// The viewpoint at `t` seconds (held at the ends).
    pub fn at(&self, t: f32) -> Viewpoint {
        let i = self.keys.partition_point(|k| k.time_s <= t);
        let (a, b) = match i {
            0 => (&self.keys[0], &self.keys[0]),
            i if i == self.keys.len() => (&self.keys[i - 1], &self.keys[i - 1]),
            i => (&self.keys[i - 1], &self.keys[i]),
        };
        let s = if b.time_s > a.time_s {
            (t - a.time_s) / (b.time_s - a.time_s)
        } else {
            0.0
        };
        // `a + (b - a) * s`, not glam's `lerp` (`a * (1 - s) + b * s`): between two equal
        // keyframes (a stop) it is exactly the keyframe, where `lerp` is off by a rounding step
        // at one instant in a few dozen. Each such instant is a camera that differs from the last
        // one sent, so the viewer sent the SMA several cameras a second while the walk stood
        // still, and the SMA never saw the camera rest (DESIGN.md §3: refinement waits for rest).
        Viewpoint {
            name: "path".into(),
            eye: a.eye.lerp_monotonic(b.eye, s).to_array(),
            target: a.target.lerp_monotonic(b.target, s).to_array(),
            up: [0.0, 1.0, 0.0],
            fov_y_deg: a.fov_y_deg + (b.fov_y_deg - a.fov_y_deg) * s,
        }
    }
}

fn keyframe(t: f32, eye: [f32; 3], target: [f32; 3], fov: f32) -> Keyframe {
    Keyframe {
        time_s: t,
        eye: Vec3::from(eye),
        target: Vec3::from(target),
        fov_y_deg: fov,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolates_between_keyframes_and_holds_at_the_ends() {
        let path = CameraPath::parse("# walk\n0 0 0 0  0 0 -1\n2 4 0 0  4 0 -1 30 # turn\n", 60.0)
            .unwrap();
        assert_eq!(path.at(-1.0).eye, [0.0, 0.0, 0.0]);
        let mid = path.at(1.0);
        assert_eq!(
            (mid.eye, mid.target, mid.fov_y_deg),
            ([2.0, 0.0, 0.0], [2.0, 0.0, -1.0], 45.0)
        );
        assert_eq!(path.at(9.0).eye, [4.0, 0.0, 0.0]);
    }

    /// A stop (two equal keyframes) is the same camera at every instant of it, to the bit: the
    /// viewer sends a camera whenever it differs from the last one sent.
    #[test]
    fn a_stop_holds_the_camera_exactly() {
        let path = CameraPath::parse(
            "40.8 -1.5 1.7 60  0.5 3 -20\n43.767 -1.5 1.7 60  0.5 3 -20\n45 0 1.7 58 0 1.7 0\n",
            60.0,
        )
        .unwrap();
        let held = path.at(40.8);
        for k in 0..1000 {
            let at = path.at(40.8 + 2.967 * k as f32 / 1000.0);
            assert_eq!((at.eye, at.target), (held.eye, held.target), "step {k}");
        }
    }

    #[test]
    fn rejects_malformed_files() {
        for bad in [
            "",
            "0 1 2",
            "0 0 0 0 0 0 -1\n0 1 0 0 0 0 -1",
            "0 a 0 0 0 0 -1",
            "0 0 0 0 0 0 -1 190",
        ] {
            assert!(CameraPath::parse(bad, 60.0).is_err(), "{bad:?} accepted");
        }
    }
}
