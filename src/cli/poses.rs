//! `seam poses site.seam [--session N] [--format csv|json|kitti|tum]`
//!
//! World poses `A_m · p_i` of every keyframe in the newest graph version, in
//! the store's world frame, so trajectories go straight into evo or a
//! spreadsheet. CSV is the default.

use super::output::print_json;
use super::{Ctx, Format, UsageError};
use crate::geometry::{pose_to_kitti_row, pose_to_tum_quat};
use crate::store::{self, SessionId, Store};
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct PosesArgs {
    /// The store.
    pub store: PathBuf,
    /// Only this session (its number, 1 = first ingested, or its name).
    #[arg(long)]
    pub session: Option<String>,
}

#[derive(serde::Serialize)]
struct Row {
    session: i64,
    keyframe: i64,
    stamp_s: Option<f64>,
    x_m: f64,
    y_m: f64,
    z_m: f64,
    qx: f64,
    qy: f64,
    qz: f64,
    qw: f64,
}

/// Resolves `--session` (a number or a name) against the stored sessions.
pub fn resolve_session(sessions: &[store::SessionRow], arg: &str) -> anyhow::Result<SessionId> {
    store::find_session(sessions, arg).ok_or_else(|| {
        UsageError(format!("no session {arg:?} in this store; it has: {}", store::session_list(sessions, "none")))
            .into()
    })
}

pub fn run(ctx: &Ctx, a: PosesArgs) -> anyhow::Result<()> {
    let store = Store::open_read_only(&a.store)?;
    let conn = store.conn();
    let sessions = store::sessions(conn)?;
    let wanted: Vec<SessionId> = match &a.session {
        Some(s) => vec![resolve_session(&sessions, s)?],
        None => sessions.iter().filter(|s| s.status == "complete").map(|s| s.session_id).collect(),
    };
    if matches!(ctx.format, Format::Kitti | Format::Tum) && wanted.len() != 1 {
        return Err(UsageError("--format kitti and tum hold one trajectory: pass --session".into()).into());
    }
    let Some(version) = store::latest_graph_version(conn)? else {
        return Err(UsageError(format!("{} has no poses yet: ingest a session first", a.store.display())).into());
    };
    let mut rows = Vec::new();
    for sid in wanted {
        let stamps: std::collections::HashMap<i64, Option<f64>> =
            store::keyframes(conn, sid)?.into_iter().map(|k| (k.keyframe_index, k.stamp_s)).collect();
        for (k, p) in store::world_poses(conn, version, sid)? {
            let t = p.translation.vector;
            let q = pose_to_tum_quat(&p);
            rows.push((
                p,
                Row {
                    session: sid.0,
                    keyframe: k,
                    stamp_s: stamps.get(&k).copied().flatten(),
                    x_m: t.x,
                    y_m: t.y,
                    z_m: t.z,
                    qx: q[0],
                    qy: q[1],
                    qz: q[2],
                    qw: q[3],
                },
            ));
        }
    }
    match ctx.format {
        Format::Json => print_json(&rows.iter().map(|r| &r.1).collect::<Vec<_>>())?,
        Format::Kitti => {
            for (p, _) in &rows {
                let v = pose_to_kitti_row(p);
                println!("{}", v.iter().map(|x| format!("{x:.9e}")).collect::<Vec<_>>().join(" "));
            }
        }
        Format::Tum => {
            for (_, r) in &rows {
                let t = r.stamp_s.unwrap_or(r.keyframe as f64);
                println!(
                    "{t:.6} {:.6} {:.6} {:.6} {:.9} {:.9} {:.9} {:.9}",
                    r.x_m, r.y_m, r.z_m, r.qx, r.qy, r.qz, r.qw
                );
            }
        }
        Format::Table | Format::Csv => {
            println!("session,keyframe,x_m,y_m,z_m,qx,qy,qz,qw");
            for (_, r) in &rows {
                println!(
                    "{},{},{:.6},{:.6},{:.6},{:.9},{:.9},{:.9},{:.9}",
                    r.session, r.keyframe, r.x_m, r.y_m, r.z_m, r.qx, r.qy, r.qz, r.qw
                );
            }
        }
    }
    Ok(())
}
