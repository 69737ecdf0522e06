//! ρ (MATH.md §4) of single scans as the loop test sees them (GICP
//! preprocessing, then the 0.5 m DOP voxel): what a scan's own geometry
//! scores, to choose `DopConfig::rho_max` for a sensor.
//!
//! `cargo run --release --example rho_probe -- hdl64e ../shared/data/semantickitti/04/velodyne/00000*.bin`

use seam::registration::{DopConfig, GicpConfig, preprocess, rho};
use seam::sensor::SensorModel;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(model) = args.first().and_then(|m| SensorModel::parse(m)) else {
        return Err("usage: rho_probe SENSOR_MODEL SCAN... (models: os1-64, vlp16, hdl64e, hdl32e, avia)".into());
    };
    let voxel = DopConfig::default().voxel_size_m;
    println!("scan,points,mean_range_m,n,n_typ,g0,rho");
    for p in &args[1..] {
        let scan = seam::io::read_scan(std::path::Path::new(p))?;
        let prepared = preprocess(&scan.points, &GicpConfig::default());
        let r = rho(prepared.points(), &model.fov(), voxel);
        println!("{p},{},{:.1},{},{:.0},{:.3},{:.3}", scan.len(), r.mean_range_m, r.n, r.n_typ, r.g0, r.rho);
    }
    Ok(())
}
