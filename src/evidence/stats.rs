//! Per-voxel directional evidence and the local ephemerality ε_l
//! (MATH.md §6, eqs. 4-8).
//!
//! A voxel keeps hit and free evidence apart, each as the number of observing
//! keyframes `n`, the weight `Q = Σ q` and the direction matrix
//! `M = Σ q u uᵀ` (six numbers, upper triangle). The eigenvalues of `M` say
//! how many distinct directions the voxel was seen from: one direction gives
//! `M ≈ Q u uᵀ` (rank 1, α ≈ 0), many give a spread spectrum (α near 1).

use serde::{Deserialize, Serialize};

/// The evidence stage's parameters (MATH.md §6; every default is a choice
/// there, not a measured value).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EvidenceConfig {
    /// Edge of the evidence voxels.
    pub voxel_size_m: f64,
    /// Range up to which a keyframe's weight q is 1 (eq. 4).
    pub r0_m: f64,
    /// Range scale of q's decay past `r0_m` (eq. 4).
    pub rs_m: f64,
    /// α at which the direction factor of ω saturates (eq. 5).
    pub alpha0: f64,
    /// Weight Q at which the count factor of ω saturates (eq. 5).
    pub n0: f64,
    /// Observing keyframes at which the support s saturates (eq. 7).
    /// MATH.md's choice is 5; seam uses 2 with `free_clearance_m` 0.2 m (was
    /// 3 and 0.3 m). Point-wise F1 of `bench/dor_vs_dufomap.py`, a run with
    /// the old defaults → one with the new: SemanticKITTI 04 85.74 → 89.13
    /// (PR 99.74 → 99.45), 08 10.59 → 14.92 (PR 99.53 → 99.21), against
    /// DUFOMap's default 86.87 and 12.88 in the run with the new; the bench's
    /// simulated 60-keyframe sessions (seed 1) OS1-64 84.5 → 88.2, HDL-64E
    /// 89.3 → 91.3, VLP-16 77.7 → 83.7, HDL-32E 79.4 → 84.8, Avia 86.8 →
    /// 91.2, PR ≥ 99.0 % except the Avia's (98.06 → 97.78 %). Each of the two
    /// changes alone gets about half of it. Change detection on the demo site
    /// (`seam eval changes`): permanent structure static 99.35 → 99.29 %,
    /// removed objects left 22.39 → 21.21 %, mover voxels in the static map
    /// 0.25 → 0.12 %; on the 150-keyframe sites of `DeletedReliability`'s
    /// table HDL-64E 99.41 / 13.92 / 0.56 → 99.39 / 12.34 / 0.33, HDL-32E
    /// 99.45 / 18.37 / 0.50 → 99.45 / 16.58 / 0.28, VLP-16 99.31 / 23.36 /
    /// 0.46 → 99.33 / 21.13 / 0.28, Avia 98.29 / 48.00 / 0.54 → 98.32 /
    /// 47.41 / 0.40.
    pub n_sat: u32,
    /// Floor of ω's direction factor: `ω = (ω_min + (1 − ω_min)·clip(α/α0, 0, 1))·min(1, Q/n0)`.
    /// 0 is eq. 5. With 0, evidence from one direction weighs nothing, and
    /// a voxel whose hits and frees each came from one direction has
    /// `h + f = 0`.
    pub omega_floor: f64,
    /// A voxel is dynamic when its clamped ε_l exceeds this.
    pub tau_dyn: f64,
    /// Lower clamp of ε_l before the Bayes update (0 would be absorbing).
    pub eps_min: f64,
    /// Upper clamp of ε_l before the Bayes update (1 would be absorbing).
    pub eps_max: f64,
    /// Pseudo-count c in `ε_l = s·f / (h + f + c)` (eq. 8 regularised).
    /// 0 is the paper's formula. MATH.md §6 warns that with c = 0 a surface
    /// hit from one direction (ω_hit = 0) is removed by any free evidence at
    /// all; the value of c is to be measured on real data (PR of DOR), and
    /// this default changed only with the numbers that justify it.
    pub pseudo_count: f64,
    /// A keyframe does not free a voxel it hit, nor one within this many
    /// voxels (Chebyshev) of a voxel it hit: a ray grazing a surface the same
    /// scan sees is not evidence that the surface is gone. 0 keeps only the
    /// first rule. (DUFOMap's hit extension and "no ray pass-through hits"
    /// play the same role.) Hits at the ground level beneath a voxel do not
    /// count unless `ground_hits_guard`.
    pub free_guard_voxels: u32,
    /// The guard widens with range: a voxel at range r is guarded by the
    /// keyframe's hits within `max(free_guard_voxels, ⌈r·θ / voxel⌉)` voxels,
    /// θ this angle (0.4°: 2 voxels past 29 m, 3 past 57 m at 0.2 m). A ray
    /// passes a surface the same scan hits at a lateral distance that grows
    /// with range for the same angular error (beam spacing and divergence,
    /// the pose's rotation error), so far walls, fences and trees were freed
    /// by rays grazing them one voxel beyond the fixed guard. 0: the fixed
    /// guard only.
    ///
    /// One run of `bench/dor_vs_dufomap.py` (store poses; point-wise PR /
    /// F1, 0 → 0.4°; the 0 column is the previous run of the same bench):
    /// SemanticKITTI 04 99.27 / 92.86 → 99.51 / 92.75, 08 99.02 / 17.03 →
    /// 99.27 / 17.03; simulated 60-keyframe sessions (seed 1) OS1-64 98.94 /
    /// 89.20 → 99.41 / 89.38, HDL-64E 99.43 / 92.57 → 99.68 / 92.67, VLP-16
    /// 99.13 / 84.18 → 99.36 / 84.24, HDL-32E 99.63 / 85.33 → 99.75 / 85.35,
    /// Avia 97.70 / 91.98 → 99.25 / 92.47. Pose error is rotation too, so
    /// store poses gain most. With `examples/dor_probe` (true poses), 0.3°
    /// and 0.5°: Avia PR 99.27 / 99.61 %, SemanticKITTI 04 F1 92.89 /
    /// 92.66, 08 17.03 / 16.80. `seam eval changes` on the 5 × 150-keyframe
    /// sites (permanent kept / removed left, 0 → 0.4°): HDL-64E 99.25 / 7.90
    /// → 99.32 / 8.21 %, OS1-64 99.22 / 17.28 → 99.32 / 17.66 %, Avia 98.16 /
    /// 44.91 → 99.08 / 45.97 %. Keeping the fixed guard on earlier
    /// sessions' map voxels this session does not occupy gave back little of
    /// the removed objects and lost permanent structure (HDL-64E 99.26 /
    /// 8.07 %, Avia 98.39 / 45.53 %). Reprojection against recomputation
    /// (`examples/reproject_check`) rose too: OS1-64 93.34 → 96.02 %.
    pub free_guard_deg: f64,
    /// Earlier sessions' map voxels that this session's points do not
    /// occupy, and whose own points cannot have been ground (at least three,
    /// and not a plane within about 37° of level: `MapPatch::maybe_ground`),
    /// are freed next to a keyframe's own hits (no `free_guard_voxels`) and
    /// down to `vacated_clearance_m` above a downward ray's endpoint (instead
    /// of `free_clearance_m`). No point of the session lies in them, so only
    /// change detection sees this; DOR's labels cannot change.
    ///
    /// Why: a removed container's or pallet's lowest layer, 0.2-0.4 m above
    /// the ground the next session hits, was never freed. Every ray crossing
    /// it ends on that ground just behind, so the clearance dropped it, and
    /// the guard dropped it next to the keyframe's own ground hits. Both are
    /// there so that grazing rays do not free the ground; ground-like voxels
    /// keep them: a vacated voxel whose points were a level plane, or too
    /// few to tell, is treated as ground.
    ///
    /// Measured with `seam eval changes` on the 5 × 150-keyframe sites of
    /// `DeletedReliability`'s table (seed 3; OS1-64 the demo site, seed 1),
    /// permanent structure kept static / removed objects' voxels left static,
    /// off → on: OS1-64 99.27 / 18.78 → 99.25 / 17.72 %, HDL-64E 99.33 /
    /// 9.44 → 99.27 / 8.12 %, HDL-32E 99.42 / 14.63 → 99.40 / 13.01 %,
    /// VLP-16 99.32 / 19.24 → 99.31 / 17.93 %, Avia 98.31 / 47.04 → 98.26 /
    /// 45.72 %; object changes with events in the right session, after:
    /// 91.4 % (Avia) to 98.9 %. Variants tried on the HDL-64E site's last
    /// session (permanent voxels lost / removed-object voxels gained, against
    /// 265 / 179 for this rule): every vacated voxel, no ground test, 3,245 /
    /// 225 (most of the loss ground); only level planes kept as ground, not
    /// voxels of fewer than three points, 986 / 220; without the guard but
    /// with the usual clearance, 12 gained; a clearance of 0 instead of
    /// 0.05 m, 338 / 193. The evidence step takes about 1 s longer on a
    /// 150-keyframe HDL-64E session (24 s).
    ///
    /// Also tried and not taken: level planes that are not at the map's
    /// ground level (`surface::map_ground_keys`: the top of a rebar bundle
    /// or a pallet whose ground was never seen) taken as vacated too. On the
    /// demo site (`bench/change_sites.py --sensors os1-64`): permanent
    /// structure static 99.33 → 99.22 % (the building 28,246 → 27,865 of
    /// 29,132 voxels), removed objects' voxels left 6.49 → 5.21 %, but the
    /// gain was mostly a crane jib's (623 → 416 crane-jib voxels left), not
    /// the low stacks it was for: rebar bundle 116 216 → 183, pipe stack 129
    /// (90) and rebar bundle 130 (103) unchanged: session 5 passes them 14
    /// to 27 m off, and under either rule none of its rays frees their
    /// places (deleted without overlap).
    pub free_vacated_low: bool,
    /// The clearance of `free_vacated_low`, m.
    pub vacated_clearance_m: f64,
    /// DOR removes a voxel only if none of its 26 neighbours is a static
    /// occupied voxel (hit, ε_l ≤ τ_dyn). A surface grazed by rays is freed
    /// in patches, but its patches touch parts that were not; a mover stands
    /// in free space. (DUFOMap's "unknown inflation" d_p plays this role.)
    pub static_neighbour_veto: bool,
    /// DOR's growth step (`evidence::grow`): a keyframe's dynamic verdict
    /// spreads to 26-neighbouring voxels of its own points that at most this
    /// many keyframes hit and none saw free, except a column's lowest voxel.
    /// 0 disables it. Numbers in `evidence::grow`'s docs.
    pub grow_max_hits: u32,
    /// ... at most this many voxel steps from a voxel dynamic by ε_l.
    pub grow_depth_voxels: u32,
    /// Growth also enters voxels some keyframe saw free (still at most
    /// `grow_max_hits` hits) above the ground level (`evidence::ground`):
    /// evidence both ways that ε_l did not find decisive, where the
    /// neighbours decide. false: only voxels no keyframe saw free (their
    /// own evidence decides). Numbers in `evidence::grow`'s docs.
    pub grow_freed: bool,
    /// DOR's cluster step (`evidence::grow`): a keyframe's points joined
    /// through their voxels above the ground level (`evidence::ground`),
    /// neighbours up to `cluster_reach_deg` of arc apart, form pieces; a
    /// piece of at most `cluster_max_voxels` voxels whose points are at least
    /// this share dynamic (after growth) becomes dynamic whole. 0 disables.
    pub cluster_share: f64,
    /// The cluster step's reach between voxels of a piece, degrees of arc
    /// seen from the keyframe's sensor: 1 voxel near, up to 3 far (at 0.8°
    /// and 0.2 m voxels, 2 from 21 m and 3 from 36 m), so a far mover whose
    /// beams land a voxel or two apart is still one piece.
    pub cluster_reach_deg: f64,
    /// A piece larger than this many voxels (a building, a stretch of
    /// fence) is never made dynamic.
    pub cluster_max_voxels: u32,
    /// DOR's footing step (`evidence::grow`): a static point in a voxel at
    /// its column's ground level, beside a voxel with a dynamic point of the
    /// same keyframe, becomes dynamic when it lies more than this above the
    /// lowest point any keyframe put in its column, m. 0 disables it.
    pub footing_height_m: f64,
    /// ... and when at most this many keyframes, its own included, put a
    /// point that high at ground level in that column (a static kerb, bush
    /// or fence foot is seen there by many).
    pub footing_max_keyframes: u32,
    /// A ray that ends below the sensor (by 0.5 m or more) frees only voxels
    /// whose centre is at least this much above its endpoint. Rays to the ground graze it for
    /// metres before they end (at 40 m a ray from 1.7 m height runs within one
    /// voxel of the road for its last 4.6 m) and would free the road that
    /// other keyframes hit. Movers stand above the ground, and rays that end
    /// above the sensor are not limited. 0 disables it. 0.2 m (one voxel)
    /// since it was measured with `n_sat` = 2 (see there); at 0 SemanticKITTI
    /// 04 keeps 99.45 % of its static points instead of 99.74 %
    /// (`evidence::surface`). Only rays that end at the ground, with
    /// `clearance_near_ground_only`.
    pub free_clearance_m: f64,
    /// `free_clearance_m` applies only to rays that end at their column's
    /// ground level (`evidence::ground`: within one voxel of the lowest
    /// voxel the session's points occupy in that column). A ray ending on a
    /// car, a person or a wall does not graze the ground on its way, and the
    /// clearance only kept it from freeing the voxels at its own height: a
    /// car driving ahead along the beams, whose old places only rays ending
    /// on its own back cross. false: every downward ray gets the clearance.
    pub clearance_near_ground_only: bool,
    /// The ceiling's clearance: a ray that ends at least 0.5 m above the
    /// sensor on a level surface (the session's points in its endpoint
    /// voxel and the 26 around it lie on a plane within about 37° of level:
    /// the underside of a slab) frees only voxels whose centre is at least
    /// `free_clearance_m` below its endpoint. Rays rising to a slab's
    /// underside graze it for metres, through the underside voxels this
    /// session does not hit itself (parts it sees only at grazing angles,
    /// earlier sessions' points a few centimetres off), and freed them;
    /// change detection then took those out of the static map. Nothing
    /// moves just under a ceiling. Needs `free_test = "surface"`; false:
    /// rays that end above the sensor are not limited. On the VLP-16 site
    /// of `bench/change_sites.py` (5 × 150 keyframes, seed 3), permanent
    /// structure static 98.89 → 99.15 % (the building 87.3 → 92.4 %),
    /// removed objects' voxels left 10.10 → 10.07 %.
    pub ceiling_clearance: bool,
    /// An earlier session's map voxel at the map's ground level (the lowest
    /// map voxel of its column, and within a voxel of the lowest of every
    /// column up to 1 m around: not the top of a stack whose ground was
    /// never seen) that none of this session's points occupy,
    /// and whose points may be ground ([`super::surface::MapPatch::maybe_ground`]:
    /// a level plane or too few to tell; what `free_vacated_low` leaves alone),
    /// is freed only by a ray that crosses its points' plane inside it and
    /// ends past it (`evidence::surface`; fewer than three points: the
    /// level through their centroid), the ground clearance and the guard
    /// still applying: the ground there went away. A ray
    /// from a low sensor grazes uneven ground for metres and passes a few
    /// centimetres over its crests, above the ray's end by more than the
    /// ground clearance, and freed those voxels; change detection then took
    /// patches of ground out of the static map. Needs `free_test =
    /// "surface"`; with `map_patches` every map voxel has its patch anyway.
    ///
    /// Measured with `seam eval changes` on the 4 × 150-keyframe OS1-64
    /// site of `tests/sim_align.rs` (seed 21, session 3 a legged robot),
    /// permanent structure static / removed objects' voxels left, off → on:
    /// 97.66 / 4.90 → 99.43 / 4.90 % (10,483 ground voxels had been freed
    /// by session 3, 11-20 m from its route). Taking the column's lowest
    /// voxel alone as the ground also kept the tops of removed pallet
    /// stacks (99.46 / 5.30 % on that site). On `bench/change_sites.py` (with the local
    /// loop edges), off → on: OS1-64 98.94 / 6.62 → 99.36 / 6.67 %,
    /// HDL-64E 99.19 / 4.52 → 99.47 / 4.52 %, HDL-32E 99.11 / 6.75 → 99.30 /
    /// 6.76 %, VLP-16 99.21 / 9.52 → 99.33 / 9.47 %, Avia 99.43 / 39.78 →
    /// 99.73 / 39.88 %.
    pub map_ground_crossing: bool,
    /// The ceiling's clearance also for rays that end next to an earlier
    /// session's map voxel whose points lie on a level plane
    /// ([`super::surface::is_level_plane`]) and whose top is above the
    /// lowest sensor origin by `CLEARANCE_MIN_DROP_M`: a ceiling the map
    /// knows. `ceiling_clearance` asks this session's own points around the
    /// endpoint to make a level plane, which a VLP-16's one ring there does
    /// not, and its rays rising under a slab freed the underside's voxels
    /// (then change detection took them out of the static map). Needs
    /// `ceiling_clearance`.
    ///
    /// Measured with `bench/change_sites.py` (2026-12-08, 5 × 150 keyframes;
    /// permanent structure static / removed objects' voxels left, off → on):
    /// OS1-64 99.31 / 3.73 → 99.41 / 3.75 %, HDL-64E 99.29 / 3.12 → 99.29 /
    /// 3.13, HDL-32E 98.93 / 3.84 → 99.16 / 3.86, VLP-16 99.08 / 4.48 →
    /// 99.40 / 4.50, Avia 99.68 / 36.63 → 99.69 / 36.74; appeared objects,
    /// movers and events unchanged. On the VLP-16 site the building's voxels
    /// taken out by session 5's free evidence went from 2,313 (2,164 of them
    /// the underside of a slab at 4 m) to 410 (`seam eval changes
    /// --lost-voxels`). Giving such map voxels their patch instead (freed
    /// only by rays crossing their plane, as `map_ground_crossing` does for
    /// the ground) kept more (OS1-64 99.46 %, VLP-16 99.33 %) but left a
    /// removed scaffold's decks, which only rays into the sky would cross:
    /// removed left 6.48 % and 7.73 %.
    pub map_ceiling_clearance: bool,
    /// Whether a keyframe's hits at ground level below a voxel (the layer
    /// beneath, `evidence::ground`) guard that voxel as `free_guard_voxels`
    /// says. false: they do not. The ground next to where a mover stood is
    /// hit by the very keyframes whose rays cross the mover's old place, so
    /// the guard spared its lowest layers; grazing the ground is what
    /// `free_clearance_m` guards against. Hits above the ground level
    /// (a car roof, a wall, a bush) still guard.
    ///
    /// This and `clearance_near_ground_only`, in one run of
    /// `bench/dor_vs_dufomap.py` (store poses; point-wise F1, the two off →
    /// on, PR after): SemanticKITTI 04 89.13 → 92.86 (PR 99.27 %; DUFOMap
    /// 86.90 at its defaults, 90.37 at 0.2 m), 08 14.92 → 17.03 (99.02 %;
    /// DUFOMap 12.88 / 24.04); simulated OS1-64 88.18 → 89.20 (PR 99.01 →
    /// 98.94 %, the clearance rule's cost: 99.00 % without it), HDL-64E
    /// 91.28 → 92.57, VLP-16 83.72 → 84.18, HDL-32E 84.84 → 85.33, Avia
    /// 91.19 → 91.98 (PR 97.78 → 97.70 %). `seam eval changes` on the
    /// 5 × 150-keyframe sites (permanent kept / removed left): HDL-64E
    /// 99.27 / 8.12 → 99.25 / 7.90 %, OS1-64 99.25 / 17.72 → 99.22 / 17.28
    /// %, HDL-32E 99.40 / 13.01 → 99.38 / 12.43 %, VLP-16 99.31 / 17.93 →
    /// 99.29 / 17.19 %, Avia 98.26 / 45.72 → 98.16 / 44.91 %; mover voxels
    /// in the static map 0.09-0.28 % of it (0.11-0.37 % before), object
    /// changes with events in the right session 91.4-98.9 % (unchanged).
    ///
    /// With `examples/dor_probe` (true poses; PR / RR / F1, off → on):
    /// SemanticKITTI 04 99.45 / 80.75 / 89.13 → 99.27 / 87.22 / 92.86,
    /// 08 99.21 / 8.07 / 14.92 → 99.02 / 9.32 / 17.03; the DOR bench's
    /// simulated 60-keyframe sessions (seed 1, true poses): OS1-64 88.97 →
    /// 90.42, HDL-64E 92.67 → 93.85, VLP-16 84.10 → 84.49, HDL-32E 86.90 →
    /// 87.39, Avia 91.00 → 91.92 F1, PR down by at most 0.06 points (Avia
    /// 98.72 → 98.66 %). The clearance rule alone: 04 89.81, 08 16.81 F1 at
    /// PR 99.40 / 99.17 %. Dropping every hit in the layer beneath from the
    /// guard, ground or not: 04 92.30 F1 but 08 PR 98.97 %; only the hit
    /// straight beneath: no change (the mover's old place has ground hits
    /// beside it too).
    pub ground_hits_guard: bool,
    /// What a ray must do to free a voxel of interest: cross it (MATH.md §6,
    /// `"voxel"`), or pass through the patch of points the session has in it
    /// (`"surface"`, see `evidence::surface`).
    pub free_test: FreeTest,
    /// A keyframe casts one ray per voxel its points fall in, to the first
    /// of them in scan order, instead of one per point (OctoMap's
    /// `insertPointCloud(…, discretize)` does the like). A voxel counts at
    /// most once per keyframe anyway, so the rays left out only repeat, a
    /// few centimetres aside, the walk of the one kept: a SemanticKITTI
    /// scan's 124,000 points fall in 42,000 voxels at 0.2 m, and the rays
    /// kept are 55 % of the length walked.
    ///
    /// One run of `bench/dor_vs_dufomap.py` against the previous commit's
    /// (store poses; point-wise PR / F1, per point → per voxel): SemanticKITTI
    /// 04 99.36 / 93.85 → 99.41 / 93.83, 08 99.14 / 18.34 → 99.16 / 18.20
    /// (moved F1 88.78 → 88.60); simulated sessions F1 OS1-64 90.46 → 90.42,
    /// HDL-64E 93.92 → 93.91, VLP-16 84.85 → 84.93, HDL-32E 87.14 → 87.15,
    /// Avia 93.47 → 93.47. `examples/dor_probe` on SemanticKITTI 04, ray
    /// casting 0.46-0.51 s → 0.39-0.51 s, most runs 0.43-0.44 s (timing on
    /// the 2-core VM is noisy). `bench/change_sites.py` against its previous
    /// run: permanent structure kept rose by at most 0.02 points on every
    /// site, removed objects left by at most 0.26 (VLP-16 17.80 → 18.06 %,
    /// Avia 46.06 → 46.31 %).
    pub one_ray_per_voxel: bool,
    /// Surface test: a patch reaches this many standard deviations of its
    /// points along each in-plane axis.
    pub surface_sigmas: f64,
    /// Surface test: slack added to the patch (range noise and pose error);
    /// also the radius of a voxel with one or two points.
    pub surface_tolerance_m: f64,
    /// Surface test: a ray must end at least this far behind the patch's
    /// plane (so a ray ending on the surface itself never frees it).
    pub surface_behind_m: f64,
    /// Surface test: voxels that at least this many keyframes hit get a
    /// shape; fewer, see `surface_single_sigma_m`.
    pub surface_min_keyframes: u32,
    /// Surface test on a voxel fewer keyframes hit: it gets a shape too if
    /// its points spread at least this much (σ) along both in-plane axes,
    /// and then rays free it below the ground clearance; otherwise it
    /// follows the voxel rule. 0: never.
    pub surface_single_sigma_m: f64,
    /// Whether earlier sessions' map voxels that this session's points do
    /// not occupy get their stored patch (`evidence::surface::MapPatch`):
    /// freed only by rays crossing it, but then also below the clearance and
    /// next to a keyframe's own hits. Off by default: on the demo site it
    /// kept more permanent structure (99.85 % vs 99.72 %) but left more of
    /// the removed objects (56.0 % vs 39.1 %), since a removed scaffold
    /// tube's narrow patch is crossed by one or two rays per session.
    pub map_patches: bool,
    /// With `map_patches`, a map voxel gets its patch only with at least
    /// this many points behind it; fewer: the voxel rule.
    pub surface_map_min_points: u32,
    /// Beams that returned nothing free the earlier sessions' map voxels
    /// within this range that this session's points do not occupy
    /// (`evidence::no_return`); only change detection sees it. A spinning
    /// sensor's band or a forward sensor's field of view. 0 disables.
    pub no_return_range_m: f64,
    /// ... and only voxels with none of this session's points within about
    /// this distance (cells of this size, the voxel's and its 26
    /// neighbours): a building the session sees elsewhere is still there,
    /// even where its far, dark or grazing parts return nothing. 0: only
    /// the voxel itself must hold no point.
    pub no_return_clear_m: f64,
    /// ... and only from at most this many times the range the voxel was
    /// seen from (its placing keyframe's distance): what returned at 30 m
    /// may well return nothing at 80 m.
    pub no_return_reach_factor: f64,
    /// No return within this many degrees of the direction, either way, at
    /// most. A session whose spinning sensor seam knows by name uses
    /// [`NO_RETURN_MARGIN_SPACINGS`] of its beam spacing where that is less
    /// ([`EvidenceConfig::for_beam_spacing`]): 0.54° for an OS1-64, 1.0° for
    /// an HDL-32E, this 1.5° for a VLP-16 and for sensors of unknown beams.
    pub no_return_margin_deg: f64,
    /// Only directions at least this far above the horizontal (world):
    /// below it, dark and grazing ground past the sensor's reach returns
    /// nothing too.
    pub no_return_min_elevation_deg: f64,
    /// Beams that returned nothing also free this session's own voxels
    /// (`evidence::no_return`, "within a session"): a mover seen against
    /// the sky or against ground the sparse rings never reach leaves no
    /// ray with an endpoint behind it once it has gone. Only within this
    /// range of the sensor; 0 disables. The other `own_no_return_*` keys
    /// guard the static map.
    pub own_no_return_range_m: f64,
    /// ... only directions at least this far above the horizontal (world),
    /// degrees: not the ground below the sensor.
    pub own_no_return_min_elevation_deg: f64,
    /// ... only with none of the keyframe's own points within about this
    /// distance (cells of this size, the voxel's and its 26 neighbours): a
    /// fence or scaffold a few beams missed is still seen beside it. At
    /// most a voxel: never the voxel or its neighbours.
    pub own_no_return_clear_m: f64,
    /// ... only voxels at most this many keyframes put a point in: what
    /// many keyframes saw is there.
    ///
    /// Tried for the OS1-64 session's dump truck, which stands for ten
    /// keyframes 54-63 m out and is then gone against the sky (216 of its
    /// 913 points kept; `examples/dor_probe` on the bench's 60-keyframe
    /// session, seed 1, true poses, point-wise PR / RR / F1 from 99.67 /
    /// 88.98 / 94.02): 5 keyframes 99.63 / 89.45 / 94.27, 10 or 100 99.62 /
    /// 89.45 / 94.26, 28-36 static points (far façades and fences a few
    /// beams missed) for each moving one; 100 with a 70 m range 99.59 /
    /// 90.33 / 94.73; 100 with −2° for `own_no_return_min_elevation_deg`
    /// 98.63 / 91.92 / 95.16, 20,600 static points lost. Not taken.
    pub own_no_return_max_keyframes: u32,
    /// The single-change test: a voxel is dynamic also when its ε_l is not
    /// over `tau_dyn` but at least this many consecutive keyframes crossed
    /// it and at least `change_once_min_hits` consecutive keyframes hit it,
    /// one run wholly before the other, seen from about the same direction
    /// (`change_once_max_deg`). Crossings the own-hit guard drops count here
    /// (`grid::Span`). 0: off. The directional model only.
    ///
    /// It decides DOR's labels and so what enters the cleaned map; it is not
    /// kept in the stored evidence, whose ε_l (and so reprojection and ε_g's
    /// first value) stays eq. 8's.
    ///
    /// Why: a slow mover hits, keyframe after keyframe, the voxels next to
    /// those it hit before, so the rays that cross the space it left or will
    /// fill end right beside its own hits, and the guard drops them; its
    /// voxels keep ε_l at `eps_min`. SemanticKITTI 08's car creeping 5 cm a
    /// scan towards the road is that: its bonnet fills, scan by scan, space
    /// the first scans saw through. A static surface's voxels are hit and
    /// grazed in no such order, except where the sensor's own motion turns
    /// the view: near objects (walls, poles 5-10 m away) crossed from one
    /// side and hit from another as the sensor passes. The direction limit
    /// keeps those.
    ///
    /// Measured with `examples/dor_probe` (true poses), point-wise PR / RR /
    /// F1, off → on: SemanticKITTI 08 99.11 / 10.25 / 18.58 → 99.04 / 15.31 /
    /// 26.52 (755 more moving points removed for 786 more static ones; the
    /// creeping car 26 → 525 of its 5,235), 04 99.38 / 90.57 / 94.77 → 99.31
    /// / 90.94 / 94.94; the simulated 60-keyframe sessions (seed 1) remove
    /// the same moving points and at most 46 more static ones (Avia).
    /// Variants on 08 (04): 8° F1 25.11 at PR 99.06 % (94.88), 9° 25.34
    /// (94.94), 12° and 15° 26.52 with 93 and 226 more static points (157
    /// and 350 on 04); 4 crossings and 2 hits 24.82, 3 and 3 26.22; runs not
    /// required to be consecutive (3 / 2, 12°) 28.61 at PR 98.92 %. Without
    /// the direction limit (4 / 3), 344 of the 761 static points it added on
    /// 08 lay within 10 m of the sensor; 4 with 12°, 24 with 20°, 293 with
    /// 30°. Emerged only (crossed, then hit) RR 13.26 %, vacated only 11.42
    /// (4 / 3, any order, 12°).
    pub change_once_min_frees: u32,
    /// The consecutive keyframes that must hit a voxel for the single-change
    /// test (`change_once_min_frees`).
    pub change_once_min_hits: u32,
    /// The single-change test's limit on the angle between the rays from the
    /// middle crossing keyframe and the middle hitting keyframe to the
    /// voxel's centre, degrees.
    pub change_once_max_deg: f64,
    /// Which per-voxel model turns rays into ε_l: seam's directional
    /// evidence, or the scalar log-odds baseline for the ablation.
    pub model: EvidenceModel,
    /// The scalar baseline's parameters (used when `model = "log_odds"`).
    pub log_odds: LogOddsConfig,
}

