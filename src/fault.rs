//! Fault injection for crash-consistency tests.
//!
//! `SEAM_FAULT=<point>` makes the process abort (as `kill -9` would: no
//! destructors, no flushes) when it reaches the named point. Points are named
//! `<step>:<moment>`, e.g. `scans:before_rename`, `scans:before_commit`.
//! `SEAM_FAULT=list` prints every point reached, to stderr, without aborting,
//! so a test can enumerate them. Costs one environment lookup per point.

/// Aborts the process if `SEAM_FAULT` names this point.
pub fn point(name: &str) {
    if let Some(v) = std::env::var_os("SEAM_FAULT") {
        if v == "list" {
            eprintln!("seam-fault-point {name}");
        } else if v == name {
            eprintln!("seam: injected fault at {name}");
            std::process::abort();
        }
    }
}
