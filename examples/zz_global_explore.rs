// TEMPORARY exploration (to be deleted).
use seam::registration::global::{cloud::MapCloud, fpfh::compute_fpfh, matching::mutual_matches};
use std::path::Path;
use std::time::Instant;
fn read_bin(p: &Path) -> Vec<[f32; 3]> {
    let b = std::fs::read(p).unwrap();
    b.chunks_exact(12)
        .map(|c| {
            [
                f32::from_le_bytes(c[0..4].try_into().unwrap()),
                f32::from_le_bytes(c[4..8].try_into().unwrap()),
                f32::from_le_bytes(c[8..12].try_into().unwrap()),
            ]
        })
        .collect()
}
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let d = Path::new(&args[1]);
    let voxel: f64 = args.get(2).map(|s| s.parse().unwrap()).unwrap_or(0.5);
    let nr: f64 = args.get(3).map(|s| s.parse().unwrap()).unwrap_or(1.5);
    let fr: f64 = args.get(4).map(|s| s.parse().unwrap()).unwrap_or(2.5);
    let tgt = read_bin(&d.join("target.bin"));
    let src = read_bin(&d.join("source.bin"));
    let truth = seam::io::read_kitti_poses(&d.join("truth.txt")).unwrap()[0];
    let t0 = Instant::now();
    let (ct, cs) = (MapCloud::new(&tgt, voxel, nr), MapCloud::new(&src, voxel, nr));
    let (ft, fs) = (compute_fpfh(&ct, fr), compute_fpfh(&cs, fr));
    let (ft, fs) = if std::env::var("CYL").is_ok() { (cyl(&ct, fr), cyl(&cs, fr)) } else { (ft, fs) };
    let minn: usize = std::env::var("MINN").ok().map(|s| s.parse().unwrap()).unwrap_or(0);
    let dense = |c: &MapCloud, f: Vec<(u32, seam::registration::global::fpfh::Descriptor)>| -> Vec<_> {
        let mut nb = Vec::new();
        f.into_iter()
            .filter(|(i, _)| {
                c.tree.within(&c.points[*i as usize], fr, &mut nb);
                nb.len() >= minn
            })
            .collect()
    };
    let (ft, fs) = (dense(&ct, ft), dense(&cs, fs));
    eprintln!("voxels {} {} desc {} {} in {:.2}s", ct.len(), cs.len(), ft.len(), fs.len(), t0.elapsed().as_secs_f64());
    // oracle: how many source descriptor points have a geometric counterpart in target
    let t1 = Instant::now();
    let corr = mutual_matches(&fs, &ft, usize::MAX);
    eprintln!("mutual {} in {:.2}s", corr.len(), t1.elapsed().as_secs_f64());
    let ok = |c: &seam::registration::global::matching::Correspondence| {
        let p = truth * nalgebra::Point3::from(cs.points[c.source as usize]);
        (p - nalgebra::Point3::from(ct.points[c.target as usize])).norm() < 1.0
    };
    for k in [100, 300, 1000, 3000, 10000, corr.len()] {
        let k = k.min(corr.len());
        let n = corr[..k].iter().filter(|c| ok(c)).count();
        let r = corr[k.saturating_sub(1)].ratio;
        eprintln!("top {k}: {n} true ({:.2}%), ratio at k {r:.3}", 100.0 * n as f64 / k as f64);
    }
    // how many source points with descriptors have a target descriptor point within 1 m after truth
    let tt = seam::registration::global::cloud::PointTree::build(
        &ft.iter().map(|(i, _)| ct.points[*i as usize]).collect::<Vec<_>>(),
    );
    let overl = fs
        .iter()
        .filter(|(i, _)| {
            let p = truth * nalgebra::Point3::from(cs.points[*i as usize]);
            tt.nearest(&p.into()).map_or(false, |(_, d2)| d2 < 0.5)
        })
        .count();
    eprintln!("source desc with target desc within 0.7 m under truth: {overl}");
    {
        // rank of true counterpart
        let tpts: Vec<[f64; 3]> = ft.iter().map(|(i, _)| ct.points[*i as usize]).collect();
        let tt = seam::registration::global::cloud::PointTree::build(&tpts);
        let dist = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f32>();
        let mut ranks = Vec::new();
        let (mut dsame, mut drand, mut n) = (0.0f64, 0.0f64, 0);
        for (k, (i, d)) in fs.iter().enumerate().step_by(20) {
            let p = truth * nalgebra::Point3::from(cs.points[*i as usize]);
            let Some((j, d2)) = tt.nearest(&p.into()) else { continue };
            if d2 > 0.25 {
                continue;
            }
            let dt = dist(d, &ft[j].1);
            let rank = ft.iter().filter(|(_, e)| dist(d, e) < dt).count();
            ranks.push(rank);
            dsame += (dt as f64).sqrt();
            drand += (dist(d, &ft[(k * 7919) % ft.len()].1) as f64).sqrt();
            n += 1;
        }
        ranks.sort();
        let q = |f: f64| ranks[((ranks.len() as f64 - 1.0) * f) as usize];
        eprintln!(
            "ranks n={} p10 {} p25 {} median {} p75 {} | of {} ; top1 {} top10 {} top100 {}; mean dist same {:.1} rand {:.1}",
            ranks.len(),
            q(0.1),
            q(0.25),
            q(0.5),
            q(0.75),
            ft.len(),
            ranks.iter().filter(|&&r| r == 0).count(),
            ranks.iter().filter(|&&r| r < 10).count(),
            ranks.iter().filter(|&&r| r < 100).count(),
            dsame / n as f64,
            drand / n as f64
        );
    }
    let cells = seam::registration::global::verify::coverage(&ct, 2.0);
    let sc = seam::registration::global::verify::score(&ct, &cells, 2.0, &cs, &truth, 1.0);
    {
        use seam::registration::global::robust::Dof;
        use seam::registration::global::verify::{RefineParams, refine};
        let sample = seam::registration::downsample::voxel_downsample(&cs.points, 1.0, true);
        for (dof, start) in [(Dof::Four, 3.0), (Dof::Six, 3.0), (Dof::Four, 1.0)] {
            let r = refine(
                &ct,
                &sample,
                &truth,
                &RefineParams { max_dist_start_m: start, max_dist_end_m: 0.5, iterations: 30, dof },
            );
            let e = truth.inverse() * r;
            let sc2 = seam::registration::global::verify::score(&ct, &cells, 2.0, &cs, &r, 1.0);
            eprintln!(
                "ICP from truth {dof:?} start {start}: err {:.2} m {:.2} deg  (t err {:.2?}) fit {:.3} matched {}",
                e.translation.vector.norm(),
                e.rotation.angle().to_degrees(),
                (r.translation.vector - truth.translation.vector).as_slice(),
                sc2.structure_fit(),
                sc2.matched
            );
        }
    }
    eprintln!("truth score {:?} fit {:.3} overlap {:.3}", sc, sc.structure_fit(), sc.overlap_fraction());
    // extent of both maps
    let ext = |c: &MapCloud| {
        let mut lo = [f64::MAX; 3];
        let mut hi = [f64::MIN; 3];
        for p in &c.points {
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        (lo, hi)
    };
    eprintln!("extent t {:?} s {:?}", ext(&ct), ext(&cs));
}

