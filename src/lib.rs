//! # seam — a lifelong LiDAR map store
//!
//! (crate docs are written as the pipeline lands)

pub mod config;
pub mod fault;
pub mod geometry;
pub mod io;
pub mod sensor;
pub mod sim;
pub mod store;
pub mod cli;
pub mod pipeline;
