//! `seam demo`, the README's first command, on a small site: it simulates,
//! ingests and aligns every session and reports each one.

mod common;
use common::*;

#[test]
fn demo_runs_end_to_end_on_a_small_site() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("demo");
    let o = run(&["demo", "--out", out.to_str().unwrap(), "--keyframes", "12", "--sessions", "2", "--format", "json"]);
    assert!(o.status.success(), "demo failed: {}", stderr(&o));
    let r: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let sessions = r["sessions"].as_array().unwrap();
    assert_eq!(sessions.len(), 2);
    assert!(sessions.iter().all(|s| s["status"] == "complete"));
    // Every ingest went through the alignment steps.
    for receipt in r["receipts"].as_array().unwrap() {
        let steps: Vec<&str> =
            receipt["steps"].as_array().unwrap().iter().map(|s| s["step"].as_str().unwrap()).collect();
        assert!(steps.contains(&"coarse_align") && steps.contains(&"optimize"), "{steps:?}");
    }
    let o = run(&["check", out.join("site.seam").to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));

    // The table a person sees: alignment and ATE against the truth per session.
    let out = tmp.path().join("demo-table");
    let o = run(&["demo", "--out", out.to_str().unwrap(), "--keyframes", "12", "--sessions", "2"]);
    assert!(o.status.success(), "demo failed: {}", stderr(&o));
    let table = stdout(&o);
    assert!(table.contains("ate_m") && table.contains("reference"), "{table}");
}
