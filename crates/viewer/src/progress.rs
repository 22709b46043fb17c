//! The viewer's progress as one line on stdout, for a parent that shows it (the launcher's
//! progress bar): `progress samples=N samples_per_sec=X shown=N state=WORDS`. A line protocol
//! keeps the parent out of the SMA link; [`Progress::parse`] reads a line back.

use std::io::Write;
use std::time::{Duration, Instant};

use crate::view_state::ViewState;

const MARK: &str = "progress ";
/// How often a front end prints its line.
pub const EVERY: Duration = Duration::from_millis(500);

#[derive(Clone, Debug, PartialEq)]
pub struct Progress {
    pub samples: u64,
    pub samples_per_sec: f32,
    pub shown: u64,
    /// [`crate::view_state::Activity`] in words.
    pub state: String,
}

impl Progress {
    pub fn of(state: &ViewState) -> Progress {
        Progress {
            samples: state.epoch.map_or(0, |e| e.samples),
            samples_per_sec: state.stats.samples_per_sec,
            shown: state.table.len() as u64,
            state: state.activity().to_string(),
        }
    }

    pub fn line(&self) -> String {
        format!(
            "{MARK}samples={} samples_per_sec={:.0} shown={} state={}",
            self.samples, self.samples_per_sec, self.shown, self.state
        )
    }

    /// The progress a [`Progress::line`] carries, if `line` is one.
    pub fn parse(line: &str) -> Option<Progress> {
        let fields = line.trim_end().strip_prefix(MARK)?;
        let (numbers, state) = fields.split_once(" state=")?;
        let mut values = numbers
            .split(' ')
            .map(|kv| kv.split_once('=').map(|(_, v)| v));
        let mut next = || values.next().flatten();
        Some(Progress {
            samples: next()?.parse().ok()?,
            samples_per_sec: next()?.parse().ok()?,
            shown: next()?.parse().ok()?,
            state: state.to_string(),
        })
    }
}

/// Prints the progress line at most every [`EVERY`], when asked for (`--progress`).
pub struct ProgressPrinter {
    enabled: bool,
    last: Option<Instant>,
}

impl ProgressPrinter {
    pub fn new(enabled: bool) -> ProgressPrinter {
        ProgressPrinter {
            enabled,
            last: None,
        }
    }

    pub fn tick(&mut self, state: &ViewState) {
        let now = Instant::now();
        if !self.enabled || self.last.is_some_and(|t| now - t < EVERY) {
            return;
        }
        self.last = Some(now);
        let mut out = std::io::stdout().lock();
        // A parent that stopped reading is no reason to stop viewing.
        let _ = writeln!(out, "{}", Progress::of(state).line()).and_then(|()| out.flush());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_line_reads_back_as_the_progress_it_carries() {
        let p = Progress {
            samples: 12_345,
            samples_per_sec: 2048.0,
            shown: 987,
            state: "no renderer".into(),
        };
        assert_eq!(Progress::parse(&p.line()), Some(p));
        assert_eq!(Progress::parse("viewer listening on 1.2.3.4:5"), None);
        assert_eq!(
            Progress::parse("progress samples=x samples_per_sec=1 shown=2 state=s"),
            None
        );
    }
}
