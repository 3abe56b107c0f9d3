//! Text that goes into the files stages write.

/// A name as one line of text for a file a machine reads: control characters and
/// Unicode line breaks become spaces, so that no name (of a pipeline, part or material)
/// can start a line of its own.
pub fn one_line(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_control() || matches!(c, '\u{2028}' | '\u{2029}' | '\u{85}') {
                ' '
            } else {
                c
            }
        })
        .collect()
}
