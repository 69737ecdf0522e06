//! Where the surveyor walks and how the sensor moves (odometry: `odometry.rs`).
//!
//! A session's route follows the site's roads (see `site.rs`): from a random
//! perimeter node along the perimeter, in by a spoke, once round the building
//! on the ring road (an intra-session loop, and the reason every session sees
//! the middle of the site), out by another spoke, then a random walk that
//! prefers roads it has used least. The walker keeps to the right-hand side of
//! the road with a slow lateral wander, at 1.05-1.35 m/s, so routes overlap
//! between sessions without repeating.

use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use rand::Rng;
use rand_distr::StandardNormal;

use super::ground::Ground;
use super::seeds::{self, tag};
use super::site::Roads;
use crate::geometry::Pose;

/// A 2-D polyline with its cumulative arc length.
#[derive(Debug, Clone)]
pub(crate) struct Polyline {
    pts: Vec<[f64; 2]>,
    cum: Vec<f64>,
}

impl Polyline {
    pub(crate) fn new(points: Vec<[f64; 2]>) -> Polyline {
        let mut pts: Vec<[f64; 2]> = Vec::with_capacity(points.len());
        for p in points {
            if pts.last().is_none_or(|q| (p[0] - q[0]).hypot(p[1] - q[1]) > 1e-9) {
                pts.push(p);
            }
        }
        let mut cum = vec![0.0];
        for w in pts.windows(2) {
            cum.push(cum[cum.len() - 1] + (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]));
        }
        Polyline { pts, cum }
    }

    pub(crate) fn length(&self) -> f64 {
        self.cum[self.cum.len() - 1]
    }

    /// The point at arc length `s` (clamped to the ends).
    pub(crate) fn at(&self, s: f64) -> [f64; 2] {
        if self.pts.len() == 1 {
            return self.pts[0];
        }
        let s = s.clamp(0.0, self.length());
        let i = self.cum.partition_point(|&c| c <= s).clamp(1, self.pts.len() - 1);
        let (a, b) = (self.pts[i - 1], self.pts[i]);
        let f = (s - self.cum[i - 1]) / (self.cum[i] - self.cum[i - 1]);
        [a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1])]
    }

    /// Heading (rad, from +x) of the direction of travel at `s`.
    pub(crate) fn heading(&self, s: f64) -> f64 {
        let (a, b) = (self.at(s - 0.5), self.at(s + 0.5));
        (b[1] - a[1]).atan2(b[0] - a[0])
    }

    /// The polyline with every corner replaced by a circular arc of radius
    /// `radius_m` (smaller where the segments are too short for it).
    fn filleted(&self, radius_m: f64) -> Polyline {
        let p = &self.pts;
        let mut out = vec![p[0]];
        for i in 1..p.len().saturating_sub(1) {
            let (a, b, c) = (p[i - 1], p[i], p[i + 1]);
            let (l1, l2) = (dist(a, b), dist(b, c));
            let u1 = [(b[0] - a[0]) / l1, (b[1] - a[1]) / l1];
            let u2 = [(c[0] - b[0]) / l2, (c[1] - b[1]) / l2];
            let cross = u1[0] * u2[1] - u1[1] * u2[0];
            let turn = cross.atan2(u1[0] * u2[0] + u1[1] * u2[1]);
            if turn.abs() < 1e-6 {
                out.push(b);
                continue;
            }
            let tan_len = (radius_m * (turn.abs() / 2.0).tan()).min(0.5 * l1.min(l2));
            let r = tan_len / (turn.abs() / 2.0).tan();
            let start = [b[0] - u1[0] * tan_len, b[1] - u1[1] * tan_len];
            // Centre on the inside of the turn.
            let side = turn.signum();
            let centre = [start[0] - u1[1] * r * side, start[1] + u1[0] * r * side];
            let a0 = (start[1] - centre[1]).atan2(start[0] - centre[0]);
            let n = ((turn.abs() * r) / 0.25).ceil().max(2.0) as usize;
            for k in 0..=n {
                let ang = a0 + turn * k as f64 / n as f64;
                out.push([centre[0] + r * ang.cos(), centre[1] + r * ang.sin()]);
            }
        }
        out.push(p[p.len() - 1]);
        Polyline::new(out)
    }

    /// A lane along the polyline: corners rounded to `radius_m`, points every
    /// `step_m`, offset to the left by `lateral(s)` (negative: right), lightly
    /// smoothed (±1 m). The radius must exceed every offset, or the inside of
    /// a turn would fold back on itself.
    pub(crate) fn lane(&self, radius_m: f64, step_m: f64, lateral: impl Fn(f64) -> f64) -> Polyline {
        let round = self.filleted(radius_m);
        let m = (round.length() / step_m).ceil().max(1.0) as usize + 1;
        let pts: Vec<(f64, [f64; 2])> = (0..m)
            .map(|i| {
                let s = round.length() * i as f64 / (m - 1) as f64;
                (s, round.at(s))
            })
            .collect();
        let mut off: Vec<[f64; 2]> = (0..m)
            .map(|i| {
                let (a, b) = (pts[i.saturating_sub(1)].1, pts[(i + 1).min(m - 1)].1);
                let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                let len = dx.hypot(dy).max(1e-12);
                let l = lateral(pts[i].0);
                [pts[i].1[0] - dy / len * l, pts[i].1[1] + dx / len * l]
            })
            .collect();
        let k = (1.0 / step_m).round() as usize;
        off = (0..m)
            .map(|i| {
                let w = k.min(i).min(m - 1 - i);
                let sum = off[i - w..=i + w].iter().fold([0.0, 0.0], |acc, p| [acc[0] + p[0], acc[1] + p[1]]);
                let n = (2 * w + 1) as f64;
                [sum[0] / n, sum[1] / n]
            })
            .collect();
        Polyline::new(off)
    }
}

