//! Recursive descent over the tokens into [`ast::Query`]; the grammar is in
//! `query/mod.rs`. Every error names the span it is about and what was
//! expected there.

use super::ast::*;
use super::error::{QueryError, Span, suggest};
use super::lexer::{CmpOp, Tok, Token, lex};

/// Qualifier keys with a meaning of their own; any other `key:` is a filter
/// on a field of the subject.
pub const REGION_KEYS: [&str; 3] = ["bbox", "near", "zone"];
pub const TIME_KEYS: [&str; 4] = ["since", "between", "at", "session"];

/// Parses a query.
pub fn parse(src: &str) -> Result<Query, QueryError> {
    let toks = lex(src)?;
    let mut p = Parser { toks, pos: 0 };
    p.query()
}

struct Parser {
    toks: Vec<Token>,
    pos: usize,
}

/// Largest whole number a count or limit may be (exact in an f64).
const MAX_WHOLE: f64 = 9_007_199_254_740_992.0;
/// Each stage nests the statement one level deeper; SQLite's parser has a
/// depth limit far above this, and no question needs more.
const MAX_STAGES: usize = 32;
/// Values in one `a,b,c` list (each is one SQL parameter).
const MAX_LIST: usize = 1000;

impl Parser {
    fn peek(&self) -> &Token {
        // The token list always ends with Eof, and `next` never moves past it.
        &self.toks[self.pos.min(self.toks.len() - 1)]
    }

    fn peek_at(&self, k: usize) -> &Token {
        &self.toks[(self.pos + k).min(self.toks.len() - 1)]
    }

    fn next(&mut self) -> Token {
        let t = self.peek().clone();
        if t.tok != Tok::Eof {
            self.pos += 1;
        }
        t
    }

    fn eat(&mut self, tok: &Tok) -> Option<Span> {
        if &self.peek().tok == tok { Some(self.next().span) } else { None }
    }

    fn expected(&self, what: &str) -> QueryError {
        let t = self.peek();
        QueryError::new(t.span, format!("expected {what}, found {}", t.tok.describe()))
            .label(format!("expected {what}"))
    }

    fn query(&mut self) -> Result<Query, QueryError> {
        let subject = self.subject()?;
        let mut q =
            Query { subject, region: None, radius: None, time: Vec::new(), filters: Vec::new(), stages: Vec::new() };
        loop {
            let t = self.peek().clone();
            match &t.tok {
                Tok::Eof => return Ok(q),
                Tok::Pipe => break,
                Tok::Word(w) if w.eq_ignore_ascii_case("in") => {
                    self.next();
                    let key = self.peek().clone();
                    let is_region =
                        matches!(&key.tok, Tok::Word(k) if REGION_KEYS.iter().any(|r| r.eq_ignore_ascii_case(k)));
                    if !is_region {
                        return Err(self
                            .expected("a region after `in`")
                            .help("`in` is followed by `bbox:x0,y0,z0,x1,y1,z1`, `near:x,y,z r:R` or `zone:NAME`"));
                    }
                }
                Tok::Word(w) => {
                    let key = w.to_ascii_lowercase();
                    if self.peek_at(1).tok != Tok::Colon {
                        return Err(self.bare_word(&t, &key));
                    }
                    self.next();
                    self.next();
                    self.clause(&mut q, Spanned::new(key, t.span), w)?;
                }
                _ => {
                    return Err(self
                        .expected("a qualifier such as `since:s3`, or `|`")
                        .help("qualifiers are `key:value`: regions (bbox:, near: r:, zone:), time (since:, between:, at:, session:), filters (class:, eps:, ...)"));
                }
            }
        }
        while self.eat(&Tok::Pipe).is_some() {
            let stage = self.stage()?;
            if q.stages.len() == MAX_STAGES {
                return Err(QueryError::new(stage.span, format!("more than {MAX_STAGES} pipeline stages"))
                    .label("one too many"));
            }
            q.stages.push(stage);
            match self.peek().tok {
                Tok::Eof | Tok::Pipe => {}
                _ => return Err(self.expected("`|` or the end of the query after this stage")),
            }
        }
        Ok(q)
    }

    fn subject(&mut self) -> Result<Spanned<Subject>, QueryError> {
        let names: Vec<&str> = Subject::ALL.iter().map(|s| s.name()).collect();
        let t = self.next();
        match &t.tok {
            Tok::Word(w) => match Subject::parse(w) {
                Some(s) => Ok(Spanned::new(s, t.span)),
                None => Err(QueryError::new(t.span, format!("unknown subject `{w}`"))
                    .label("not something a query can ask about")
                    .help(suggest(w, "subjects", &names))),
            },
            Tok::Eof => Err(QueryError::new(t.span, "empty query")
                .label("expected what to ask about")
                .help(format!("start with one of {}, e.g. `changes since:s3`", names.join(", ")))),
            other => Err(QueryError::new(
                t.span,
                format!("a query starts with what it asks about, found {}", other.describe()),
            )
            .label("expected a subject")
            .help(format!("subjects: {}", names.join(", ")))),
        }
    }

