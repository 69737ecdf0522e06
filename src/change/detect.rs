//! ELite's categories with seam's evidence, and the ε_g update (MATH.md §8).
//!
//! For every key of the lifelong map L (moved to the current version) and of
//! the new session's cleaned map N:
//!
//! | key | category | ε_g |
//! |---|---|---|
//! | in L, an N voxel within τ_c that explains it | coexist | `B(ε_g, ε_l)` |
//! | in N only, an L voxel within τ_c | coexist (joins the map) | `B(ε_g of that L voxel, ε_l)` |
//! | in L only, new session freed it (`n_free > 0`) | deleted, overlap | `B(ε_g, ½ + ½w)`, `w` from ω_free and support ([`ChangeConfig::deleted_weight`]) |
//! | in L only, not freed | deleted, non-overlap | unchanged, unless its object went ([`ChangeConfig::object_share`]) |
//! | in N only, a coexist voxel within τ_o | emerged, overlap | `η (2 − ω_hit) ε_l` |
//! | in N only, none | emerged, non-overlap | `ε_l` |
//!
//! "Within τ_c" is the voxel or its neighbours up to `round(τ_c / v) − 1`
//! voxels away (the 26-neighbourhood at ELite's τ_c = 0.4 m, v = 0.2 m).
//! A neighbour "explains" an L voxel unless the new session freed that
//! voxel and every N neighbour is a plane it lies more than
//! [`ChangeConfig::off_surface_m`] off (a choice beyond ELite: the layer of
//! a removed pallet just above the ground the next session hits).
//! The same test the other way (an N-only voxel whose L neighbours are all
//! planes it lies off emerges instead of joining them) was tried and left
//! out: on the five 5-session sites of `bench/change_sites.py` it changed
//! no column (object events 98.94 / 98.39 / 98.44 / 96.83 / 91.38 % with
//! and without) and added 1,406 emerged events on the OS1-64 site: some
//! 470 on objects that did appear, some 700 false (on buildings 235,
//! fences 97, no object 227, the ground under removed objects): noise in
//! the change history.
//!
//! Deleted voxels are also judged in pieces: connected voxels the session
//! freed, whose median evidence lifts the weakly seen ones
//! ([`ChangeConfig::piece_min_voxels`]) or, with nothing of the session
//! near most of them, takes them out ([`ChangeConfig::piece_gone_share`]),
//! and connected voxels above the
//! ground with no voxel of the session near, a good part of them seen
//! empty with confidence, whose unseen rest goes with them
//! ([`ChangeConfig::object_share`]).
//!
//! Deleted voxels use seam's evidence as MATH.md says: overlap means the new
//! session's rays actually crossed the voxel. Emerged voxels use ELite's
//! distance rule (a coexist voxel within τ_o), a documented deviation: the
//! earlier sessions' evidence is kept only at voxels some point occupied
//! (`evidence::grid`), so "earlier sessions saw this space free" is not
//! stored for space that was empty then — exactly where things emerge.
//!
//! Events (`ChangeEvent`) record what a person asking "what changed" wants:
//! every emerged and deleted-with-overlap voxel, a voxel seen again right
//! after a deleted-with-overlap (it came back), and the first
//! deleted-non-overlap of a run (it left the area sessions cover).

