//! Simulated construction site (placeholder: filled in by the simulator work).