    /// A word where `key:value` was expected.
    fn bare_word(&self, t: &Token, key: &str) -> QueryError {
        let err = QueryError::new(
            t.span,
            format!(
                "expected `key:value`, found `{}`",
                match &t.tok {
                    Tok::Word(w) => w.as_str(),
                    _ => "",
                }
            ),
        );
        if Stage::NAMES.contains(&key) {
            return err.label("a pipeline stage").help(format!("stages follow a `|`: `... | {key}`"));
        }
        if REGION_KEYS.contains(&key) || TIME_KEYS.contains(&key) || key == "r" {
            return err.label("missing `:`").help(format!("write `{key}:` and its value with no space"));
        }
        if Subject::parse(key).is_some() {
            return err.label("a second subject").help("a query asks about one subject");
        }
        err.label("not a qualifier")
            .help("qualifiers are `key:value`, e.g. `since:s3`, `class:emerged`; pipeline stages follow a `|`")
    }

    fn clause(&mut self, q: &mut Query, key: Spanned<String>, raw: &str) -> Result<(), QueryError> {
        let start = key.span;
        match key.value.as_str() {
            "bbox" | "near" | "zone" => {
                let region = match key.value.as_str() {
                    "bbox" => {
                        let (v, _) = self.numbers(6, "bbox:x0,y0,z0,x1,y1,z1")?;
                        Region::Bbox { min_m: [v[0], v[1], v[2]], max_m: [v[3], v[4], v[5]] }
                    }
                    "near" => {
                        let (v, _) = self.numbers(3, "near:x,y,z")?;
                        Region::Near { centre_m: [v[0], v[1], v[2]] }
                    }
                    _ => Region::Zone { name: self.name("a zone name")? },
                };
                let span = start.to(self.toks[self.pos.saturating_sub(1)].span);
                if q.region.is_some() {
                    return Err(QueryError::new(span, "a query has one region; this is a second one")
                        .label("second region")
                        .help("name a zone that covers both (`seam zones add`)"));
                }
                q.region = Some(Spanned::new(region, span));
            }
            "r" => {
                let t = self.next();
                let Tok::Number(r) = t.tok else {
                    return Err(QueryError::new(
                        t.span,
                        format!("expected a radius in metres, found {}", t.tok.describe()),
                    )
                    .label("expected a number")
                    .help("e.g. `near:12.5,3,1 r:2`"));
                };
                if r <= 0.0 {
                    return Err(QueryError::new(t.span, "the radius must be above 0 m").label("not a radius"));
                }
                if q.radius.is_some() {
                    return Err(QueryError::new(start.to(t.span), "`r:` given twice").label("second radius"));
                }
                q.radius = Some(Spanned::new(r, start.to(t.span)));
            }
            "since" | "at" => {
                let r = self.session_ref()?;
                let span = start.to(r.span);
                q.time.push(Spanned::new(if key.value == "since" { Time::Since(r) } else { Time::At(r) }, span));
            }
            "between" => {
                let a = self.session_ref()?;
                if self.eat(&Tok::DotDot).is_none() {
                    return Err(self.expected("`..` between the two sessions").help("e.g. `between:s3..s5`"));
                }
                let b = self.session_ref()?;
                let span = start.to(b.span);
                q.time.push(Spanned::new(Time::Between(a, b), span));
            }
            "session" | "sessions" => {
                let mut refs = vec![self.session_ref()?];
                while self.eat(&Tok::Comma).is_some() {
                    let r = self.session_ref()?;
                    if refs.len() == MAX_LIST {
                        return Err(QueryError::new(r.span, format!("a list holds at most {MAX_LIST} sessions"))
                            .label("one too many"));
                    }
                    refs.push(r);
                }
                let span = start.to(refs.last().map_or(start, |r| r.span));
                q.time.push(Spanned::new(Time::Sessions(refs), span));
            }
            _ => {
                let cond = self.cond()?;
                let span = start.to(self.toks[self.pos.saturating_sub(1)].span);
                q.filters.push(Filter { field: Spanned::new(raw.to_string(), key.span), cond, span });
            }
        }
        Ok(())
    }

