//! RNEA and the regressor against Pinocchio (the `pin` Python package,
//! installed by scripts/test.sh): the same URDF, the same random states,
//! torques equal to 1e-9 relative.

use robotid_tests::python;
use std::path::Path;
use std::process::Command;

use nalgebra::{DMatrix, DVector};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use robotid_stages::dynamics::{self, regressor, standard_parameters, Data, FrictionTerms, RegressorTerms};

#[test]
fn rnea_and_regressor_match_pinocchio() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    for urdf in [
        root.join("fixtures/robots/ur5.urdf"),
        root.join("../shared/realdata/kuka_lwr4/kuka_lwr4.urdf"),
    ] {
        let model = dynamics::load_robot(&urdf).unwrap();
        let n = model.dof();
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut states: [Vec<Vec<f64>>; 3] = Default::default();
        for _ in 0..30 {
            for (s, scale) in states.iter_mut().zip([3.0, 2.0, 5.0]) {
                s.push((0..n).map(|_| rng.random_range(-scale..scale)).collect());
            }
        }
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("states.json");
        let json = serde_json::json!({"q": states[0], "v": states[1], "a": states[2]});
        std::fs::write(&file, json.to_string()).unwrap();
        let out = Command::new(python())
            .arg(root.join("tests/python/pin_rnea.py"))
            .arg(&urdf)
            .arg(&file)
            .output()
            .unwrap_or_else(|e| panic!("cannot run {}: {e}; run scripts/test.sh, which installs pin", python()));
        assert!(
            out.status.success(),
            "Pinocchio failed (run scripts/test.sh to install `pin`):\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(
            v["nq"].as_u64(),
            Some(n as u64),
            "{}: Pinocchio sees {} joints",
            urdf.display(),
            v["nq"]
        );
        let names: Vec<String> = v["names"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| s.as_str().unwrap().to_string())
            .collect();
        assert_eq!(names, model.joint_names());
        let terms = RegressorTerms {
            rotor: false,
            friction: FrictionTerms::None,
            offset: false,
            spring: None,
        };
        let theta = DVector::from_vec(standard_parameters(&model, terms));
        let mut data = Data::new(&model);
        let mut phi = DMatrix::zeros(n, terms.count(n));
        let (mut worst_rnea, mut worst_reg) = (0.0f64, 0.0f64);
        for (k, tau_pin) in v["tau"].as_array().unwrap().iter().enumerate() {
            let tau_pin = DVector::from_iterator(n, tau_pin.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()));
            let (q, qd, qdd) = (&states[0][k], &states[1][k], &states[2][k]);
            // Pinocchio's RNEA is rigid-body only: no joint friction (the
            // LWR4+ URDF declares <dynamics damping friction>) and no rotors.
            let rigid = dynamics::Terms {
                gravity: true,
                friction: false,
                rotor: false,
            };
            let ours = dynamics::rnea_terms(&model, &mut data, q, qd, qdd, rigid).clone();
            regressor(&model, &mut data, q, qd, qdd, terms, &mut phi);
            let reg = &phi * &theta;
            let scale = tau_pin.amax();
            worst_rnea = worst_rnea.max((&ours - &tau_pin).amax() / scale);
            worst_reg = worst_reg.max((&reg - &tau_pin).amax() / scale);
        }
        println!(
            "{}: vs Pinocchio, RNEA {worst_rnea:.1e}, regressor {worst_reg:.1e}",
            model.name
        );
        assert!(
            worst_rnea < 1e-9 && worst_reg < 1e-9,
            "{}: {worst_rnea:e} {worst_reg:e}",
            model.name
        );
    }
}