/// What counts as a ray freeing a voxel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FreeTest {
    /// Every voxel a ray crosses before its endpoint (MATH.md §6).
    Voxel,
    /// Only where the ray passes through the voxel's points and ends behind
    /// them (`evidence::surface`).
    #[default]
    Surface,
}

/// The per-voxel model behind ε_l.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EvidenceModel {
    /// Directional hit/free evidence, eqs. 4-8.
    #[default]
    Directional,
    /// OctoMap-style scalar occupancy on the same rays: per keyframe, a
    /// voxel's log-odds gains `logit(prob_hit)` if the keyframe hit it, else
    /// `logit(prob_miss)` if it freed it, clamped after every update; then
    /// `ε_l = 1 − P(occupied)`. The baseline the paper argues against.
    LogOdds,
}

/// OctoMap's defaults (Hornung et al. 2013).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LogOddsConfig {
    pub prob_hit: f64,
    pub prob_miss: f64,
    pub clamp_min: f64,
    pub clamp_max: f64,
}

impl Default for LogOddsConfig {
    fn default() -> Self {
        LogOddsConfig { prob_hit: 0.7, prob_miss: 0.4, clamp_min: 0.12, clamp_max: 0.97 }
    }
}

fn logit(p: f64) -> f64 {
    (p / (1.0 - p)).ln()
}

