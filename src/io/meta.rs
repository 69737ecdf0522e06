//! The optional `session.toml` of a session folder:
//!
//! ```toml
//! name = "s3"
//! date = 2026-11-20          # a TOML date, or the same as a string
//! [sensor]
//! model = "os1-64"           # a name SensorModel::parse accepts, and/or
//! fov = { kind = "band", elev_min_deg = -22.5, elev_max_deg = 22.5 }
//! ```
//!
//! Unknown keys are errors naming the key and its line, so a typo never
//! silently falls back to a default.

use std::path::Path;

use serde::Deserialize;

use crate::sensor::{Fov, SensorModel};

use super::error::{Location, ReadError, ReadErrorKind, read_text};

/// What `session.toml` says about a session; all optional.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SessionMeta {
    pub name: Option<String>,
    /// As written (`YYYY-MM-DD` or an RFC 3339 date-time), checked to parse.
    pub date: Option<String>,
    pub sensor_model: Option<SensorModel>,
    /// The explicit `[sensor] fov`, else the model's field of view.
    pub fov: Option<Fov>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileToml {
    name: Option<String>,
    date: Option<toml::Value>,
    sensor: Option<SensorToml>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SensorToml {
    model: Option<String>,
    fov: Option<toml::Table>,
}

const HINT: &str = "session.toml keys: name = \"s3\", date = 2026-11-20, [sensor] model = \"os1-64\" or \
                    fov = { kind = \"band\", elev_min_deg = -22.5, elev_max_deg = 22.5 } \
                    or { kind = \"rect\", azimuth_deg = 70.4, elevation_deg = 77.2 }";

/// 1-based line of the first `key =` assignment in `text` (1 if not found).
fn line_of(text: &str, key: &str) -> usize {
    text.lines()
        .position(|l| l.trim_start().strip_prefix(key).is_some_and(|r| r.trim_start().starts_with('=')))
        .map_or(1, |i| i + 1)
}

/// Reads and validates a `session.toml`.
pub(crate) fn read_session_meta(path: &Path) -> Result<SessionMeta, ReadError> {
    let text = read_text(path)?;
    parse_session_meta(path, &text)
}

fn parse_session_meta(path: &Path, text: &str) -> Result<SessionMeta, ReadError> {
    let bad = |key: &str, message: String| {
        ReadError::new(ReadErrorKind::Parse, path, message).at(Location::Line(line_of(text, key))).hint(HINT)
    };
    let file: FileToml = toml::from_str(text).map_err(|e| {
        let line = e.span().map_or(1, |s| text.get(..s.start).unwrap_or_default().matches('\n').count() + 1);
        ReadError::new(ReadErrorKind::Parse, path, e.message().trim().to_string()).at(Location::Line(line)).hint(HINT)
    })?;
    if file.name.as_deref().is_some_and(|n| n.trim().is_empty()) {
        return Err(bad("name", "name is empty".into()));
    }
    let date = match file.date {
        None => None,
        Some(toml::Value::Datetime(d)) => Some(d.to_string()),
        Some(toml::Value::String(s)) if s.parse::<toml::value::Datetime>().is_ok() => Some(s),
        Some(other) => return Err(bad("date", format!("date {other} is not a date like 2026-11-20"))),
    };
    let sensor = file.sensor.unwrap_or(SensorToml { model: None, fov: None });
    let sensor_model = match sensor.model {
        None => None,
        Some(m) => Some(SensorModel::parse(&m).ok_or_else(|| {
            let known: Vec<&str> = SensorModel::ALL.iter().map(|m| m.name()).collect();
            bad("model", format!("unknown sensor model `{m}` (known: {})", known.join(", ")))
        })?),
    };
    let fov = match sensor.fov {
        None => sensor_model.map(SensorModel::fov),
        Some(table) => Some(parse_fov(table).map_err(|m| bad("fov", m))?),
    };
    Ok(SessionMeta { name: file.name, date, sensor_model, fov })
}

/// A `fov` table with exactly the keys of its kind and sensible angles.
fn parse_fov(table: toml::Table) -> Result<Fov, String> {
    let allowed: &[&str] = match table.get("kind").and_then(toml::Value::as_str) {
        Some("band") => &["kind", "elev_min_deg", "elev_max_deg"],
        Some("rect") => &["kind", "azimuth_deg", "elevation_deg"],
        other => return Err(format!("fov kind {other:?} is not \"band\" or \"rect\"")),
    };
    if let Some(k) = table.keys().find(|k| !allowed.contains(&k.as_str())) {
        return Err(format!("unknown key `{k}` in fov (expected {})", allowed.join(", ")));
    }
    let fov: Fov =
        toml::Value::Table(table).try_into().map_err(|e: toml::de::Error| format!("fov: {}", e.message()))?;
    let ok = match fov {
        Fov::Band { elev_min_deg: lo, elev_max_deg: hi } => {
            lo.is_finite() && hi.is_finite() && -90.0 <= lo && lo < hi && hi <= 90.0
        }
        Fov::Rect { azimuth_deg: a, elevation_deg: e } => a > 0.0 && a <= 360.0 && e > 0.0 && e <= 180.0,
    };
    if !ok {
        return Err(format!("fov {fov:?} is not a field of view (band: -90 ≤ min < max ≤ 90; rect: 0 < widths)"));
    }
    Ok(fov)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<SessionMeta, ReadError> {
        parse_session_meta(Path::new("dir/session.toml"), text)
    }

    #[test]
    fn full_file_reads() {
        let m = parse("name = \"s3\"\ndate = 2026-11-20\n[sensor]\nmodel = \"OS1-64\"\n").unwrap();
        assert_eq!(m.name.as_deref(), Some("s3"));
        assert_eq!(m.date.as_deref(), Some("2026-11-20"));
        assert_eq!(m.sensor_model, Some(SensorModel::Os1_64));
        assert_eq!(m.fov, Some(SensorModel::Os1_64.fov()));
        let m = parse(
            "date = \"2026-11-20\"\n[sensor]\nfov = { kind = \"band\", elev_min_deg = -30, elev_max_deg = 10 }\n",
        )
        .unwrap();
        assert_eq!(m.date.as_deref(), Some("2026-11-20"));
        assert_eq!(m.fov, Some(Fov::Band { elev_min_deg: -30.0, elev_max_deg: 10.0 }));
        assert_eq!(parse("").unwrap(), SessionMeta::default());
    }

    /// Asserts a `Parse` error at `line` that names the file and contains `needle`.
    fn assert_err(text: &str, line: usize, needle: &str) {
        let e = parse(text).unwrap_err();
        assert_eq!((e.kind(), e.location), (ReadErrorKind::Parse, Some(Location::Line(line))), "{e}");
        assert!(e.to_string().contains(&format!("session.toml:line {line}: ")) && e.message.contains(needle), "{e}");
    }

    #[test]
    fn unknown_keys_and_bad_values_name_the_key_and_line() {
        assert_err("name = \"s3\"\ncolour = \"red\"\n", 2, "colour");
        assert_err("name = \"s3\"\n[sensor]\nmodel = \"os1-64\"\nbeams = 64\n", 4, "beams");
        assert_err("name = \"s3\"\n[sensor]\nmodel = \"kinect\"\n", 3, "unknown sensor model `kinect`");
        assert_err("\ndate = \"last tuesday\"\n", 2, "not a date");
        assert_err(
            "[sensor]\nfov = { kind = \"band\", elev_min_deg = 10, elev_max_deg = -10 }\n",
            2,
            "not a field of view",
        );
        assert_err(
            "[sensor]\nfov = { kind = \"band\", elev_min = 10, elev_max_deg = 20 }\n",
            2,
            "unknown key `elev_min`",
        );
        assert_err("[sensor]\nfov = { kind = \"cone\" }\n", 2, "\"cone\"");
        assert_err("name = \n", 1, "");
    }
}
