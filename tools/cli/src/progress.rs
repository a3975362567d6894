//! Progress bars for long stages; hidden when stderr is not a terminal.

use indicatif::{ProgressBar, ProgressStyle};

/// A bar of `len` steps labelled `label`.
pub fn bar(len: u64, label: &str) -> ProgressBar {
    let bar = ProgressBar::new(len);
    bar.set_style(
        ProgressStyle::with_template("{prefix:>14} [{bar:30}] {pos}/{len} {msg} ({eta} left)")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    bar.set_prefix(label.to_string());
    bar
}

/// A bar for a long job's passes: the pass's name, tiles done of all, the
/// rate and the time left.
pub fn pass_bar() -> ProgressBar {
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template(
            "{msg:>18} [{bar:30}] {pos}/{len} tiles, {per_sec}, {eta} left",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    bar
}

/// Show a build's progress on a [`pass_bar`].
pub fn show_pass(bar: &ProgressBar, p: relevo_core::pyramid::Progress) {
    bar.set_message(p.pass);
    bar.set_length(p.total as u64);
    bar.set_position(p.done as u64);
}
