//! Tokens with byte spans.
//!
//! An unquoted run of characters up to a delimiter (space, `:` `,` `|`
//! `..` `<` `>` `=` `!` `"` `'` `#`) is one token: a [`Tok::Number`] if it
//! reads as a finite number (`12.5`, `-3`, `1e3`), a [`Tok::Word`]
//! otherwise (`changes`, `s3`, `2026-01-01`, `Baustelle-Süd`). `#` starts a
//! comment to the end of the line. Strings are `"…"` or `'…'` with `\"`,
//! `\'` and `\\` escapes.

use super::error::{QueryError, Span};

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CmpOp {
    Lt,
    Le,
    Gt,
    Ge,
    Eq,
    Ne,
}

impl CmpOp {
    /// The SQL operator.
    pub fn sql(self) -> &'static str {
        match self {
            CmpOp::Lt => "<",
            CmpOp::Le => "<=",
            CmpOp::Gt => ">",
            CmpOp::Ge => ">=",
            CmpOp::Eq => "=",
            CmpOp::Ne => "<>",
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub enum Tok {
    Word(String),
    Number(f64),
    Str(String),
    Colon,
    Comma,
    Pipe,
    DotDot,
    Cmp(CmpOp),
    Eof,
}

impl Tok {
    /// How the token is named in "expected …, found …" messages.
    pub fn describe(&self) -> String {
        match self {
            Tok::Word(w) => format!("`{w}`"),
            Tok::Number(n) => format!("the number {n}"),
            Tok::Str(s) => format!("the string {s:?}"),
            Tok::Colon => "`:`".into(),
            Tok::Comma => "`,`".into(),
            Tok::Pipe => "`|`".into(),
            Tok::DotDot => "`..`".into(),
            Tok::Cmp(op) => format!("`{}`", if *op == CmpOp::Ne { "!=" } else { op.sql() }),
            Tok::Eof => "the end of the query".into(),
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct Token {
    pub tok: Tok,
    pub span: Span,
}

fn is_delimiter(c: char) -> bool {
    c.is_whitespace() || matches!(c, ':' | ',' | '|' | '<' | '>' | '=' | '!' | '"' | '\'' | '#')
}

/// Characters that have no meaning in the language, refused where they stand.
fn is_stray(c: char) -> bool {
    matches!(c, '(' | ')' | '[' | ']' | '{' | '}' | ';' | '`' | '\\')
}

/// The tokens of `src`, ending with [`Tok::Eof`].
pub fn lex(src: &str) -> Result<Vec<Token>, QueryError> {
    let mut out = Vec::new();
    let mut it = src.char_indices().peekable();
    while let Some(&(i, c)) = it.peek() {
        let one = |tok: Tok| Token { tok, span: Span::new(i, i + c.len_utf8()) };
        match c {
            _ if c.is_whitespace() => {
                it.next();
            }
            '#' => while it.next_if(|&(_, c)| c != '\n').is_some() {},
            ':' => {
                it.next();
                out.push(one(Tok::Colon));
            }
            ',' => {
                it.next();
                out.push(one(Tok::Comma));
            }
            '|' => {
                it.next();
                out.push(one(Tok::Pipe));
            }
            '<' | '>' | '=' | '!' => {
                it.next();
                let eq = it.next_if(|&(_, c)| c == '=').is_some();
                let op = match (c, eq) {
                    ('<', false) => CmpOp::Lt,
                    ('<', true) => CmpOp::Le,
                    ('>', false) => CmpOp::Gt,
                    ('>', true) => CmpOp::Ge,
                    ('=', _) => CmpOp::Eq,
                    ('!', true) => CmpOp::Ne,
                    _ => {
                        return Err(QueryError::new(Span::new(i, i + 1), "`!` on its own means nothing here")
                            .label("expected `!=`")
                            .help("compare with `field:!=value`, e.g. `class:!=coexist`"));
                    }
                };
                out.push(Token { tok: Tok::Cmp(op), span: Span::new(i, i + 1 + usize::from(eq)) });
            }
            '"' | '\'' => out.push(string(src, &mut it, c, i)?),
            _ if is_stray(c) => {
                let help = match c {
                    '(' | ')' | '[' | ']' | '{' | '}' => {
                        "regions need no brackets: `bbox:x0,y0,z0,x1,y1,z1`, `near:x,y,z r:2`"
                    }
                    _ => "quote names with spaces or symbols: `zone:\"Tower B\"`",
                };
                return Err(QueryError::new(one(Tok::Eof).span, format!("unexpected `{c}`"))
                    .label("not part of the query language")
                    .help(help));
            }
            '.' if src[i..].starts_with("..") => {
                it.next();
                it.next();
                out.push(Token { tok: Tok::DotDot, span: Span::new(i, i + 2) });
            }
            _ => {
                let mut end = i;
                while let Some(&(j, c)) = it.peek() {
                    if is_delimiter(c) || is_stray(c) || src[j..].starts_with("..") {
                        break;
                    }
                    end = j + c.len_utf8();
                    it.next();
                }
                out.push(atom(&src[i..end], Span::new(i, end))?);
            }
        }
    }
    out.push(Token { tok: Tok::Eof, span: Span::new(src.len(), src.len()) });
    Ok(out)
}

/// A quoted string starting at `start` with `quote`.
fn string(
    src: &str,
    it: &mut std::iter::Peekable<std::str::CharIndices<'_>>,
    quote: char,
    start: usize,
) -> Result<Token, QueryError> {
    it.next();
    let mut s = String::new();
    while let Some((j, c)) = it.next() {
        if c == quote {
            return Ok(Token { tok: Tok::Str(s), span: Span::new(start, j + 1) });
        }
        if c == '\\'
            && let Some(&(_, n)) = it.peek()
            && matches!(n, '"' | '\'' | '\\')
        {
            s.push(n);
            it.next();
            continue;
        }
        s.push(c);
    }
    Err(QueryError::new(Span::new(start, src.len()), "unterminated string")
        .label("this string never ends")
        .help(format!("close it with {quote}")))
}

/// A number if the atom reads as one, else a word.
fn atom(text: &str, span: Span) -> Result<Token, QueryError> {
    let b = text.as_bytes();
    let numeric_start = b[0].is_ascii_digit()
        || (matches!(b[0], b'-' | b'+' | b'.') && b.get(1).is_some_and(|c| c.is_ascii_digit() || *c == b'.'));
    if numeric_start && let Ok(v) = text.parse::<f64>() {
        if !v.is_finite() {
            return Err(QueryError::new(span, format!("the number {text} is too large")).label("out of range"));
        }
        return Ok(Token { tok: Tok::Number(v), span });
    }
    Ok(Token { tok: Tok::Word(text.to_string()), span })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn toks(src: &str) -> Vec<Tok> {
        lex(src).unwrap().into_iter().map(|t| t.tok).collect()
    }

    #[test]
    fn lexes_the_design_examples() {
        use Tok::*;
        let w = |s: &str| Word(s.into());
        assert_eq!(
            toks("changes in zone:\"Tower B\" since:s3"),
            [w("changes"), w("in"), w("zone"), Colon, Str("Tower B".into()), w("since"), Colon, w("s3"), Eof]
        );
        assert_eq!(
            toks("between:s3..s5 eps:>=0.5 near:12.5,-3,1e1 # comment\n| count"),
            [
                w("between"),
                Colon,
                w("s3"),
                DotDot,
                w("s5"),
                w("eps"),
                Colon,
                Cmp(CmpOp::Ge),
                Number(0.5),
                w("near"),
                Colon,
                Number(12.5),
                Comma,
                Number(-3.0),
                Comma,
                Number(10.0),
                Pipe,
                w("count"),
                Eof
            ]
        );
        assert_eq!(
            toks("since:2026-01-01 1..5"),
            [w("since"), Colon, w("2026-01-01"), Number(1.0), DotDot, Number(5.0), Eof]
        );
        assert_eq!(toks("zone:'a \\'b\\''"), [w("zone"), Colon, Str("a 'b'".into()), Eof]);
        assert_eq!(toks("nan inf"), [w("nan"), w("inf"), Eof], "words that Rust would read as floats");
    }

    #[test]
    fn spans_are_byte_ranges() {
        let t = lex("zone:Süd | x").unwrap();
        assert_eq!(t[2].span, Span::new(5, 9));
        assert_eq!(t[3].span, Span::new(10, 11));
        assert_eq!(t.last().unwrap().span, Span::new(13, 13));
    }

    #[test]
    fn errors_point_at_the_problem() {
        let e = lex("changes in zone:\"Tower B").unwrap_err();
        assert_eq!(e.span, Span::new(16, 24));
        assert!(e.message.contains("unterminated"));
        let e = lex("bbox:(1,2)").unwrap_err();
        assert_eq!(e.span, Span::new(5, 6));
        let e = lex("eps:>1e999").unwrap_err();
        assert_eq!(e.span, Span::new(5, 10));
        let e = lex("class:!coexist").unwrap_err();
        assert_eq!(e.span, Span::new(6, 7));
    }
}
