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
/// number. Returns the value a reader parses back from what was written.
pub fn push_num(out: &mut String, v: f64, digits: usize) -> f64 {
    // Fixed point through an integer: `format!` with a precision takes the exact
    // (slow) path for many values, and a G-code file formats millions of them.
    match scaled(v, digits) {
        Some((0, _)) => {
            out.push('0');
            0.0
        }
        Some((n, unit)) => {
            let (int, mut frac) = (n.unsigned_abs() / unit, n.unsigned_abs() % unit);
            if n < 0 {
                out.push('-');
            }
            push_int(out, int);
            if frac != 0 {
                let mut width = digits;
                while frac % 10 == 0 {
                    frac /= 10;
                    width -= 1;
                }
                out.push('.');
                push_padded(out, frac, width);
            }
            read_back(n, unit)
        }
        None => {
            let s = format!("{v:.digits$}");
            let s = if s.contains('.') {
                s.trim_end_matches('0').trim_end_matches('.')
            } else {
                &s
            };
            let s = if s == "-0" { "0" } else { s };
            out.push_str(s);
            s.parse().unwrap_or(v)
        }
    }
}

/// `v` with exactly `digits` decimals (`0.01230`), as `format!("{v:.digits$}")`
/// writes it but for `-0`, which is written `0` with its decimals. Returns the value
/// a reader parses back from what was written.
pub fn push_fixed(out: &mut String, v: f64, digits: usize) -> f64 {
    match scaled(v, digits) {
        Some((n, unit)) => {
            if n < 0 {
                out.push('-');
            }
            push_int(out, n.unsigned_abs() / unit);
            if digits > 0 {
                out.push('.');
                push_padded(out, n.unsigned_abs() % unit, digits);
            }
            read_back(n, unit)
        }
        None => {
            let start = out.len();
            // Writing into a `String` cannot fail.
            let _ = std::fmt::Write::write_fmt(out, format_args!("{v:.digits$}"));
            out[start..].parse().unwrap_or(v)
        }
    }
}

/// `v` times 10^`digits`, rounded, and 10^`digits`: `None` where that is not a
/// whole number an `f64` holds exactly (or `digits` is past nine).
fn scaled(v: f64, digits: usize) -> Option<(i64, u64)> {
    if digits > 9 {
        return None;
    }
    let unit = 10u64.pow(digits as u32);
    let scaled = (v * unit as f64).round();
    (scaled.is_finite() && scaled.abs() < 9.0e15).then_some((scaled as i64, unit))
}

/// The value of the decimal `n` / `unit` as a reader parses it: both are exact in an
/// `f64` and the quotient is correctly rounded, as parsing is.
fn read_back(n: i64, unit: u64) -> f64 {
    n as f64 / unit as f64
}

/// The decimal digits of `n`.
fn push_int(out: &mut String, n: u64) {
    push_padded(out, n, 1);
}

/// The decimal digits of `n`, zero-padded on the left to `width`.
fn push_padded(out: &mut String, mut n: u64, width: usize) {
    let mut digits = [b'0'; 20];
    let mut i = digits.len();
    while n > 0 {
        i -= 1;
        digits[i] = b'0' + (n % 10) as u8;
        n /= 10;
    }
    let i = i.min(digits.len() - width.min(digits.len()));
    // Only ASCII digits were written.
    out.push_str(std::str::from_utf8(&digits[i..]).unwrap_or("0"));
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

    /// What is written reads back as the value returned, digit for digit as the
    /// formatter writes it but for a near tie (then within half a unit of the last
    /// digit either way).
    #[test]
    fn numbers_read_back_as_returned() {
        let mut ties = 0;
        for i in 0..20_000 {
            let v = (i as f64 - 10_000.0) * 0.012_345_678_9 + 1e-7 * f64::from(i % 7);
            for digits in [0, 3, 4, 5] {
                let mut short = String::new();
                let back = push_num(&mut short, v, digits);
                assert_eq!(short.parse::<f64>().ok(), Some(back), "{v} {digits}: {short}");
                let mut fixed = String::new();
                let back = push_fixed(&mut fixed, v, digits);
                assert_eq!(fixed.parse::<f64>().ok(), Some(back), "{v} {digits}: {fixed}");
                let exact = format!("{v:.digits$}");
                if fixed != exact && exact != format!("-{fixed}") {
                    ties += 1;
                    let other: f64 = exact.parse().expect("a number");
                    assert!(
                        (other - back).abs() <= 1.0001 * 10f64.powi(-(digits as i32)),
                        "{v}: {fixed} {exact}"
                    );
                }
            }
        }
        assert!(ties < 20, "{ties}");
        let mut out = String::new();
        assert_eq!(push_fixed(&mut out, 0.0123, 5), 0.0123);
        assert_eq!(push_fixed(&mut out, -0.000001, 5), 0.0);
        assert_eq!(push_fixed(&mut out, 7.0, 0), 7.0);
        assert_eq!(push_fixed(&mut out, 1.0e20, 5), 1.0e20);
        assert_eq!(out, "0.012300.000007100000000000000000000.00000");
    }
}
