//! Progress of long jobs (collection, dataset build, training): an indicatif
//! bar on a terminal; elsewhere (a job in the background writing to a file)
//! a plain line every few seconds, which indicatif does not draw.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// How often a line is written when stderr is not a terminal.
const LOG_EVERY: Duration = Duration::from_secs(10);

/// A progress bar over `total` units of work (states, logs, samples).
pub struct Progress {
    bar: ProgressBar,
    unit: &'static str,
    /// Last plain line, when stderr is not a terminal.
    plain: Option<Mutex<Instant>>,
    /// Where this run started (a resumed job starts part-way).
    start: std::sync::atomic::AtomicU64,
}

impl Progress {
    /// A bar towards `total` `unit`s (e.g. "states") on stderr.
    pub fn new(total: u64, unit: &'static str) -> Self {
        let tty = std::io::stderr().is_terminal();
        let bar = ProgressBar::with_draw_target(
            Some(total),
            if tty {
                ProgressDrawTarget::stderr()
            } else {
                ProgressDrawTarget::hidden()
            },
        );
        let template = format!(
            "[{{bar:30}}] {{human_pos}}/{{human_len}} {unit} {{msg}} {{per_sec}} elapsed {{elapsed}} left {{eta}}"
        );
        bar.set_style(
            ProgressStyle::with_template(&template)
                .expect("a valid template")
                .progress_chars("#>."),
        );
        let plain = (!tty).then(|| Mutex::new(Instant::now()));
        Self {
            bar,
            unit,
            plain,
            start: std::sync::atomic::AtomicU64::new(0),
        }
    }

    /// Starts from `done` (a resumed job): the rate counts only what is
    /// done from here on.
    pub fn resume_at(&self, done: u64) {
        self.bar.set_position(done);
        self.bar.reset_eta();
        self.bar.reset_elapsed();
        self.start.store(done, std::sync::atomic::Ordering::Relaxed);
    }

    /// Sets the work done and a short note (e.g. "12 episodes").
    pub fn update(&self, done: u64, note: impl Into<String>) {
        self.bar.set_position(done);
        self.bar.set_message(note.into());
        if let Some(last) = &self.plain {
            let mut last = last.lock().expect("not poisoned");
            if last.elapsed() >= LOG_EVERY {
                *last = Instant::now();
                eprintln!("{}", self.line());
            }
        }
    }

    /// Runs `f` (which writes to the terminal) with the bar cleared.
    pub fn suspend<R>(&self, f: impl FnOnce() -> R) -> R {
        self.bar.suspend(f)
    }

    /// Ends the bar, leaving its last state on screen (or in the log): a
    /// job stopped part-way shows where it stopped, not its total.
    pub fn finish(&self) {
        // indicatif's `finish` would set the position to the length.
        self.bar.abandon();
        if self.plain.is_some() {
            eprintln!("{}", self.line());
        }
    }

    fn line(&self) -> String {
        let b = &self.bar;
        format!(
            "{}/{} {} {} {:.0}/s elapsed {:.0} s",
            b.position(),
            b.length().unwrap_or(0),
            self.unit,
            b.message(),
            b.position()
                .saturating_sub(self.start.load(std::sync::atomic::Ordering::Relaxed))
                as f64
                / b.elapsed().as_secs_f64().max(1e-3),
            b.elapsed().as_secs_f64(),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stopped_job_ends_where_it_stopped() {
        let p = Progress::new(3710, "batches");
        p.update(650, "epoch 2/10");
        p.finish();
        assert!(p.line().starts_with("650/3710 batches"), "{}", p.line());
    }
}