use super::lifelong::{Category, ChangeEvent, LifelongMap, MapVoxel};
use super::places::{find, union};
use crate::evidence::grid::{pack, unpack};
use crate::evidence::ground::GroundLevel;
use crate::evidence::surface::{is_level_plane, plane_normal};
use crate::geometry::{SYM3_PAIRS, Sym3, UNKNOWN_SPREAD, VoxelKey};
use crate::registration::kdtree::{KdTree, to_f32};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Change detection settings (MATH.md §8; ELite's defaults).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ChangeConfig {
    /// Coexistence distance τ_c, metres.
    pub tau_c_m: f64,
    /// Overlap distance τ_o for emerged voxels, metres.
    pub tau_o_m: f64,
    /// η of the emerged-overlap update.
    pub eta: f64,
    /// ε_g is clamped to `[eps_g_min, eps_g_max]` after every update.
    ///
    /// Tried and not taken: `eps_g_min = 0.2`, so that one session's
    /// weaker free evidence (`w` 0.6 instead of 0.8, three keyframes instead
    /// of five) takes a long-static voxel out of the static map. On the
    /// sites of `bench/change_sites.py` (2026-12-06), permanent voxels lost /
    /// removed-object voxels no longer left: OS1-64 521 / 69 (removed left
    /// 6.67 → 6.37 %), HDL-64E 581 / 19 (4.52 → 4.39 %), HDL-32E 466 / 334
    /// (6.76 → 5.04 %), VLP-16 695 / 386 (9.47 → 7.29 %), Avia 734 / 248
    /// (39.88 → 38.46 %); permanent structure kept 99.21-99.58 % instead of
    /// 99.30-99.73 %. 1.4 to 30 permanent voxels lost for each removed
    /// one; 0.15 changed nothing that matters (OS1-64 6.67, HDL-32E 6.72 %),
    /// 0.25 on the OS1-64 lost 697 for 72 (6.35 %).
    ///
    /// Re-run later the same day on the OS1-64 and HDL-32E sites, with
    /// `free_support_keyframes` 4 as well (`bench/change_sites.py --sensors
    /// os1-64,hdl-32e --config ...`; permanent static / removed left):
    /// defaults 99.33 / 6.49 and 99.01 / 6.68 %; `eps_g_min` 0.2: 99.21 /
    /// 6.23 and 98.89 / 4.97 %; `free_support_keyframes` 4: 99.31 / 6.41 and
    /// 98.99 / 6.58 %; both: 99.19 / 6.18 and 98.87 / 4.92 %. The HDL-32E
    /// just passes 5 %, the OS1-64 does not move: of its 1,468 leftovers
    /// only 502 were ever seen free by a later session (2.32 % of those
    /// voxels), and no weight on free evidence reaches the rest.
    pub eps_g_min: f64,
    pub eps_g_max: f64,
    /// The static map is the voxels with ε_g below this.
    pub static_threshold: f64,
    /// What a deleted-with-overlap voxel's free evidence is trusted by.
    pub deleted_reliability: DeletedReliability,
    /// Keyframes of free evidence at which a deleted voxel's support s
    /// saturates (`s = min(n_free, n) / n`). Its own setting, not
    /// `evidence.n_sat`: DOR wants few keyframes (a mover is seen through
    /// briefly), removing map structure wants more.
    pub free_support_keyframes: u32,
    /// An L voxel whose own key the new session did not hit, whose N
    /// neighbours within τ_c are all planar (≥ 3 points, smallest spread
    /// eigenvalue under a tenth of the middle one) with the voxel's centroid
    /// farther than this off every one of their planes, and which the new
    /// session freed itself, is not coexist: it goes down the deleted path.
    /// 0 turns the test off (ELite's rule: any neighbour within τ_c).
    ///
    /// Why: a removed pallet's or rebar bundle's lowest layer neighbours the
    /// ground the next session hits, so ELite's rule keeps it as coexist
    /// however clearly that session saw it empty. A surface seen a little
    /// off (drift of centimetres) still lies on its neighbours' plane, and
    /// structure beside something that is no plane (a tree, a corner) still
    /// coexists. Measured with `seam eval changes` on the 5 × 150-keyframe
    /// sites of [`DeletedReliability`]'s table (permanent structure kept /
    /// removed objects' voxels left, 0 → 0.15 m): OS1-64 (demo) 99.29 /
    /// 21.21 → 99.27 / 18.78 %, HDL-64E 99.39 / 12.34 → 99.33 / 9.44 %,
    /// HDL-32E 99.45 / 16.58 → 99.42 / 14.63 %, VLP-16 99.33 / 21.13 →
    /// 99.32 / 19.24 %, Avia 98.32 / 47.41 → 98.31 / 47.04 %. 0.10 m gives
    /// the same on the demo (99.27 / 18.75 %).
    ///
    /// Tried and not taken: a voxel the session before saw empty
    /// (deleted-overlap) coming back only when the new session hits that
    /// voxel itself, not a neighbour. With `evidence.free_vacated_low`, on
    /// the same sites: HDL-64E 99.27 / 8.12 → 99.06 / 6.77 %, OS1-64 99.25 /
    /// 17.72 → 98.98 / 14.68 %, VLP-16 99.31 / 17.93 → 99.01 / 15.77 %: two
    /// to seven permanent voxels lost (ground, building, trees) for each
    /// removed one, and the Avia site (98.26 %) has no room for 0.3 points.
    pub off_surface_m: f64,
    /// Pieces of space the new session saw empty are judged whole: L voxels
    /// it freed and did not hit, joined through their 26-neighbours, make a
    /// piece; in a piece of at least this many voxels each voxel's free
    /// evidence counts at least as much as the piece's median (its `w`,
    /// [`ChangeConfig::deleted_weight`]), and a voxel kept as coexist only
    /// by a neighbour the session hit goes down the deleted path when that
    /// median alone takes a voxel out of the static map
    /// ([`ChangeConfig::strong_weight`]) and most of the piece has no voxel
    /// of the new session within τ_c. 0 turns it off. Choice beyond ELite
    /// ([`piece_weights`]).
    ///
    /// Why: a removed object is seen empty unevenly. Its near face is
    /// crossed by many rays, its top and far side by one or two, its lowest
    /// layer neighbours the ground; voxel by voxel, the weakly seen ones
    /// stay static for sessions. Most of a piece seen empty with confidence
    /// says the object as a whole is gone. The majority rule for the
    /// neighbour-kept voxels spares a surface seen one voxel over: the old
    /// layer's voxels all neighbour the new one.
    ///
    /// Measured with `bench/change_sites.py` (5 × 150 keyframes, seed 3, the
    /// OS1-64 seed 1; `seam eval changes`), permanent structure static /
    /// removed objects' voxels left static / the same among voxels some
    /// session saw free, 0 → 10: OS1-64 99.31 / 14.50 / 8.30 → 98.82 / 8.60 /
    /// 3.47 %, HDL-64E 99.34 / 8.20 / 3.13 → 99.11 / 5.09 / 1.23 %, HDL-32E
    /// 99.40 / 13.09 / 6.86 → 98.98 / 7.56 / 3.21 %, VLP-16 99.35 / 18.06 /
    /// 10.75 → 98.89 / 10.10 / 5.11 %, Avia 99.09 / 46.31 / 15.13 → 98.75 /
    /// 41.50 / 9.57 %; appeared objects, mover leftovers and events in the
    /// right session unchanged. On the VLP-16 site 2,604 of the 3,947
    /// permanent voxels it takes out of the static map are the underside of
    /// the building's first slab: layers earlier sessions placed a few
    /// centimetres lower, crossed by the last session's rays rising to the
    /// slab at grazing angles (the slab stays, seen by that session; ceilings
    /// have no clearance rule as the ground has). Variants on the VLP-16
    /// site: without the majority rule 98.67 / 9.66 %; lifting weights only
    /// (no neighbour-kept voxel leaves) 99.21 / 15.09 %; lifting only in
    /// pieces mostly gone 98.90 / 10.17 %. With `[evidence] map_patches =
    /// true` (an earlier session's voxel freed only by a ray crossing its
    /// patch and ending `surface_behind_m` past it, which spares the slab's
    /// layers): VLP-16 99.40 / 14.38 %, HDL-64E 99.56 / 6.21 %, better than
    /// the defaults before pieces on both counts.
    pub piece_min_voxels: u32,
    /// A piece ([`ChangeConfig::piece_min_voxels`]) at least this share of
    /// which has no voxel of the new session within τ_c, and whose median
    /// `w` is at least [`ChangeConfig::piece_gone_min_w`], is taken as seen
    /// gone with confidence: its voxels get at least the strong weight
    /// ([`ChangeConfig::strong_weight`]). 0 turns it off.
    ///
    /// Why: the session's rays crossed the piece's space, two or more
    /// keyframes per voxel in the median, and hit nothing near four fifths
    /// of it: whatever stood there is gone, even if each voxel was crossed
    /// from one direction only (a parked van passed on one side, the sparse
    /// beams of a VLP-16). A surface still standing is hit nearby: the layer
    /// of a slab or wall that misalignment leaves beside the new one has the
    /// new session's voxels within τ_c.
    ///
    /// Only voxels above the ground level (`GroundLevel::above_nearby`)
    /// are lifted: without that the HDL-64E site lost 900 ground voxels
    /// (permanent structure 99.29 → 99.15 %) for no fewer leftovers.
    ///
    /// Measured with `bench/change_sites.py` (2026-12-07, the sites above,
    /// with `object_sure_share` 0.9), permanent structure static / removed
    /// objects' voxels left, off → 0.8 with `piece_gone_min_w` 0.4: OS1-64
    /// 99.31 / 3.89 → 99.15 / 3.72 %, HDL-64E 99.29 / 3.12 → 99.29 /
    /// 3.12 %, HDL-32E 98.96 / 3.89 → 98.93 / 3.84 %, VLP-16 99.12 / 7.60 →
    /// 99.08 / 4.48 %, Avia 99.71 / 38.74 → 99.68 / 36.63 %; appeared objects
    /// 100 %, events unchanged.
    /// On the VLP-16 site two parked vans seen empty from one side, two or
    /// three keyframes per voxel, were most of what was left. Variants
    /// (without the ground rule): 0.9 / 0.5 VLP-16 99.11 / 6.53 %, HDL-64E
    /// 99.28 / 3.12 %; 0.9 / 0.4 VLP-16 99.09 / 4.51 %, HDL-64E 99.15 %.
    ///
    /// No piece of which half or more are level planes is judged gone
    /// ([`PIECE_GONE_MAX_LEVEL_SHARE`]). What the OS1-64 site paid above
    /// (`seam eval changes --lost-voxels`, against a run with the rule
    /// off): 714 permanent voxels, 597 of them a 28 × 5 m strip of the
    /// building's slab underside at 3.96 m that session 5 saw only through
    /// rays rising under the slab, and 51 of a crane, 43 of a stockpile.
    /// With the level rule (2026-12-08, same sites): OS1-64 99.31 / 3.73 %,
    /// HDL-64E 99.29 / 3.12, HDL-32E 98.93 / 3.84, VLP-16 99.08 / 4.48, Avia
    /// 99.68 / 36.63; appeared objects 100 %, events unchanged.
    pub piece_gone_share: f64,
    /// The least median `w` of a piece [`ChangeConfig::piece_gone_share`]
    /// judges gone (0.4: two of `free_support_keyframes` = 5 keyframes).
    pub piece_gone_min_w: f64,
    /// What is left of an object partly seen gone goes with it: the map's
    /// voxels above the ground level (`GroundLevel::above_nearby`) that the new
    /// session left on the deleted path with no voxel of its own within
    /// τ_c, seen empty or not seen at all, joined through their
    /// 26-neighbours into pieces; in a piece of
    /// `piece_min_voxels` to [`ChangeConfig::object_max_voxels`] voxels of
    /// which at least this share the session's free evidence alone takes
    /// out of the static map ([`ChangeConfig::strong_weight`]), every voxel
    /// gets at least the lower median of those voxels' `w`, also the ones
    /// the session did not see (deleted, non-overlap: ε_g updated as if
    /// seen empty with that `w`, the category unchanged). 0 turns it off.
    /// Choice beyond ELite ([`object_weights`]).
    ///
    /// Why: a removed crane jib, rebar bundle or pipe stack is seen empty
    /// where the next session's rays cross its space, not where they never
    /// reach (above the sensor's band, behind what still stands); voxel by
    /// voxel, the unseen part stays in the static map for good.
    ///
    /// Measured with `bench/change_sites.py` (2026-12-07, the sites of
    /// [`ChangeConfig::piece_min_voxels`]), permanent structure static /
    /// removed objects' voxels left, 0 → 0.5: OS1-64 99.32 / 6.34 → 99.32 /
    /// 4.48 %, HDL-64E 99.31 / 4.53 → 99.29 / 4.30 %, HDL-32E 99.00 / 6.68 →
    /// 98.99 / 6.66 %, VLP-16 99.15 / 9.48 → 99.13 / 9.43 %, Avia 99.73 /
    /// 39.04 → 99.73 / 38.91 %; appeared objects, movers and events
    /// unchanged. Then 0.5 → 0.3 (2026-12-07, the same sites): OS1-64
    /// 99.31 / 4.45 %, HDL-64E 99.29 / 3.38 %, HDL-32E 98.97 / 5.03 %,
    /// VLP-16 99.12 / 8.84 %, Avia 99.71 / 38.78 %, appeared objects 100 %,
    /// events unchanged. 0.25 left HDL-32E at 98.96 / 4.39 % (HDL-64E
    /// unchanged); 0.2 the same HDL-32E numbers and VLP-16 7.80 %, but the
    /// HDL-64E site's car parked where another had stood lost its static
    /// voxels (appeared 94.44 %): 0.3 keeps a margin from that. Variants
    /// (at 0.5): no limit on new voxels in a piece's box (OS1-64
    /// 3.04 %, HDL-32E 98.75 / 5.21 %: the building beside removed shoring
    /// left with it); a quarter of the piece within 2 voxels of new voxels
    /// instead (OS1-64 3.23 %, HDL-64E 3.85 %, HDL-32E 98.98 / 5.29 %, but
    /// the HDL-64E site lost a parked car that replaced another, appeared
    /// objects 94.44 %); `object_max_new` 1.0 (OS1-64 3.23 %, the same car
    /// lost) and 0.25 (OS1-64 4.69 %); reach from the strong voxels limited
    /// to 1 / 3 / 6 steps without the box test (OS1-64 5.07 / 4.23 /
    /// 3.59 %, HDL-32E 6.03 / 5.58 / 5.33 %).
    pub object_share: f64,
    /// The largest piece [`ChangeConfig::object_share`] judges whole: a
    /// building's side out of a session's view is one piece of many
    /// thousand voxels, and no verdict of a few of them should reach it.
    pub object_max_voxels: u32,
    /// The most voxels of the new session above the ground level, per voxel
    /// of a piece, that may lie in the piece's bounding box (grown by
    /// [`OBJECT_BOX_MARGIN_VOXELS`]) for [`ChangeConfig::object_share`] to
    /// judge it whole: where the session hit something inside, what stood
    /// there was replaced or reshaped, not taken away (a car parked where
    /// another stood, a stockpile seen from one side), and its unseen part
    /// may well be there.
    pub object_max_new: f64,
    /// A piece of which at least this share is strong skips the
    /// [`ChangeConfig::object_max_new`] test: nearly all of it was seen gone
    /// with confidence, so what the session hit around it (the building a
    /// scaffold stood against, in a box of 8 × 30 × 8 m around a 30 m
    /// scaffold) says nothing about its unseen rest, at most a tenth of it.
    /// 1.0 turns it off (every piece takes the test).
    ///
    /// Measured with `bench/change_sites.py` (2026-12-07, the sites of
    /// [`ChangeConfig::piece_min_voxels`]), permanent structure static /
    /// removed objects' voxels left, 1.0 → 0.9: OS1-64 99.31 / 4.45 →
    /// 99.31 / 3.89 %, HDL-64E 99.29 / 3.38 → 99.29 / 3.12 %, HDL-32E 98.97 /
    /// 5.03 → 98.96 / 3.89 %, VLP-16 99.12 / 8.84 → 99.12 / 7.60 %, Avia
    /// 99.71 / 38.78 → 99.71 / 38.74 %; appeared objects 100 % (the HDL-64E
    /// site's car parked where another stood stays), movers and events
    /// unchanged. On the HDL-32E site a scaffold's session-5 piece (4,311
    /// voxels, 96 % strong) had 9,032 new voxels in its box. 0.8 left
    /// HDL-32E 3.73 %, VLP-16 7.50 %, HDL-64E the same as 0.9: a tenth of a
    /// point more for twice the unseen share let go, so 0.9.
    pub object_sure_share: f64,
}

/// The reliability `w` of the new session's free evidence at a deleted
/// voxel, which enters ε_g as `B(ε_g, ½ + ½w)` ([`deleted_factor`]); `s` is
/// the free support `min(n_free, n) / n`, n = `free_support_keyframes`.
///
/// The default is `omega_or_support`: four of five keyframes seeing the
/// space empty, from whatever direction, take a voxel out of the static map
/// in one session. Free evidence from one direction only (ω ≈ 0) is common
/// at deleted voxels (72 % of them on an OS1-64 site), so `omega` alone
/// removes little. Measured on simulated 5-session sites, 150 keyframes per
/// session (seed 3; the OS1-64 row is the README's demo site, seed 1), with
/// the no-return evidence: `seam eval changes`, permanent structure kept
/// static / removed objects' voxels left static:
///
/// | sensor (ATE per session) | `omega_or_half_support` | `omega_or_support` |
/// |---|---|---|
/// | OS1-64 (48-73 mm) | 99.71 / 30.45 % | 99.35 / 22.39 % |
/// | HDL-64E (41-74 mm) | 99.80 / 38.62 % | 99.41 / 13.92 % |
/// | HDL-32E (48-83 mm) | 99.69 / 44.08 % | 99.45 / 18.37 % |
/// | VLP-16 (64-118 mm) | 99.59 / 45.52 % | 99.31 / 23.36 % |
/// | Avia (117-187 mm) | 99.28 / 77.54 % | 98.31 / 53.45 % |
///
/// (The Avia row is before no-return evidence for forward sensors; with it,
/// `omega_or_support` gives 98.29 / 48.00 %. The table predates
/// `evidence.n_sat` = 2 and `free_clearance_m` = 0.2 m, which leave a few
/// points fewer removed-object voxels static on every row: see
/// `EvidenceConfig::n_sat`.)
///
/// `free_support_keyframes = 3` on the demo site: 99.09 / 20.74 %; on the
/// 5 × 150-keyframe sites of `bench/change_sites.py` (seed 3, 2026-12-02),
/// HDL-64E 99.32 / 8.12 → 99.05 / 7.56 % and VLP-16 99.33 / 17.80 → 99.10 /
/// 14.83 %: a third more permanent structure lost for a tenth to a sixth
/// fewer leftovers, so the default stays 5. What it
/// costs grows with misalignment between sessions: on earlier 80-keyframe
/// sites whose sessions were 0.3-0.65 m apart (too little route overlap for
/// loops), `omega_or_support` with n = 8 kept only 97.30 % of HDL-64E's
/// permanent structure (`omega_or_half_support`: 99.40 %). On a site whose
/// sessions `seam eval align` (or the loop count in `seam info`) shows
/// poorly tied together, `omega_or_half_support` (two sessions must see a
/// voxel empty) is the safer choice. Beams that returned nothing add support
/// of their own on top of this ([`ChangeConfig::deleted_weight`],
/// `evidence::no_return`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DeletedReliability {
    /// `w = ω_free` (MATH.md §8, ω for ELite's γ).
    Omega,
    /// `w = max(ω_free, s / 2)`: at most `B(ε_g, ¾)` per session from
    /// support alone, so one session seeing the space empty from one
    /// direction cannot take a voxel out of the static map (0.1 → 0.25),
    /// two such sessions can (→ 0.5).
    OmegaOrHalfSupport,
    /// `w = max(ω_free, s)`: enough keyframes saw the space empty, from
    /// whatever direction. Removes the most; eats the most.
    #[default]
    OmegaOrSupport,
}

