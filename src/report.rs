//! Error rendering: errors that point into a file are shown with the offending line
//! and a label (miette); the others as a chain of causes.

use std::error::Error as _;

use lamina_core::Error;
use miette::{Diagnostic, GraphicalReportHandler, GraphicalTheme, LabeledSpan, NamedSource, SourceSpan};

#[derive(Debug)]
struct Located {
    message: String,
    help: Option<String>,
    source: NamedSource<String>,
    span: SourceSpan,
}

impl std::fmt::Display for Located {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for Located {}

impl Diagnostic for Located {
    fn help<'a>(&'a self) -> Option<Box<dyn std::fmt::Display + 'a>> {
        self.help
            .as_ref()
            .map(|h| Box::new(h) as Box<dyn std::fmt::Display>)
    }

    fn source_code(&self) -> Option<&dyn miette::SourceCode> {
        Some(&self.source)
    }

    fn labels(&self) -> Option<Box<dyn Iterator<Item = LabeledSpan> + '_>> {
        Some(Box::new(std::iter::once(LabeledSpan::new_with_span(
            Some("here".into()),
            self.span,
        ))))
    }
}

/// `s` as it may reach a terminal: a control character (an escape sequence that would
/// clear the screen or move the cursor, from a name or a script's message) is shown
/// as its code, `\x1b`; line breaks and tabs stay.
pub fn visible(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        if c.is_control() && !matches!(c, '\n' | '\t') {
            out.push_str(&format!("\\x{:02x}", c as u32));
        } else {
            out.push(c);
        }
    }
    out
}

/// The same text with each control character but line breaks and tabs replaced by
/// `?`, one byte for one byte, so that spans into it still point where they did.
fn same_length(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_control() && !matches!(c, '\n' | '\t' | '\r') {
                '?'
            } else {
                c
            }
        })
        .collect()
}

/// Prints `e` to stderr. The first line always reads `error: FILE:LINE:COL: message`
/// when the error has a place, so scripts and tests can rely on it.
pub fn print(e: &Error) {
    if let Error::Several(all) = e {
        for one in all {
            print(one);
        }
        eprintln!("error: {} errors in all", all.len());
        return;
    }
    let mut message = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        let s = c.to_string();
        if !message.contains(&s) {
            message.push_str(": ");
            message.push_str(&s);
        }
        cause = c.source();
    }
    eprintln!("error: {}", visible(&message));
    let Some(loc) = e.location() else {
        if let Some(h) = e.help() {
            eprintln!("help: {}", visible(h));
        }
        return;
    };
    // Control characters are one byte each: replaced one for one, spans still fit.
    let text = same_length(&loc.file.text);
    let start = loc.span.start.min(text.len());
    let len = loc
        .span
        .end
        .saturating_sub(loc.span.start)
        .min(text.len() - start);
    let diag = Located {
        message: "here:".into(),
        help: e.help().map(visible),
        source: NamedSource::new(loc.file.path.display().to_string(), text),
        span: (start, len).into(),
    };
    let theme = if std::io::IsTerminal::is_terminal(&std::io::stderr()) {
        GraphicalTheme::unicode()
    } else {
        GraphicalTheme::unicode_nocolor()
    };
    let mut out = String::new();
    if GraphicalReportHandler::new_themed(theme)
        .render_report(&mut out, &diag)
        .is_ok()
    {
        eprint!("{out}");
    }
}
