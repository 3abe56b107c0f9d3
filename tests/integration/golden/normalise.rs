//! The one rule by which golden outputs are compared: which numbers may move.
//!
//! Every output is compared as written, but for one kind of number: a decimal written
//! with more precision than the plan can vouch for. Lamina writes its machine files
//! with a fixed number of decimals (G-code and NC 3 to 5), and those stay exactly as
//! written, so a change to their formatting, or a value moving by one unit in the last
//! place, shows. JSON, CLI coordinates and bitmap headers carry every digit of an
//! `f64` (`0.30000000000000004`), and there the last digits follow the order of a sum:
//! a refactoring that adds the same terms in another order moves them without changing
//! the part. Such numbers, and only those, are rounded to [`DIGITS`] significant digits
//! and to [`RESOLUTION`] absolute before they are compared.

use std::borrow::Cow;

/// Significant digits a long decimal keeps: nine are a nanometre on a metre-long part,
/// far finer than any machine, far coarser than the last bit of an `f64`.
pub const DIGITS: usize = 9;

/// Magnitudes below this are zero (`-0.000000000001` and `0.000000000000` alike).
pub const RESOLUTION: f64 = 1e-9;

/// `text` with every long decimal rounded by [`number`]; everything else is untouched.
pub fn text(text: &str) -> String {
    let bytes = text.as_bytes();
    let mut out = String::with_capacity(text.len());
    let mut copied = 0;
    let mut i = 0;
    while i < bytes.len() {
        let starts_number = bytes[i].is_ascii_digit()
            || (bytes[i] == b'-' && bytes.get(i + 1).is_some_and(u8::is_ascii_digit));
        // A digit inside a word (`M163`, `T0`, `abc123`) is not where a number starts.
        let inside_word = i > 0 && (bytes[i - 1].is_ascii_digit() || bytes[i - 1] == b'.');
        if !starts_number || inside_word {
            i += 1;
            continue;
        }
        let end = token_end(bytes, i);
        let token = &text[i..end];
        // In a word such as `ab5e9` (base64, hex) only a decimal point makes a number.
        let after_letter = i > 0 && bytes[i - 1].is_ascii_alphabetic();
        if after_letter && !token.contains('.') {
            i = end;
            continue;
        }
        if let Cow::Owned(rounded) = number(token) {
            out.push_str(&text[copied..i]);
            out.push_str(&rounded);
            copied = end;
        }
        i = end;
    }
    out.push_str(&text[copied..]);
    out
}

/// The end of the number token that starts at `start`: sign, digits, a fraction, an
/// exponent.
fn token_end(bytes: &[u8], start: usize) -> usize {
    let digits = |mut i: usize| {
        while i < bytes.len() && bytes[i].is_ascii_digit() {
            i += 1;
        }
        i
    };
    let mut i = digits(start + usize::from(bytes[start] == b'-'));
    if i + 1 < bytes.len() && bytes[i] == b'.' && bytes[i + 1].is_ascii_digit() {
        i = digits(i + 1);
    }
    if i < bytes.len() && (bytes[i] == b'e' || bytes[i] == b'E') {
        let mut j = i + 1;
        if j < bytes.len() && (bytes[j] == b'-' || bytes[j] == b'+') {
            j += 1;
        }
        if j < bytes.len() && bytes[j].is_ascii_digit() {
            i = digits(j);
        }
    }
    i
}

/// One number token as compared: an integer, or a decimal of at most [`DIGITS`]
/// significant digits and at most [`DIGITS`] decimals, is kept as written; a longer
/// decimal (or one in exponent form) is rounded to [`DIGITS`] significant digits and
/// written shortest, and one below [`RESOLUTION`] in magnitude is `0`.
pub fn number(token: &str) -> Cow<'_, str> {
    let mantissa_end = token.find(['e', 'E']).unwrap_or(token.len());
    let mantissa = &token[..mantissa_end];
    let exponent = mantissa_end < token.len();
    let Some(point) = mantissa.find('.') else {
        if !exponent {
            return Cow::Borrowed(token);
        }
        return round(token);
    };
    let decimals = mantissa.len() - point - 1;
    let significant = mantissa
        .bytes()
        .filter(u8::is_ascii_digit)
        .skip_while(|&b| b == b'0')
        .count();
    if exponent || decimals > DIGITS || significant > DIGITS {
        round(token)
    } else {
        Cow::Borrowed(token)
    }
}

fn round(token: &str) -> Cow<'_, str> {
    let Ok(value) = token.parse::<f64>() else {
        return Cow::Borrowed(token);
    };
    if value.abs() < RESOLUTION {
        return Cow::Owned("0".into());
    }
    let rounded: f64 = format!("{value:.*e}", DIGITS - 1).parse().unwrap_or(value);
    Cow::Owned(format!("{rounded}"))
}

#[cfg(test)]
mod tests {
    use super::{number, text};

    #[test]
    fn numbers_written_to_a_fixed_precision_are_kept_as_written() {
        for kept in ["12.345", "12.340", "0.2000", "110.0324", "-0.00878", "3676.01231"] {
            assert_eq!(number(kept), kept);
        }
        // Integers are exact, however long.
        assert_eq!(number("12345678901234"), "12345678901234");
        assert_eq!(number("-7000"), "-7000");
    }

    #[test]
    fn long_decimals_lose_only_the_digits_a_sum_order_moves() {
        assert_eq!(number("0.30000000000000004"), "0.3");
        assert_eq!(number("0.29999999999999993"), "0.3");
        assert_eq!(number("1.0999999999999999"), "1.1");
        assert_eq!(number("6991.5681934362065"), "6991.56819");
        assert_eq!(number("-343.47372029192604"), "-343.47372");
        assert_eq!(number("1.2345678901234567e-5"), "0.0000123456789");
        // Below a nanometre is zero, whatever its sign or spelling.
        assert_eq!(number("-0.000000000001"), "0");
        assert_eq!(number("0.000000000000"), "0");
        assert_eq!(number("1e-12"), "0");
        // Nine significant digits are still nine, and a tenth is rounded.
        assert_eq!(number("123.456789"), "123.456789");
        assert_eq!(number("123.4567891"), "123.456789");
        assert_eq!(number("123.4567896"), "123.45679");
    }

    #[test]
    fn text_rounds_each_number_in_place_and_nothing_else() {
        assert_eq!(
            text("G1 X110.2493 Y98.4278 E14.24323 F1200 ; T0 M163"),
            "G1 X110.2493 Y98.4278 E14.24323 F1200 ; T0 M163"
        );
        assert_eq!(
            text(r#"{"z":0.30000000000000004,"p":[-0.000000000001,7000]}"#),
            r#"{"z":0.3,"p":[0,7000]}"#
        );
        assert_eq!(
            text("$$POLYLINE/1,1,129,6991.5681934362065,343.4737202919261"),
            "$$POLYLINE/1,1,129,6991.56819,343.47372"
        );
        // A version, a date or a word is not a decimal to round.
        assert_eq!(text("lamina 0.1.0, 2026-11-27"), "lamina 0.1.0, 2026-11-27");
        assert_eq!(text("data:ab5e9Q, T1e30"), "data:ab5e9Q, T1e30");
        // A one-character change of a machine file's number shows.
        assert_ne!(text("G1 X110.2493"), text("G1 X110.249"));
        assert_ne!(text("E14.24323"), text("E14.2432"));
    }
}