impl DeletedReliability {
    /// `w` from the free evidence's ω and support `s`.
    pub fn of(self, omega_free: f64, support: f64) -> f64 {
        match self {
            DeletedReliability::Omega => omega_free,
            DeletedReliability::OmegaOrHalfSupport => omega_free.max(support / 2.0),
            DeletedReliability::OmegaOrSupport => omega_free.max(support),
        }
    }
}

impl ChangeConfig {
    /// `w` of a deleted-with-overlap voxel the new session freed from
    /// `free_n` keyframes, `no_return_n` of them by beams that returned
    /// nothing (`evidence::no_return`). Those saw a whole window of
    /// directions around the voxel empty, not a ray passing beside what it
    /// held, so their support counts in full whatever `deleted_reliability`:
    /// `w = max(reliability(ω_free, s(free_n)), s(no_return_n))`,
    /// `s(n) = min(n, free_support_keyframes) / free_support_keyframes`.
    pub fn deleted_weight(&self, omega_free: f64, free_n: u32, no_return_n: u32) -> f64 {
        let n_sat = self.free_support_keyframes.max(1);
        let support = |n: u32| n.min(n_sat) as f64 / n_sat as f64;
        self.deleted_reliability.of(omega_free, support(free_n)).max(support(no_return_n))
    }

    /// The least `w` with which one session's free evidence alone takes a
    /// voxel at ε_g's floor out of the static map (0.8 at the defaults:
    /// `B(0.1, 0.9) = 0.5`).
    pub fn strong_weight(&self) -> f64 {
        let (a, t) = (self.eps_g_min, self.static_threshold);
        let factor = t * (1.0 - a) / (a * (1.0 - t) + t * (1.0 - a));
        (2.0 * factor - 1.0).clamp(0.0, 1.0)
    }
}

impl Default for ChangeConfig {
    fn default() -> Self {
        ChangeConfig {
            tau_c_m: 0.4,
            tau_o_m: 2.0,
            eta: 2.0,
            eps_g_min: 0.1,
            eps_g_max: 0.9,
            static_threshold: 0.5,
            deleted_reliability: DeletedReliability::default(),
            free_support_keyframes: 5,
            off_surface_m: 0.15,
            piece_min_voxels: 10,
            piece_gone_share: 0.8,
            piece_gone_min_w: 0.4,
            object_share: 0.3,
            object_max_voxels: 20_000,
            object_max_new: 0.5,
            object_sure_share: 0.9,
        }
    }
}

impl ChangeConfig {
    pub fn validate(&self) -> Result<(), String> {
        let pos = |name: &str, v: f64| {
            if v.is_finite() && v > 0.0 { Ok(()) } else { Err(format!("[change] {name} must be > 0, got {v}")) }
        };
        pos("tau_c_m", self.tau_c_m)?;
        pos("tau_o_m", self.tau_o_m)?;
        pos("eta", self.eta)?;
        if !(self.off_surface_m.is_finite() && self.off_surface_m >= 0.0) {
            return Err(format!("[change] off_surface_m must be ≥ 0 (0 turns it off), got {}", self.off_surface_m));
        }
        let unit = |name: &str, v: f64| {
            if (0.0..=1.0).contains(&v) { Ok(()) } else { Err(format!("[change] {name} must be in [0, 1], got {v}")) }
        };
        unit("eps_g_min", self.eps_g_min)?;
        unit("eps_g_max", self.eps_g_max)?;
        unit("static_threshold", self.static_threshold)?;
        unit("piece_gone_share", self.piece_gone_share)?;
        unit("piece_gone_min_w", self.piece_gone_min_w)?;
        unit("object_share", self.object_share)?;
        unit("object_sure_share", self.object_sure_share)?;
        if !(self.object_max_new.is_finite() && self.object_max_new >= 0.0) {
            return Err(format!("[change] object_max_new must be ≥ 0, got {}", self.object_max_new));
        }
        if self.object_share > 0.0 && self.object_max_voxels == 0 {
            return Err(
                "[change] object_max_voxels must be at least 1 (default 20000; object_share 0 turns the step off)"
                    .into(),
            );
        }
        if self.free_support_keyframes == 0 {
            return Err("[change] free_support_keyframes must be at least 1 (default 5)".into());
        }
        if self.eps_g_min >= self.eps_g_max {
            return Err(format!(
                "[change] eps_g_min ({}) must be below eps_g_max ({})",
                self.eps_g_min, self.eps_g_max
            ));
        }
        Ok(())
    }

    /// Neighbour radius in voxels that counts as "within τ_c".
    fn coexist_radius(&self, voxel_m: f64) -> i32 {
        ((self.tau_c_m / voxel_m).round() as i32 - 1).max(0)
    }
}

/// One voxel of the new session's cleaned map, with the session's evidence
/// there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NewVoxel {
    pub key: VoxelKey,
    /// Centroid of the static points, world frame (current version).
    pub xyz_m: [f64; 3],
    pub eps_l: f32,
    pub points: u32,
    pub owner_keyframe: u32,
    /// ω of the session's hit evidence at the voxel.
    pub omega_hit: f32,
    /// Covariance of the static points about the centroid, m² (see
    /// `CleanedMap::spread_m2`).
    pub spread_m2: Sym3,
}

/// One row of a submap's cleaned map, in the world frame of the current
/// graph version.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CleanedRow {
    pub xyz_m: [f64; 3],
    pub eps_l: f32,
    pub points: u32,
    pub owner_keyframe: u32,
    pub spread_m2: Sym3,
}

/// The new session's free evidence at a voxel: `(n_free, w)`, `w` its
/// reliability per [`DeletedReliability`].
pub type FreeAt<'a> = dyn Fn(u64) -> Option<(u32, f32)> + Sync + 'a;

/// Counts of one session's update (SQLite's `session_changes`).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct SessionChanges {
    pub coexist: usize,
    pub deleted_overlap: usize,
    pub deleted_non_overlap: usize,
    pub emerged_overlap: usize,
    pub emerged_non_overlap: usize,
    pub events: usize,
    pub merged_on_move: usize,
    pub lifelong_voxels: usize,
    pub static_voxels: usize,
}

impl SessionChanges {
    fn count(&mut self, c: Category) {
        match c {
            Category::Initial => {}
            Category::Coexist => self.coexist += 1,
            Category::DeletedOverlap => self.deleted_overlap += 1,
            Category::DeletedNonOverlap => self.deleted_non_overlap += 1,
            Category::EmergedOverlap => self.emerged_overlap += 1,
            Category::EmergedNonOverlap => self.emerged_non_overlap += 1,
        }
    }
}

/// ELite's `B(a, b) = a b / (a b + (1 − a)(1 − b))`.
pub fn bayes(a: f64, b: f64) -> f64 {
    let d = a * b + (1.0 - a) * (1.0 - b);
    if d <= 0.0 { 0.5 } else { a * b / d }
}

/// The factor a deleted-with-overlap voxel's ε_g is updated with:
/// `0.5 + 0.5·ω_free` (choice). MATH.md puts ω_free where ELite has its
/// objectness γ, but B(a, ω) with ω < 0.5 *lowers* ε_g, and B(a, 0) = 0:
/// free evidence too one-sided to trust would make a vanished voxel more
/// static than before. Mapped to `[0.5, 1]`, unreliable evidence leaves ε_g
/// as it was and fully reliable evidence (ω = 1) removes the voxel at once.
pub fn deleted_factor(reliability: f32) -> f64 {
    0.5 + 0.5 * (reliability as f64).clamp(0.0, 1.0)
}

/// What a voxel's piece says, for [`ChangeConfig::piece_min_voxels`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Piece {
    /// The lower median of the piece's free-evidence weights `w`; 0 for a
    /// piece smaller than `min_voxels`.
    pub median_w: f32,
    /// The share of the piece's voxels with no voxel of the new session
    /// within τ_c (0 for a piece smaller than `min_voxels`).
    pub gone_share: f32,
    /// The share of the piece's voxels whose points lie on a level plane
    /// (0 for a piece smaller than `min_voxels`).
    pub level_share: f32,
}

/// Each voxel's [`Piece`]: `keys` (packed, sorted, unique) are joined
/// through their 26-neighbours into pieces; `w` is each voxel's free
/// evidence weight, `gone` whether the new session hit nothing within
/// τ_c of it and `level` whether its points lie on a level plane.
pub fn piece_weights(keys: &[u64], w: &[f32], gone: &[bool], level: &[bool], min_voxels: u32) -> Vec<Piece> {
    debug_assert!(keys.len() == w.len() && keys.len() == gone.len() && keys.len() == level.len());
    let roots = join_pieces(keys);
    let mut members: rustc_hash::FxHashMap<usize, (Vec<f32>, usize, usize)> = rustc_hash::FxHashMap::default();
    for (((&r, &x), &g), &l) in roots.iter().zip(w).zip(gone).zip(level) {
        let e = members.entry(r).or_default();
        e.0.push(x);
        e.1 += usize::from(g);
        e.2 += usize::from(l);
    }
    let pieces: rustc_hash::FxHashMap<usize, Piece> = members
        .into_iter()
        .filter(|(_, (ws, _, _))| ws.len() >= min_voxels.max(1) as usize)
        .map(|(r, (mut ws, gone, level))| {
            let n = ws.len();
            let (_, m, _) = ws.select_nth_unstable_by((n - 1) / 2, f32::total_cmp);
            let share = |c: usize| c as f32 / n as f32;
            (r, Piece { median_w: *m, gone_share: share(gone), level_share: share(level) })
        })
        .collect();
    roots.iter().map(|r| pieces.get(r).copied().unwrap_or_default()).collect()
}

