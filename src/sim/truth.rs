//! Reading a simulation's ground truth back, for evaluation code: objects and
//! their presence, true poses, movers' boxes, and "which object is at this
//! point".

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use super::SimError;
use super::assets::{Part, Surface};
use super::ground::GRID_MIN;
use super::shapes::{Shape, ShapeKind};
use super::site::{ObjectId, SiteObject};
use super::writer::session_dir_name;
use crate::geometry::{Pose, pose_from_kitti_row};

/// One session's truth.
#[derive(Debug, Clone)]
pub struct GtSession {
    /// 1-based session number (`session_01` is 1).
    pub number: usize,
    pub dir: PathBuf,
    /// True `t_world_lidar` per keyframe.
    pub poses: Vec<Pose>,
    /// Where the session's odometry frame sits in the world: exact at the
    /// first keyframe (`t_world_session * odometry[0] == poses[0]`), the
    /// reference for coarse alignment; odometry drifts after it.
    pub t_world_session: Pose,
    /// Per keyframe, every mover's id and box in the world frame.
    pub movers: Vec<Vec<(ObjectId, Shape)>>,
}

/// Everything a simulation knows that its sessions' files do not say.
#[derive(Debug, Clone)]
pub struct GroundTruth {
    pub out_dir: PathBuf,
    /// Every object, static and moving, ordered by id.
    pub objects: Vec<SiteObject>,
    /// Sessions in order; `sessions[0]` is session 1.
    pub sessions: Vec<GtSession>,
    /// The sensor model of `site.toml` (`None`: not one seam knows).
    pub sensor: Option<crate::sensor::SensorModel>,
    index: StaticIndex,
}

/// Static parts binned in 2 m cells over the grid (bounds grown by 1 m).
#[derive(Debug, Clone)]
struct StaticIndex {
    cells: HashMap<(i32, i32), Vec<(u32, u32)>>,
}

const INDEX_CELL_M: f64 = 2.0;
const INDEX_GROW_M: f64 = 1.0;

fn index_cell(x: f64, y: f64) -> (i32, i32) {
    (((x - GRID_MIN[0]) / INDEX_CELL_M).floor() as i32, ((y - GRID_MIN[1]) / INDEX_CELL_M).floor() as i32)
}

impl StaticIndex {
    fn new(objects: &[SiteObject]) -> StaticIndex {
        let mut cells: HashMap<(i32, i32), Vec<(u32, u32)>> = HashMap::new();
        for (oi, o) in objects.iter().enumerate().filter(|(_, o)| !o.dynamic) {
            for (pi, p) in o.parts.iter().enumerate() {
                let b = p.shape.xy_bounds();
                let (i0, j0) = index_cell(b[0] - INDEX_GROW_M, b[1] - INDEX_GROW_M);
                let (i1, j1) = index_cell(b[2] + INDEX_GROW_M, b[3] + INDEX_GROW_M);
                for j in j0..=j1 {
                    for i in i0..=i1 {
                        cells.entry((i, j)).or_default().push((oi as u32, pi as u32));
                    }
                }
            }
        }
        StaticIndex { cells }
    }
}

impl GroundTruth {
    pub fn object(&self, id: ObjectId) -> Option<&SiteObject> {
        self.objects.get((id.0 as usize).checked_sub(1)?).filter(|o| o.id == id)
    }

    /// Session `number` (1-based).
    pub fn session(&self, number: usize) -> Option<&GtSession> {
        self.sessions.get(number.checked_sub(1)?)
    }

    /// Static objects present in `session` but not in the one before.
    pub fn appeared_in(&self, session: usize) -> Vec<ObjectId> {
        let s = session;
        self.objects
            .iter()
            .filter(|o| !o.dynamic && s > 1 && o.present_in(s) && !o.present_in(s - 1))
            .map(|o| o.id)
            .collect()
    }

    /// Static objects present in the session before `session` but not in it.
    pub fn disappeared_in(&self, session: usize) -> Vec<ObjectId> {
        let s = session;
        self.objects
            .iter()
            .filter(|o| !o.dynamic && s > 1 && !o.present_in(s) && o.present_in(s - 1))
            .map(|o| o.id)
            .collect()
    }

