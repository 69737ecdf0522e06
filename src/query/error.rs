//! Query errors: a message about a span of the query, a label under the
//! span and an optional help line, rendered the way rustc renders its own:
//!
//! ```text
//! error: unknown subject `chnages`
//!  --> query:1:1
//!   |
//! 1 | chnages in zone:"Tower B" since:s3
//!   | ^^^^^^^ not a subject
//!   |
//!   = help: did you mean `changes`?
//! ```

use std::fmt::Write as _;
use unicode_width::UnicodeWidthChar;

/// Byte offsets `start..end` into the query text, on char boundaries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Span {
    pub start: usize,
    pub end: usize,
}

impl Span {
    pub fn new(start: usize, end: usize) -> Span {
        Span { start, end }
    }
    /// The span from the start of `self` to the end of `other`.
    pub fn to(self, other: Span) -> Span {
        Span { start: self.start.min(other.start), end: self.end.max(other.end) }
    }
}

/// A mistake in a query: what is wrong, where, and what to type instead.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{message}")]
pub struct QueryError {
    pub span: Span,
    pub message: String,
    /// Printed under the span.
    pub label: Option<String>,
    /// Printed as `= help: ...`.
    pub help: Option<String>,
}

impl QueryError {
    pub fn new(span: Span, message: impl Into<String>) -> QueryError {
        QueryError { span, message: message.into(), label: None, help: None }
    }
    pub fn label(mut self, label: impl Into<String>) -> QueryError {
        self.label = Some(label.into());
        self
    }
    pub fn help(mut self, help: impl Into<String>) -> QueryError {
        self.help = Some(help.into());
        self
    }
    /// Sets the help if there is one.
    pub fn maybe_help(mut self, help: Option<String>) -> QueryError {
        if help.is_some() {
            self.help = help;
        }
        self
    }

    /// The whole report: `error: message`, the query line with `^^^` under
    /// the span, and the help. `color`: ANSI colours (the caller checks
    /// `NO_COLOR` and whether stderr is a terminal).
    pub fn render(&self, src: &str, color: bool) -> String {
        let p = Paint(color);
        format!("{}{} {}\n{}", p.red("error"), p.bold(":"), p.bold(&self.message), self.render_snippet(src, color))
    }

    /// Everything after the message line.
    pub fn render_snippet(&self, src: &str, color: bool) -> String {
        let p = Paint(color);
        // Clamp defensively: a span past the text still renders.
        let start = floor_boundary(src, self.span.start.min(src.len()));
        let end = floor_boundary(src, self.span.end.clamp(start, src.len()));
        let line_start = src[..start].rfind('\n').map_or(0, |i| i + 1);
        let line_end = src[start..].find('\n').map_or(src.len(), |i| start + i);
        let line_no = src[..start].matches('\n').count() + 1;
        let line = &src[line_start..line_end];
        let col = src[line_start..start].chars().count() + 1;
        let gutter = line_no.to_string().len();
        let pad = " ".repeat(gutter);

        // Display columns: tabs and control characters print as one space.
        let shown: String = line.chars().map(|c| if c.is_control() { ' ' } else { c }).collect();
        let lead: usize = src[line_start..start].chars().map(width).sum();
        let under_end = end.min(line_end);
        let mut span_w: usize = src[start..under_end].chars().map(width).sum();
        if span_w == 0 {
            span_w = 1;
        }
        let mut out = String::new();
        let _ = writeln!(out, "{pad}{} query:{line_no}:{col}", p.blue("-->"));
        let _ = writeln!(out, "{pad} {}", p.blue("|"));
        let _ = writeln!(out, "{} {} {shown}", p.blue(&line_no.to_string()), p.blue("|"));
        let carets = "^".repeat(span_w);
        let label = self.label.as_deref().map(|l| format!(" {l}")).unwrap_or_default();
        let more = if end > line_end { " ..." } else { "" };
        let _ = writeln!(out, "{pad} {} {}{}", p.blue("|"), " ".repeat(lead), p.red(&format!("{carets}{more}{label}")));
        if let Some(h) = &self.help {
            let _ = writeln!(out, "{pad} {}", p.blue("|"));
            let mut lines = h.lines();
            if let Some(first) = lines.next() {
                let _ = writeln!(out, "{pad} {} {}: {first}", p.blue("="), p.bold("help"));
            }
            for l in lines {
                let _ = writeln!(out, "{pad}         {l}");
            }
        }
        out
    }
}

fn width(c: char) -> usize {
    if c.is_control() { 1 } else { c.width().unwrap_or(1) }
}