/// The piece of every key: `keys` (packed, sorted, unique) joined through
/// their 26-neighbours; each key's value is its piece's root index.
fn join_pieces(keys: &[u64]) -> Vec<usize> {
    debug_assert!(keys.windows(2).all(|p| p[0] < p[1]));
    let set = KeySet(keys);
    let mut parent: Vec<usize> = (0..keys.len()).collect();
    for (i, &k) in keys.iter().enumerate() {
        for (_, n) in unpack(k).neighbours(1) {
            if let Some(j) = pack(n).and_then(|n| set.find(n)) {
                union(&mut parent, i, j);
            }
        }
    }
    (0..keys.len()).map(|i| find(&mut parent, i)).collect()
}

/// One map voxel for [`object_weights`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObjectMember {
    /// Packed key.
    pub key: u64,
    /// The new session's free evidence alone takes it out of the static map
    /// ([`ChangeConfig::strong_weight`]).
    pub strong: bool,
    /// Its free-evidence weight `w` (0 where the session did not free it).
    pub w: f32,
}

/// How far around a piece's bounding box [`object_weights`] looks for the
/// new session's voxels, in voxels.
pub const OBJECT_BOX_MARGIN_VOXELS: i32 = 2;

/// For [`ChangeConfig::object_share`]: `members` (sorted by key, unique)
/// are the map's voxels above the ground level that the new session left on
/// the deleted path with none of its own voxels within τ_c, `new_above` the
/// new session's voxel keys above the ground level. Members are joined
/// through their 26-neighbours into pieces; a piece of `piece_min_voxels`
/// to `object_max_voxels` voxels, at least `object_share` of them strong,
/// with at most `object_max_new` times its size of `new_above` voxels in its
/// bounding box grown by [`OBJECT_BOX_MARGIN_VOXELS`], gives each of its
/// voxels the lower median of its strong voxels' `w` (`None` elsewhere).
pub fn object_weights(members: &[ObjectMember], new_above: &[[i32; 3]], cfg: &ChangeConfig) -> Vec<Option<f32>> {
    let keys: Vec<u64> = members.iter().map(|m| m.key).collect();
    let roots = join_pieces(&keys);
    struct Acc {
        n: usize,
        ws: Vec<f32>,
        lo: [i32; 3],
        hi: [i32; 3],
    }
    let mut pieces: rustc_hash::FxHashMap<usize, Acc> = rustc_hash::FxHashMap::default();
    for (&r, m) in roots.iter().zip(members) {
        let k = unpack(m.key).0;
        let e = pieces.entry(r).or_insert(Acc { n: 0, ws: Vec::new(), lo: k, hi: k });
        e.n += 1;
        if m.strong {
            e.ws.push(m.w);
        }
        e.lo = [0, 1, 2].map(|a| e.lo[a].min(k[a]));
        e.hi = [0, 1, 2].map(|a| e.hi[a].max(k[a]));
    }
    let sizes = cfg.piece_min_voxels.max(1) as usize..=cfg.object_max_voxels as usize;
    let g = OBJECT_BOX_MARGIN_VOXELS;
    // By x, so each piece's box counts only the slice within its x range.
    let mut by_x = new_above.to_vec();
    by_x.sort_unstable();
    let verdicts: rustc_hash::FxHashMap<usize, f32> = pieces
        .into_iter()
        .filter(|(_, p)| sizes.contains(&p.n) && !p.ws.is_empty() && p.ws.len() as f64 >= cfg.object_share * p.n as f64)
        .filter(|(_, p)| {
            if p.ws.len() as f64 >= cfg.object_sure_share * p.n as f64 && cfg.object_sure_share < 1.0 {
                return true;
            }
            let (lo, hi) = (p.lo.map(|c| c.saturating_sub(g)), p.hi.map(|c| c.saturating_add(g)));
            let in_x = &by_x[by_x.partition_point(|k| k[0] < lo[0])..by_x.partition_point(|k| k[0] <= hi[0])];
            let inside = in_x.iter().filter(|k| (1..3).all(|a| k[a] >= lo[a] && k[a] <= hi[a])).count();
            inside as f64 <= cfg.object_max_new * p.n as f64
        })
        .map(|(r, mut p)| {
            let k = (p.ws.len() - 1) / 2;
            let (_, m, _) = p.ws.select_nth_unstable_by(k, f32::total_cmp);
            (r, *m)
        })
        .collect();
    roots.iter().map(|r| verdicts.get(r).copied()).collect()
}

/// Columns around a voxel whose lowest occupied voxel sets its ground
/// level for [`ChangeConfig::object_share`] (5: a metre each way at 0.2 m;
/// `GroundLevel::above_nearby`).
const GROUND_NEARBY_VOXELS: i32 = 5;

/// [`ChangeConfig::piece_gone_share`] judges no piece gone of which at
/// least this share are level planes ([`is_level_plane`]): rays rising
/// under a slab cross its underside's voxels for metres before they hit it
/// farther in, so a strip of underside the session sees only that way has
/// nothing of the session near it. A van seen empty has sides too.
const PIECE_GONE_MAX_LEVEL_SHARE: f32 = 0.5;

/// Sorted packed keys with a lookup, for neighbourhood queries.
struct KeySet<'a>(&'a [u64]);

impl KeySet<'_> {
    fn find(&self, k: u64) -> Option<usize> {
        self.0.binary_search(&k).ok()
    }

    /// Index of the key itself, else of the neighbour within `r` voxels
    /// nearest to it (ties: lowest key).
    fn nearest_within(&self, key: VoxelKey, r: i32) -> Option<usize> {
        if let Some(i) = pack(key).and_then(|k| self.find(k)) {
            return Some(i);
        }
        // Neighbours come in key order, so the first at the least distance
        // is the lowest key among the nearest.
        let mut best: Option<(i32, usize)> = None;
        for (d, n) in key.neighbours(r) {
            let d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
            if best.is_some_and(|(b, _)| b <= d2) {
                continue;
            }
            if let Some(i) = pack(n).and_then(|k| self.find(k)) {
                best = Some((d2, i));
            }
        }
        best.map(|(_, i)| i)
    }
}