// cylindrical height descriptor: rings x height bins + normal verticality, padded to 33 dims
fn cyl(c: &MapCloud, r: f64) -> Vec<(u32, seam::registration::global::fpfh::Descriptor)> {
    use rayon::prelude::*;
    let rings = [r * 0.25, r * 0.5, r * 0.75, r];
    let hz = [-1.0, -0.25, 0.25, 1.0, 2.0, 3.5];
    (0..c.len())
        .into_par_iter()
        .map_init(Vec::new, |nb, i| {
            let n = c.normals[i]?;
            c.tree.within(&c.points[i], r, nb);
            if nb.len() < 10 {
                return None;
            }
            let p = c.points[i];
            let mut d = [0.0f32; 33];
            for &(j, _) in nb.iter() {
                let q = c.points[j as usize];
                let rxy = ((q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2)).sqrt();
                let dz = q[2] - p[2];
                let ri = rings.iter().position(|&x| rxy <= x).unwrap_or(3);
                let zi = hz.iter().position(|&x| dz < x).unwrap_or(6);
                d[ri * 7 + zi] += 1.0;
                if let Some(m) = c.normals[j as usize] {
                    let v = (m.z.abs() * 4.99) as usize;
                    d[28 + v] += 1.0;
                }
            }
            // normalise rings to distributions
            for ri in 0..4 {
                let s: f32 = d[ri * 7..ri * 7 + 7].iter().sum();
                if s > 0.0 {
                    for k in 0..7 {
                        d[ri * 7 + k] *= 100.0 / s;
                    }
                }
            }
            let s: f32 = d[28..33].iter().sum();
            if s > 0.0 {
                for k in 28..33 {
                    d[k] *= 100.0 / s;
                }
            }
            let _ = n;
            Some((i as u32, d))
        })
        .flatten()
        .collect()
}
