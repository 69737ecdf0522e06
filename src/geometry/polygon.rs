//! Polygons in the world xy plane, for named zones: WKT in and out, and the
//! point-in-polygon test queries run on rows the zone's bounding box let
//! through.

/// A polygon of one outer ring and any number of holes, world frame metres.
/// Rings are stored open (the closing vertex is not repeated).
#[derive(Debug, Clone, PartialEq)]
pub struct Polygon {
    /// `rings[0]` is the outer ring, the rest are holes.
    pub rings: Vec<Vec<[f64; 2]>>,
}

impl Polygon {
    /// Parses `POLYGON((x y, x y, ...), (hole ...))` (case-insensitive, the
    /// closing vertex optional). Coordinates are 2-D: a zone's z range is
    /// given separately.
    pub fn from_wkt(text: &str) -> Result<Polygon, String> {
        let t = text.trim();
        let upper = t.to_ascii_uppercase();
        let Some(rest) = upper.strip_prefix("POLYGON") else {
            return Err(format!("expected `POLYGON((x y, ...))`, found {:?}", short(t)));
        };
        // Work on the original text from the same offset (ASCII prefix).
        let body = t[t.len() - rest.len()..].trim();
        if body.to_ascii_uppercase().starts_with('Z') || body.to_ascii_uppercase().starts_with('M') {
            return Err("only 2-D polygons: give x y pairs and the z range separately (--z 0..12)".into());
        }
        let inner = body
            .strip_prefix('(')
            .and_then(|b| b.strip_suffix(')'))
            .ok_or_else(|| "a polygon is written POLYGON((x y, x y, x y, ...))".to_string())?;
        let mut rings = Vec::new();
        let mut rest = inner.trim();
        while !rest.is_empty() {
            let r =
                rest.strip_prefix('(').ok_or_else(|| format!("expected `(` to open a ring at {:?}", short(rest)))?;
            let end = r.find(')').ok_or_else(|| "a ring is not closed with `)`".to_string())?;
            rings.push(parse_ring(&r[..end], rings.len())?);
            rest = r[end + 1..].trim_start();
            if let Some(r) = rest.strip_prefix(',') {
                rest = r.trim_start();
                if rest.is_empty() {
                    return Err("a `,` after the last ring".into());
                }
            } else if !rest.is_empty() {
                return Err(format!("expected `,` or the end after a ring, found {:?}", short(rest)));
            }
        }
        if rings.is_empty() {
            return Err("the polygon has no ring".into());
        }
        let p = Polygon { rings };
        if p.area_m2() <= 0.0 {
            return Err("the polygon has no area (its vertices are on one line)".into());
        }
        Ok(p)
    }

    /// `POLYGON((x y, ..., x y))` with the closing vertex, numbers in their
    /// shortest exact form, so parsing it gives the same polygon back.
    pub fn to_wkt(&self) -> String {
        let rings: Vec<String> = self
            .rings
            .iter()
            .map(|r| {
                let mut pts: Vec<String> = r.iter().map(|p| format!("{} {}", p[0], p[1])).collect();
                if let Some(first) = pts.first().cloned() {
                    pts.push(first);
                }
                format!("({})", pts.join(", "))
            })
            .collect();
        format!("POLYGON({})", rings.join(", "))
    }

    /// Even-odd rule over all rings, so holes are outside. A point exactly on
    /// an edge may fall either side.
    pub fn contains(&self, x: f64, y: f64) -> bool {
        let mut inside = false;
        for ring in &self.rings {
            let n = ring.len();
            for i in 0..n {
                let (a, b) = (ring[i], ring[(i + n - 1) % n]);
                if (a[1] > y) != (b[1] > y) {
                    let x_cross = a[0] + (y - a[1]) * (b[0] - a[0]) / (b[1] - a[1]);
                    if x < x_cross {
                        inside = !inside;
                    }
                }
            }
        }
        inside
    }

