//! Progress on stderr for work longer than a second: a bar on a terminal; elsewhere (a farm's
//! log, a pipe) one plain line per tenth of the work or per 30 s, so Deadline- or Tractor-style
//! log parsers see a job is alive. `--quiet` silences both.

use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

static QUIET: AtomicBool = AtomicBool::new(false);

/// `--quiet`: no progress of any kind for the rest of the process.
pub fn set_quiet(quiet: bool) {
    QUIET.store(quiet, Ordering::Relaxed);
}

/// A line for the log on stderr (how an input was read, a choice made for the user), unless
/// `--quiet`: what the report on stdout does not repeat but a technical artist checks first.
pub fn note(line: &str) {
    if !QUIET.load(Ordering::Relaxed) {
        eprintln!("{line}");
    }
}

/// Plain lines: the first no sooner than this after the start (short work stays silent) ...
const FIRST_AFTER: Duration = Duration::from_secs(1);
/// ... unless this variable says otherwise (seconds; 0 logs from the first tenth, e.g. for a farm
/// that wants every job's lines whatever its length, or a test that must not depend on speed).
const FIRST_AFTER_VAR: &str = "GARMENTBAKE_PROGRESS_AFTER_S";
/// ... then one per tenth of the work, and one at least this often when the work is slow.
const AT_LEAST_EVERY: Duration = Duration::from_secs(30);

/// A bar of `len` steps labelled `what`. `hide_bar` (a command's `--json`, or work too small
/// to show) hides the terminal bar; plain lines off a terminal still go to the log, as stderr
/// is not the report. `--quiet` hides everything.
pub fn bar(len: u64, what: &str, hide_bar: bool) -> Progress {
    let (bar, plain) = if QUIET.load(Ordering::Relaxed) {
        (indicatif::ProgressBar::hidden(), None)
    } else if !std::io::stderr().is_terminal() {
        (
            indicatif::ProgressBar::hidden(),
            Some(Mutex::new(Plain::new(
                what,
                len,
                Instant::now(),
                first_after(),
            ))),
        )
    } else if hide_bar {
        (indicatif::ProgressBar::hidden(), None)
    } else {
        let bar = indicatif::ProgressBar::new(len);
        bar.set_style(
            indicatif::ProgressStyle::with_template("{msg:>12} [{bar:30}] {pos}/{len} ({eta})")
                .expect("valid template")
                .progress_chars("=> "),
        );
        bar.set_message(what.to_string());
        (bar, None)
    };
    Progress { bar, plain }
}

/// Progress of one piece of work: a terminal bar, plain log lines, or nothing.
pub struct Progress {
    bar: indicatif::ProgressBar,
    plain: Option<Mutex<Plain>>,
}

impl Progress {
    pub fn inc(&self, delta: u64) {
        self.bar.inc(delta);
        self.plain(|p| p.position += delta);
    }

    pub fn set_position(&self, position: u64) {
        self.bar.set_position(position);
        self.plain(|p| p.position = position);
    }

    pub fn set_length(&self, len: u64) {
        self.bar.set_length(len);
        self.plain(|p| p.len = len);
    }

    /// What the work is at now (e.g. an epoch's loss), shown with the count.
    pub fn set_message(&self, message: impl Into<String>) {
        let message = message.into();
        self.bar.set_message(message.clone());
        self.plain(|p| p.message = Some(message));
    }

    /// A line of its own above the bar (in a log, a line like any other).
    pub fn println(&self, line: impl AsRef<str>) {
        match &self.plain {
            Some(_) => eprintln!("{}", line.as_ref()),
            None => self.bar.println(line),
        }
    }

    pub fn finish_and_clear(&self) {
        self.bar.finish_and_clear();
    }

    /// Stops the bar where it is (the work failed).
    pub fn abandon(&self) {
        self.bar.abandon();
    }

    /// Updates the plain state and prints its line when one is due.
    fn plain(&self, update: impl FnOnce(&mut Plain)) {
        let Some(plain) = &self.plain else { return };
        let mut p = plain.lock().unwrap_or_else(|e| e.into_inner());
        update(&mut p);
        if let Some(line) = p.due(Instant::now()) {
            eprintln!("{line}");
        }
    }
}

/// The quiet start of plain lines: `GARMENTBAKE_PROGRESS_AFTER_S` when it holds a number of seconds.
fn first_after() -> Duration {
    std::env::var(FIRST_AFTER_VAR)
        .ok()
        .and_then(|v| v.trim().parse::<f64>().ok())
        .filter(|s| s.is_finite() && *s >= 0.0)
        .map_or(FIRST_AFTER, Duration::from_secs_f64)
}

