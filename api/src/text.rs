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

/// Layer indices as ranges, in order and each once: `3-17, 20, 31-33`; past `most`
/// ranges the rest are counted (`and 4 more ranges`). What the CLI's summary and the
/// stages' own messages say of the layers something happened on.
pub fn layer_ranges(layers: &[usize], most: usize) -> String {
    let mut sorted = layers.to_vec();
    sorted.sort_unstable();
    sorted.dedup();
    let mut ranges: Vec<(usize, usize)> = Vec::new();
    for l in sorted {
        match ranges.last_mut() {
            Some(r) if r.1 + 1 == l => r.1 = l,
            _ => ranges.push((l, l)),
        }
    }
    let shown: Vec<String> = ranges
        .iter()
        .take(most)
        .map(|&(a, b)| if a == b { a.to_string() } else { format!("{a}-{b}") })
        .collect();
    let mut out = shown.join(", ");
    if ranges.len() > most {
        out.push_str(&format!(" and {} more ranges", ranges.len() - most));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::layer_ranges;

    #[test]
    fn layers_are_told_as_ranges_and_the_rest_counted() {
        assert_eq!(layer_ranges(&[0, 1, 2, 5, 7, 8], 6), "0-2, 5, 7-8");
        assert_eq!(layer_ranges(&[8, 7, 7, 5], 6), "5, 7-8");
        assert_eq!(layer_ranges(&[], 6), "");
        assert_eq!(layer_ranges(&[1, 3, 5, 7], 2), "1, 3 and 2 more ranges");
    }
}
