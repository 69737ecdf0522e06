// TEMPORARY exploration (to be deleted): statistics separating right from wrong hypotheses.
use nalgebra::{Point3, Vector3};
use seam::geometry::Pose;
use seam::registration::global::{bev, cloud::MapCloud, robust::Dof, verify};
use std::path::Path;
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
fn sfit(
    ct: &MapCloud,
    st: &seam::registration::global::cloud::PointTree,
    sidx: &[usize],
    cs: &MapCloud,
    cells: &std::collections::HashSet<(i32, i32)>,
    t: &Pose,
    md: f64,
    cosmin: f64,
) -> f64 {
    let r = t.rotation;
    let (mut cov, mut m) = (0.0f64, 0.0f64);
    for (p, n) in cs.points.iter().zip(&cs.normals) {
        let Some(n) = n else { continue };
        let rn = r * n;
        if rn.z.abs() >= 0.7 {
            continue;
        }
        let q = t * Point3::from(*p);
        if !cells.contains(&(((q.x / 2.0).floor() as i32), ((q.y / 2.0).floor() as i32))) {
            continue;
        }
        cov += 1.0;
        if let Some((j, d2)) = st.nearest(&q.into()) {
            if d2 < md * md && ct.normals[sidx[j]].unwrap().dot(&rn).abs() >= cosmin {
                m += 1.0;
            }
        }
    }
    m / cov.max(1.0)
}
fn structure_tree(c: &MapCloud) -> (seam::registration::global::cloud::PointTree, Vec<usize>) {
    let idx: Vec<usize> = (0..c.len()).filter(|&i| c.normals[i].is_some_and(|n| n.z.abs() < 0.7)).collect();
    (seam::registration::global::cloud::PointTree::build(&idx.iter().map(|&i| c.points[i]).collect::<Vec<_>>()), idx)
}
fn stats(ct: &MapCloud, cs: &MapCloud, cells: &std::collections::HashSet<(i32, i32)>, t: &Pose) -> [f64; 6] {
    let r = t.rotation;
    let (mut cov, mut m1, mut m05, mut p2p, mut gcov, mut gok) = (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for (p, n) in cs.points.iter().zip(&cs.normals) {
        let Some(n) = n else { continue };
        let q = t * Point3::from(*p);
        let rn = r * n;
        if !cells.contains(&(((q.x / 2.0).floor() as i32), ((q.y / 2.0).floor() as i32))) {
            continue;
        }
        let nn = ct.tree.nearest(&q.into());
        if rn.z.abs() < 0.7 {
            cov += 1.0;
            if let Some((j, d2)) = nn {
                if d2 < 1.0 {
                    m1 += 1.0;
                }
                if d2 < 0.25 {
                    m05 += 1.0;
                }
                if d2 < 1.0 {
                    if let Some(tn) = ct.normals[j] {
                        if tn.dot(&rn).abs() > 0.9 && tn.dot(&(q - Point3::from(ct.points[j]))).abs() < 0.1 {
                            p2p += 1.0;
                        }
                    }
                }
            }
        } else if rn.z.abs() > 0.9 {
            gcov += 1.0;
            if let Some((j, d2)) = nn {
                if d2 < 1.0 && (q.z - ct.points[j][2]).abs() < 0.1 {
                    gok += 1.0;
                }
            }
        }
    }
    [m1 / cov, m05 / cov, p2p / cov, gok / gcov.max(1.0), m1, cov]
}
fn main() {
    let args: Vec<String> = std::env::args().collect();
    for d in &args[1..] {
        let d = Path::new(d);
        let tgt = read_bin(&d.join("target.bin"));
        let src = read_bin(&d.join("source.bin"));
        let truth = seam::io::read_kitti_poses(&d.join("truth.txt")).unwrap()[0];
        let (ct, cs) = (MapCloud::new(&tgt, 0.5, 1.5), MapCloud::new(&src, 0.5, 1.5));
        let cells = verify::coverage(&ct, 2.0);
        let hyps = bev::bev_hypotheses(
            &ct,
            &cs,
            &bev::BevParams {
                cell_m: 2.0,
                yaw_step_deg: 1.5,
                max_hypotheses: 8,
                suppress_yaw_deg: 10.0,
                suppress_m: 5.0,
            },
        );
        let sample = seam::registration::downsample::voxel_downsample(&cs.points, 1.0, true);
        let mut rows = vec![];
        for h in hyps.iter().chain(std::iter::once(&truth)) {
            let p = verify::refine(
                &ct,
                &sample,
                h,
                &verify::RefineParams { max_dist_start_m: 5.0, max_dist_end_m: 0.5, iterations: 40, dof: Dof::Four },
            );
            let e = truth.inverse() * p;
            let ok = e.translation.vector.norm() < 1.5 && e.rotation.angle() < 5f64.to_radians();
            let s = stats(&ct, &cs, &cells, &p);
            let cells_s = verify::coverage(&cs, 2.0);
            let rev = stats(&cs, &ct, &cells_s, &p.inverse());
            let (stt, sti) = structure_tree(&ct);
            let (sts, ssi) = structure_tree(&cs);
            let mut extra = vec![];
            for (md, cm) in [(1.0, 0.0), (1.0, 0.7), (0.75, 0.7)] {
                let a = sfit(&ct, &stt, &sti, &cs, &cells, &p, md, cm);
                let b = sfit(&cs, &sts, &ssi, &ct, &cells_s, &p.inverse(), md, cm);
                extra.push(a.min(b));
                extra.push(a);
            }
            println!(
                "X {} {} {:?}",
                if ok { "OK" } else { "BAD" },
                {
                    let e = truth.inverse() * p;
                    format!("{:.1} {:.1}", e.translation.vector.norm(), e.rotation.angle().to_degrees())
                },
                extra.iter().map(|v| (v * 1000.0).round() / 1000.0).collect::<Vec<_>>()
            );
            // sharpness: max of fit at shifted poses
            let shifted: f64 = 0.0;
            for (dx, dy, dyaw) in [
                (3.0, 0.0, 0.0),
                (-3.0, 0.0, 0.0),
                (0.0, 3.0, 0.0),
                (0.0, -3.0, 0.0),
                (0.0, 0.0, 4.0),
                (0.0, 0.0, -4.0),
            ] {
                let dp = Pose::new(Vector3::new(dx, dy, 0.0), Vector3::new(0.0, 0.0, f64::to_radians(dyaw)));
                let q = dp * p;
                let _ = q;
            }
            rows.push((ok, s, rev[0].min(s[0]), e.translation.vector.norm(), e.rotation.angle().to_degrees()));
        }
        for (k, (ok, s, sh, et, er)) in rows.iter().enumerate() {
            println!(
                "{} {} {} err {:.1} m {:.1} deg fit1 {:.3} fit05 {:.3} p2p {:.3} ground {:.3} matched {} cov {} minfit {:.3} ",
                d.display(),
                if k == rows.len() - 1 { "TRUTH" } else { "hyp" },
                if *ok { "OK " } else { "BAD" },
                et,
                er,
                s[0],
                s[1],
                s[2],
                s[3],
                s[4],
                s[5],
                sh
            );
        }
    }
}
