//! One `Config`, a sub-struct per stage, defaults in `Default`.
//!
//! Running with no config file works; a TOML file overrides only what it
//! names, and a key seam does not know is an error that names it (a typo must
//! not silently fall back to a default).
//!
//! ```toml
//! [submap]
//! submap_length_m = 30.0
//!
//! [loops]              # registration::LoopConfig
//! radius_m = 15.0
//! [loops.dop]          # registration::DopConfig
//! rho_max = 4.0
//!
//! [graph]              # graph::GraphConfig
//! mode = "session"
//!
//! [global]             # registration::global::GlobalConfig
//! voxel_size_m = 0.75
//!
//! [evidence]           # evidence::EvidenceConfig
//! model = "log_odds"   # the scalar baseline instead of directional evidence
//!
//! [change]             # change::ChangeConfig
//! tau_o_m = 2.0
//! ```

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    pub submap: SubmapConfig,
    pub ingest: IngestConfig,
    /// Maps for the coarse alignment (MATH.md §2).
    pub coarse: crate::align::CoarseConfig,
    /// Global map-to-map registration (MATH.md §2).
    pub global: crate::registration::global::GlobalConfig,
    /// Loop candidates, GICP and the DOP test (MATH.md §3-4).
    pub loops: crate::registration::LoopConfig,
    /// The pose graph (MATH.md §5).
    pub graph: crate::graph::GraphConfig,
    /// Directional evidence, DOR and the scalar baseline (MATH.md §6).
    pub evidence: crate::evidence::EvidenceConfig,
    /// Change detection and the lifelong map (MATH.md §8).
    pub change: crate::change::ChangeConfig,
}

/// Submap cutting (MATH.md §1).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SubmapConfig {
    /// A new submap starts when the travel since the submap's first keyframe
    /// exceeds this (choice: 20 m).
    pub submap_length_m: f64,
    /// A trailing submap shorter than this is merged into the one before it.
    pub min_keyframes: usize,
}

impl Default for SubmapConfig {
    fn default() -> Self {
        SubmapConfig { submap_length_m: 20.0, min_keyframes: 2 }
    }
}

/// Reading and storing scans.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct IngestConfig {
    /// Scans read in parallel per batch while writing the scans file; bounds
    /// memory to about this many scans.
    pub read_batch_scans: usize,
}

impl Default for IngestConfig {
    fn default() -> Self {
        IngestConfig { read_batch_scans: 16 }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("{path}: {message}\n  hint: see the `Config` docs for the keys seam knows; only name what you change")]
    Parse { path: PathBuf, message: String },
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
}

