//! A robot file as TOML and as URDF (the first byte chooses), loaded and,
//! when it loads, its mass matrix and inverse dynamics at a fixed state:
//! never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;
use robotid_stages::dynamics::{load_robot, mass_matrix, rnea, Data};

#[path = "common.rs"]
mod common;

fuzz_target!(|data: &[u8]| {
    let Some((&kind, rest)) = data.split_first() else { return };
    let path = common::as_file(rest, if kind % 2 == 0 { "robot.toml" } else { "robot.urdf" });
    if let Ok(model) = load_robot(&path) {
        let n = model.dof();
        if n == 0 || n > 64 {
            return;
        }
        let mut d = Data::new(&model);
        let q: Vec<f64> = (0..n).map(|i| 0.1 * i as f64).collect();
        let _ = mass_matrix(&model, &mut d, &q);
        let _ = rnea(&model, &mut d, &q, &q, &q);
    }
});
