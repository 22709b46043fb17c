//! Which of the CPU's vector units the ray queries use, chosen at run time (DESIGN.md §7): one
//! binary built for generic x86-64 carries the traversal twice, for the baseline and for
//! `x86-64-v3` (AVX2, FMA, BMI, LZCNT), and takes the second where the CPU has it. obvhs's
//! traversal is generic, so it is compiled inside each of our entry points with that entry
//! point's target features (`bvh.rs`).

use std::sync::OnceLock;

/// The variable that forces a level (`baseline` or `v3`), so tests run on both.
pub const VAR: &str = "WALKTHROUGH_SIMD";

/// A level of x86-64 vector instructions the ray queries are compiled for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VectorLevel {
    /// What every x86-64 (or any other architecture) runs: SSE2 only.
    Baseline,
    /// `x86-64-v3`: AVX2, FMA, BMI1/2, LZCNT, POPCNT, MOVBE, F16C.
    V3,
}

impl VectorLevel {
    pub fn name(self) -> &'static str {
        match self {
            VectorLevel::Baseline => "baseline",
            VectorLevel::V3 => "x86-64-v3",
        }
    }

    /// Whether this CPU can run the level.
    pub fn available(self) -> bool {
        match self {
            VectorLevel::Baseline => true,
            VectorLevel::V3 => v3_detected(),
        }
    }

    /// The best level this CPU runs.
    pub fn detected() -> VectorLevel {
        if VectorLevel::V3.available() {
            VectorLevel::V3
        } else {
            VectorLevel::Baseline
        }
    }

    /// The level named by `forced` (the value of [`VAR`]), or the detected one when unset. A
    /// level the CPU lacks is refused: running it would be undefined behaviour.
    pub fn choose(forced: Option<&str>) -> Result<VectorLevel, String> {
        let level = match forced.map(str::trim) {
            None | Some("") => return Ok(VectorLevel::detected()),
            Some("baseline") => VectorLevel::Baseline,
            Some("v3") => VectorLevel::V3,
            Some(other) => return Err(format!("{VAR}={other:?}: expected baseline or v3")),
        };
        if level.available() {
            Ok(level)
        } else {
            Err(format!(
                "{VAR} asks for {}, which this CPU lacks",
                level.name()
            ))
        }
    }

    /// The process's level, chosen once from [`VAR`] and the CPU and logged. Panics when the
    /// variable is malformed or asks for a level the CPU lacks: a forced level silently replaced
    /// would make a test on it pass for the wrong reason.
    pub fn selected() -> VectorLevel {
        static SELECTED: OnceLock<VectorLevel> = OnceLock::new();
        *SELECTED.get_or_init(|| {
            let forced = std::env::var(VAR).ok();
            let level = VectorLevel::choose(forced.as_deref()).unwrap_or_else(|e| panic!("{e}"));
            tracing::debug!(
                level = level.name(),
                forced = forced.is_some(),
                "ray traversal vector level"
            );
            level
        })
    }
}

#[cfg(target_arch = "x86_64")]
fn v3_detected() -> bool {
    // The features of `V3_FEATURES` in `bvh.rs`, every one of them.
    std::arch::is_x86_feature_detected!("avx2")
        && std::arch::is_x86_feature_detected!("fma")
        && std::arch::is_x86_feature_detected!("bmi1")
        && std::arch::is_x86_feature_detected!("bmi2")
        && std::arch::is_x86_feature_detected!("lzcnt")
        && std::arch::is_x86_feature_detected!("popcnt")
        && std::arch::is_x86_feature_detected!("movbe")
        && std::arch::is_x86_feature_detected!("f16c")
}

#[cfg(not(target_arch = "x86_64"))]
fn v3_detected() -> bool {
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unset_or_empty_means_the_detected_level() {
        assert_eq!(VectorLevel::choose(None), Ok(VectorLevel::detected()));
        assert_eq!(VectorLevel::choose(Some(" ")), Ok(VectorLevel::detected()));
    }

    #[test]
    fn baseline_is_always_available_and_v3_only_where_detected() {
        assert_eq!(
            VectorLevel::choose(Some("baseline")),
            Ok(VectorLevel::Baseline)
        );
        assert_eq!(
            VectorLevel::choose(Some("v3")).is_ok(),
            VectorLevel::V3.available()
        );
    }

    #[test]
    fn an_unknown_level_is_refused() {
        assert!(VectorLevel::choose(Some("avx512")).is_err());
    }
}
