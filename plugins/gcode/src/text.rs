//! Text that reaches the G-code: names made safe for comment lines, and numbers
//! written as firmwares read them.

/// The longest name written into a comment.
const MAX_NAME: usize = 80;

/// A name (pipeline, part, material, head) made safe for a `;` comment: control
/// characters and Unicode line breaks become spaces, so that a name with a newline can
/// never start an executable line, and very long names are cut.
pub fn clean(name: &str) -> String {
    let mut out: String = lamina_api::text::one_line(name).chars().take(MAX_NAME).collect();
    if name.chars().count() > MAX_NAME {
        out.push_str("...");
    }
    let trimmed = out.trim();
    if trimmed.is_empty() {
        "?".to_string()
    } else {
        trimmed.to_string()
    }
}

/// A coordinate or temperature with at most `digits` decimals and no trailing zeros
/// (`210`, `0.2`, `12.345`), and never `-0`.
pub fn num(v: f64, digits: usize) -> String {
    let mut out = String::with_capacity(24);
    push_num(&mut out, v, digits);
    out
}

/// [`num`] appended to `out`: the lines of moves are written without a string per
/// number.
pub fn push_num(out: &mut String, v: f64, digits: usize) {
    use std::fmt::Write;
    // Fixed point through an integer: `format!` with a precision takes the exact
    // (slow) path for many values, and a G-code file formats millions of them.
    let scale = 10f64.powi(digits.min(15) as i32);
    let scaled = (v * scale).round();
    if digits <= 9 && scaled.is_finite() && scaled.abs() < 9.0e15 {
        let n = scaled as i64;
        if n == 0 {
            out.push('0');
            return;
        }
        let unit = 10i64.pow(digits as u32);
        let (int, mut frac) = (n.abs() / unit, n.abs() % unit);
        if n < 0 {
            out.push('-');
        }
        // Writing into a `String` cannot fail.
        let _ = write!(out, "{int}");
        if frac != 0 {
            let mut width = digits;
            while frac % 10 == 0 {
                frac /= 10;
                width -= 1;
            }
            let _ = write!(out, ".{frac:0width$}");
        }
        return;
    }
    let s = format!("{v:.digits$}");
    let s = if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.')
    } else {
        &s
    };
    out.push_str(if s == "-0" { "0" } else { s });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_cannot_break_lines() {
        assert_eq!(clean("red\nG28 X0"), "red G28 X0");
        assert_eq!(clean("a\r\u{2028}b\u{0}"), "a  b");
        assert_eq!(clean("\n"), "?");
        assert!(clean(&"x".repeat(200)).len() <= MAX_NAME + 3);
    }

    #[test]
    fn numbers_are_short() {
        assert_eq!(num(210.0, 1), "210");
        assert_eq!(num(0.2, 4), "0.2");
        assert_eq!(num(-0.00001, 3), "0");
        assert_eq!(num(12.34567, 3), "12.346");
        assert_eq!(num(-12.34567, 4), "-12.3457");
        assert_eq!(num(0.05, 4), "0.05");
        assert_eq!(num(-0.5, 1), "-0.5");
        assert_eq!(num(1.0e20, 3), "100000000000000000000");
        // Within half a unit of the last digit of the value (the product with the
        // scale may round a near tie the other way than the exact formatter).
        for i in 0..2000 {
            let v = (i as f64 - 1000.0) * 0.123_456_7;
            let back: f64 = num(v, 4).parse().expect("a number");
            assert!((back - v).abs() <= 0.5e-4 + 1e-12, "{v} -> {back}");
        }
    }
}