impl LogOddsConfig {
    /// `(l_hit, l_miss, l_min, l_max)` in log-odds.
    pub fn log_odds(&self) -> (f32, f32, f32, f32) {
        let l = |p| logit(p) as f32;
        (l(self.prob_hit), l(self.prob_miss), l(self.clamp_min), l(self.clamp_max))
    }

    fn validate(&self) -> Result<(), String> {
        for (name, v) in [
            ("prob_hit", self.prob_hit),
            ("prob_miss", self.prob_miss),
            ("clamp_min", self.clamp_min),
            ("clamp_max", self.clamp_max),
        ] {
            if !(v > 0.0 && v < 1.0) {
                return Err(format!("evidence.log_odds.{name} is {v}; it must lie strictly between 0 and 1"));
            }
        }
        if !(self.prob_hit > 0.5 && self.prob_miss < 0.5 && self.clamp_min < 0.5 && self.clamp_max > 0.5) {
            return Err("evidence.log_odds needs prob_hit > 0.5, prob_miss < 0.5, clamp_min < 0.5 < clamp_max".into());
        }
        Ok(())
    }
}

/// The no-return margin in beam spacings (`EvidenceConfig::for_beam_spacing`).
/// A window 1.5 spacings tall always holds a row of beams, and the several
/// columns of that row in it: a lone beam lost to dropout is no hole.
///
/// Why not one margin for all: the ± 1.5° window a VLP-16's 2° rows need
/// spans 2.6 m at 50 m, where an OS1-64's beams are 0.6 m apart, and any
/// return in it (the crane's new jib a few metres in front of where the
/// old one was) hides the beams that did go through empty space. Measured
/// with `bench/change_sites.py` on the demo site (OS1-64, 5 × 150 keyframes,
/// seed 1), permanent structure static / removed objects' voxels left:
/// margin 1.5° 99.31 / 17.66 %, 0.75° 99.30 / 15.23 %, 0.5° 99.30 / 14.41 %
/// (crane-jib leftovers 1,699 → 1,191 → 1,020 voxels). With this rule, the
/// whole bench (every site seed 3 but the demo's): OS1-64 99.31 / 17.66 → 99.30 / 14.48
/// %, HDL-32E (1.5° → 1.0°) 99.42 / 13.07 → 99.38 / 12.90 %, HDL-64E
/// 99.33 / 8.13 → 99.32 / 8.12 % (it looks no higher than +2°); the VLP-16
/// and the Avia keep 1.5°.
pub const NO_RETURN_MARGIN_SPACINGS: f64 = 0.75;