/// The state behind plain progress lines.
struct Plain {
    what: String,
    len: u64,
    position: u64,
    message: Option<String>,
    started: Instant,
    first_after: Duration,
    /// When the last line was printed, and the tenth of the work it reported.
    last_line: Option<Instant>,
    last_tenth: u64,
}

impl Plain {
    fn new(what: &str, len: u64, now: Instant, first_after: Duration) -> Plain {
        Plain {
            what: what.to_string(),
            len,
            position: 0,
            message: None,
            started: now,
            first_after,
            last_line: None,
            last_tenth: 0,
        }
    }

    /// The line to print at `now`, if one is due: the work reached a new tenth, or the last line
    /// is 30 s old; never in the first second (or `first_after`).
    fn due(&mut self, now: Instant) -> Option<String> {
        let elapsed = now.duration_since(self.started);
        if elapsed < self.first_after {
            return None;
        }
        let tenth = (self.position.min(self.len) * 10)
            .checked_div(self.len)
            .unwrap_or(0);
        let stale = now.duration_since(self.last_line.unwrap_or(self.started)) >= AT_LEAST_EVERY;
        if tenth <= self.last_tenth && !stale {
            return None;
        }
        self.last_line = Some(now);
        self.last_tenth = self.last_tenth.max(tenth);
        Some(self.line(elapsed))
    }

    /// `progress: epochs 3/10 30% 12 s, about 28 s left (loss 0.1234)`: `NN%` for log
    /// parsers' usual pattern.
    fn line(&self, elapsed: Duration) -> String {
        let s = elapsed.as_secs_f64();
        let mut line = if self.len > 0 {
            let done = self.position.min(self.len) as f64 / self.len as f64;
            let mut l = format!(
                "progress: {} {}/{} {}% {:.0} s",
                self.what,
                self.position,
                self.len,
                self.position.min(self.len) * 100 / self.len,
                s
            );
            if done > 0.0 && done < 1.0 {
                l.push_str(&format!(", about {:.0} s left", s * (1.0 - done) / done));
            }
            l
        } else {
            format!("progress: {} {} {:.0} s", self.what, self.position, s)
        };
        if let Some(m) = self.message.as_deref().filter(|m| *m != self.what) {
            line.push_str(&format!(" ({m})"));
        }
        line
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The lines a run of `len` steps prints when step k ends at `times[k]` seconds.
    fn lines(len: u64, times: &[f64]) -> Vec<String> {
        let start = Instant::now();
        let mut p = Plain::new("epochs", len, start, FIRST_AFTER);
        times
            .iter()
            .filter_map(|&t| {
                p.position += 1;
                p.due(start + Duration::from_secs_f64(t))
            })
            .collect()
    }

    #[test]
    fn one_line_per_tenth_after_the_first_second() {
        // 100 steps, one every 0.1 s: steps 1..=9 fall in the first second; then a line at
        // each tenth (the first one at step 10, 1.0 s).
        let times: Vec<f64> = (1..=100).map(|k| k as f64 * 0.1).collect();
        let out = lines(100, &times);
        assert_eq!(out.len(), 10, "{out:#?}");
        assert_eq!(out[0], "progress: epochs 10/100 10% 1 s, about 9 s left");
        assert_eq!(out[9], "progress: epochs 100/100 100% 10 s");
    }

    #[test]
    fn slow_work_prints_every_30_seconds_and_short_work_nothing() {
        // 1000 steps of 1 s: tenths every 100 s, and a line every 30 s between them.
        let times: Vec<f64> = (1..=1000).map(|k| k as f64).collect();
        let out = lines(1000, &times);
        assert!(
            out[0].starts_with("progress: epochs 30/1000 3% 30 s"),
            "{out:#?}"
        );
        assert!(
            out[1].starts_with("progress: epochs 60/1000 6% 60 s"),
            "{out:#?}"
        );
        assert!(
            out[2].starts_with("progress: epochs 90/1000 9% 90 s"),
            "{out:#?}"
        );
        assert!(
            out[3].starts_with("progress: epochs 100/1000 10% 100 s"),
            "{out:#?}"
        );
        assert_eq!(out.len(), 10 + 30, "{out:#?}");
        assert!(lines(5, &[0.1, 0.2, 0.3, 0.4, 0.5]).is_empty());
    }

    #[test]
    fn unknown_length_counts_and_messages_follow() {
        let start = Instant::now();
        let mut p = Plain::new("simulate", 0, start, FIRST_AFTER);
        p.position = 7;
        assert_eq!(
            p.due(start + Duration::from_secs(5)),
            None,
            "no tenth of nothing"
        );
        p.message = Some("frame 7".into());
        assert_eq!(
            p.due(start + Duration::from_secs(31)).as_deref(),
            Some("progress: simulate 7 31 s (frame 7)")
        );
    }
}