    /// The object containing world point `p` at keyframe `keyframe` of
    /// `session`, with shapes grown by `margin_m`: a mover (tested with its
    /// box) before a static object present in that session (tested with its
    /// primitives); among static objects the lowest id. None for ground and
    /// free space.
    pub fn object_at(&self, session: usize, keyframe: usize, p: [f64; 3], margin_m: f64) -> Option<ObjectId> {
        let movers = self.session(session)?.movers.get(keyframe)?;
        if let Some((id, _)) = movers.iter().find(|(_, b)| b.contains(p, margin_m)) {
            return Some(*id);
        }
        let inside = |oi: usize, pi: usize| {
            let o = &self.objects[oi];
            o.present_in(session) && o.parts[pi].shape.contains(p, margin_m)
        };
        if margin_m > INDEX_GROW_M {
            return (self.objects.iter().enumerate())
                .filter(|(_, o)| !o.dynamic)
                .find(|(oi, o)| (0..o.parts.len()).any(|pi| inside(*oi, pi)))
                .map(|(_, o)| o.id);
        }
        let entries = self.index.cells.get(&index_cell(p[0], p[1]))?;
        entries.iter().find(|&&(oi, pi)| inside(oi as usize, pi as usize)).map(|&(oi, _)| self.objects[oi as usize].id)
    }
}

fn parse_err(path: &Path, line: usize, message: impl Into<String>) -> SimError {
    SimError::Format { path: path.to_path_buf(), line, message: message.into() }
}

fn read(path: &Path) -> Result<String, SimError> {
    std::fs::read_to_string(path).map_err(|source| SimError::Io { path: path.to_path_buf(), source })
}

/// The data rows of a CSV whose header must be `header`, split on commas.
fn csv_rows<'t>(path: &Path, text: &'t str, header: &str) -> Result<Vec<(usize, Vec<&'t str>)>, SimError> {
    let mut lines = text.lines().enumerate();
    match lines.next() {
        Some((_, h)) if h.trim() == header => {}
        _ => return Err(parse_err(path, 1, format!("expected the header `{header}`"))),
    }
    let n = header.split(',').count();
    let mut rows = Vec::new();
    for (i, l) in lines.filter(|(_, l)| !l.trim().is_empty()) {
        let cells: Vec<&str> = l.split(',').map(str::trim).collect();
        if cells.len() != n {
            return Err(parse_err(path, i + 1, format!("{} fields, expected {n}", cells.len())));
        }
        rows.push((i + 1, cells));
    }
    Ok(rows)
}

fn num<T: std::str::FromStr>(path: &Path, line: usize, cell: &str, what: &str) -> Result<T, SimError> {
    cell.parse().map_err(|_| parse_err(path, line, format!("{what} `{cell}` is not a number")))
}

fn shape_of(path: &Path, line: usize, kind: &str, c: &[&str]) -> Result<Shape, SimError> {
    let kind = ShapeKind::parse(kind).ok_or_else(|| parse_err(path, line, format!("unknown shape kind `{kind}`")))?;
    let v: Vec<f64> = c.iter().map(|x| num(path, line, x, "coordinate")).collect::<Result<_, _>>()?;
    Ok(Shape { kind, center: [v[0], v[1], v[2]], size: [v[3], v[4], v[5]], yaw: v[6] })
}

const OBJECTS_HEADER: &str =
    "id,class,label,dynamic,cx,cy,cz,length,width,height,yaw,first_session,last_session,sessions";
const PRIMITIVES_HEADER: &str =
    "object_id,part,kind,label,cx,cy,cz,length,width,height,yaw,reflectivity,surface,surface_param";
const DYNAMIC_HEADER: &str = "keyframe,time_s,object_id,class,label,cx,cy,cz,length,width,height,yaw";