impl EvidenceConfig {
    /// This configuration for a session whose sensor's beams are
    /// `beam_spacing_deg` apart (`SensorModel::beam_spacing_deg`; `None`:
    /// unknown): the no-return margin becomes [`NO_RETURN_MARGIN_SPACINGS`]
    /// of the spacing where that is less than `no_return_margin_deg`.
    pub fn for_beam_spacing(&self, beam_spacing_deg: Option<f64>) -> std::borrow::Cow<'_, EvidenceConfig> {
        match beam_spacing_deg.map(|s| NO_RETURN_MARGIN_SPACINGS * s) {
            Some(m) if m > 0.0 && m < self.no_return_margin_deg => {
                std::borrow::Cow::Owned(EvidenceConfig { no_return_margin_deg: m, ..self.clone() })
            }
            _ => std::borrow::Cow::Borrowed(self),
        }
    }
}

impl Default for EvidenceConfig {
    fn default() -> Self {
        EvidenceConfig {
            voxel_size_m: 0.2,
            r0_m: 20.0,
            rs_m: 30.0,
            alpha0: 0.2,
            n0: 3.0,
            n_sat: 2,
            omega_floor: 0.2,
            tau_dyn: 0.5,
            eps_min: 0.1,
            eps_max: 1.0,
            pseudo_count: 0.0,
            free_guard_voxels: 1,
            free_guard_deg: 0.4,
            free_vacated_low: true,
            vacated_clearance_m: 0.05,
            static_neighbour_veto: false,
            grow_max_hits: 2,
            grow_depth_voxels: 2,
            grow_freed: true,
            cluster_share: 0.5,
            cluster_reach_deg: 0.8,
            cluster_max_voxels: 1500,
            footing_height_m: 0.05,
            footing_max_keyframes: 2,
            free_clearance_m: 0.2,
            clearance_near_ground_only: true,
            ceiling_clearance: true,
            map_ground_crossing: true,
            map_ceiling_clearance: true,
            ground_hits_guard: false,
            free_test: FreeTest::Surface,
            one_ray_per_voxel: true,
            surface_sigmas: 2.0,
            surface_tolerance_m: 0.03,
            surface_behind_m: 0.1,
            surface_min_keyframes: 2,
            surface_single_sigma_m: 0.03,
            map_patches: false,
            surface_map_min_points: 3,
            no_return_range_m: 100.0,
            no_return_clear_m: 1.0,
            no_return_reach_factor: 1.25,
            no_return_margin_deg: 1.5,
            no_return_min_elevation_deg: 3.0,
            own_no_return_range_m: 60.0,
            own_no_return_min_elevation_deg: -1.0,
            own_no_return_clear_m: 2.0,
            own_no_return_max_keyframes: 2,
            change_once_min_frees: 3,
            change_once_min_hits: 2,
            change_once_max_deg: 10.0,
            model: EvidenceModel::Directional,
            log_odds: LogOddsConfig::default(),
        }
    }
}

