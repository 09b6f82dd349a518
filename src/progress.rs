//! Progress bars on stderr for work longer than a second, hidden for machine output.

/// A bar of `len` steps labelled `what`; hidden when `quiet` (`--json`) or stderr is not a
/// terminal, so machine output stays clean.
pub fn bar(len: u64, what: &str, quiet: bool) -> indicatif::ProgressBar {
    if quiet {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(len);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{msg:>12} [{bar:30}] {pos}/{len} ({eta})")
            .expect("valid template")
            .progress_chars("=> "),
    );
    bar.set_message(what.to_string());
    bar
}