/// Radius of the road centre line at corners, m: larger than any lane offset.
pub(crate) const LANE_RADIUS_M: f64 = 6.0;

/// A walk on the road graph from `start`, at least `min_len_m` long, that
/// never turns back and prefers the edges it has used least.
pub(crate) fn random_walk(roads: &Roads, rng: &mut impl Rng, mut nodes: Vec<usize>, min_len_m: f64) -> Vec<usize> {
    let mut used = vec![0usize; roads.edges.len()];
    let edge = |a: usize, b: usize| roads.neighbours(a).into_iter().find(|&(_, o)| o == b).map(|(e, _)| e);
    for w in nodes.windows(2) {
        if let Some(e) = edge(w[0], w[1]) {
            used[e] += 1;
        }
    }
    let mut len = path_length(roads, &nodes);
    while len < min_len_m {
        let cur = nodes[nodes.len() - 1];
        let prev = (nodes.len() > 1).then(|| nodes[nodes.len() - 2]);
        let options: Vec<(usize, usize)> =
            roads.neighbours(cur).into_iter().filter(|&(_, o)| Some(o) != prev).collect();
        let least = options.iter().map(|&(e, _)| used[e]).min().unwrap_or(0);
        let best: Vec<&(usize, usize)> = options.iter().filter(|&&(e, _)| used[e] == least).collect();
        let &(e, next) = best[rng.random_range(0..best.len())];
        used[e] += 1;
        len += dist(roads.nodes[cur], roads.nodes[next]);
        nodes.push(next);
    }
    nodes
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

fn path_length(roads: &Roads, nodes: &[usize]) -> f64 {
    nodes.windows(2).map(|w| dist(roads.nodes[w[0]], roads.nodes[w[1]])).sum()
}

/// The surveyor's route for a session, as road-graph nodes: perimeter to the
/// first spoke, in, one full lap of the ring, out by another spoke, then a
/// random walk until `min_len_m`.
fn route_nodes(roads: &Roads, rng: &mut impl Rng, min_len_m: f64) -> Vec<usize> {
    let start = 8 + rng.random_range(0..8);
    let (dp, dr) = (if rng.random_bool(0.5) { 1 } else { 7 }, if rng.random_bool(0.5) { 1 } else { 7 });
    let mut nodes = vec![start];
    let mut cur = start;
    // Perimeter (nodes 8..16) to a spoke junction (even), at least one edge.
    loop {
        cur = 8 + (cur - 8 + dp) % 8;
        nodes.push(cur);
        if cur % 2 == 0 {
            break;
        }
    }
    let entry = cur - 8;
    nodes.push(entry);
    cur = entry;
    // A full lap, then on to a different spoke.
    for k in 0.. {
        cur = (cur + dr) % 8;
        nodes.push(cur);
        if k >= 8 && cur % 2 == 0 && cur != entry {
            break;
        }
    }
    nodes.push(cur + 8);
    random_walk(roads, rng, nodes, min_len_m)
}

/// How the sensor is carried.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Platform {
    /// Handheld / backpack at 1.8 m, walking sway.
    Backpack,
    /// A legged robot at 0.6 m that pitches and rolls with the terrain.
    Robot,
}

