//! A progress bar on standard error for long reads of log files (only when it is a terminal):
//! how far through the input files, frames and bytes per second.

use std::fs::File;
use std::io::{IsTerminal, Seek};
use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// Records between two looks at the input files' positions.
const EVERY: u64 = 16_384;

/// Progress through a set of input files, by their read positions.
pub struct Progress {
    bar: Option<ProgressBar>,
    files: Vec<File>,
    frames: u64,
}

impl Progress {
    /// A bar over `files` (handles sharing the inputs' read positions), drawn only when
    /// standard error is a terminal.
    pub fn new(files: Vec<File>) -> Self {
        let total: u64 = files
            .iter()
            .filter_map(|f| f.metadata().ok())
            .map(|m| m.len())
            .sum();
        let bar = (std::io::stderr().is_terminal() && total > 0).then(|| {
            let bar = ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr());
            bar.set_style(
                ProgressStyle::with_template(
                    "{bar:30} {bytes}/{total_bytes} {binary_bytes_per_sec} {msg} (eta {eta})",
                )
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
            );
            bar.enable_steady_tick(Duration::from_millis(200));
            bar
        });
        Progress {
            bar,
            files,
            frames: 0,
        }
    }

    /// One more frame read.
    pub fn frame(&mut self) {
        self.frames += 1;
        if !self.frames.is_multiple_of(EVERY) {
            return;
        }
        if let Some(bar) = &self.bar {
            let position: u64 = self
                .files
                .iter_mut()
                .filter_map(|f| f.stream_position().ok())
                .sum();
            bar.set_position(position);
            let per_second = self.frames as f64 / bar.elapsed().as_secs_f64().max(1e-3);
            bar.set_message(format!("{} frames, {per_second:.0} frames/s", self.frames));
        }
    }

    /// Take the bar off the terminal.
    pub fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}