fn floor_boundary(s: &str, mut i: usize) -> usize {
    while i > 0 && !s.is_char_boundary(i) {
        i -= 1;
    }
    i
}

struct Paint(bool);

impl Paint {
    fn wrap(&self, code: &str, s: &str) -> String {
        if self.0 { format!("\x1b[{code}m{s}\x1b[0m") } else { s.to_string() }
    }
    fn red(&self, s: &str) -> String {
        self.wrap("1;31", s)
    }
    fn blue(&self, s: &str) -> String {
        self.wrap("1;34", s)
    }
    fn bold(&self, s: &str) -> String {
        self.wrap("1", s)
    }
}

/// A query error together with its query, for the command line: its
/// `Display` is the rendered report without the leading `error: ` (which
/// `seam`'s `main` prints).
#[derive(Debug)]
pub struct Report {
    pub error: QueryError,
    pub query: String,
    pub color: bool,
}

impl std::fmt::Display for Report {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let p = Paint(self.color);
        write!(f, "{}\n{}", p.bold(&self.error.message), self.error.render_snippet(&self.query, self.color).trim_end())
    }
}

impl std::error::Error for Report {}

/// The candidate closest to `word` by edit distance (case-insensitive, a
/// swap of two letters counts once), if close enough to be what was meant.
pub fn did_you_mean<'a>(word: &str, candidates: impl IntoIterator<Item = &'a str>) -> Option<&'a str> {
    let w = word.to_lowercase();
    let n = w.chars().count();
    let mut best: Option<(usize, &'a str)> = None;
    for c in candidates {
        let cl = c.to_lowercase();
        let mut d = strsim::osa_distance(&w, &cl);
        // A prefix of a long name is what was meant (`emer` → `emerged`).
        if n >= 3 && cl.starts_with(&w) {
            d = d.min(1);
        }
        if best.is_none_or(|(bd, _)| d < bd) {
            best = Some((d, c));
        }
    }
    let limit = (n / 3).max(1);
    best.filter(|(d, _)| *d <= limit).map(|(_, c)| c)
}

/// `did you mean `x`?` plus the list of what exists, as a help text.
pub fn suggest(word: &str, what: &str, candidates: &[&str]) -> String {
    let list = candidates.iter().map(|c| format!("`{c}`")).collect::<Vec<_>>().join(", ");
    match did_you_mean(word, candidates.iter().copied()) {
        Some(m) => format!("did you mean `{m}`?\n{what}: {list}"),
        None => format!("{what}: {list}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn renders_carets_under_the_span() {
        let src = "changes in zone:\"Towr B\" since:s3";
        let e =
            QueryError::new(Span::new(16, 24), "no zone `Towr B`").label("not a zone").help("did you mean `Tower B`?");
        let r = e.render(src, false);
        let want = "error: no zone `Towr B`\n --> query:1:17\n  |\n1 | changes in zone:\"Towr B\" since:s3\n  |                 ^^^^^^^^ not a zone\n  |\n  = help: did you mean `Tower B`?\n";
        assert_eq!(r, want);
        assert!(e.render(src, true).contains("\x1b[1;31m"));
        assert!(!r.contains('\x1b'));
    }

    #[test]
    fn renders_second_lines_wide_chars_and_empty_spans_at_the_end() {
        let src = "# tower\nchanges since:";
        let e = QueryError::new(Span::new(src.len(), src.len()), "expected a session after `since:`");
        let r = e.render(src, false);
        assert!(r.contains("--> query:2:15"), "{r}");
        assert!(r.contains("2 | changes since:\n  |               ^\n"), "{r}");
        let src = "changes in zone:塔B";
        let s = src.find('塔').unwrap();
        let r = QueryError::new(Span::new(s, src.len()), "x").render(src, false);
        assert!(r.contains(&format!("  | {}^^^\n", " ".repeat(16))), "wide char is two columns: {r}");
    }

    #[test]
    fn suggestions_find_typos_and_not_strangers() {
        let subjects = ["changes", "static", "lifelong", "history", "sessions", "loops", "volume", "coverage"];
        assert_eq!(did_you_mean("chnages", subjects), Some("changes"));
        assert_eq!(did_you_mean("Sesions", subjects), Some("sessions"));
        assert_eq!(did_you_mean("loop", subjects), Some("loops"));
        assert_eq!(did_you_mean("cov", subjects), Some("coverage"));
        assert_eq!(did_you_mean("xyz", subjects), None);
        assert_eq!(did_you_mean("Towr B", ["Tower B", "stockpile"]), Some("Tower B"));
    }
}
