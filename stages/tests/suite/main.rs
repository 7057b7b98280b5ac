//! The stages crate's integration tests, one binary: each file a module
//! (linked once rather than once per file; fixtures made once per run).
//! Tests that count a process's allocations keep binaries of their own.

mod adequacy;
mod band_limit;
mod corrupt;
mod dynamics;
mod estimate;
mod excite;
mod identifiability;
mod identification;
mod preprocess;
mod read;
mod regressor;
mod rollout;
mod rows_on_demand;
mod simulate;

/// The UR5 (fixtures/robots/ur5.toml) with a coupled wrist: its last motor
/// also turns with joint 5, 40 turns the other way, with a rotor
/// `rotor_inertia` and a motor-side friction of its own (viscous,
/// Coulomb).
fn coupled_ur5(rotor_inertia: f64, (viscous, coulomb): (f64, f64)) -> robotid_stages::dynamics::Model {
    let mut model = robotid_stages::dynamics::load_robot(&robotid_tests::fixture("robots/ur5.toml")).unwrap();
    model.couplings.push(robotid_stages::dynamics::Coupling {
        motor: 5,
        with: vec![(4, -40.0)],
        viscous,
        coulomb,
    });
    model.drives[5].rotor_inertia = rotor_inertia;
    model.validate().unwrap();
    model
}
