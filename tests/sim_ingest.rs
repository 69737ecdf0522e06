//! `seam simulate` with each sensor model, then `seam ingest` of every
//! session: what the demo does, through the binary.

mod common;
use common::*;

#[test]
fn simulate_then_ingest_every_session_for_each_sensor() {
    for sensor in ["os1-64", "vlp16", "avia"] {
        let tmp = tempfile::tempdir().unwrap();
        let summary = simulate(&tmp.path().join("sim"), 2, 8, 7, &["--sensor", sensor]);
        let store = tmp.path().join("site.seam");
        init_store(&store);
        for (k, s) in summary["sessions"].as_array().unwrap().iter().enumerate() {
            let dir = s["dir"].as_str().unwrap();
            let o = run(&["ingest", store.to_str().unwrap(), dir, "--format", "json"]);
            assert!(o.status.success(), "{sensor}: {}", stderr(&o));
            let r: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
            assert_eq!(r["session_id"], k as i64 + 1);
            assert_eq!(r["keyframes"], 8);
            assert_eq!(r["points"], s["points"], "{sensor}: stored points differ from simulated points");
        }
        let o = run(&["sessions", store.to_str().unwrap(), "--format", "json"]);
        let sessions: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
        for (k, s) in sessions.as_array().unwrap().iter().enumerate() {
            assert_eq!(s["name"], format!("s{}", k + 1));
            assert_eq!(s["sensor_model"], sensor);
            assert_eq!(s["status"], "complete");
            assert!(s["date"].as_str().is_some_and(|d| d.starts_with("20")), "{s}");
        }
        assert!(run(&["check", store.to_str().unwrap()]).status.success());
    }
}
