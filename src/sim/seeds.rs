//! Seed derivation and stateless per-ray random numbers.
//!
//! Everything random in the simulator is a pure function of the user's seed
//! and *where* the number is used (session, keyframe, ray, primitive). That is
//! what makes the output independent of the thread count: no random stream is
//! shared between keyframes, and within a keyframe a ray's noise does not
//! depend on how many numbers earlier rays drew. Per-ray numbers are hashes,
//! not a stream, because a ray may test the same primitive in several grid
//! cells and must make the same "does it pass through the fence mesh" decision
//! every time.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// SplitMix64's finaliser: a bijective 64-bit mixer with good avalanche.
pub(crate) fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A seed for one use, derived from the user's seed and a path of tags.
pub(crate) fn derive(seed: u64, tags: &[u64]) -> u64 {
    tags.iter().fold(mix(seed), |acc, &t| mix(acc ^ mix(t.wrapping_add(0x5EA1))))
}

/// A seeded stream for sequential decisions (layouts, routes, schedules).
pub(crate) fn rng(seed: u64, tags: &[u64]) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(derive(seed, tags))
}

/// Tags that name what a derived seed is for, so two uses never collide.
pub(crate) mod tag {
    pub const SITE: u64 = 1;
    pub const SESSION: u64 = 2;
    pub const ROUTE: u64 = 3;
    pub const ODOMETRY: u64 = 4;
    pub const MOVERS: u64 = 5;
    pub const KEYFRAME: u64 = 6;
    pub const FRAME: u64 = 7;
}

/// A uniform number in `[0, 1)` from a hash key.
pub(crate) fn unit(key: u64) -> f64 {
    (mix(key) >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// A standard normal number from a hash key (Box-Muller on two hashes).
pub(crate) fn gauss(key: u64) -> f64 {
    let u1 = unit(key ^ 0xA5A5_A5A5_0000_0001).max(1e-300);
    let u2 = unit(key ^ 0x5A5A_5A5A_0000_0002);
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// The hash key of ray `ray` of a keyframe whose seed is `keyframe_seed`.
pub(crate) fn ray_key(keyframe_seed: u64, ray: u64) -> u64 {
    mix(keyframe_seed ^ ray.wrapping_mul(0x9E37_79B9_7F4A_7C15))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn derived_seeds_differ_by_tag_and_order() {
        assert_ne!(derive(1, &[2, 3]), derive(1, &[3, 2]));
        assert_ne!(derive(1, &[2]), derive(2, &[2]));
        assert_eq!(derive(7, &[1, 2, 3]), derive(7, &[1, 2, 3]));
    }

    #[test]
    fn hashed_numbers_have_the_right_moments() {
        let n = 200_000u64;
        let (mut su, mut sg, mut sg2) = (0.0, 0.0, 0.0);
        for i in 0..n {
            let u = unit(ray_key(42, i));
            assert!((0.0..1.0).contains(&u));
            su += u;
            let g = gauss(ray_key(43, i));
            sg += g;
            sg2 += g * g;
        }
        let nf = n as f64;
        assert!((su / nf - 0.5).abs() < 0.005, "mean of unit {}", su / nf);
        assert!((sg / nf).abs() < 0.01, "mean of gauss {}", sg / nf);
        assert!((sg2 / nf - 1.0).abs() < 0.02, "variance of gauss {}", sg2 / nf);
    }
}