/// Folds session `session` into the lifelong map. `map` must already be on
/// the current graph version (see [`LifelongMap::moved`]) and `new` sorted
/// by packed key with unique keys. `next_id` is the first id for voxels new
/// to the map. An empty map is the first session: ε_g starts at ε_l and no
/// events are recorded.
pub fn update_map(
    map: LifelongMap,
    new: &[NewVoxel],
    free_at: &FreeAt<'_>,
    session: i64,
    next_id: i64,
    cfg: &ChangeConfig,
) -> (LifelongMap, Vec<ChangeEvent>, SessionChanges) {
    let v = map.voxel_m;
    let clamp = |e: f64| e.clamp(cfg.eps_g_min, cfg.eps_g_max) as f32;
    let first = map.is_empty();
    let r = cfg.coexist_radius(v);
    let l_keys: Vec<u64> = map.voxels.iter().filter_map(|x| pack(x.key)).collect();
    let n_keys: Vec<u64> = new.iter().filter_map(|x| pack(x.key)).collect();
    let (l_set, n_set) = (KeySet(&l_keys), KeySet(&n_keys));
    let mut stats = SessionChanges::default();
    let mut events = Vec::new();

    // Every L voxel: coexist or deleted.
    let normals: Vec<Option<[f64; 3]>> = if cfg.off_surface_m > 0.0 {
        new.par_iter().map(|n| plane_normal(&n.spread_m2, n.points)).collect()
    } else {
        Vec::new()
    };
    // Whether N voxel `j` explains L voxel `x` being there: it is not a
    // plane, or `x` lies on its plane.
    let explains = |x: &MapVoxel, j: usize| match normals[j] {
        None => true,
        Some(nu) => {
            let n = &new[j];
            (0..3).map(|a| nu[a] * (x.xyz_m[a] - n.xyz_m[a])).sum::<f64>().abs() <= cfg.off_surface_m
        }
    };
    // The new session's free evidence at each L voxel: `(n_free, w)` where
    // it freed the voxel.
    let freed: Vec<Option<(u32, f32)>> =
        map.voxels.par_iter().map(|x| pack(x.key).and_then(free_at).filter(|&(n_free, _)| n_free > 0)).collect();
    // Each L voxel's match, the new session's voxel nearest it within τ_c
    // where that explains it, and whether there is any within τ_c.
    let (mut l_match, near): (Vec<Option<usize>>, Vec<bool>) = map
        .voxels
        .par_iter()
        .zip(&freed)
        .map(|(x, f)| {
            let Some(m) = n_set.nearest_within(x.key, r) else { return (None, false) };
            if cfg.off_surface_m <= 0.0 || new[m].key == x.key {
                return (Some(m), true);
            }
            // Only a voxel the new session freed can be unexplained.
            let explained = f.is_none()
                || x.key.neighbours(r).filter_map(|(_, k)| pack(k).and_then(|k| n_set.find(k))).any(|j| explains(x, j));
            (explained.then_some(m), true)
        })
        .unzip();
    // Pieces of freed space, judged whole (`piece_min_voxels`): every freed
    // L voxel the session did not hit itself.
    let mut weight: Vec<f32> = freed.iter().map(|f| f.map_or(0.0, |(_, w)| w)).collect();
    // The ground level of the map and the session, for the steps below.
    let piece_gone = cfg.piece_min_voxels > 0 && cfg.piece_gone_share > 0.0;
    let ground = (!first && (cfg.object_share > 0.0 || piece_gone))
        .then(|| GroundLevel::from_keys(l_keys.iter().chain(&n_keys)));
    let above = |k: &[i32; 3]| ground.as_ref().is_some_and(|g| g.above_nearby(k, GROUND_NEARBY_VOXELS));
    if cfg.piece_min_voxels > 0 && !first {
        let members: Vec<(u64, usize)> = (0..map.len())
            .filter(|&i| freed[i].is_some() && l_match[i].is_none_or(|m| new[m].key != map.voxels[i].key))
            .filter_map(|i| Some((pack(map.voxels[i].key)?, i)))
            .collect();
        let w: Vec<f32> = members.iter().map(|&(_, i)| weight[i]).collect();
        let gone: Vec<bool> = members.iter().map(|&(_, i)| l_match[i].is_none()).collect();
        let level: Vec<bool> =
            members.iter().map(|&(_, i)| is_level_plane(&map.voxels[i].spread_m2, map.voxels[i].points)).collect();
        let keys: Vec<u64> = members.iter().map(|&(k, _)| k).collect();
        let pieces = piece_weights(&keys, &w, &gone, &level, cfg.piece_min_voxels);
        let strong = cfg.strong_weight();
        // A piece crossed by enough rays with nothing hit near most of it is
        // gone (`piece_gone_share`).
        let gone_piece = |p: &Piece| {
            cfg.piece_gone_share > 0.0
                && f64::from(p.gone_share) >= cfg.piece_gone_share
                && f64::from(p.median_w) >= cfg.piece_gone_min_w
                && p.level_share < PIECE_GONE_MAX_LEVEL_SHARE
        };
        for (&(key, i), p) in members.iter().zip(&pieces) {
            let pw = if gone_piece(p) && above(&unpack(key).0) { p.median_w.max(strong as f32) } else { p.median_w };
            weight[i] = weight[i].max(pw);
            if f64::from(pw) >= strong && p.gone_share >= 0.5 {
                l_match[i] = None;
            }
        }
    }
    // What is left of an object partly seen gone goes with it
    // (`object_share`): the session's strong free evidence, as the lower
    // median of its pieces above the ground level, for the rest of them.
    // A voxel the session did not free has weight 0 until then.
    if cfg.object_share > 0.0 && !first {
        let strong = cfg.strong_weight() as f32;
        let members: Vec<(u64, usize)> = (0..map.len())
            .into_par_iter()
            .filter(|&i| l_match[i].is_none() && !near[i] && above(&map.voxels[i].key.0))
            .filter_map(|i| Some((pack(map.voxels[i].key)?, i)))
            .collect();
        // The new session's voxels above the ground level: the ground it
        // hits around a removed object lies beside every object.
        let new_above: Vec<[i32; 3]> = n_keys.par_iter().map(|&k| unpack(k).0).filter(|k| above(k)).collect();
        let rows: Vec<ObjectMember> = members
            .iter()
            .map(|&(key, i)| ObjectMember { key, strong: freed[i].is_some() && weight[i] >= strong, w: weight[i] })
            .collect();
        let objects = object_weights(&rows, &new_above, cfg);
        for (&(_, i), m) in members.iter().zip(objects) {
            if let Some(m) = m {
                weight[i] = weight[i].max(m);
            }
        }
    }
    let mut out: Vec<MapVoxel> = Vec::with_capacity(map.len() + new.len());
    for (i, (x, m)) in map.voxels.iter().zip(&l_match).enumerate() {
        let mut y = *x;
        let category = match m {
            Some(j) => {
                let n = &new[*j];
                y.eps_g = clamp(bayes(x.eps_g as f64, n.eps_l as f64));
                if n.key == x.key {
                    // The newest observation places the voxel from now on.
                    y.xyz_m = n.xyz_m;
                    y.spread_m2 = n.spread_m2;
                    y.points = n.points;
                    y.owner_session = session;
                    y.owner_keyframe = n.owner_keyframe;
                }
                y.eps_l = n.eps_l;
                y.last_seen_session = session;
                Category::Coexist
            }
            None if freed[i].is_some() => {
                y.eps_g = clamp(bayes(x.eps_g as f64, deleted_factor(weight[i])));
                Category::DeletedOverlap
            }
            None => {
                // Unseen, but part of an object seen gone (`object_share`).
                if weight[i] > 0.0 {
                    y.eps_g = clamp(bayes(x.eps_g as f64, deleted_factor(weight[i])));
                }
                Category::DeletedNonOverlap
            }
        };
        stats.count(category);
        let event = match category {
            Category::DeletedOverlap => true,
            Category::DeletedNonOverlap => x.category != Category::DeletedNonOverlap,
            Category::Coexist => x.category == Category::DeletedOverlap,
            _ => false,
        };
        if event {
            events.push(ChangeEvent {
                session_id: session,
                voxel_id: x.voxel_id,
                xyz_m: y.xyz_m,
                category,
                eps_g_before: Some(x.eps_g),
                eps_g_after: y.eps_g,
            });
        }
        y.category = category;
        y.category_session = session;
        out.push(y);
    }

    // N voxels not in L: coexist next to an L voxel, else emerged.
    let coexist_pts: Vec<[f64; 3]> = out.iter().filter(|x| x.category == Category::Coexist).map(|x| x.xyz_m).collect();
    let coexist_tree = KdTree::build(&coexist_pts);
    let tau_o2 = (cfg.tau_o_m * cfg.tau_o_m) as f32;
    let mut id = next_id;
    for (n, &nk) in new.iter().zip(&n_keys) {
        if l_set.find(nk).is_some() {
            continue;
        }
        let neighbour = if first { None } else { l_set.nearest_within(n.key, r) };
        let (category, eps_g, before) = if first {
            (Category::Initial, clamp(n.eps_l as f64), None)
        } else if let Some(i) = neighbour {
            let prev = map.voxels[i].eps_g;
            (Category::Coexist, clamp(bayes(prev as f64, n.eps_l as f64)), Some(prev))
        } else if coexist_tree.nearest(&to_f32(&n.xyz_m)).is_some_and(|(_, d2)| d2 < tau_o2) {
            let e = cfg.eta * (2.0 - n.omega_hit as f64) * n.eps_l as f64;
            (Category::EmergedOverlap, clamp(e), None)
        } else {
            (Category::EmergedNonOverlap, clamp(n.eps_l as f64), None)
        };
        stats.count(category);
        let voxel = MapVoxel {
            voxel_id: id,
            key: n.key,
            xyz_m: n.xyz_m,
            eps_g,
            eps_l: n.eps_l,
            points: n.points,
            first_session: session,
            last_seen_session: session,
            category,
            category_session: session,
            owner_session: session,
            owner_keyframe: n.owner_keyframe,
            spread_m2: n.spread_m2,
        };
        id += 1;
        if matches!(category, Category::EmergedOverlap | Category::EmergedNonOverlap) {
            events.push(ChangeEvent {
                session_id: session,
                voxel_id: voxel.voxel_id,
                xyz_m: voxel.xyz_m,
                category,
                eps_g_before: before,
                eps_g_after: eps_g,
            });
        }
        out.push(voxel);
    }
    let (map, merged) = LifelongMap::from_voxels(out, v);
    debug_assert_eq!(merged, 0, "L and N keys are disjoint");
    stats.events = events.len();
    stats.lifelong_voxels = map.len();
    stats.static_voxels = map.static_count(cfg.static_threshold);
    (map, events, stats)
}

