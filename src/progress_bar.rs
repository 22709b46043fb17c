//! The launcher's one progress line (indicatif), fed by the viewer's `progress …` lines
//! (`viewer::progress`). On a terminal it redraws in place; elsewhere it stays hidden, and the
//! launcher reports the last progress once at the end.

use std::io::{BufRead, BufReader, Read};

use indicatif::{ProgressBar, ProgressStyle};
use viewer::progress::Progress;

/// Shows the progress of the lines read from `viewer_stdout` until it closes; returns the last.
/// Any other line the viewer prints goes on to our stdout, above the bar.
pub fn show(viewer_stdout: impl Read) -> Option<Progress> {
    let bar = ProgressBar::new_spinner();
    bar.set_style(
        ProgressStyle::with_template("{spinner} {msg}").unwrap_or(ProgressStyle::default_spinner()),
    );
    let mut last = None;
    for line in BufReader::new(viewer_stdout).lines() {
        let Ok(line) = line else { break };
        match Progress::parse(&line) {
            Some(p) => {
                bar.set_message(message(&p));
                bar.tick();
                last = Some(p);
            }
            None => bar.println(line),
        }
    }
    bar.finish_and_clear();
    last
}

fn message(p: &Progress) -> String {
    format!(
        "{} samples · {:.0} samples/s · {} triangles shown · {}",
        p.samples, p.samples_per_sec, p.shown, p.state
    )
}