impl EvidenceConfig {
    /// Checks the values a TOML file may have set; the message names the key.
    pub fn validate(&self) -> Result<(), String> {
        for (name, v) in
            [("voxel_size_m", self.voxel_size_m), ("rs_m", self.rs_m), ("alpha0", self.alpha0), ("n0", self.n0)]
        {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("evidence.{name} is {v}; it must be a positive number"));
            }
        }
        for (name, v) in [
            ("r0_m", self.r0_m),
            ("pseudo_count", self.pseudo_count),
            ("free_clearance_m", self.free_clearance_m),
            ("vacated_clearance_m", self.vacated_clearance_m),
            ("surface_sigmas", self.surface_sigmas),
            ("surface_tolerance_m", self.surface_tolerance_m),
            ("surface_behind_m", self.surface_behind_m),
            ("surface_single_sigma_m", self.surface_single_sigma_m),
            ("no_return_range_m", self.no_return_range_m),
            ("no_return_clear_m", self.no_return_clear_m),
            ("no_return_reach_factor", self.no_return_reach_factor),
            ("footing_height_m", self.footing_height_m),
            ("own_no_return_range_m", self.own_no_return_range_m),
            ("own_no_return_clear_m", self.own_no_return_clear_m),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("evidence.{name} is {v}; it must be zero or a positive number"));
            }
        }
        if self.grow_depth_voxels > 8 {
            return Err(format!(
                "evidence.grow_depth_voxels is {}; it must lie in 0..=8 voxel steps (default 2; 0 turns growth off)",
                self.grow_depth_voxels
            ));
        }
        if !(0.0..=1.0).contains(&self.cluster_share) {
            return Err(format!(
                "evidence.cluster_share is {}; it must lie in [0, 1] (default 0.5; 0 turns the cluster step off)",
                self.cluster_share
            ));
        }
        if !(self.cluster_reach_deg > 0.0 && self.cluster_reach_deg <= 10.0) {
            return Err(format!(
                "evidence.cluster_reach_deg is {}; it must lie in (0, 10] degrees (default 0.8)",
                self.cluster_reach_deg
            ));
        }
        if self.cluster_share > 0.0 && self.cluster_max_voxels == 0 {
            return Err("evidence.cluster_max_voxels is 0; it must be at least 1 while cluster_share is on \
                        (default 1500)"
                .into());
        }
        if self.footing_max_keyframes == 0 {
            return Err("evidence.footing_max_keyframes is 0; it must be at least 1, the point's own keyframe \
                        (default 2; footing_height_m = 0 turns the footing step off)"
                .into());
        }
        if !(0.0..=2.0).contains(&self.free_guard_deg) {
            return Err(format!(
                "evidence.free_guard_deg is {}; it must lie in [0, 2] degrees (default 0.4)",
                self.free_guard_deg
            ));
        }
        if !(self.no_return_margin_deg.is_finite() && self.no_return_margin_deg > 0.0) {
            return Err(format!(
                "evidence.no_return_margin_deg is {}; it must be a positive number of degrees (default 1.5)",
                self.no_return_margin_deg
            ));
        }
        if !(-90.0..=90.0).contains(&self.no_return_min_elevation_deg) {
            return Err(format!(
                "evidence.no_return_min_elevation_deg is {}; it must lie in [-90, 90] (default 3)",
                self.no_return_min_elevation_deg
            ));
        }
        if !(0.0..=180.0).contains(&self.change_once_max_deg) {
            return Err(format!(
                "evidence.change_once_max_deg is {}; it must lie in [0, 180] degrees (default 10)",
                self.change_once_max_deg
            ));
        }
        if self.change_once_min_frees > 0 && self.change_once_min_hits == 0 {
            return Err("evidence.change_once_min_hits is 0; it must be at least 1 while change_once_min_frees \
                        is on (default 2)"
                .into());
        }
        if !(-90.0..=90.0).contains(&self.own_no_return_min_elevation_deg) {
            return Err(format!(
                "evidence.own_no_return_min_elevation_deg is {}; it must lie in [-90, 90] (default -1)",
                self.own_no_return_min_elevation_deg
            ));
        }
        if self.own_no_return_max_keyframes == 0 {
            return Err("evidence.own_no_return_max_keyframes is 0; it must be at least 1 \
                        (default 2; own_no_return_range_m = 0 turns the step off)"
                .into());
        }
        if !(0.0..=1.0).contains(&self.omega_floor) {
            return Err(format!("evidence.omega_floor is {}; it must lie in [0, 1] (default 0.2)", self.omega_floor));
        }
        if self.n_sat == 0 {
            return Err("evidence.n_sat is 0; it must be at least 1 (default 2)".into());
        }
        if !(0.0 <= self.eps_min && self.eps_min <= self.eps_max && self.eps_max <= 1.0) {
            return Err(format!(
                "evidence.eps_min ({}) and eps_max ({}) must satisfy 0 ≤ eps_min ≤ eps_max ≤ 1 (defaults 0.1 and 1)",
                self.eps_min, self.eps_max
            ));
        }
        if !(0.0..=1.0).contains(&self.tau_dyn) {
            return Err(format!("evidence.tau_dyn is {}; it must lie in [0, 1] (default 0.5)", self.tau_dyn));
        }
        self.log_odds.validate()
    }

    /// Eq. 4: the weight of one keyframe's observation at range `r_m`.
    pub fn range_weight(&self, r_m: f64) -> f64 {
        (-(r_m - self.r0_m).max(0.0) / self.rs_m).exp()
    }
}