impl Config {
    /// Reads a TOML file that overrides the defaults it names.
    pub fn from_file(path: &Path) -> Result<Config, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io { path: path.into(), source })?;
        Config::from_toml(&text, path)
    }

    pub fn from_toml(text: &str, path: &Path) -> Result<Config, ConfigError> {
        let cfg: Config =
            toml::from_str(text).map_err(|e| ConfigError::Parse { path: path.into(), message: e.to_string() })?;
        cfg.validate(path)?;
        Ok(cfg)
    }

    /// The whole configuration as JSON, every key: what a store records
    /// ([`crate::store::Store::record_config`]).
    pub fn to_recorded(&self) -> String {
        serde_json::to_string(self).expect("a Config serialises")
    }

    /// The configuration a store recorded (`store` names it in errors).
    /// Keys added to seam since take their defaults.
    pub fn from_recorded(json: &str, store: &Path) -> Result<Config, ConfigError> {
        serde_json::from_str(json).map_err(|e| ConfigError::Parse {
            path: store.into(),
            message: format!("the configuration recorded in this store does not parse: {e}"),
        })
    }

    /// The settings that differ from `other`'s, as `section.key = ours
    /// (theirs)` lines, leaving out `[ingest]` (how scans are read, not
    /// what comes of them).
    pub fn differences(&self, other: &Config) -> Vec<String> {
        fn walk(prefix: &str, a: &serde_json::Value, b: &serde_json::Value, out: &mut Vec<String>) {
            match (a, b) {
                (serde_json::Value::Object(x), serde_json::Value::Object(y)) => {
                    for (k, va) in x {
                        let key = if prefix.is_empty() { k.clone() } else { format!("{prefix}.{k}") };
                        match y.get(k) {
                            Some(vb) => walk(&key, va, vb, out),
                            None => out.push(format!("{key} = {va} (not set)")),
                        }
                    }
                }
                _ if a != b => out.push(format!("{prefix} = {a} ({b})")),
                _ => {}
            }
        }
        let json = |c: &Config| {
            let mut v = serde_json::to_value(c).expect("a Config serialises");
            v.as_object_mut().map(|o| o.remove("ingest"));
            v
        };
        let mut out = Vec::new();
        walk("", &json(self), &json(other), &mut out);
        out
    }

    fn validate(&self, path: &Path) -> Result<(), ConfigError> {
        let bad = |m: String| Err(ConfigError::Invalid { path: path.into(), message: m });
        if !(self.submap.submap_length_m > 0.0 && self.submap.submap_length_m.is_finite()) {
            return bad(format!("submap.submap_length_m = {} must be a positive length", self.submap.submap_length_m));
        }
        if self.submap.min_keyframes == 0 {
            return bad("submap.min_keyframes must be at least 1".into());
        }
        if self.ingest.read_batch_scans == 0 {
            return bad("ingest.read_batch_scans must be at least 1".into());
        }
        let positive = |name: &str, v: f64| -> Result<(), ConfigError> {
            if v > 0.0 && v.is_finite() { Ok(()) } else { bad(format!("{name} = {v} must be positive")) }
        };
        let g = &self.graph;
        positive("graph.odom_sigma_rot_rad", g.odom_sigma_rot_rad)?;
        positive("graph.odom_sigma_trans_m", g.odom_sigma_trans_m)?;
        positive("graph.loop_sigma_rot_rad", g.loop_sigma_rot_rad)?;
        positive("graph.loop_sigma_trans_m", g.loop_sigma_trans_m)?;
        positive("graph.loop_cauchy_k", g.loop_cauchy_k)?;
        positive("graph.anchor_prior_sigma_rot_rad", g.anchor_prior_sigma_rot_rad)?;
        positive("graph.anchor_prior_sigma_trans_m", g.anchor_prior_sigma_trans_m)?;
        positive("graph.submap_boundary_sigma_scale", g.submap_boundary_sigma_scale)?;
        let l = &self.loops;
        positive("loops.radius_m", l.radius_m)?;
        positive("loops.gicp.voxel_size_m", l.gicp.voxel_size_m)?;
        positive("loops.dop.voxel_size_m", l.dop.voxel_size_m)?;
        positive("coarse.map_voxel_m", self.coarse.map_voxel_m)?;
        if !(l.local_travel_m >= 0.0 && l.local_travel_m.is_finite()) {
            return bad(format!("loops.local_travel_m = {} must be 0 (off) or a positive length", l.local_travel_m));
        }
        if !(0.0..=1.0).contains(&l.min_inlier_ratio) {
            return bad(format!("loops.min_inlier_ratio = {} must be within [0, 1]", l.min_inlier_ratio));
        }
        if l.keyframe_stride == 0 || l.max_sessions_per_keyframe == 0 || self.coarse.map_keyframe_stride == 0 {
            return bad("loops.keyframe_stride, loops.max_sessions_per_keyframe and coarse.map_keyframe_stride must be at least 1".into());
        }
        self.global
            .validate()
            .map_err(|m| ConfigError::Invalid { path: path.into(), message: format!("global: {m}") })?;
        self.evidence.validate().map_err(|m| ConfigError::Invalid { path: path.into(), message: m })?;
        self.change.validate().map_err(|m| ConfigError::Invalid { path: path.into(), message: m })?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn file_overrides_only_what_it_names() {
        let c = Config::from_toml("[submap]\nsubmap_length_m = 30.0\n", Path::new("c.toml")).unwrap();
        assert_eq!(c.submap.submap_length_m, 30.0);
        assert_eq!(c.submap.min_keyframes, SubmapConfig::default().min_keyframes);
        assert_eq!(c.ingest, IngestConfig::default());
        assert_eq!(Config::from_toml("", Path::new("c.toml")).unwrap(), Config::default());
    }

    #[test]
    fn unknown_keys_and_bad_values_are_errors_naming_them() {
        let e = Config::from_toml("[submap]\nsubmap_lenght_m = 3\n", Path::new("c.toml")).unwrap_err();
        assert!(e.to_string().contains("submap_lenght_m"), "{e}");
        let e = Config::from_toml("[submap]\nsubmap_length_m = -1.0\n", Path::new("c.toml")).unwrap_err();
        assert!(e.to_string().contains("positive"), "{e}");
        let e = Config::from_toml("[graph]\nloop_sigma_trans_m = 0.0\n", Path::new("c.toml")).unwrap_err();
        assert!(e.to_string().contains("graph.loop_sigma_trans_m"), "{e}");
        let e = Config::from_toml("[loops.dop]\nrho_mx = 4.0\n", Path::new("c.toml")).unwrap_err();
        assert!(e.to_string().contains("rho_mx"), "{e}");
    }

    /// What a store records reads back as the same configuration, and the
    /// differences name exactly the keys that differ, `[ingest]` aside.
    #[test]
    fn recorded_config_round_trips_and_differences_name_the_keys() {
        let text = "[submap]\nsubmap_length_m = 12.5\n[loops.dop]\nrho_max = 4.0\n[ingest]\nread_batch_scans = 3\n";
        let c = Config::from_toml(text, Path::new("c.toml")).unwrap();
        let back = Config::from_recorded(&c.to_recorded(), Path::new("site.seam")).unwrap();
        assert_eq!(back, c);
        assert!(back.differences(&c).is_empty());
        let mut d = c.differences(&Config::default());
        d.sort();
        assert_eq!(d, vec!["loops.dop.rho_max = 4.0 (6.0)".to_string(), "submap.submap_length_m = 12.5 (20.0)".into()]);
        let e = Config::from_recorded("{\"submap\": 3}", Path::new("site.seam")).unwrap_err();
        assert!(e.to_string().contains("site.seam") && e.to_string().contains("recorded"), "{e}");
    }

    /// The nested sections of the module doc parse and land where they say.
    #[test]
    fn alignment_sections_override_their_stages() {
        let text = "[loops]\nradius_m = 15.0\n[loops.dop]\nrho_max = 4.0\n[graph]\nmode = \"session\"\n[global]\nvoxel_size_m = 0.75\n";
        let c = Config::from_toml(text, Path::new("c.toml")).unwrap();
        assert_eq!(c.loops.radius_m, 15.0);
        assert_eq!(c.loops.dop.rho_max, 4.0);
        assert_eq!(c.loops.dop.kappa, crate::registration::DopConfig::default().kappa);
        assert_eq!(c.graph.mode, crate::graph::AnchorMode::Session);
        assert_eq!(c.global.voxel_size_m, 0.75);
    }
}