    /// `n` numbers separated by commas.
    fn numbers(&mut self, n: usize, form: &str) -> Result<(Vec<f64>, Span), QueryError> {
        let mut out = Vec::with_capacity(n);
        let first = self.peek().span;
        let mut last = first;
        loop {
            let t = self.next();
            match t.tok {
                Tok::Number(v) => out.push(v),
                other => {
                    return Err(QueryError::new(t.span, format!("expected a number, found {}", other.describe()))
                        .label(format!("number {} of {form}", out.len() + 1))
                        .help(format!("write `{form}`, {n} numbers in metres")));
                }
            }
            last = last.to(t.span);
            if out.len() == n {
                break;
            }
            if self.eat(&Tok::Comma).is_none() {
                return Err(QueryError::new(first.to(last), format!("expected {n} numbers, found {}", out.len()))
                    .label(format!("{} of {n}", out.len()))
                    .help(format!("write `{form}`")));
            }
        }
        if self.peek().tok == Tok::Comma {
            let extra = self.peek().span;
            return Err(QueryError::new(first.to(extra), format!("too many numbers: `{form}` takes {n}"))
                .label(format!("more than {n}")));
        }
        Ok((out, first.to(last)))
    }

    /// A word or a quoted string.
    fn name(&mut self, what: &str) -> Result<Spanned<String>, QueryError> {
        let t = self.next();
        match t.tok {
            Tok::Word(w) | Tok::Str(w) => Ok(Spanned::new(w, t.span)),
            other => Err(QueryError::new(t.span, format!("expected {what}, found {}", other.describe()))
                .label(format!("expected {what}"))
                .help("quote names with spaces: `zone:\"Tower B\"`")),
        }
    }

    fn session_ref(&mut self) -> Result<SessionRef, QueryError> {
        let t = self.next();
        let help = "a session is its name (`s3`), its number (`3`) or a date (`2026-01-01`)";
        match t.tok {
            Tok::Number(v) => {
                if v.fract() != 0.0 || !(1.0..=MAX_WHOLE).contains(&v) {
                    return Err(QueryError::new(t.span, "session numbers are whole numbers from 1")
                        .label("not a session number")
                        .help(help));
                }
                Ok(SessionRef { text: format!("{}", v as i64), kind: RefKind::Number(v as i64), span: t.span })
            }
            Tok::Str(w) => Ok(SessionRef { text: w, kind: RefKind::Name, span: t.span }),
            Tok::Word(w) => {
                let kind = match date(&w) {
                    Some(Ok((y, m, d))) => RefKind::Date { y, m, d },
                    Some(Err(msg)) => {
                        return Err(QueryError::new(t.span, msg).label("not a date").help("dates are YYYY-MM-DD"));
                    }
                    None => RefKind::Name,
                };
                Ok(SessionRef { text: w, kind, span: t.span })
            }
            other => Err(QueryError::new(t.span, format!("expected a session, found {}", other.describe()))
                .label("expected a session")
                .help(help)),
        }
    }

    fn lit(&mut self) -> Result<Spanned<Lit>, QueryError> {
        let t = self.next();
        match t.tok {
            Tok::Number(v) => Ok(Spanned::new(Lit::Number(v), t.span)),
            Tok::Word(w) | Tok::Str(w) => Ok(Spanned::new(Lit::Text(w), t.span)),
            other => Err(QueryError::new(t.span, format!("expected a value, found {}", other.describe()))
                .label("expected a value")
                .help("e.g. `class:emerged,deleted`, `eps:>0.5`, `eps:0.2..0.4`, `accepted:false`")),
        }
    }

    fn cond(&mut self) -> Result<Cond, QueryError> {
        if let Tok::Cmp(op) = self.peek().tok {
            self.next();
            return Ok(Cond::Cmp(op, self.lit()?));
        }
        let first = self.lit()?;
        if self.eat(&Tok::DotDot).is_some() {
            return Ok(Cond::Range(first, self.lit()?));
        }
        if self.peek().tok != Tok::Comma {
            return Ok(Cond::Cmp(CmpOp::Eq, first));
        }
        let mut all = vec![first];
        while self.eat(&Tok::Comma).is_some() {
            let l = self.lit()?;
            if all.len() == MAX_LIST {
                return Err(
                    QueryError::new(l.span, format!("a list holds at most {MAX_LIST} values")).label("one too many")
                );
            }
            all.push(l);
        }
        Ok(Cond::AnyOf(all))
    }

    fn field(&mut self) -> Result<Spanned<String>, QueryError> {
        let t = self.next();
        match t.tok {
            Tok::Word(w) => Ok(Spanned::new(w, t.span)),
            other => Err(QueryError::new(t.span, format!("expected a field name, found {}", other.describe()))
                .label("expected a field")),
        }
    }