fn read_objects(out_dir: &Path) -> Result<Vec<SiteObject>, SimError> {
    let path = out_dir.join("objects.csv");
    let text = read(&path)?;
    let mut objects = Vec::new();
    for (line, c) in csv_rows(&path, &text, OBJECTS_HEADER)? {
        let id = ObjectId(num(&path, line, c[0], "id")?);
        if id.0 as usize != objects.len() + 1 {
            return Err(parse_err(&path, line, format!("id {} out of order", id.0)));
        }
        let sessions = c[13].split(';').map(|s| num(&path, line, s, "session")).collect::<Result<Vec<usize>, _>>()?;
        objects.push(SiteObject {
            id,
            class: c[1].to_string(),
            label: num(&path, line, c[2], "label")?,
            dynamic: c[3] == "1",
            bbox: shape_of(&path, line, "box", &c[4..11])?,
            parts: Vec::new(),
            sessions,
        });
    }
    let path = out_dir.join("primitives.csv");
    let text = read(&path)?;
    for (line, c) in csv_rows(&path, &text, PRIMITIVES_HEADER)? {
        let id: usize = num(&path, line, c[0], "object_id")?;
        let param: f32 = num(&path, line, c[13], "surface_param")?;
        let surface = match c[12] {
            "solid" => Surface::Solid,
            "mesh" => Surface::Mesh { pass: param },
            "foliage" => Surface::Foliage { extinction_per_m: param },
            other => return Err(parse_err(&path, line, format!("unknown surface `{other}`"))),
        };
        let part = Part {
            shape: shape_of(&path, line, c[2], &c[4..11])?,
            label: num(&path, line, c[3], "label")?,
            reflectivity: num(&path, line, c[11], "reflectivity")?,
            surface,
        };
        let o = objects.get_mut(id.wrapping_sub(1)).ok_or_else(|| parse_err(&path, line, format!("no object {id}")))?;
        o.parts.push(part);
    }
    Ok(objects)
}

fn read_poses(path: &Path) -> Result<Vec<Pose>, SimError> {
    let text = read(path)?;
    let mut poses = Vec::new();
    for (i, l) in text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()) {
        let v: Vec<f64> = l.split_whitespace().map(|x| num(path, i + 1, x, "pose entry")).collect::<Result<_, _>>()?;
        let row: [f64; 12] = v.try_into().map_err(|_| parse_err(path, i + 1, "expected 12 numbers"))?;
        poses.push(
            pose_from_kitti_row(&row).map_err(|e| parse_err(path, i + 1, format!("not a rotation (error {e:.1e})")))?,
        );
    }
    Ok(poses)
}

fn read_dynamic(path: &Path, keyframes: usize) -> Result<Vec<Vec<(ObjectId, Shape)>>, SimError> {
    let text = read(path)?;
    let mut movers = vec![Vec::new(); keyframes];
    for (line, c) in csv_rows(path, &text, DYNAMIC_HEADER)? {
        let k: usize = num(path, line, c[0], "keyframe")?;
        let slot =
            movers.get_mut(k).ok_or_else(|| parse_err(path, line, format!("keyframe {k} beyond {keyframes}")))?;
        slot.push((ObjectId(num(path, line, c[2], "object_id")?), shape_of(path, line, "box", &c[5..12])?));
    }
    Ok(movers)
}

/// Reads the ground truth of the simulation in `out_dir`.
pub fn read_ground_truth(out_dir: &Path) -> Result<GroundTruth, SimError> {
    let site_path = out_dir.join("site.toml");
    let site: toml::Table =
        read(&site_path)?.parse().map_err(|e: toml::de::Error| parse_err(&site_path, 1, e.message().to_string()))?;
    let count = site.get("sessions").and_then(toml::Value::as_array).map(Vec::len).ok_or_else(|| {
        parse_err(&site_path, 1, "no `sessions = [..]` list: is this a folder written by `seam simulate`?")
    })?;
    let objects = read_objects(out_dir)?;
    let mut sessions = Vec::with_capacity(count);
    for number in 1..=count {
        let dir = out_dir.join(session_dir_name(number, count));
        let poses = read_poses(&dir.join("gt/poses.txt"))?;
        let movers = read_dynamic(&dir.join("gt/dynamic.csv"), poses.len())?;
        let frame_path = dir.join("gt/t_world_session.txt");
        let t_world_session = read_poses(&frame_path)?
            .first()
            .copied()
            .ok_or_else(|| parse_err(&frame_path, 1, "expected one KITTI pose row"))?;
        sessions.push(GtSession { number, dir, poses, t_world_session, movers });
    }
    let index = StaticIndex::new(&objects);
    let sensor = site.get("sensor").and_then(toml::Value::as_str).and_then(crate::sensor::SensorModel::parse);
    Ok(GroundTruth { out_dir: out_dir.to_path_buf(), objects, sessions, sensor, index })
}
