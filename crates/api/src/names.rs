//! Names people give things (uploads, sweeps, workers): shown in the dashboard, logs and
//! tables, so they must read as written. Control characters (NUL among them) and Unicode's
//! bidirectional formatting characters (the right-to-left override that makes `exe.txt` of
//! `txt.exe`) are refused.

/// The longest name, in characters.
pub const MAX_NAME: usize = 128;

/// Unicode's bidirectional formatting characters: embeddings, overrides, isolates and marks.
fn bidi_control(c: char) -> bool {
    matches!(c, '\u{202A}'..='\u{202E}' | '\u{2066}'..='\u{2069}' | '\u{200E}' | '\u{200F}' | '\u{061C}')
}

/// `Ok` for 1 to [`MAX_NAME`] characters with no control or bidirectional formatting
/// character; else what is wrong.
pub fn check_name(name: &str) -> Result<(), &'static str> {
    if name.is_empty() {
        return Err("must not be empty");
    }
    if name.chars().count() > MAX_NAME {
        return Err("at most 128 characters");
    }
    if name.chars().any(char::is_control) {
        return Err("no control characters");
    }
    if name.chars().any(bidi_control) {
        return Err(
            "no bidirectional formatting characters (U+202A-U+202E, U+2066-U+2069, U+200E, U+200F, U+061C)",
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_read_as_written() {
        assert_eq!(check_name("grasp sweep 3 (ü)"), Ok(()));
        assert!(check_name("").is_err());
        assert!(check_name(&"x".repeat(129)).is_err());
        assert!(check_name("a\0b").is_err());
        assert!(check_name("evil\u{202E}txt.exe").is_err());
        assert!(check_name("\u{2067}isolate").is_err());
    }
}