/// α below this is treated as 0 (see [`DirectionalStats::alpha`]).
pub const ALPHA_FLOOR: f64 = 1e-4;

/// One kind of evidence (hit or free) of one voxel.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct DirectionalStats {
    /// Observing keyframes (each counted at most once).
    pub n: u32,
    /// `Q = Σ q` over those keyframes.
    pub q_sum: f64,
    /// `M = Σ q u uᵀ`, upper triangle `[xx, xy, xz, yy, yz, zz]`.
    pub m: [f64; 6],
}

impl DirectionalStats {
    /// Adds one keyframe's observation with weight `q` along the unit
    /// direction `u` (sensor → voxel centre). A zero `u` adds to n and Q only.
    pub fn add(&mut self, q: f64, u: &[f64; 3]) {
        self.n += 1;
        self.q_sum += q;
        let [x, y, z] = *u;
        for (m, p) in self.m.iter_mut().zip([x * x, x * y, x * z, y * y, y * z, z * z]) {
            *m += q * p;
        }
    }

    /// Sums two accumulations (e.g. when re-binning voxels, MATH.md §7).
    pub fn merge(&mut self, other: &DirectionalStats) {
        self.n += other.n;
        self.q_sum += other.q_sum;
        for (m, o) in self.m.iter_mut().zip(other.m) {
            *m += o;
        }
    }

    /// `α = λ1 / λ2` of M (0 when λ2 = 0), in [0, 1]: near 0 when every
    /// observation shares one direction (MATH.md §6's choice over λ2/λ1).
    ///
    /// Below [`ALPHA_FLOOR`] α is rounding noise (one direction gives a rank-1
    /// M whose λ1 is ~1e-7·λ2 in f32 storage) and reads as exactly 0: with
    /// both ω near 0, eq. 8's `f / (h + f)` would otherwise be a ratio of two
    /// noise values.
    pub fn alpha(&self) -> f64 {
        let [_, l1, l2] = sym3_eigenvalues(&self.m);
        if l2 > 0.0 && l1 > ALPHA_FLOOR * l2 { (l1 / l2).clamp(0.0, 1.0) } else { 0.0 }
    }

    /// Eq. 5 with a floor: `ω = (ω_min + (1 − ω_min)·clip(α/α0, 0, 1)) ·
    /// min(1, Q/n0)`, ω_min = `omega_floor` (0 is the paper's eq. 5).
    pub fn omega(&self, cfg: &EvidenceConfig) -> f64 {
        let d = (self.alpha() / cfg.alpha0).clamp(0.0, 1.0);
        (cfg.omega_floor + (1.0 - cfg.omega_floor) * d) * (self.q_sum / cfg.n0).min(1.0)
    }
}

/// Everything one voxel has gathered, from the keyframes of one submap.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct VoxelEvidence {
    pub hit: DirectionalStats,
    pub free: DirectionalStats,
    /// The owner keyframe: the one whose contribution to `Q_hit + Q_free` is
    /// largest (MATH.md §7 moves the voxel with this keyframe's pose).
    /// Ties go to the lower index, so the owner does not depend on the order
    /// keyframes are accumulated in.
    pub owner_keyframe: u32,
    /// That keyframe's contribution: q, or 2q when it both hit and freed the
    /// voxel. Exact, not an approximation, because each keyframe adds to a
    /// voxel in one go (a keyframe's q is the same for both kinds); 0 only
    /// before any keyframe was added.
    pub owner_q: f64,
}

impl VoxelEvidence {
    /// Records keyframe `keyframe`'s contribution `q_total` to this voxel's Q,
    /// keeping the largest as the owner.
    pub fn offer_owner(&mut self, keyframe: u32, q_total: f64) {
        if q_total > self.owner_q || (q_total == self.owner_q && keyframe < self.owner_keyframe) {
            self.owner_keyframe = keyframe;
            self.owner_q = q_total;
        }
    }

    /// Eq. 6: `(h, f) = (n_hit ω_hit, n_free ω_free)`.
    pub fn hit_free_scores(&self, cfg: &EvidenceConfig) -> (f64, f64) {
        (self.hit.n as f64 * self.hit.omega(cfg), self.free.n as f64 * self.free.omega(cfg))
    }

    /// Eq. 7: `s = min(n_hit + n_free, n_sat) / n_sat`.
    pub fn support(&self, cfg: &EvidenceConfig) -> f64 {
        (self.hit.n.saturating_add(self.free.n).min(cfg.n_sat)) as f64 / cfg.n_sat as f64
    }

    /// Eq. 8, unclamped: `ε_l = s·f / (h + f + c)`, 0 when the denominator
    /// is 0. In [0, 1].
    pub fn epsilon_l_raw(&self, cfg: &EvidenceConfig) -> f64 {
        let (h, f) = self.hit_free_scores(cfg);
        let den = h + f + cfg.pseudo_count;
        if den > 0.0 { self.support(cfg) * f / den } else { 0.0 }
    }

