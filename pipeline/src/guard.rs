//! A last line of defence for readers of hostile files: a panic inside a parser (ours or a
//! dependency's: `exr`, `tiff`, the Zemax/ISET lens parsers) becomes one error line naming the
//! file, instead of a crash with a backtrace. The panic message is kept in the error; the
//! default panic output is suppressed only on the thread inside [`guarded`].
use crate::error::CliError;
use std::cell::Cell;
use std::path::Path;

thread_local! {
    static QUIET: Cell<bool> = const { Cell::new(false) };
}

fn install_hook() {
    static HOOK: std::sync::Once = std::sync::Once::new();
    HOOK.call_once(|| {
        let prev = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !QUIET.with(|q| q.get()) {
                prev(info)
            }
        }));
    });
}

/// Run the reader `f` of `path`; a panic in it is returned as
/// `"{path}: malformed file (the reader failed: …)"`.
pub fn guarded<T>(path: &Path, f: impl FnOnce() -> Result<T, CliError>) -> Result<T, CliError> {
    install_hook();
    let was = QUIET.with(|q| q.replace(true));
    let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
    QUIET.with(|q| q.set(was));
    r.unwrap_or_else(|p| {
        let why = p
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| p.downcast_ref::<&str>().copied())
            .unwrap_or("unknown");
        Err(CliError::input(
            path,
            format!(
                "malformed file (the reader failed: {})",
                why.split_whitespace().collect::<Vec<_>>().join(" ")
            ),
        ))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_panicking_reader_is_one_error_line() {
        let e = guarded::<()>(Path::new("x.exr"), || panic!("index out of\nbounds"))
            .unwrap_err()
            .one_line();
        assert_eq!(
            e,
            "x.exr: malformed file (the reader failed: index out of bounds)"
        );
        assert_eq!(guarded(Path::new("x"), || Ok(3)).unwrap(), 3);
    }
}