    fn fields(&mut self) -> Result<Vec<Spanned<String>>, QueryError> {
        let mut out = vec![self.field()?];
        while self.eat(&Tok::Comma).is_some() {
            let f = self.field()?;
            if out.len() == MAX_LIST {
                return Err(
                    QueryError::new(f.span, format!("a list holds at most {MAX_LIST} fields")).label("one too many")
                );
            }
            out.push(f);
        }
        Ok(out)
    }

    fn whole(&mut self, what: &str) -> Result<Spanned<u64>, QueryError> {
        let t = self.next();
        match t.tok {
            Tok::Number(v) if v.fract() == 0.0 && (0.0..=MAX_WHOLE).contains(&v) => Ok(Spanned::new(v as u64, t.span)),
            Tok::Number(_) => Err(QueryError::new(t.span, format!("{what} is a whole number of rows"))
                .label(format!("not a whole number from 0 to {}", MAX_WHOLE as u64))),
            other => Err(QueryError::new(t.span, format!("expected {what}, found {}", other.describe()))
                .label("expected a number of rows")),
        }
    }

    fn is_word(&self, w: &str) -> bool {
        matches!(&self.peek().tok, Tok::Word(x) if x.eq_ignore_ascii_case(w))
    }

    fn stage(&mut self) -> Result<Spanned<Stage>, QueryError> {
        let t = self.next();
        let Tok::Word(w) = &t.tok else {
            return Err(QueryError::new(t.span, format!("expected a pipeline stage, found {}", t.tok.describe()))
                .label("expected a stage")
                .help(format!("stages: {}", Stage::NAMES.join(", "))));
        };
        let stage = match w.to_ascii_lowercase().as_str() {
            "count" => {
                if self.is_word("by") {
                    self.next();
                    Stage::Count { by: self.fields()? }
                } else {
                    Stage::Count { by: Vec::new() }
                }
            }
            "top" => {
                let n = self.whole("how many rows `top` keeps")?;
                if n.value == 0 {
                    return Err(QueryError::new(n.span, "`top 0` keeps nothing").label("at least 1"));
                }
                if !self.is_word("by") {
                    return Err(self.expected("`by` and a field").help("e.g. `| top 10 by volume_m3`"));
                }
                self.next();
                Stage::Top { n, by: self.field()? }
            }
            "sort" => {
                let by = self.field()?;
                let descending = if self.is_word("desc") {
                    self.next();
                    true
                } else {
                    if self.is_word("asc") {
                        self.next();
                    }
                    false
                };
                Stage::Sort { by, descending }
            }
            "fields" => Stage::Fields(self.fields()?),
            "limit" => Stage::Limit(self.whole("how many rows `limit` keeps")?),
            "sum" => Stage::Sum,
            _ => {
                return Err(QueryError::new(t.span, format!("unknown pipeline stage `{w}`"))
                    .label("not a stage")
                    .help(suggest(w, "stages", &Stage::NAMES)));
            }
        };
        let span = t.span.to(self.toks[self.pos.saturating_sub(1)].span);
        Ok(Spanned::new(stage, span))
    }
}

