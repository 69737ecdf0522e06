//! The evidence stage's outputs as column-oriented tables: what is stored as
//! Parquet per submap and per session, and what reprojection reads back.
//!
//! Frames: every position here is on the **world grid of the graph version
//! the table was generated from** (`graph_version` in SQLite). Moving it to a
//! later version is eq. 10 with that version's anchor: `ΔT_i = A_now · T_rigid,i
//! · A_gen⁻¹`, `i` the row's owner keyframe (MATH.md §7). Coordinates in the
//! submap frame are `A_gen⁻¹ · x`.

use crate::geometry::{Sym3, VoxelKey};

/// One kind (hit or free) of directional evidence for many voxels, as
/// columns: `n` observing keyframes, `Q = Σ q`, `M = Σ q u uᵀ` (upper
/// triangle `[xx, xy, xz, yy, yz, zz]`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct StatsColumns {
    pub n: Vec<u32>,
    pub q: Vec<f32>,
    pub m: Vec<[f32; 6]>,
}

impl StatsColumns {
    pub fn zeros(len: usize) -> StatsColumns {
        StatsColumns { n: vec![0; len], q: vec![0.0; len], m: vec![[0.0; 6]; len] }
    }

    pub fn len(&self) -> usize {
        self.n.len()
    }

    pub fn is_empty(&self) -> bool {
        self.n.is_empty()
    }
}

/// The evidence one submap's keyframes cast, one row per voxel that got any.
/// Rows are sorted by key and keys are unique.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SubmapEvidence {
    pub keys: Vec<VoxelKey>,
    pub hit: StatsColumns,
    pub free: StatsColumns,
    /// The keyframe (index in its session) that contributed most of the
    /// voxel's `Q_hit + Q_free`: the voxel moves with it (MATH.md §7).
    pub owner_keyframe: Vec<u32>,
    /// That keyframe's contribution.
    pub owner_q: Vec<f32>,
    /// Bounding box of the submap's points in the voxel, as offsets in metres
    /// from the voxel's lower corner: `[lo_x, lo_y, lo_z, hi_x, hi_y, hi_z]`;
    /// NaN where none of the submap's points fell (the voxel was only freed).
    /// Reprojection moves this box, not the voxel centre, so a voxel whose
    /// points straddle a new voxel boundary lands in every voxel they do.
    pub hit_box_m: Vec<[f32; 6]>,
    /// Keyframes whose beams that returned nothing freed the voxel (part of
    /// `free.n`; `evidence::no_return`). Files written before it read as 0.
    pub no_return_n: Vec<u32>,
}

/// The `hit_box_m` of a voxel no point fell into.
pub const NO_HIT_BOX: [f32; 6] = [f32::NAN; 6];

impl SubmapEvidence {
    pub fn len(&self) -> usize {
        self.keys.len()
    }

    pub fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }
}

/// A submap's cleaned map: the static points (ε_l ≤ τ_dyn) summarised as
/// one centroid per evidence voxel, with that voxel's ε_l.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CleanedMap {
    /// Centroid of the voxel's static points, metres.
    pub xyz_m: Vec<[f32; 3]>,
    /// Clamped ε_l of the voxel the points fell in.
    pub eps_l: Vec<f32>,
    /// Points averaged into the centroid.
    pub points: Vec<u32>,
    /// The keyframe (index in its session) most of those points came from.
    pub owner_keyframe: Vec<u32>,
    /// Covariance of those points about the centroid (m², upper triangle):
    /// the patch the points make, which later sessions' rays must cross to
    /// see the voxel gone (`evidence::surface`). `UNKNOWN_SPREAD` in maps
    /// written before seam kept it.
    pub spread_m2: Vec<Sym3>,
}

impl CleanedMap {
    pub fn len(&self) -> usize {
        self.xyz_m.len()
    }

    pub fn is_empty(&self) -> bool {
        self.xyz_m.is_empty()
    }
}

/// DOR's verdict for every point of a session, in scan order: row `j` of
/// keyframe `k` is point `j` of that keyframe's scan file.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PointLabels {
    /// The scan's index in its session.
    pub keyframe: Vec<i32>,
    /// The point's index in its scan file.
    pub point_index: Vec<i32>,
    /// The verdict: the voxel's (ε_l > τ_dyn), or grown into from its
    /// keyframe's dynamic neighbours (`evidence::grow`), so a dynamic point
    /// may have ε_l ≤ τ_dyn.
    pub dynamic: Vec<bool>,
    /// Clamped ε_l of the point's voxel.
    pub eps_l: Vec<f32>,
}

impl PointLabels {
    pub fn len(&self) -> usize {
        self.keyframe.len()
    }

    pub fn is_empty(&self) -> bool {
        self.keyframe.is_empty()
    }
}