/// Merges cleaned-map rows (several submaps can hold one voxel) into sorted
/// unique [`NewVoxel`]s: point-weighted centroid, the pooled spread, the
/// owner of the larger share. `omega_hit_at` gives the session's ω_hit per
/// packed key.
pub fn new_voxels(
    rows: impl IntoIterator<Item = CleanedRow>,
    voxel_m: f64,
    omega_hit_at: impl Fn(u64) -> f32,
) -> Vec<NewVoxel> {
    /// Point-weighted sums: Σ n x and Σ n (C + x xᵀ), for the pooled centroid
    /// and covariance.
    struct Acc {
        voxel: NewVoxel,
        best: u32,
        sum: [f64; 3],
        sum_sq: [f64; 6],
    }
    let mut by_key: rustc_hash::FxHashMap<u64, Acc> = rustc_hash::FxHashMap::default();
    for r in rows {
        let Some(k) = crate::evidence::grid::packed_key(&r.xyz_m, voxel_m) else { continue };
        let e = by_key.entry(k).or_insert(Acc {
            voxel: NewVoxel {
                key: unpack(k),
                xyz_m: [0.0; 3],
                eps_l: r.eps_l,
                points: 0,
                owner_keyframe: r.owner_keyframe,
                omega_hit: 0.0,
                spread_m2: UNKNOWN_SPREAD,
            },
            best: 0,
            sum: [0.0; 3],
            sum_sq: [0.0; 6],
        });
        let w = r.points as f64;
        for a in 0..3 {
            e.sum[a] += w * r.xyz_m[a];
        }
        for (j, (p, q)) in SYM3_PAIRS.into_iter().enumerate() {
            e.sum_sq[j] += w * (r.spread_m2[j] as f64 + r.xyz_m[p] * r.xyz_m[q]);
        }
        if r.points > e.best {
            e.best = r.points;
            e.voxel.owner_keyframe = r.owner_keyframe;
        }
        e.voxel.points += r.points;
        e.voxel.eps_l = e.voxel.eps_l.max(r.eps_l);
    }
    let mut out: Vec<(u64, NewVoxel)> = by_key
        .into_iter()
        .map(|(k, e)| {
            let mut n = e.voxel;
            let total = n.points.max(1) as f64;
            n.xyz_m = e.sum.map(|s| s / total);
            n.spread_m2 = std::array::from_fn(|j| {
                (e.sum_sq[j] / total - n.xyz_m[SYM3_PAIRS[j].0] * n.xyz_m[SYM3_PAIRS[j].1]) as f32
            });
            n.omega_hit = omega_hit_at(k);
            (k, n)
        })
        .collect();
    out.sort_unstable_by_key(|(k, _)| *k);
    out.into_iter().map(|(_, n)| n).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::evidence::grid::packed_key;

    fn nv(xyz: [f64; 3], eps_l: f32) -> NewVoxel {
        NewVoxel {
            key: unpack(packed_key(&xyz, 0.2).unwrap()),
            xyz_m: xyz,
            eps_l,
            points: 5,
            owner_keyframe: 0,
            omega_hit: 0.5,
            spread_m2: [1e-4, 0.0, 0.0, 1e-4, 0.0, 1e-6],
        }
    }

    fn sorted(mut v: Vec<NewVoxel>) -> Vec<NewVoxel> {
        v.sort_by_key(|n| pack(n.key).unwrap());
        v
    }

    #[test]
    fn free_support_keyframes_reads_from_toml_and_must_be_positive() {
        let c: ChangeConfig = toml::from_str("free_support_keyframes = 8").unwrap();
        assert_eq!(c.free_support_keyframes, 8);
        assert!(c.validate().is_ok());
        let zero: ChangeConfig = toml::from_str("free_support_keyframes = 0").unwrap();
        assert!(zero.validate().unwrap_err().contains("free_support_keyframes"));
        assert_eq!(ChangeConfig::default().free_support_keyframes, 5);
    }

    #[test]
    fn by_default_four_of_five_keyframes_seeing_a_voxel_empty_take_it_out_in_one_session() {
        let c = ChangeConfig::default();
        assert_eq!(c.deleted_reliability, DeletedReliability::OmegaOrSupport);
        // From ε_g's floor, with one-sided free evidence (ω ≈ 0).
        let after = |free_n: u32, no_return_n: u32| {
            bayes(0.1, deleted_factor(c.deleted_weight(0.0, free_n, no_return_n) as f32))
        };
        let is_static = |eps: f64| eps < c.static_threshold;
        assert!(is_static(after(3, 0)), "{}", after(3, 0));
        assert!(!is_static(after(4, 0)), "{}", after(4, 0));
        assert!(!is_static(after(5, 0)));
        // Beams that returned nothing count the same way, whatever the rest.
        assert!(!is_static(after(1, 4)));
        assert!(is_static(after(1, 3)));
    }

    #[test]
    fn deleted_reliability_reads_from_toml() {
        let c: ChangeConfig = toml::from_str("deleted_reliability = \"omega_or_support\"").unwrap();
        assert_eq!(c.deleted_reliability, DeletedReliability::OmegaOrSupport);
        assert_eq!(c.tau_c_m, 0.4);
        assert!(toml::from_str::<ChangeConfig>("deleted_reliability = \"support\"").is_err());
        let half: ChangeConfig = toml::from_str("deleted_reliability = \"omega_or_half_support\"").unwrap();
        assert_eq!(half.deleted_reliability.of(0.1, 1.0), 0.5);
        assert_eq!(DeletedReliability::Omega.of(0.1, 1.0), 0.1);
        assert_eq!(DeletedReliability::OmegaOrSupport.of(0.1, 0.6), 0.6);
        // Half support: one session cannot leave the static map, two can.
        let once = bayes(0.1, deleted_factor(0.5));
        assert!(once < 0.5 && bayes(once, deleted_factor(0.5)) >= 0.5 - 1e-12);
        // Unreliable free evidence leaves ε_g alone; reliable evidence removes.
        assert!((bayes(0.3, deleted_factor(0.0)) - 0.3).abs() < 1e-12);
        assert!(bayes(0.1, deleted_factor(1.0)) > 0.99);
    }

    #[test]
    fn no_return_support_counts_in_full() {
        let c = ChangeConfig { deleted_reliability: DeletedReliability::OmegaOrHalfSupport, ..Default::default() };
        // Five keyframes of ordinary free evidence from one direction: half
        // support under `omega_or_half_support`.
        assert_eq!(c.deleted_weight(0.2, 5, 0), 0.5);
        // The same five from beams that returned nothing: full support,
        // enough for one session to take the voxel out of the static map.
        assert_eq!(c.deleted_weight(0.2, 5, 5), 1.0);
        assert_eq!(c.deleted_weight(0.2, 5, 2), 0.5);
        assert_eq!(c.deleted_weight(0.9, 5, 2), 0.9);
        assert!(bayes(0.1, deleted_factor(c.deleted_weight(0.2, 5, 5) as f32)) >= c.static_threshold);
        assert!(bayes(0.1, deleted_factor(c.deleted_weight(0.2, 5, 0) as f32)) < c.static_threshold);
    }

    #[test]
    fn bayes_is_elites_update() {
        assert!((bayes(0.5, 0.8) - 0.8).abs() < 1e-12);
        assert!((bayes(0.2, 0.2) - 0.04 / (0.04 + 0.64)).abs() < 1e-12);
        assert_eq!(bayes(0.0, 1.0), 0.5);
    }

    #[test]
    fn config_validation_names_the_key() {
        let bad = ChangeConfig { eps_g_min: 0.9, eps_g_max: 0.1, ..Default::default() };
        assert!(bad.validate().unwrap_err().contains("eps_g_min"));
        let bad = ChangeConfig { tau_o_m: -1.0, ..Default::default() };
        assert!(bad.validate().unwrap_err().contains("tau_o_m"));
        assert!(ChangeConfig::default().validate().is_ok());
    }

    /// Three sessions over a wall and a box: the first initialises, the
    /// second removes the box (seen free) and adds a crate next to the wall
    /// and a shed far away, the third sees the box back.
    #[test]
    fn categories_updates_and_events_follow_the_table() {
        let cfg = ChangeConfig::default();
        let none: &FreeAt<'_> = &|_| None;
        let wall: Vec<NewVoxel> = (0..20).map(|i| nv([i as f64 * 0.2 + 0.1, 0.1, 0.1], 0.1)).collect();
        let boxv = nv([1.1, 1.1, 0.1], 0.1);
        let mut s1 = wall.clone();
        s1.push(boxv);
        let (map, ev, st) = update_map(LifelongMap { voxel_m: 0.2, voxels: vec![] }, &sorted(s1), none, 1, 1, &cfg);
        assert!(ev.is_empty());
        assert_eq!((st.lifelong_voxels, st.static_voxels), (21, 21));
        assert!(map.voxels.iter().all(|x| x.category == Category::Initial && (x.eps_g - 0.1).abs() < 1e-6));

        // Session 2: the wall (one voxel seen one voxel off), no box (freed),
        // a crate 1 m from the wall, a shed 30 m away.
        let mut s2: Vec<NewVoxel> = wall[1..].to_vec();
        s2.push(nv([0.1, 0.3, 0.1], 0.1)); // wall's first voxel, seen one up in y
        s2.push(nv([2.1, 1.3, 0.1], 0.2)); // crate
        s2.push(nv([30.1, 30.1, 0.1], 0.1)); // shed
        let box_key = pack(boxv.key).unwrap();
        let freed: &FreeAt<'_> = &move |k| (k == box_key).then_some((4, 0.95));
        let (map, ev, st) = update_map(map, &sorted(s2), freed, 2, 100, &cfg);
        assert_eq!(st.deleted_overlap, 1);
        assert_eq!(st.deleted_non_overlap, 0);
        assert_eq!((st.emerged_overlap, st.emerged_non_overlap), (1, 1));
        // 20 wall voxels coexist, plus the off-by-one wall voxel joining as coexist.
        assert_eq!(st.coexist, 21);
        let at = |xyz: [f64; 3]| *map.voxels.iter().find(|x| x.key == unpack(packed_key(&xyz, 0.2).unwrap())).unwrap();
        let b = at([1.1, 1.1, 0.1]);
        assert_eq!(b.category, Category::DeletedOverlap);
        assert!((b.eps_g as f64 - bayes(0.1, 0.975)).abs() < 1e-6, "{}", b.eps_g);
        assert!(b.eps_g > 0.5, "reliable free evidence takes the box out of the static map");
        let crate_ = at([2.1, 1.3, 0.1]);
        assert_eq!(crate_.category, Category::EmergedOverlap);
        assert!((crate_.eps_g as f64 - 2.0 * 1.5 * 0.2).abs() < 1e-6);
        assert_eq!(at([30.1, 30.1, 0.1]).category, Category::EmergedNonOverlap);
        let cats: Vec<Category> = ev.iter().map(|e| e.category).collect();
        assert_eq!(ev.len(), 3, "{cats:?}");
        assert!(ev.iter().all(|e| e.session_id == 2));
        assert_eq!(ev.iter().filter(|e| e.eps_g_before.is_none()).count(), 2);

        // Session 3: the box is back; the shed is not seen and not freed.
        let mut s3 = wall.clone();
        s3.push(boxv);
        s3.push(nv([2.1, 1.3, 0.1], 0.1));
        let (map, ev, st) = update_map(map, &sorted(s3), none, 3, 200, &cfg);
        assert_eq!(st.deleted_non_overlap, 1, "the shed (the off-by-one wall voxel neighbours the wall)");
        let back: Vec<&ChangeEvent> = ev.iter().filter(|e| e.category == Category::Coexist).collect();
        assert_eq!(back.len(), 1);
        assert_eq!(back[0].voxel_id, b.voxel_id);
        assert_eq!(at_id(&map, b.voxel_id).category, Category::Coexist);
        let shed = at_id_key(&map, [30.1, 30.1, 0.1]);
        assert!(ev.iter().any(|e| e.category == Category::DeletedNonOverlap && e.voxel_id == shed));
        // A second unseen session records no new event for the shed.
        let (_, ev, _) = update_map(map, &sorted(wall.clone()), none, 4, 300, &cfg);
        assert!(!ev.iter().any(|e| e.voxel_id == shed), "{ev:?}");
    }

    /// A pallet stood on the ground in session 1 and is gone in session 2:
    /// its lowest layer neighbours the ground, which session 2 hits. With
    /// `off_surface_m`, a freed voxel off the ground's plane is deleted; one
    /// on it (the ground seen a little higher), one next to a voxel that is
    /// no plane, and one not freed stay coexist. Without, all coexist.
    #[test]
    fn voxels_off_the_plane_of_their_only_neighbours_can_be_deleted() {
        let flat = [1e-3, 0.0, 0.0, 1e-3, 0.0, 1e-6];
        let ground = |x: f64, y: f64, z: f64| NewVoxel { points: 20, spread_m2: flat, ..nv([x, y, z], 0.1) };
        let s2: Vec<NewVoxel> = (0..10)
            .flat_map(|i| (0..10).map(move |j| (i as f64 * 0.2 + 0.1, j as f64 * 0.2 + 0.1)))
            .map(|(x, y)| ground(x, y, if x < 1.0 { 0.05 } else { 0.15 }))
            .chain([NewVoxel { points: 20, spread_m2: [1e-3, 0.0, 0.0, 1e-3, 0.0, 1e-3], ..nv([3.1, 3.1, 0.1], 0.1) }])
            .collect();
        let pallet = [1.1, 1.1, 0.3]; // 0.15 m over the ground at x ≥ 1
        let kept_pallet = [1.5, 1.5, 0.3]; // not freed
        let ground_up = [1.7, 0.5, 0.25]; // 0.10 m over the ground: on it
        let by_bush = [3.1, 3.1, 0.3]; // over a voxel that is no plane
        let s1: Vec<NewVoxel> =
            s2.iter().copied().chain([pallet, kept_pallet, ground_up, by_bush].map(|p| nv(p, 0.1))).collect();
        let freed_keys: Vec<u64> = [pallet, ground_up, by_bush].iter().map(|p| packed_key(p, 0.2).unwrap()).collect();
        let freed: &FreeAt<'_> = &move |k| freed_keys.contains(&k).then_some((5, 1.0));
        let run = |off_surface_m: f64| {
            let cfg = ChangeConfig { off_surface_m, ..ChangeConfig::default() };
            let (map, ..) =
                update_map(LifelongMap { voxel_m: 0.2, voxels: vec![] }, &sorted(s1.clone()), freed, 1, 1, &cfg);
            let (map, ..) = update_map(map, &sorted(s2.clone()), freed, 2, 1000, &cfg);
            [pallet, kept_pallet, ground_up, by_bush].map(|p| at_id_category(&map, p))
        };
        use Category::{Coexist, DeletedOverlap};
        assert_eq!(run(0.12), [DeletedOverlap, Coexist, Coexist, Coexist]);
        assert_eq!(run(0.0), [Coexist; 4]);
        // Farther than the pallet is off the ground: coexist again.
        assert_eq!(run(0.2)[0], Coexist);
        let bad = ChangeConfig { off_surface_m: -0.1, ..ChangeConfig::default() };
        assert!(bad.validate().unwrap_err().contains("off_surface_m"));
    }

    #[test]
    fn strong_weight_is_what_takes_a_floor_voxel_out_in_one_session() {
        let c = ChangeConfig::default();
        let w = c.strong_weight();
        assert!((w - 0.8).abs() < 1e-12, "{w}");
        assert!(bayes(c.eps_g_min, deleted_factor(w as f32 + 1e-6)) >= c.static_threshold);
        assert!(bayes(c.eps_g_min, deleted_factor(w as f32 - 1e-3)) < c.static_threshold);
    }

    #[test]
    fn pieces_join_through_26_neighbours_and_give_their_lower_median() {
        let key = |x: i32, y: i32, z: i32| pack(VoxelKey([x, y, z])).unwrap();
        // Piece A: 12 voxels along a diagonal staircase (each touches the
        // next only by an edge or a corner), 7 strong and 5 weak; piece B:
        // 3 voxels far away, all strong, too small.
        let mut items: Vec<(u64, f32, bool)> = (0..12)
            .map(|i| (key(i, i / 2, i / 3), if i % 2 == 0 || i == 11 { 1.0 } else { 0.2 }, i < 9))
            .chain((0..3).map(|i| (key(100 + i, 0, 0), 1.0, true)))
            .collect();
        items.sort_by_key(|t| t.0);
        let keys: Vec<u64> = items.iter().map(|t| t.0).collect();
        let w: Vec<f32> = items.iter().map(|t| t.1).collect();
        let gone: Vec<bool> = items.iter().map(|t| t.2).collect();
        let level: Vec<bool> = items.iter().map(|t| t.0 == key(0, 0, 0)).collect();
        let pieces = piece_weights(&keys, &w, &gone, &level, 10);
        let of = |x: i32| pieces[keys.binary_search(&key(x, x / 2, x / 3)).unwrap()];
        // 12 weights, 5 of 0.2 and 7 of 1.0: the lower median (6th) is 1.0.
        for i in 0..12 {
            assert_eq!(of(i).median_w, 1.0, "voxel {i}");
            assert!((of(i).gone_share - 0.75).abs() < 1e-6);
            assert!((of(i).level_share - 1.0 / 12.0).abs() < 1e-6);
        }
        let small = pieces[keys.binary_search(&key(100, 0, 0)).unwrap()];
        assert_eq!(small, Piece::default(), "a piece under min_voxels says nothing");
        // With one more weak voxel than strong, the median is weak.
        let w6: Vec<f32> = (0..12).map(|i| if i < 6 { 0.2 } else { 1.0 }).collect();
        let line: Vec<u64> = (0..12).map(|i| key(i, 0, 0)).collect();
        assert_eq!(piece_weights(&line, &w6, &[true; 12], &[false; 12], 10)[0].median_w, 0.2);
        // Two voxels two apart are two pieces.
        let apart = [key(0, 0, 0), key(2, 0, 0)];
        assert_eq!(piece_weights(&apart, &[1.0; 2], &[true; 2], &[false; 2], 2), vec![Piece::default(); 2]);
    }

    /// A crate of 4 × 4 × 3 voxels stands on the ground in session 1 and is
    /// gone in session 2, which sees its top and sides empty from many
    /// keyframes and its lowest layer (next to the ground it hits, on that
    /// ground's plane within `off_surface_m`, so coexist by ELite's rule) and
    /// a few voxels above from one or two. Judged voxel by voxel, those stay
    /// static; judged as a piece, the whole crate leaves. A wall seen one
    /// voxel over in session 2, its old layer freed from many keyframes, is
    /// a piece of voxels the session's own wall explains: it stays. A small
    /// weakly freed cluster stays too.
    #[test]
    fn a_piece_seen_empty_with_confidence_leaves_as_a_whole() {
        let flat = [1e-3, 0.0, 0.0, 1e-3, 0.0, 1e-6];
        let upright = [1e-3, 0.0, 0.0, 1e-6, 0.0, 1e-3]; // a plane of normal y
        let at = |x: i32, y: i32, z: f64, spread: Sym3| NewVoxel {
            points: 20,
            spread_m2: spread,
            ..nv([x as f64 * 0.2 + 0.1, y as f64 * 0.2 + 0.1, z], 0.1)
        };
        let ground: Vec<NewVoxel> = (0..12).flat_map(|x| (0..12).map(move |y| at(x, y, 0.15, flat))).collect();
        let crate_: Vec<NewVoxel> =
            (4..8).flat_map(|x| (4..8).flat_map(move |y| [0.25, 0.5, 0.7].map(|z| at(x, y, z, flat)))).collect();
        // The old layer at y = 6.1 m (key 30), the new one 0.11 m over (key 31).
        let wall = |y: f64| {
            (20..34)
                .flat_map(move |x| {
                    [0.9, 1.1].map(|z| NewVoxel { xyz_m: [x as f64 * 0.2 + 0.1, y, z], ..at(x, 0, z, upright) })
                })
                .map(|n| NewVoxel { key: unpack(packed_key(&n.xyz_m, 0.2).unwrap()), ..n })
        };
        let cluster: Vec<NewVoxel> = (0..4).map(|i| at(40 + i, 0, 0.5, flat)).collect();
        let s1: Vec<NewVoxel> = ground.iter().copied().chain(crate_.clone()).chain(wall(6.1)).chain(cluster).collect();
        let s2: Vec<NewVoxel> = ground.iter().copied().chain(wall(6.21)).collect();
        let key_of = |n: &NewVoxel| pack(n.key).unwrap();
        let weak: Vec<u64> =
            crate_.iter().enumerate().filter(|(i, n)| n.xyz_m[2] < 0.3 || i % 9 == 1).map(|(_, n)| key_of(n)).collect();
        let strong: Vec<u64> =
            crate_.iter().map(key_of).filter(|k| !weak.contains(k)).chain(wall(6.1).map(|n| key_of(&n))).collect();
        let cluster_keys: Vec<u64> = (0..4).map(|i| key_of(&at(40 + i, 0, 0.5, flat))).collect();
        let free: &FreeAt<'_> = &move |k| {
            if strong.contains(&k) {
                Some((5, 1.0))
            } else if weak.contains(&k) || cluster_keys.contains(&k) {
                Some((1, 0.3))
            } else {
                None
            }
        };
        let run = |piece_min_voxels: u32| {
            let cfg = ChangeConfig { piece_min_voxels, object_share: 0.0, ..ChangeConfig::default() };
            let (map, ..) =
                update_map(LifelongMap { voxel_m: 0.2, voxels: vec![] }, &sorted(s1.clone()), free, 1, 1, &cfg);
            let (map, _, stats) = update_map(map, &sorted(s2.clone()), free, 2, 10_000, &cfg);
            let is_static = |n: &NewVoxel| {
                let x = map.voxels.iter().find(|x| x.key == n.key).unwrap();
                (x.eps_g as f64) < cfg.static_threshold
            };
            let crate_left = crate_.iter().filter(|n| is_static(n)).count();
            let wall_kept = wall(6.1).filter(|n| is_static(n)).count();
            let cluster_kept = (0..4).filter(|&i| is_static(&at(40 + i, 0, 0.5, flat))).count();
            (crate_left, wall_kept, cluster_kept, stats)
        };
        let (left, wall_kept, cluster_kept, stats) = run(0);
        // Ground, the crate's lowest layer, the wall's old layer and its new
        // one (joining next to the old).
        assert_eq!(stats.coexist, ground.len() + 16 + 28 + 28);
        assert_eq!(left, 16 + 6, "lowest layer (coexist) and the weakly freed voxels above it");
        assert_eq!((wall_kept, cluster_kept), (28, 4));
        let (left, wall_kept, cluster_kept, stats) = run(10);
        assert_eq!(left, 0, "the crate leaves as a whole");
        assert_eq!(stats.deleted_overlap, 48 + 4);
        assert_eq!((wall_kept, cluster_kept), (28, 4), "the wall's old layer and the small cluster stay");
    }

    /// A van (5 × 2 × 3 voxels, 0.6 m above the ground) is gone in session
    /// 2, whose rays crossed its space from one direction, two keyframes per
    /// voxel (w 0.4), and hit nothing near it but the ground. Voxel by voxel
    /// it stays static; as a piece with nothing hit near it, it leaves
    /// (`piece_gone_share`). Crossed by one keyframe per voxel (w 0.2), it
    /// stays; so does a wall the session sees again one voxel over, and a
    /// strip of a slab's underside (level planes) crossed the same way,
    /// which rays rising under the slab graze before they hit it farther in.
    #[test]
    fn a_piece_crossed_by_rays_with_nothing_hit_near_it_is_gone() {
        let at = |x: i32, y: i32, z: i32| nv([x as f64 * 0.2 + 0.1, y as f64 * 0.2 + 0.1, z as f64 * 0.2 + 0.1], 0.1);
        let ground: Vec<NewVoxel> = (0..12).flat_map(|x| (0..12).map(move |y| at(x, y, 0))).collect();
        // The van's points spread every way (its sides, its corners).
        let van: Vec<NewVoxel> = (3..8)
            .flat_map(|x| (4..6).flat_map(move |y| (3..6).map(move |z| at(x, y, z))))
            .map(|n| NewVoxel { spread_m2: [1e-3, 0.0, 0.0, 1e-3, 0.0, 1e-3], ..n })
            .collect();
        let wall = |y: i32| (20..30).flat_map(move |x| (1..4).map(move |z| at(x, y, z)));
        // The slab 4 m over a floor both sessions hit; `level`: its points
        // lie on a level plane (as they do), else spread every way.
        let floor: Vec<NewVoxel> = (38..52).flat_map(|x| (0..8).map(move |y| at(x, y, 0))).collect();
        let slab = |level: bool| -> Vec<NewVoxel> {
            (40..50)
                .flat_map(|x| (0..6).map(move |y| at(x, y, 20)))
                .map(|n| if level { n } else { NewVoxel { spread_m2: [1e-3, 0.0, 0.0, 1e-3, 0.0, 1e-3], ..n } })
                .collect()
        };
        let s2: Vec<NewVoxel> = ground.iter().chain(&floor).copied().chain(wall(11)).collect();
        let crossed: Vec<u64> =
            van.iter().chain(&wall(10).collect::<Vec<_>>()).chain(&slab(true)).map(|n| pack(n.key).unwrap()).collect();
        let run_slab = |piece_gone_share: f64, w: f32, level: bool| {
            let s1: Vec<NewVoxel> =
                ground.iter().chain(&floor).copied().chain(van.clone()).chain(wall(10)).chain(slab(level)).collect();
            let slab = slab(level);
            let crossed = &crossed;
            let free = move |k: u64| crossed.contains(&k).then_some((2, w));
            let cfg = ChangeConfig { piece_gone_share, object_share: 0.0, ..ChangeConfig::default() };
            let (map, ..) =
                update_map(LifelongMap { voxel_m: 0.2, voxels: vec![] }, &sorted(s1.clone()), &free, 1, 1, &cfg);
            let (map, ..) = update_map(map, &sorted(s2.clone()), &free, 2, 10_000, &cfg);
            let left = |of: &[NewVoxel]| {
                of.iter()
                    .filter(|n| {
                        (map.voxels.iter().find(|x| x.key == n.key).unwrap().eps_g as f64) < cfg.static_threshold
                    })
                    .count()
            };
            (left(&van), left(&wall(10).collect::<Vec<_>>()), left(&slab))
        };
        let run = |piece_gone_share: f64, w: f32| run_slab(piece_gone_share, w, true);
        assert_eq!(run(0.8, 0.4), (0, 30, 60), "the van leaves as a piece; the wall and the slab stay");
        assert_eq!(run(0.0, 0.4), (30, 30, 60), "voxel by voxel all stay");
        assert_eq!(run(0.8, 0.2), (30, 30, 60), "one keyframe per voxel is not enough");
        assert_eq!(run_slab(0.8, 0.4, false), (0, 30, 0), "the same layer as no plane leaves with the van");
    }

    /// A pipe stack (6 × 3 voxels, four layers) stood on ground no session
    /// saw beneath it; session 2 sees the ground around, its near face and
    /// top empty with confidence (30 of the 54 voxels above the ground
    /// level) and never reaches the rest. Voxel by voxel, the unseen 24 stay
    /// static; with `object_share`, what is left of the stack goes with it.
    /// A wall session 2 does not see at all, 5 of its voxels freed (a few
    /// rays grazing it), stays whole; so does the ground. A box replaced by
    /// another that session 2 sees from two sides only keeps its unseen
    /// part: 21 of the new box's voxels lie in the box of its 12-voxel piece.
    #[test]
    fn what_is_left_of_an_object_mostly_seen_gone_goes_with_it() {
        let at = |x: i32, y: i32, z: i32| nv([x as f64 * 0.2 + 0.1, y as f64 * 0.2 + 0.1, z as f64 * 0.2 + 0.1], 0.1);
        let under_stack = |x: i32, y: i32| (4..10).contains(&x) && (4..7).contains(&y);
        let ground: Vec<NewVoxel> = (0..20)
            .flat_map(|x| (0..20).map(move |y| (x, y)))
            .filter(|&(x, y)| !under_stack(x, y))
            .map(|(x, y)| at(x, y, 0))
            .collect();
        let stack: Vec<NewVoxel> =
            (4..10).flat_map(|x| (4..7).flat_map(move |y| (1..5).map(move |z| at(x, y, z)))).collect();
        let wall: Vec<NewVoxel> = (30..40).flat_map(|x| (1..9).map(move |z| at(x, 10, z))).collect();
        // A box of 4 × 4 voxels that session 2 finds replaced by another, of
        // which it hits two faces (y key 14 and x key 14).
        let old_box: Vec<NewVoxel> =
            (14..18).flat_map(|x| (14..18).flat_map(move |y| (1..5).map(move |z| at(x, y, z)))).collect();
        let new_face: Vec<NewVoxel> = (1..5)
            .flat_map(|z| (14..18).map(move |x| at(x, 14, z)).chain((15..18).map(move |y| at(14, y, z))))
            .collect();
        let s1: Vec<NewVoxel> = ground.iter().chain(&stack).chain(&wall).chain(&old_box).copied().collect();
        let s2: Vec<NewVoxel> = ground.iter().chain(&new_face).copied().collect();
        let key_of = |n: &NewVoxel| pack(n.key).unwrap();
        // The stack's near face (y key 4) and top (z key 4) above the ground
        // level; five of the wall's voxels; the old box's voxels two behind
        // the new front face and two beside the new side face.
        let strong: Vec<u64> = stack
            .iter()
            .filter(|n| n.key.0[2] >= 2 && (n.key.0[1] == 4 || n.key.0[2] == 4))
            .chain(wall.iter().filter(|n| n.key.0[2] == 5 && n.key.0[0] < 35))
            .chain(old_box.iter().filter(|n| {
                let [x, y, z] = n.key.0;
                z >= 2 && y == 16 && x >= 16
            }))
            .map(key_of)
            .collect();
        assert_eq!(strong.len(), 30 + 5 + 6);
        let free: &FreeAt<'_> = &move |k| strong.contains(&k).then_some((5, 1.0));
        let run = |object_share: f64, object_max_new: f64| {
            let cfg = ChangeConfig { object_share, object_max_new, ..ChangeConfig::default() };
            let (map, ..) =
                update_map(LifelongMap { voxel_m: 0.2, voxels: vec![] }, &sorted(s1.clone()), free, 1, 1, &cfg);
            let (map, _, stats) = update_map(map, &sorted(s2.clone()), free, 2, 10_000, &cfg);
            let left = |of: &[NewVoxel]| {
                of.iter()
                    .filter(|n| n.key.0[2] >= 2)
                    .filter(|n| {
                        (map.voxels.iter().find(|x| x.key == n.key).unwrap().eps_g as f64) < cfg.static_threshold
                    })
                    .count()
            };
            (left(&stack), left(&wall), left(&old_box), stats)
        };
        // The old box's voxels next to the new faces (coexist) stay.
        let kept = 12 * 3;
        let (stack_left, wall_left, box_left, stats) = run(0.0, 0.5);
        assert_eq!((stack_left, wall_left), (24, 65), "voxel by voxel the unseen part of the stack stays");
        assert_eq!(box_left, kept + 6);
        assert_eq!(stats.deleted_overlap, 35 + 6);
        let (stack_left, wall_left, box_left, stats) = run(0.5, 0.5);
        assert_eq!(stack_left, 0, "the stack leaves whole");
        assert_eq!(wall_left, 70 - 5, "the wall stays but for the voxels seen empty");
        assert_eq!(box_left, kept + 6, "21 new voxels by a piece of 12: nothing inferred");
        assert_eq!(stats.deleted_overlap, 35 + 6, "the categories say what the session saw");
        assert_eq!(run(0.5, 2.0).2, kept, "allowing that many new voxels, the old box's unseen part leaves");
        // A share above what the stack shows keeps its unseen part.
        assert_eq!(run(0.6, 0.5).0, 24);
    }

    #[test]
    fn object_pieces_need_the_share_the_size_and_no_new_voxels_inside() {
        let line: Vec<u64> = (0..10).map(|x| pack(VoxelKey([x, 0, 5])).unwrap()).collect();
        let rows = |strong: &dyn Fn(usize) -> bool| -> Vec<ObjectMember> {
            (0..10).map(|i| ObjectMember { key: line[i], strong: strong(i), w: i as f32 / 8.0 }).collect()
        };
        let first5 = rows(&|i| i < 5);
        let cfg = |f: &dyn Fn(&mut ChangeConfig)| {
            let mut c = ChangeConfig {
                piece_min_voxels: 1,
                object_max_voxels: 10,
                object_max_new: 0.25,
                ..ChangeConfig::default()
            };
            f(&mut c);
            c
        };
        let got = object_weights(&first5, &[], &cfg(&|_| {}));
        assert!(got.iter().all(|&m| m == Some(0.25)), "lower median of the strong ones: {got:?}");
        let none = |c: ChangeConfig, rows: &[ObjectMember], new: &[[i32; 3]]| {
            object_weights(rows, new, &c).iter().all(Option::is_none)
        };
        assert!(none(cfg(&|c| c.object_share = 0.6), &first5, &[]), "under the share");
        assert!(none(cfg(&|c| c.object_max_voxels = 9), &first5, &[]), "over the size");
        assert!(none(cfg(&|c| c.piece_min_voxels = 11), &first5, &[]), "under the size");
        assert!(none(cfg(&|c| c.object_share = 0.0), &rows(&|_| false), &[]), "nothing strong");
        // New voxels in the box grown by 2 voxels (corners included): three
        // are too many for a piece of 10 at 0.25, two are not; voxels 3
        // off the box do not count.
        let new = [[3, 2, 5], [11, 0, 7], [-2, -2, 3]];
        assert!(none(cfg(&|_| {}), &first5, &new), "three new voxels inside");
        assert!(!none(cfg(&|_| {}), &first5, &new[..2]), "two new voxels inside");
        assert!(!none(cfg(&|_| {}), &first5, &[[3, 3, 5], [12, 0, 5], [0, 0, 8], [0, 0, 2]]), "all outside");
        // A piece nearly all strong leaves whatever the session hit in its
        // box (`object_sure_share`); one short of the share does not.
        let sure = |c: &mut ChangeConfig| c.object_sure_share = 0.9;
        assert!(!none(cfg(&sure), &rows(&|i| i < 9), &new), "9 of 10 strong: sure");
        assert!(none(cfg(&sure), &rows(&|i| i < 8), &new), "8 of 10 strong: the box test applies");
        assert!(none(cfg(&|c| c.object_sure_share = 1.0), &rows(&|_| true), &new), "1.0 turns it off");
    }

    fn at_id_category(map: &LifelongMap, xyz: [f64; 3]) -> Category {
        map.voxels.iter().find(|x| x.key == unpack(packed_key(&xyz, 0.2).unwrap())).unwrap().category
    }

    fn at_id_key(map: &LifelongMap, xyz: [f64; 3]) -> i64 {
        map.voxels.iter().find(|x| x.key == unpack(packed_key(&xyz, 0.2).unwrap())).unwrap().voxel_id
    }

    fn at_id(map: &LifelongMap, id: i64) -> MapVoxel {
        *map.voxels.iter().find(|x| x.voxel_id == id).unwrap()
    }

    #[test]
    fn new_voxels_merge_submaps_by_key() {
        let row = |xyz_m, eps_l, points, owner_keyframe, spread_m2| CleanedRow {
            xyz_m,
            eps_l,
            points,
            owner_keyframe,
            spread_m2,
        };
        let flat = [1e-4, 0.0, 0.0, 1e-4, 0.0, 0.0];
        let rows = vec![
            row([0.05, 0.05, 0.05], 0.1f32, 2u32, 3u32, flat),
            row([0.15, 0.05, 0.05], 0.3, 6, 9, flat),
            row([1.0, 1.0, 1.0], 0.1, 1, 1, UNKNOWN_SPREAD),
        ];
        let n = new_voxels(rows, 0.2, |_| 0.7);
        assert_eq!(n.len(), 2);
        let a = n.iter().find(|x| x.key == VoxelKey([0, 0, 0])).unwrap();
        assert_eq!((a.points, a.owner_keyframe), (8, 9));
        assert!((a.xyz_m[0] - 0.125).abs() < 1e-12);
        assert_eq!(a.eps_l, 0.3);
        assert_eq!(a.omega_hit, 0.7);
        // Pooled: within-row 1e-4 plus the spread of the two centroids along
        // x (2 at -0.075, 6 at +0.025: variance 0.001875).
        assert!((a.spread_m2[0] - (1e-4 + 0.001875)).abs() < 1e-7, "{:?}", a.spread_m2);
        assert!((a.spread_m2[3] - 1e-4).abs() < 1e-7 && a.spread_m2[5].abs() < 1e-7);
        let b = n.iter().find(|x| x.key != VoxelKey([0, 0, 0])).unwrap();
        assert!(b.spread_m2.iter().all(|c| c.is_nan()), "an unknown spread stays unknown");
    }
}
