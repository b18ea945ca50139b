//! Progress bars for long commands (indicatif; drawn on stderr only when it is a terminal).
use indicatif::{ProgressBar, ProgressStyle};

/// A bar of `len` steps with the indicatif `template`, or a hidden bar when `enabled` is false.
pub fn bar(enabled: bool, len: u64, template: &str) -> ProgressBar {
    let bar = if enabled {
        ProgressBar::new(len)
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template(template)
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    bar
}
