//! The routes of `bench walk`, one per scene: where a person would walk and stop to look
//! (`route` turns them into camera paths).

use super::route::{Leg, Route};

fn stop(look_at: [f32; 3], seconds: f32, what: &'static str) -> Leg {
    Leg::Stop {
        look_at,
        seconds,
        what,
    }
}

/// The built-in Roman town (`scene::builtin::bracara`): from outside the city wall through the
/// gate, up the colonnaded street, round the pool to the temple front, and back to the street's
/// end looking down it to the gate. About 173 m and eight stops: 165 s a pass.
pub(crate) fn bracara() -> Route {
    use Leg::To;
    Route {
        scene: "bracara",
        start: (2.0, 110.0),
        fov_y_deg: 60.0,
        legs: vec![
            stop(
                [0.0, 6.0, 80.0],
                5.0,
                "the city wall and its gate (view MC)",
            ),
            To(0.5, 92.0),
            To(0.0, 79.5),
            To(-1.5, 60.0),
            stop(
                [0.5, 3.0, -20.0],
                3.0,
                "down the street to the temple (view VR)",
            ),
            To(-3.5, 40.0),
            stop([6.0, 1.5, 33.0], 2.0, "the east portico in the low sun"),
            To(2.5, 20.0),
            stop([-9.0, 4.0, 14.0], 4.0, "the west portico and houses"),
            To(0.0, 0.0),
            To(-9.0, -11.0),
            stop(
                [0.0, 6.0, -40.0],
                8.0,
                "the temple front past the pool (view VT)",
            ),
            To(-6.5, -20.0),
            stop([0.0, 0.35, -21.0], 3.0, "the pool's reflection"),
            To(-6.5, -29.5),
            stop([-4.5, 9.0, -36.0], 6.0, "the temple's columns, looking up"),
            To(-6.5, -12.0),
            To(3.0, -6.0),
            stop([0.0, 4.0, 78.0], 10.0, "back down the street to the gate"),
        ],
    }
}

/// Dabrovic Sponza (`scenes/sponza.toml`): round the courtyard, through the gaps between the
/// ground-floor pillars (x ≈ -9.0, 0.1, 4.7, 9.15) into both galleries, and back to the start,
/// so the second pass follows on without a cut. About 90 m and eight stops: 104 s a pass.
pub(crate) fn sponza() -> Route {
    use Leg::To;
    Route {
        scene: "sponza",
        start: (-10.0, 1.5),
        fov_y_deg: 60.0,
        legs: vec![
            stop(
                [4.0, 0.8, -2.5],
                5.0,
                "the courtyard floor, pillar shadows (view S1)",
            ),
            To(-2.0, 0.5),
            stop(
                [2.0, 9.0, -3.5],
                4.0,
                "the arches of the -z facade, looking up",
            ),
            To(6.0, 0.0),
            stop([6.0, 1.5, 6.0], 3.0, "into the shaded +z gallery"),
            To(9.15, 0.0),
            To(9.15, -5.2),
            stop([-10.0, 1.2, -5.2], 6.0, "along the -z gallery, sun patches"),
            To(0.1, -5.2),
            stop([0.1, 0.5, 0.0], 3.0, "out to the sunlit courtyard floor"),
            To(-10.5, -5.2),
            stop(
                [3.0, 1.0, -3.4],
                8.0,
                "the -z gallery from its end (view S2)",
            ),
            To(-9.0, -2.8),
            To(-9.0, 2.8),
            To(-9.0, 5.2),
            stop([10.0, 1.2, 5.2], 4.0, "along the +z gallery"),
            To(4.7, 5.2),
            To(4.7, 0.0),
            stop([-4.0, 6.0, -3.5], 7.0, "the -z facade in the sun"),
            To(-10.0, 1.5),
        ],
    }
}
