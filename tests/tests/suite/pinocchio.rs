//! RNEA and the regressor against Pinocchio (the `pin` Python package,
//! installed by scripts/test.sh): the same URDF, the same random states,
//! torques equal to 1e-9 relative.

use robotid_tests::{panda_urdf, python};
use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

use nalgebra::{DMatrix, DVector};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use robotid_stages::dynamics::{self, regressor, standard_parameters, Data, FrictionTerms, RegressorTerms};

/// A 4-link arm with a prismatic joint in mid-chain and a mimic pair at the
/// tool: both load, locked; the reduced model is Pinocchio's.
const PRISMATIC_URDF: &str = r#"<robot name="telescope">
  <link name="base"/>
  <link name="l1"><inertial><origin xyz="0 0 0.2" rpy="0.1 0 0"/><mass value="3"/><inertia ixx="0.05" ixy="0.001" ixz="0" iyy="0.04" iyz="0.002" izz="0.02"/></inertial></link>
  <link name="l2"><inertial><origin xyz="0.1 0 0.1" rpy="0 0 0"/><mass value="2"/><inertia ixx="0.02" ixy="0" ixz="0" iyy="0.03" iyz="0" izz="0.015"/></inertial></link>
  <link name="l3"><inertial><origin xyz="0 0.05 0.3" rpy="0 0.2 0"/><mass value="1.5"/><inertia ixx="0.02" ixy="0" ixz="0.001" iyy="0.02" iyz="0" izz="0.005"/></inertial></link>
  <link name="l4"><inertial><origin xyz="0.05 0 0.1" rpy="0 0 0"/><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.004"/></inertial></link>
  <link name="f1"><inertial><origin xyz="0 0.01 0.02" rpy="0 0 0"/><mass value="0.1"/><inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial></link>
  <link name="f2"><inertial><origin xyz="0 -0.01 0.02" rpy="0 0 0"/><mass value="0.1"/><inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.1" rpy="0 0 0"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="100" velocity="2"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.4" rpy="0 0 0"/><axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="100" velocity="2"/></joint>
  <joint name="slide" type="prismatic"><parent link="l2"/><child link="l3"/><origin xyz="0.2 0 0" rpy="0 0.3 0"/><axis xyz="0 0 1"/><limit lower="0.05" upper="0.5" effort="100" velocity="0.5"/></joint>
  <joint name="j4" type="revolute"><parent link="l3"/><child link="l4"/><origin xyz="0 0 0.5" rpy="0 0 0"/><axis xyz="1 0 0"/><limit lower="-3" upper="3" effort="100" velocity="2"/></joint>
  <joint name="finger1" type="prismatic"><parent link="l4"/><child link="f1"/><origin xyz="0 0 0.2" rpy="0 0 0"/><axis xyz="0 1 0"/><limit lower="0" upper="0.04" effort="10" velocity="0.1"/></joint>
  <joint name="finger2" type="prismatic"><parent link="l4"/><child link="f2"/><origin xyz="0 0 0.2" rpy="0 0 0"/><axis xyz="0 -1 0"/><limit lower="0" upper="0.04" effort="10" velocity="0.1"/><mimic joint="finger1"/></joint>
</robot>"#;

#[test]
fn rnea_and_regressor_match_pinocchio() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let dir = tempfile::tempdir().unwrap();
    let telescope = dir.path().join("telescope.urdf");
    std::fs::write(&telescope, PRISMATIC_URDF).unwrap();
    let mut cases: Vec<(std::path::PathBuf, BTreeMap<String, f64>)> = vec![
        (root.join("fixtures/robots/ur5.urdf"), BTreeMap::new()),
        (
            telescope,
            BTreeMap::from([("slide".to_string(), 0.23), ("finger1".to_string(), 0.015)]),
        ),
    ];
    if let Some(dir) = robotid_tests::realdata("kuka_lwr4") {
        cases.push((dir.join("kuka_lwr4.urdf"), BTreeMap::new()));
    }
    if let Some(p) = panda_urdf() {
        cases.push((p, BTreeMap::from([("panda_finger_joint1".to_string(), 0.02)])));
    }
    for (urdf, locks) in cases {
        let lock = dynamics::Locks {
            keep: None,
            positions: locks.clone(),
        };
        let model = dynamics::load_robot_with(&urdf, &lock).unwrap();
        // Pinocchio locks every joint the model does not keep, mimics included.
        let locked: BTreeMap<String, f64> = model.locked.iter().cloned().collect();
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
        let mut cmd = Command::new(python());
        cmd.arg(root.join("tests/python/pin_rnea.py")).arg(&urdf).arg(&file);
        if !locked.is_empty() {
            cmd.arg(serde_json::to_string(&locked).unwrap());
        }
        let out = cmd
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
        let mut phi = DMatrix::zeros(n, terms.count(&model));
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
