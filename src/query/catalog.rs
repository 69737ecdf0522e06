//! What the planner needs to know about a store: its sessions, zones, voxel
//! size and tables. Read once per query; the planner itself never touches
//! SQLite, so it can be tested (and fuzzed) against a hand-made catalog.

use crate::store::{Store, StoreError, Zone};

/// A session as queries name it.
#[derive(Debug, Clone, PartialEq)]
pub struct SessionInfo {
    /// Its number, 1, 2, ... in ingest order.
    pub id: i64,
    pub name: String,
    /// `YYYY-MM-DD`: the date of its `session.toml`, else the day it was
    /// ingested.
    pub date: String,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Catalog {
    /// By id.
    pub sessions: Vec<SessionInfo>,
    pub zones: Vec<Zone>,
    /// Edge of the map's voxels, metres.
    pub voxel_m: f64,
    /// `static` is the map voxels with ε_g below this (`[change] static_threshold`).
    pub static_threshold: f64,
    /// Tables the store has (a read-only store of an older schema lacks some).
    pub tables: Vec<String>,
}

impl Catalog {
    /// Reads the catalog of `store`.
    pub fn load(store: &Store, static_threshold: f64) -> Result<Catalog, StoreError> {
        let conn = store.conn();
        let root = store.root();
        let err = |e| crate::store::StoreError::Sql { path: root.join(crate::store::DB_FILE), source: e };
        let tables: Vec<String> = {
            let mut st = conn.prepare("SELECT name FROM sqlite_master WHERE type = 'table'").map_err(err)?;
            st.query_map([], |r| r.get(0)).map_err(err)?.collect::<Result<_, _>>().map_err(err)?
        };
        let sessions = crate::store::sessions(conn)?
            .into_iter()
            .map(|s| SessionInfo {
                id: s.session_id.0,
                date: s
                    .date
                    .as_deref()
                    .filter(|d| d.len() >= 10 && d.is_char_boundary(10))
                    .map(|d| d[..10].to_string())
                    .unwrap_or_else(|| s.created_at.chars().take(10).collect()),
                name: s.name,
            })
            .collect();
        let map_voxel = if tables.iter().any(|t| t == "map_state") {
            crate::store::map_state(conn)?.map(|m| m.voxel_m).filter(|v| *v > 0.0)
        } else {
            None
        };
        let voxel_m = match map_voxel {
            Some(v) => v,
            None => store.meta()?.voxel_size_m,
        };
        Ok(Catalog { sessions, zones: crate::store::zones(conn)?, voxel_m, static_threshold, tables })
    }

    pub fn has_table(&self, t: &str) -> bool {
        self.tables.iter().any(|x| x == t)
    }

    /// "sessions in this store: 1 `s1` (2026-03-02), ...", for help texts.
    pub fn session_list(&self) -> String {
        if self.sessions.is_empty() {
            return "this store has no sessions yet".into();
        }
        let show = |s: &SessionInfo| format!("{} `{}` ({})", s.id, s.name, s.date);
        let n = self.sessions.len();
        let list = if n <= 12 {
            self.sessions.iter().map(show).collect::<Vec<_>>().join(", ")
        } else {
            let head: Vec<String> = self.sessions[..5].iter().map(show).collect();
            let tail: Vec<String> = self.sessions[n - 5..].iter().map(show).collect();
            format!("{}, ... {}", head.join(", "), tail.join(", "))
        };
        format!("sessions in this store: {list}")
    }
}