    /// The bounding rectangle `(min, max)` of the outer ring.
    pub fn bounds(&self) -> ([f64; 2], [f64; 2]) {
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        for p in self.rings.first().into_iter().flatten() {
            for k in 0..2 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        (lo, hi)
    }

    /// Area of the outer ring minus the holes, m².
    pub fn area_m2(&self) -> f64 {
        let ring_area = |r: &Vec<[f64; 2]>| {
            let n = r.len();
            (0..n).map(|i| r[i][0] * r[(i + 1) % n][1] - r[(i + 1) % n][0] * r[i][1]).sum::<f64>().abs() / 2.0
        };
        let mut it = self.rings.iter();
        let outer = it.next().map_or(0.0, ring_area);
        outer - it.map(ring_area).sum::<f64>()
    }
}

fn short(s: &str) -> String {
    s.chars().take(24).collect()
}

fn parse_ring(text: &str, index: usize) -> Result<Vec<[f64; 2]>, String> {
    let what = if index == 0 { "the outer ring".to_string() } else { format!("hole {index}") };
    let mut pts: Vec<[f64; 2]> = Vec::new();
    for (i, pair) in text.split(',').enumerate() {
        let nums: Vec<&str> = pair.split_whitespace().collect();
        if nums.len() != 2 {
            return Err(format!("{what}, vertex {}: expected `x y`, found {:?}", i + 1, pair.trim()));
        }
        let mut p = [0.0; 2];
        for (k, n) in nums.iter().enumerate() {
            p[k] = n
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("{what}, vertex {}: {n:?} is not a finite number", i + 1))?;
        }
        pts.push(p);
    }
    if pts.len() > 1 && pts.first() == pts.last() {
        pts.pop();
    }
    pts.dedup();
    if pts.len() < 3 {
        return Err(format!("{what} needs at least 3 distinct vertices, found {}", pts.len()));
    }
    Ok(pts)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wkt_round_trips_and_contains_follows_even_odd() {
        let p = Polygon::from_wkt("polygon ((0 0, 10 0, 10 10, 0 10, 0 0), (4 4, 6 4, 6 6, 4 6))").unwrap();
        assert_eq!(p.rings.len(), 2);
        assert_eq!(p.rings[0].len(), 4, "closing vertex dropped");
        assert_eq!(Polygon::from_wkt(&p.to_wkt()).unwrap(), p);
        assert_eq!(p.area_m2(), 96.0);
        assert_eq!(p.bounds(), ([0.0, 0.0], [10.0, 10.0]));
        assert!(p.contains(1.0, 1.0));
        assert!(!p.contains(5.0, 5.0), "in the hole");
        assert!(!p.contains(11.0, 5.0));
        assert!(!p.contains(-0.1, 5.0));
        // A concave L shape.
        let l = Polygon::from_wkt("POLYGON((0 0, 4 0, 4 1, 1 1, 1 4, 0 4))").unwrap();
        assert!(l.contains(0.5, 3.0) && l.contains(3.0, 0.5));
        assert!(!l.contains(3.0, 3.0));
    }

    #[test]
    fn bad_wkt_says_what_is_wrong() {
        for (text, want) in [
            ("LINESTRING(0 0, 1 1)", "expected `POLYGON"),
            ("POLYGON((0 0, 1 0))", "at least 3"),
            ("POLYGON((0 0, 1 0, 2 0))", "no area"),
            ("POLYGON((0 0 1, 1 0 1, 1 1 1))", "expected `x y`"),
            ("POLYGON Z((0 0 1, 1 0 1, 1 1 1))", "only 2-D"),
            ("POLYGON((0 0, 1 0, nan 1))", "not a finite number"),
            ("POLYGON((0 0, 1 0, 1 1)", "not closed"),
            ("POLYGON(0 0, 1 0, 1 1)", "to open a ring"),
            ("POLYGON((0 0, 1 0, 1 1),)", "after the last ring"),
            ("POLYGON()", "no ring"),
        ] {
            let err = Polygon::from_wkt(text).unwrap_err();
            assert!(err.contains(want), "{text}: {err}");
        }
    }
}