    /// ε_l clamped to `[eps_min, eps_max]`, as it enters change detection.
    pub fn epsilon_l(&self, cfg: &EvidenceConfig) -> f64 {
        self.epsilon_l_raw(cfg).clamp(cfg.eps_min, cfg.eps_max)
    }

    /// Whether DOR removes this voxel's points: clamped ε_l > τ_dyn.
    pub fn is_dynamic(&self, cfg: &EvidenceConfig) -> bool {
        self.epsilon_l(cfg) > cfg.tau_dyn
    }
}

/// Eigenvalues `[λ0, λ1, λ2]` (ascending) of the symmetric 3×3 matrix with
/// upper triangle `[a00, a01, a02, a11, a12, a22]`, in closed form
/// (trigonometric method, Smith 1961). Accurate to about `1e-8·‖A‖` near
/// repeated eigenvalues (acos is ill-conditioned at ±1), far better
/// elsewhere: ample for α.
pub fn sym3_eigenvalues(m: &[f64; 6]) -> [f64; 3] {
    let [a00, a01, a02, a11, a12, a22] = *m;
    let off = a01 * a01 + a02 * a02 + a12 * a12;
    if off == 0.0 {
        let mut d = [a00, a11, a22];
        d.sort_by(f64::total_cmp);
        return d;
    }
    let q = (a00 + a11 + a22) / 3.0;
    let (b00, b11, b22) = (a00 - q, a11 - q, a22 - q);
    let p = ((b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * off) / 6.0).sqrt();
    if p == 0.0 || !p.is_finite() {
        return [q; 3];
    }
    // det(B) / 2 with B = (A - qI) / p; clamped because rounding can step
    // outside acos's domain.
    let det = b00 * (b11 * b22 - a12 * a12) - a01 * (a01 * b22 - a12 * a02) + a02 * (a01 * a12 - b11 * a02);
    let r = (det / (2.0 * p * p * p)).clamp(-1.0, 1.0);
    let phi = r.acos() / 3.0;
    let l2 = q + 2.0 * p * phi.cos();
    let l0 = q + 2.0 * p * (phi + 2.0 * std::f64::consts::FRAC_PI_3).cos();
    let l1 = 3.0 * q - l2 - l0;
    // l0 ≤ l1 ≤ l2 holds mathematically; rounding may swap near-equal ones.
    let mut l = [l0, l1, l2];
    l.sort_by(f64::total_cmp);
    l
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix3, SymmetricEigen, Vector3};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn reference(m: &[f64; 6]) -> [f64; 3] {
        let mut e: Vec<f64> =
            SymmetricEigen::new(crate::geometry::sym3_matrix(m)).eigenvalues.iter().copied().collect();
        e.sort_by(f64::total_cmp);
        [e[0], e[1], e[2]]
    }

    fn assert_eig(m: &[f64; 6]) {
        let (got, want) = (sym3_eigenvalues(m), reference(m));
        let scale = m.iter().fold(1e-300f64, |s, v| s.max(v.abs()));
        for i in 0..3 {
            assert!((got[i] - want[i]).abs() <= 1e-7 * scale, "{m:?}: {got:?} vs {want:?}");
        }
    }

    /// `R diag(l) Rᵀ` for a random rotation R, as an upper triangle.
    fn with_spectrum(rng: &mut ChaCha8Rng, l: [f64; 3]) -> [f64; 6] {
        let axis = Vector3::new(rng.random::<f64>() - 0.5, rng.random::<f64>() - 0.5, rng.random::<f64>() - 0.5);
        let r = nalgebra::Rotation3::new(axis * 6.0).into_inner();
        let a = r * Matrix3::from_diagonal(&Vector3::from(l)) * r.transpose();
        [a[(0, 0)], a[(0, 1)], a[(0, 2)], a[(1, 1)], a[(1, 2)], a[(2, 2)]]
    }

    #[test]
    fn the_no_return_margin_follows_a_known_sensors_beams_and_never_widens() {
        let cfg = EvidenceConfig::default();
        let m = |s: Option<f64>| cfg.for_beam_spacing(s).no_return_margin_deg;
        assert!((m(Some(45.0 / 63.0)) - 0.75 * 45.0 / 63.0).abs() < 1e-12);
        assert_eq!(m(Some(2.0)), 1.5, "a VLP-16 keeps the configured margin");
        assert_eq!(m(Some(4.0)), 1.5, "never wider than configured");
        assert_eq!(m(None), 1.5);
        assert_eq!(m(Some(0.0)), 1.5);
        // Nothing else changes.
        let os1 = cfg.for_beam_spacing(Some(0.7)).into_owned();
        assert_eq!(EvidenceConfig { no_return_margin_deg: cfg.no_return_margin_deg, ..os1 }, cfg);
    }

    #[test]
    fn eigenvalues_match_nalgebra() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for _ in 0..2000 {
            let m: [f64; 6] = std::array::from_fn(|_| rng.random::<f64>() * 20.0 - 10.0);
            assert_eig(&m);
        }
        // Degenerate spectra: repeated, zero, rank 1 and 2, tiny and huge.
        for l in [
            [1.0, 1.0, 1.0],
            [0.0, 0.0, 0.0],
            [0.0, 0.0, 5.0],
            [0.0, 3.0, 3.0],
            [2.0, 2.0, 7.0],
            [1.0, 1.0 + 1e-9, 1.0 + 2e-9],
            [-4.0, 0.0, 4.0],
            [1e-12, 1e-12, 1.0],
            [1e6, 1e6, 1e6 + 1.0],
        ] {
            for _ in 0..50 {
                assert_eig(&with_spectrum(&mut rng, l));
            }
        }
        assert_eig(&[3.0, 0.0, 0.0, 1.0, 0.0, 2.0]);
        assert_eq!(sym3_eigenvalues(&[3.0, 0.0, 0.0, 1.0, 0.0, 2.0]), [1.0, 2.0, 3.0]);
    }

    fn unit(v: [f64; 3]) -> [f64; 3] {
        let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        [v[0] / n, v[1] / n, v[2] / n]
    }

    #[test]
    fn alpha_is_near_one_from_many_directions_and_zero_from_one() {
        let mut many = DirectionalStats::default();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for _ in 0..500 {
            let u = unit([rng.random::<f64>() - 0.5, rng.random::<f64>() - 0.5, rng.random::<f64>() - 0.5]);
            many.add(1.0, &u);
        }
        assert!(many.alpha() > 0.8, "α = {}", many.alpha());

        let mut one = DirectionalStats::default();
        for q in [1.0, 0.7, 0.3, 0.9] {
            one.add(q, &unit([1.0, 2.0, -0.5]));
        }
        assert!(one.alpha() < 1e-6, "α = {}", one.alpha());
        assert_eq!(DirectionalStats::default().alpha(), 0.0);
        // Two orthogonal directions: λ1 = λ2.
        let mut two = DirectionalStats::default();
        two.add(1.0, &[1.0, 0.0, 0.0]);
        two.add(1.0, &[0.0, 1.0, 0.0]);
        assert!((two.alpha() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn range_weight_follows_eq_4() {
        let cfg = EvidenceConfig::default();
        assert_eq!(cfg.range_weight(0.0), 1.0);
        assert_eq!(cfg.range_weight(20.0), 1.0);
        assert!((cfg.range_weight(50.0) - (-1.0f64).exp()).abs() < 1e-15);
    }

    /// A voxel seen `n` times (q = 1) from the directions `dirs` in turn.
    fn stats(n: u32, dirs: &[[f64; 3]]) -> DirectionalStats {
        let mut s = DirectionalStats::default();
        for i in 0..n as usize {
            s.add(1.0, &unit(dirs[i % dirs.len()]));
        }
        s
    }

    const SPREAD: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

    /// Eqs. 5 and 7 as the paper writes them: no floor on ω, n_sat = 5.
    fn paper() -> EvidenceConfig {
        EvidenceConfig { omega_floor: 0.0, n_sat: 5, ..Default::default() }
    }

    #[test]
    fn epsilon_l_follows_eqs_6_to_8() {
        let cfg = paper();
        // No free evidence: ε_l = 0 (clamped to 0.1), static.
        let hit_only = VoxelEvidence { hit: stats(6, &SPREAD), ..Default::default() };
        assert_eq!(hit_only.epsilon_l_raw(&cfg), 0.0);
        assert_eq!(hit_only.epsilon_l(&cfg), 0.1);
        assert!(!hit_only.is_dynamic(&cfg));
        // Only free evidence: ε_l = s once f > 0 (one keyframe alone has
        // α = 0, so f = 0 and ε_l = 0).
        let single = VoxelEvidence { free: stats(1, &SPREAD), ..Default::default() };
        assert_eq!(single.epsilon_l_raw(&cfg), 0.0);
        for n in 2..8 {
            let free_only = VoxelEvidence { free: stats(n, &SPREAD), ..Default::default() };
            let s = n.min(5) as f64 / 5.0;
            assert!((free_only.epsilon_l_raw(&cfg) - s).abs() < 1e-12, "n = {n}");
            assert_eq!(free_only.support(&cfg), s);
        }
        // Nothing at all: 0, clamped up.
        assert_eq!(VoxelEvidence::default().epsilon_l_raw(&cfg), 0.0);
        assert_eq!(VoxelEvidence::default().epsilon_l(&cfg), 0.1);
        // Balanced, well spread: h = f, s = 1 → 0.5, not dynamic (strict >).
        let both = VoxelEvidence { hit: stats(3, &SPREAD), free: stats(3, &SPREAD), ..Default::default() };
        assert!((both.epsilon_l_raw(&cfg) - 0.5).abs() < 1e-12);
        assert!(!both.is_dynamic(&cfg));
        // The warned case: a surface hit from one direction is removed by
        // free evidence; the pseudo-count softens it.
        let one_sided =
            VoxelEvidence { hit: stats(5, &[[1.0, 0.0, 0.0]]), free: stats(3, &SPREAD), ..Default::default() };
        assert!((one_sided.epsilon_l_raw(&cfg) - 1.0).abs() < 1e-12);
        assert!(one_sided.is_dynamic(&cfg));
        let soft = EvidenceConfig { pseudo_count: 3.0, ..cfg.clone() };
        assert!((one_sided.epsilon_l_raw(&soft) - 0.5).abs() < 1e-12);
        // Clamping to the configured bounds.
        let tight = EvidenceConfig { eps_min: 0.2, eps_max: 0.9, ..cfg.clone() };
        assert_eq!(one_sided.epsilon_l(&tight), 0.9);
        assert_eq!(hit_only.epsilon_l(&tight), 0.2);
    }

    #[test]
    fn omega_saturates_in_alpha_and_weight() {
        let cfg = paper();
        assert!((stats(3, &SPREAD).omega(&cfg) - 1.0).abs() < 1e-12);
        assert!((stats(1, &SPREAD).omega(&cfg) - 0.0).abs() < 1e-12, "one direction");
        // Two orthogonal directions at q = 1: α = 1, Q = 2 → 2/3.
        assert!((stats(2, &SPREAD).omega(&cfg) - 2.0 / 3.0).abs() < 1e-12);
    }

    #[test]
    fn omega_floor_lets_one_direction_count() {
        let cfg = EvidenceConfig::default();
        assert_eq!((cfg.omega_floor, cfg.n_sat), (0.2, 2));
        // One direction: ω = floor · min(1, Q/n0).
        assert!((stats(1, &SPREAD).omega(&cfg) - 0.2 / 3.0).abs() < 1e-12);
        assert!((stats(3, &SPREAD).omega(&cfg) - 1.0).abs() < 1e-12, "spread: the floor changes nothing");
        // A mover: hit once, then seen through twice, all along one line of
        // sight. Eq. 8 with the paper's ω gives 0/0 = 0 (kept); with the
        // floor h = 1·0.2/3, f = 2·0.4/3, s = 1 → ε_l = 0.8 (removed).
        let dir = [[1.0, 0.2, 0.0]];
        let mover = VoxelEvidence { hit: stats(1, &dir), free: stats(2, &dir), ..Default::default() };
        assert_eq!(mover.epsilon_l_raw(&paper()), 0.0);
        assert!((mover.epsilon_l_raw(&cfg) - 0.8).abs() < 1e-12);
        assert!(mover.is_dynamic(&cfg));
        // Hit once and seen through once: two keyframes already saturate s
        // (n_sat = 2), ε_l = 0.5, which is not above τ_dyn: one look through
        // a point does not remove it.
        let once = VoxelEvidence { hit: stats(1, &dir), free: stats(1, &dir), ..Default::default() };
        assert!((once.support(&cfg) - 1.0).abs() < 1e-12);
        assert!((once.epsilon_l_raw(&cfg) - 0.5).abs() < 1e-12);
        assert!(!once.is_dynamic(&cfg));
        // A wall hit by six keyframes from one side and grazed by two stays.
        let wall = VoxelEvidence { hit: stats(6, &dir), free: stats(2, &dir), ..Default::default() };
        assert!(!wall.is_dynamic(&cfg), "ε_l = {}", wall.epsilon_l_raw(&cfg));
    }

    #[test]
    fn owner_is_the_largest_contribution_with_ties_to_the_lower_index() {
        let mut v = VoxelEvidence::default();
        v.offer_owner(5, 0.5);
        v.offer_owner(3, 0.4);
        assert_eq!((v.owner_keyframe, v.owner_q), (5, 0.5));
        v.offer_owner(9, 1.0);
        v.offer_owner(2, 1.0);
        v.offer_owner(4, 1.0);
        assert_eq!((v.owner_keyframe, v.owner_q), (2, 1.0));
    }

    #[test]
    fn config_defaults_validate_and_unknown_keys_fail() {
        let cfg = EvidenceConfig::default();
        assert!(cfg.validate().is_ok());
        let parsed: EvidenceConfig = toml::from_str("r0_m = 10.0").unwrap();
        assert_eq!(parsed, EvidenceConfig { r0_m: 10.0, ..cfg.clone() });
        assert!(toml::from_str::<EvidenceConfig>("r0 = 10.0").is_err());
        assert!(EvidenceConfig { n_sat: 0, ..cfg.clone() }.validate().unwrap_err().contains("n_sat"));
        assert!(EvidenceConfig { eps_min: 0.6, eps_max: 0.5, ..cfg.clone() }.validate().is_err());
        let deg = EvidenceConfig { change_once_max_deg: f64::NAN, ..cfg.clone() }.validate().unwrap_err();
        assert!(deg.contains("change_once_max_deg"), "{deg}");
        let hits = EvidenceConfig { change_once_min_hits: 0, ..cfg.clone() }.validate().unwrap_err();
        assert!(hits.contains("change_once_min_hits"), "{hits}");
        assert!(EvidenceConfig { change_once_min_hits: 0, change_once_min_frees: 0, ..cfg.clone() }.validate().is_ok());
        for bad in [
            EvidenceConfig { cluster_share: 1.5, ..cfg.clone() },
            EvidenceConfig { cluster_share: f64::NAN, ..cfg.clone() },
        ] {
            assert!(bad.validate().unwrap_err().contains("cluster_share"));
        }
        let reach = EvidenceConfig { cluster_reach_deg: 0.0, ..cfg.clone() }.validate().unwrap_err();
        assert!(reach.contains("cluster_reach_deg"), "{reach}");
        let size = EvidenceConfig { cluster_max_voxels: 0, ..cfg.clone() }.validate().unwrap_err();
        assert!(size.contains("cluster_max_voxels"), "{size}");
        assert!(EvidenceConfig { cluster_max_voxels: 0, cluster_share: 0.0, ..cfg.clone() }.validate().is_ok());
        assert!(EvidenceConfig { voxel_size_m: -1.0, ..cfg }.validate().unwrap_err().contains("voxel_size_m"));
    }
}