impl Platform {
    /// Every third session is surveyed by the robot.
    pub(crate) fn of_session(session: usize) -> Platform {
        if session.is_multiple_of(3) { Platform::Robot } else { Platform::Backpack }
    }

    pub(crate) fn height_m(self) -> f64 {
        match self {
            Platform::Backpack => 1.8,
            Platform::Robot => 0.6,
        }
    }
}

/// The true motion of one session.
pub(crate) struct TruePath {
    /// `t_world_lidar` per keyframe.
    pub poses: Vec<Pose>,
    /// Seconds since the session's first keyframe.
    pub times: Vec<f64>,
    pub platform: Platform,
    /// Sum of the distances between consecutive keyframes, m.
    pub length_m: f64,
}

/// The true keyframe poses and times of session `session` (1-based).
pub(crate) fn true_path(
    roads: &Roads,
    ground: &Ground,
    seed: u64,
    session: usize,
    keyframes: usize,
    spacing_m: f64,
) -> TruePath {
    let mut rng = seeds::rng(seed, &[tag::ROUTE, session as u64]);
    let travel = (keyframes.saturating_sub(1)) as f64 * spacing_m * 1.05;
    let nodes = route_nodes(roads, &mut rng, travel + 30.0);
    let raw = Polyline::new(nodes.iter().map(|&n| roads.nodes[n]).collect());
    let ph: [f64; 8] = std::array::from_fn(|_| rng.random_range(0.0..std::f64::consts::TAU));
    let tau = std::f64::consts::TAU;
    // Keep right (3 m from the centre line), wandering ±0.6 m.
    let lane = raw.lane(LANE_RADIUS_M, 0.25, |s| {
        -3.0 + 0.4 * (tau * s / 37.0 + ph[0]).sin() + 0.2 * (tau * s / 13.0 + ph[1]).sin()
    });
    let platform = Platform::of_session(session);
    let start = rng.random_range(0.0..5.0);
    let (mut poses, mut times, mut length_m): (Vec<Pose>, Vec<f64>, f64) =
        (Vec::with_capacity(keyframes), Vec::with_capacity(keyframes), 0.0);
    let mut prev_s = start;
    let mut t = 0.0;
    for k in 0..keyframes {
        let jitter = if k == 0 { 0.0 } else { rng.random_range(-0.05..0.05) * spacing_m };
        let s = start + k as f64 * spacing_m + jitter;
        let mid = (s + prev_s) / 2.0;
        let speed = 1.2 + 0.1 * (tau * mid / 57.0 + ph[2]).sin() + 0.05 * (tau * mid / 19.0 + ph[3]).sin();
        t += (s - prev_s) / speed;
        prev_s = s;
        let [x, y] = lane.at(s);
        let heading = lane.heading(s);
        let (sh, ch) = heading.sin_cos();
        let (n1, n2, n3): (f64, f64, f64) =
            (rng.sample(StandardNormal), rng.sample(StandardNormal), rng.sample(StandardNormal));
        let deg = std::f64::consts::PI / 180.0;
        let (roll, pitch, yaw, bob) = match platform {
            Platform::Backpack => (
                (1.2 * (tau * 0.93 * t + ph[4]).sin() + 0.3 * n1) * deg,
                (1.5 * (tau * 1.86 * t + ph[5]).sin() + 0.3 * n2) * deg,
                heading + (2.0 * (tau * 0.93 * t + ph[6]).sin() + 0.3 * n3) * deg,
                0.03 * (tau * 1.86 * t + ph[7]).sin(),
            ),
            Platform::Robot => {
                // The body follows the terrain slope under it.
                let along =
                    (ground.height_at(x + 0.4 * ch, y + 0.4 * sh) - ground.height_at(x - 0.4 * ch, y - 0.4 * sh)) / 0.8;
                let left =
                    (ground.height_at(x - 0.3 * sh, y + 0.3 * ch) - ground.height_at(x + 0.3 * sh, y - 0.3 * ch)) / 0.6;
                (
                    left.atan() + (0.5 * (tau * 1.6 * t + ph[4]).sin() + 0.15 * n1) * deg,
                    -along.atan() + (0.6 * (tau * 1.6 * t + ph[5]).sin() + 0.15 * n2) * deg,
                    heading + (1.0 * (tau * 0.8 * t + ph[6]).sin() + 0.2 * n3) * deg,
                    0.01 * (tau * 3.2 * t + ph[7]).sin(),
                )
            }
        };
        let z = ground.height_at(x, y) + platform.height_m() + bob;
        let pose =
            Isometry3::from_parts(Translation3::new(x, y, z), UnitQuaternion::from_euler_angles(roll, pitch, yaw));
        if let Some(p) = poses.last() {
            length_m += (pose.translation.vector - p.translation.vector).norm();
        }
        poses.push(pose);
        times.push(t);
    }
    TruePath { poses, times, platform, length_m }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use nalgebra::Vector3;

    /// A route over flat ground (seed 21, 1 m spacing), for this module's
    /// tests and the odometry's.
    pub(crate) fn path(session: usize, keyframes: usize) -> TruePath {
        let ground = Ground::new(1, |_, _| false);
        true_path(&Roads::site(), &ground, 21, session, keyframes, 1.0)
    }

    #[test]
    fn routes_are_smooth_walks_with_a_loop() {
        for session in 1..=4 {
            let p = path(session, 300);
            assert_eq!(p.poses.len(), 300);
            assert!((p.length_m - 299.0).abs() < 15.0, "length {}", p.length_m);
            for w in p.poses.windows(2).zip(p.times.windows(2)) {
                let (a, b) = (w.0[0].translation.vector, w.0[1].translation.vector);
                let d = (b - a).norm();
                let dt = w.1[1] - w.1[0];
                assert!(d > 0.85 && d < 1.15, "step {d}");
                assert!(d / dt > 0.95 && d / dt < 1.45, "speed {}", d / dt);
            }
            // An intra-session revisit: some keyframe is near one 40+ keyframes earlier.
            let revisit = (40..300).any(|j| {
                (0..j - 40).any(|i| (p.poses[i].translation.vector - p.poses[j].translation.vector).xy().norm() < 3.0)
            });
            assert!(revisit, "session {session} has no loop");
            let h = p.platform.height_m();
            assert!(p.poses.iter().all(|q| q.translation.z > h - 1.0 && q.translation.z < h + 1.0));
        }
    }

    #[test]
    fn sessions_start_in_different_places() {
        let starts: Vec<Vector3<f64>> = (1..=5).map(|s| path(s, 2).poses[0].translation.vector).collect();
        let distinct = starts.iter().enumerate().all(|(i, a)| starts[..i].iter().all(|b| (a - b).norm() > 1.0));
        assert!(distinct, "{starts:?}");
    }
}
