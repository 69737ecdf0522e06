//! Submaps cut a session's trajectory by cumulative travel distance (MATH.md §1).

use crate::config::SubmapConfig;
use crate::geometry::Pose;

/// Splits keyframes `0..poses.len()` into submaps: a new submap starts at the
/// keyframe whose travel since the current submap's first keyframe exceeds
/// `submap_length_m`. A trailing submap with fewer than `min_keyframes` is
/// merged into the one before it. Returns `(first, last, length_m)` spans
/// that cover every keyframe exactly once, in order.
pub fn cut_submaps(poses: &[Pose], cfg: &SubmapConfig) -> Vec<(usize, usize, f64)> {
    let mut spans: Vec<(usize, usize, f64)> = Vec::new();
    if poses.is_empty() {
        return spans;
    }
    let (mut first, mut travelled) = (0usize, 0.0f64);
    for i in 1..poses.len() {
        let step = (poses[i].translation.vector - poses[i - 1].translation.vector).norm();
        if travelled + step > cfg.submap_length_m {
            spans.push((first, i - 1, travelled));
            first = i;
            travelled = 0.0;
        } else {
            travelled += step;
        }
    }
    spans.push((first, poses.len() - 1, travelled));
    // Merge short submaps into their predecessor; the first one has none.
    let mut merged: Vec<(usize, usize, f64)> = Vec::with_capacity(spans.len());
    for s in spans {
        let short = s.1 + 1 - s.0 < cfg.min_keyframes;
        match merged.last_mut() {
            Some(prev) if short => {
                let gap = (poses[s.0].translation.vector - poses[prev.1].translation.vector).norm();
                prev.2 += gap + s.2;
                prev.1 = s.1;
            }
            _ => merged.push(s),
        }
    }
    // A short first submap followed by another is merged forward.
    if merged.len() > 1 && merged[0].1 + 1 - merged[0].0 < cfg.min_keyframes {
        let head = merged.remove(0);
        let gap = (poses[merged[0].0].translation.vector - poses[head.1].translation.vector).norm();
        merged[0].0 = head.0;
        merged[0].2 += head.2 + gap;
    }
    merged
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};
    use proptest::prelude::*;

    fn line(steps: &[f64]) -> Vec<Pose> {
        let mut x = 0.0;
        let mut out = vec![Pose::identity()];
        for s in steps {
            x += s;
            out.push(Pose::from_parts(Translation3::new(x, 0.0, 0.0), UnitQuaternion::identity()));
        }
        out
    }

    #[test]
    fn cuts_every_twenty_metres_of_travel() {
        let poses = line(&[1.0; 50]); // 51 keyframes, 50 m
        let spans = cut_submaps(&poses, &SubmapConfig::default());
        assert_eq!(spans.iter().map(|s| (s.0, s.1)).collect::<Vec<_>>(), vec![(0, 20), (21, 41), (42, 50)]);
        assert!((spans[0].2 - 20.0).abs() < 1e-9);
    }

    #[test]
    fn trailing_single_keyframe_is_merged() {
        let poses = line(&[10.0, 10.0, 10.0]); // cut at 2 (30 m > 20)... then the last alone
        let spans = cut_submaps(&poses, &SubmapConfig::default());
        assert!(spans.iter().all(|s| s.1 > s.0), "{spans:?}");
        assert_eq!(spans.last().map(|s| s.1), Some(3));
    }

    proptest! {
        #[test]
        fn spans_cover_each_keyframe_once(steps in proptest::collection::vec(0.0f64..30.0, 0..80), len in 1.0f64..40.0) {
            let poses = line(&steps);
            let cfg = SubmapConfig { submap_length_m: len, min_keyframes: 2 };
            let spans = cut_submaps(&poses, &cfg);
            let mut next = 0;
            for s in &spans {
                prop_assert_eq!(s.0, next);
                prop_assert!(s.1 >= s.0);
                if poses.len() >= 2 { prop_assert!(s.1 > s.0, "{:?}", spans); }
                next = s.1 + 1;
            }
            prop_assert_eq!(next, poses.len());
        }
    }
}