/// `Some(Ok(date))` for a valid `YYYY-MM-DD`, `Some(Err)` for something
/// shaped like one that is not a date, `None` for anything else.
fn date(w: &str) -> Option<Result<(i32, u32, u32), String>> {
    let b = w.as_bytes();
    let shaped = b.len() == 10
        && b[4] == b'-'
        && b[7] == b'-'
        && b.iter().enumerate().all(|(i, c)| i == 4 || i == 7 || c.is_ascii_digit());
    if !shaped {
        return None;
    }
    let (y, m, d) = (w[0..4].parse::<i32>().ok()?, w[5..7].parse::<u32>().ok()?, w[8..10].parse::<u32>().ok()?);
    let leap = (y % 4 == 0 && y % 100 != 0) || y % 400 == 0;
    let days = match m {
        1 | 3 | 5 | 7 | 8 | 10 | 12 => 31,
        4 | 6 | 9 | 11 => 30,
        2 if leap => 29,
        2 => 28,
        _ => return Some(Err(format!("{w} is not a date: there is no month {m}"))),
    };
    if d == 0 || d > days {
        return Some(Err(format!("{w} is not a date: month {m} of {y} has {days} days")));
    }
    Some(Ok((y, m, d)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_design_examples() {
        let q = parse("changes in zone:\"Tower B\" since:s3").unwrap();
        assert_eq!(q.subject.value, Subject::Changes);
        let Some(Spanned { value: Region::Zone { name }, .. }) = &q.region else { panic!("{q:?}") };
        assert_eq!(name.value, "Tower B");
        assert!(matches!(&q.time[0].value, Time::Since(r) if r.text == "s3" && r.kind == RefKind::Name));

        let q = parse("changes in bbox:10,20,0,40,60,5 between:s3..s5 class:emerged,deleted").unwrap();
        assert_eq!(q.region.unwrap().value, Region::Bbox { min_m: [10.0, 20.0, 0.0], max_m: [40.0, 60.0, 5.0] });
        assert!(matches!(&q.time[0].value, Time::Between(a, b) if a.text == "s3" && b.text == "s5"));
        assert!(matches!(&q.filters[0].cond, Cond::AnyOf(v) if v.len() == 2));

        let q = parse("changes near:12.5,3,1 r:2 | count by session").unwrap();
        assert_eq!(q.radius.unwrap().value, 2.0);
        assert!(matches!(&q.stages[0].value, Stage::Count { by } if by[0].value == "session"));

        let q = parse("history near:12.5,3,1 r:0.5          # one spot through every session").unwrap();
        assert_eq!(q.subject.value, Subject::History);
        let q = parse("sessions since:2026-01-01").unwrap();
        assert!(matches!(&q.time[0].value, Time::Since(r) if r.kind == RefKind::Date { y: 2026, m: 1, d: 1 }));
        let q = parse("loops session:s4 accepted:false      # why did s4 not merge?").unwrap();
        assert!(matches!(&q.filters[0].cond, Cond::Cmp(CmpOp::Eq, l) if l.value == Lit::Text("false".into())));
        parse("volume in zone:stockpile since:s2    # m³ emerged / deleted").unwrap();
        let q = parse("static in bbox:0,0,-2,50,50,10 | count").unwrap();
        assert_eq!(q.stages.len(), 1);
        let q = parse("static eps:>=0.3 | top 5 by eps_g | sort z_m desc | fields x_m,z_m | limit 2 | sum").unwrap();
        assert_eq!(q.stages.len(), 5);
        assert!(matches!(&q.filters[0].cond, Cond::Cmp(CmpOp::Ge, l) if l.value == Lit::Number(0.3)));
    }

    fn err(src: &str) -> QueryError {
        parse(src).unwrap_err()
    }

    fn at<'a>(src: &'a str, e: &QueryError) -> &'a str {
        &src[e.span.start..e.span.end]
    }

    #[test]
    fn errors_point_at_the_span_and_suggest() {
        let s = "chnages in zone:\"Tower B\"";
        let e = err(s);
        assert_eq!(at(s, &e), "chnages");
        assert!(e.help.as_deref().unwrap().contains("did you mean `changes`?"), "{e:?}");

        let s = "changes in bbox:1,2,3,4";
        let e = err(s);
        assert!(e.message.contains("expected 6 numbers, found 4"), "{e:?}");
        assert_eq!(at(s, &e), "1,2,3,4");

        let s = "changes bbox:1,2,3,4,5,6,7";
        assert!(err(s).message.contains("too many"));
        let s = "changes since:2026-02-30";
        assert_eq!(at(s, &err(s)), "2026-02-30");
        let s = "changes since";
        assert!(err(s).help.unwrap().contains("since:"));
        let s = "changes | count by";
        assert_eq!(err(s).span, Span::new(s.len(), s.len()));
        let s = "changes | cuont";
        assert!(err(s).help.unwrap().contains("did you mean `count`?"));
        let s = "changes | top 2.5 by x_m";
        assert_eq!(at(s, &err(s)), "2.5");
        let s = "changes between:s3 s5";
        assert_eq!(at(s, &err(s)), "s5");
        let s = "changes in since:s3";
        assert_eq!(at(s, &err(s)), "since");
        let s = "changes near:1,2,3 r:-1";
        assert_eq!(at(s, &err(s)), "-1");
        let s = "changes bbox:0,0,0,1,1,1 zone:a";
        assert_eq!(at(s, &err(s)), "zone:a");
        assert!(err("").message.contains("empty"));
        // Limits that keep the SQL within SQLite's: stages and list lengths.
        let s = format!("changes{}", " | limit 1".repeat(33));
        assert_eq!(at(&s, &err(&s)), "limit 1");
        let s = format!("changes class:{}", vec!["coexist"; 1001].join(","));
        assert!(err(&s).message.contains("at most 1000"));
        assert!(parse(&format!("changes{}", " | limit 1".repeat(32))).is_ok());
        assert!(err("changes count").help.unwrap().contains("| count"));
    }
}
