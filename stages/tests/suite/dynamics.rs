//! RNEA against independent truths: closed forms (1-dof, planar 2-dof) and
//! the Lagrangian twin (energies by forward kinematics, finite differences).

use robotid_tests::fixture;
use std::path::Path;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use robotid_stages::dynamics::{self, lagrange, Data, Model};

fn rel_err(a: &[f64], b: &[f64]) -> f64 {
    let num = a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
    let den = b.iter().map(|y| y.abs()).fold(0.0, f64::max);
    num / den
}

fn random_state(rng: &mut ChaCha8Rng, n: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let mut v = |s: f64| (0..n).map(|_| rng.random_range(-s..s)).collect::<Vec<f64>>();
    (v(3.0), v(2.0), v(5.0))
}

#[test]
fn one_dof_matches_swevers_eq7() {
    let model = dynamics::load_robot(&fixture("robots/kuka_axis3.toml")).unwrap();
    let mut data = Data::new(&model);
    let link = &model.links[0];
    let (m, lx, ly) = (link.mass, link.com.x, link.com.y);
    let j = link.inertia_com[(2, 2)] + m * (lx * lx + ly * ly);
    assert!(
        (j - 8.348).abs() < 1e-12,
        "inertia about the axis is Swevers' 8.348, got {j}"
    );
    let g = 9.81;
    let (v, c) = (3.676, 15.8927);
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    for _ in 0..200 {
        let (q, qd, qdd) = random_state(&mut rng, 1);
        let expected = j * qdd[0] - m * g * lx * q[0].sin() - m * g * ly * q[0].cos() + v * qd[0] + c * qd[0].signum();
        let tau = dynamics::rnea(&model, &mut data, &q, &qd, &qdd)[0];
        assert!(rel_err(&[tau], &[expected]) < 1e-12, "{tau} vs {expected}");
    }
}

const PLANAR_2DOF: &str = r#"
name = "planar2"
gravity = [0.0, -9.81, 0.0]
[[joint]]
name = "j1"
mass = 3.0
com = [0.35, 0.0, 0.0]
inertia = { ixx = 0.01, iyy = 0.2, izz = 0.21 }
[[joint]]
name = "j2"
origin = { xyz = [0.8, 0.0, 0.0] }
mass = 2.0
com = [0.25, 0.0, 0.0]
inertia = { ixx = 0.01, iyy = 0.1, izz = 0.11 }
"#;

#[test]
fn planar_two_dof_matches_closed_form() {
    let model = dynamics::parse_robot_file(PLANAR_2DOF, Path::new("planar2.toml")).unwrap();
    let mut data = Data::new(&model);
    let (m1, m2, l1, c1, c2, i1, i2, g) = (3.0, 2.0, 0.8, 0.35, 0.25, 0.21, 0.11, 9.81);
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    for _ in 0..200 {
        let (q, qd, qdd) = random_state(&mut rng, 2);
        let (s2, k2) = q[1].sin_cos();
        let m11 = i1 + i2 + m1 * c1 * c1 + m2 * (l1 * l1 + c2 * c2 + 2.0 * l1 * c2 * k2);
        let m12 = i2 + m2 * (c2 * c2 + l1 * c2 * k2);
        let m22 = i2 + m2 * c2 * c2;
        let h = m2 * l1 * c2 * s2;
        let g1 = (m1 * c1 + m2 * l1) * g * q[0].cos() + m2 * c2 * g * (q[0] + q[1]).cos();
        let g2 = m2 * c2 * g * (q[0] + q[1]).cos();
        let t1 = m11 * qdd[0] + m12 * qdd[1] - h * (2.0 * qd[0] * qd[1] + qd[1] * qd[1]) + g1;
        let t2 = m12 * qdd[0] + m22 * qdd[1] + h * qd[0] * qd[0] + g2;
        let tau = dynamics::rnea(&model, &mut data, &q, &qd, &qdd).as_slice().to_vec();
        assert!(rel_err(&tau, &[t1, t2]) < 1e-12, "{tau:?} vs {:?}", [t1, t2]);
    }
}

fn check_against_lagrangian(model: &Model, seed: u64) {
    let mut data = Data::new(model);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = model.dof();
    let (mut worst_m, mut worst_tau) = (0.0f64, 0.0f64);
    for _ in 0..20 {
        let (q, qd, qdd) = random_state(&mut rng, n);
        // Mass matrix: from the kinetic energy, exact up to round-off.
        let m_lag = lagrange::mass_matrix_lagrange(model, &mut data, &q);
        let m_ne = dynamics::mass_matrix(model, &mut data, &q).clone();
        let em = rel_err(m_ne.as_slice(), m_lag.as_slice());
        worst_m = worst_m.max(em);
        assert!(em < 1e-12, "mass matrix: {em:e}");
        // Full torque: gravity and Coriolis by central differences (h = 1e-5
        // rad: truncation ~1e-10, round-off ~1e-11 relative).
        let lag = lagrange::inverse_dynamics_lagrange(model, &mut data, &q, &qd, &qdd, 1e-5);
        let ne = dynamics::rnea(model, &mut data, &q, &qd, &qdd).clone();
        let e = rel_err(ne.as_slice(), lag.as_slice());
        worst_tau = worst_tau.max(e);
        assert!(e < 1e-6, "{}: RNEA vs Lagrangian relative error {e:e}", model.name);
    }
    println!(
        "{}: worst relative error, mass matrix {worst_m:.1e}, torques {worst_tau:.1e}",
        model.name
    );
}

#[test]
fn six_dof_ur5_matches_lagrangian() {
    let model = dynamics::load_robot(&fixture("robots/ur5.toml")).unwrap();
    assert_eq!(model.dof(), 6);
    assert_eq!(model.joints[0].name, "shoulder_pan_joint");
    // The fixed ee_link adds no mass; the tool point is 0.0823 m out on y.
    assert!((model.end_effector - nalgebra::Vector3::new(0.0, 0.0823, 0.0)).norm() < 1e-15);
    check_against_lagrangian(&model, 3);
}

#[test]
fn three_dof_arm_matches_lagrangian() {
    let model = dynamics::load_robot(&fixture("robots/arm3.toml")).unwrap();
    check_against_lagrangian(&model, 4);
}

/// A robot file whose link inertia no body has (a typo: j2's moments
/// 8.0, 3.7, 0.35 kg·m² break the triangle inequality, 8.0 > 4.05) loads
/// with a warning that names the link and both sets of moments, its body
/// the nearest physical one: in the principal axes the mass's second
/// moments (½tr − I) = (−1.975, 2.325, 5.675) with the negative one set to
/// 0, so the moments become (8.0, 5.675, 2.325): the triangle met with
/// equality, the other links untouched.
#[test]
fn a_link_no_body_has_is_loaded_as_the_nearest_body_and_said() {
    let dir = tempfile::tempdir().unwrap();
    let file = robotid_tests::arm3_with_a_link_no_body_has(dir.path());
    let model = dynamics::load_robot(&file).unwrap();
    let good = dynamics::load_robot(&fixture("robots/arm3.toml")).unwrap();
    assert_eq!(model.warnings.len(), 1, "{:?}", model.warnings);
    let w = &model.warnings[0];
    assert!(w.contains("`j2`") && w.contains("triangle inequality"), "{w}");
    assert!(w.contains("3.500000e-1, 3.700000e0, 8.000000e0"), "{w}");
    assert!(w.contains("2.325000e0, 5.675000e0, 8.000000e0"), "{w}");
    let i = model.links[1].inertia_com;
    let expected = nalgebra::Matrix3::from_diagonal(&nalgebra::Vector3::new(8.0, 5.675, 2.325));
    assert!((i - expected).abs().max() < 1e-12, "{i}");
    assert_eq!(model.links[0], good.links[0]);
    assert_eq!(model.links[2], good.links[2]);
    assert!(good.warnings.is_empty());
}

#[test]
fn real_kuka_lwr4_urdf_loads_and_matches_lagrangian() {
    let Some(dir) = robotid_tests::realdata("kuka_lwr4") else {
        return;
    };
    let model = dynamics::load_robot(&dir.join("kuka_lwr4.urdf")).unwrap();
    assert_eq!(model.dof(), 7);
    assert_eq!(model.warnings.len(), 1, "{:?}", model.warnings);
    assert!(model.warnings[0].contains("box_lwr_base_joint"));
    check_against_lagrangian(&model, 5);
}

/// Also on a coupled wrist: its rotor (in M) and its friction (at the
/// motor's speed, through Rᵀ) both inverted.
#[test]
fn forward_dynamics_inverts_rnea() {
    let model = dynamics::load_robot(&fixture("robots/ur5.toml")).unwrap();
    let coupled = super::coupled_ur5(2.5e-4, (3e-3, 0.2));
    for model in [model, coupled] {
        let mut data = Data::new(&model);
        let mut rng = ChaCha8Rng::seed_from_u64(6);
        for _ in 0..50 {
            let (q, qd, qdd) = random_state(&mut rng, 6);
            let tau = dynamics::rnea(&model, &mut data, &q, &qd, &qdd).as_slice().to_vec();
            let mut back = vec![0.0; 6];
            dynamics::forward_dynamics(&model, &mut data, &q, &qd, &tau, &mut back);
            assert!(rel_err(&back, &qdd) < 1e-9, "{back:?} vs {qdd:?}");
        }
    }
}

#[test]
fn robot_file_errors_name_the_place() {
    let bad = "name = \"x\"\n[[joint]]\nname = \"a\"\nmass = 1.0\ninertia = { ixx = 1.0, iyy = 1.0, izz = 1.0 }\nmasss = 2.0\n";
    let e = dynamics::parse_robot_file(bad, Path::new("bad.toml"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("bad.toml") && e.contains("masss") && e.contains("line 6"),
        "{e}"
    );

    let both = PLANAR_2DOF.replace("name = \"j2\"", "name = \"j2\"\nviscous = 1.0\nviscous_pos = 2.0");
    let e = dynamics::parse_robot_file(&both, Path::new("p.toml"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("joint `j2`") && e.contains("viscous"), "{e}");

    let dup = PLANAR_2DOF.replace("name = \"j2\"", "name = \"j1\"");
    let e = dynamics::parse_robot_file(&dup, Path::new("p.toml"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("`j1` is used twice"), "{e}");

    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("neg.toml");
    std::fs::write(&p, PLANAR_2DOF.replace("mass = 2.0", "mass = -2.0")).unwrap();
    let e = dynamics::load_robot(&p).unwrap_err().to_string();
    assert!(e.contains("joint 2 (`j2`)") && e.contains("mass"), "{e}");
}

#[test]
fn modified_dh_equals_explicit_origin() {
    let dh = PLANAR_2DOF.replace(
        "origin = { xyz = [0.8, 0.0, 0.0] }",
        "dh = { a = 0.8, alpha = 0.0, d = 0.0 }",
    );
    let a = dynamics::parse_robot_file(PLANAR_2DOF, Path::new("a.toml")).unwrap();
    let b = dynamics::parse_robot_file(&dh, Path::new("b.toml")).unwrap();
    assert_eq!(a.joints[1].origin_xyz, b.joints[1].origin_xyz);
    // A twisted DH joint: alpha = pi/2 turns z into -y... of the parent.
    let twisted = dh.replace("alpha = 0.0, d = 0.0", "alpha = 1.5707963267948966, d = 0.3");
    let c = dynamics::parse_robot_file(&twisted, Path::new("c.toml")).unwrap();
    let z_in_parent = c.joints[1].origin_rot * nalgebra::Vector3::z();
    assert!((z_in_parent - nalgebra::Vector3::new(0.0, -1.0, 0.0)).norm() < 1e-15);
    assert!((c.joints[1].origin_xyz - nalgebra::Vector3::new(0.8, -0.3, 0.0)).norm() < 1e-15);
}

/// URDF export round trip: the exported file, loaded again, has the same
/// inverse dynamics, gravity direction included (the KUKA axis's gravity is
/// −x; the export turns the base so that URDF's −z is it). Rotor inertia
/// and asymmetric friction have no place in URDF (they go into comments),
/// so they are left out of the comparison.
#[test]
fn urdf_export_round_trips() {
    use robotid_stages::dynamics::{parse_urdf, rnea, Friction};
    use robotid_stages::export::to_urdf;
    for robot in ["kuka_axis3.toml", "arm3.toml", "ur5.urdf"] {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../fixtures/robots")
            .join(robot);
        let mut model = dynamics::load_robot(&path).unwrap();
        model.drives.iter_mut().for_each(|d| d.rotor_inertia = 0.0);
        model.friction.iter_mut().for_each(|f| *f = Friction::default());
        let text = to_urdf(&model, "round trip");
        let back = parse_urdf(&text, Path::new("exported.urdf")).unwrap();
        let (mut d1, mut d2) = (Data::new(&model), Data::new(&back));
        let n = model.dof();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut worst: f64 = 0.0;
        for _ in 0..20 {
            let mut v = |a: f64| (0..n).map(|_| rng.random_range(-a..a)).collect::<Vec<f64>>();
            let (q, qd, qdd) = (v(2.0), v(2.0), v(5.0));
            let t1 = rnea(&model, &mut d1, &q, &qd, &qdd).clone();
            let t2 = rnea(&back, &mut d2, &q, &qd, &qdd).clone();
            worst = worst.max((&t1 - &t2).amax() / t1.amax().max(1.0));
        }
        println!("{robot}: exported URDF vs model, worst relative torque difference {worst:e}");
        assert!(worst < 1e-9, "{robot}: {worst}");
    }
}

/// URDFs that are not trees are refused by name, at once: a joint that is
/// its own parent, a link with two parents, a cycle away from the root
/// (they made `model inspect` and `lint` allocate 9.66 GB and abort).
#[test]
fn urdfs_that_are_not_trees_are_refused() {
    use robotid_stages::dynamics::parse_urdf;
    let link = |n: &str| {
        format!(
            r#"<link name="{n}"><inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>"#
        )
    };
    let joint = |n: &str, p: &str, c: &str| {
        format!(
            r#"<joint name="{n}" type="revolute"><parent link="{p}"/><child link="{c}"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="10" velocity="1"/></joint>"#
        )
    };
    let urdf = |links: &[&str], joints: &[(&str, &str, &str)]| {
        let l: String = links.iter().map(|n| link(n)).collect();
        let j: String = joints.iter().map(|(n, p, c)| joint(n, p, c)).collect();
        format!(r#"<robot name="r">{l}{j}</robot>"#)
    };
    let cases = [
        (
            urdf(&["base", "a", "b"], &[("j1", "base", "a"), ("j2", "b", "b")]),
            "joint `j2` is its own parent",
        ),
        (
            urdf(
                &["base", "a", "b"],
                &[("j1", "base", "a"), ("j2", "a", "b"), ("j3", "base", "b")],
            ),
            "link `b` is the child of joints `j2` and `j3`",
        ),
        (
            urdf(
                &["base", "a", "b", "c"],
                &[("j1", "base", "a"), ("j2", "b", "c"), ("j3", "c", "b")],
            ),
            "link `b` is not connected to the root link `base`",
        ),
    ];
    for (text, says) in cases {
        let e = parse_urdf(&text, Path::new("r.urdf")).unwrap_err().to_string();
        assert!(e.contains(says), "{e}");
    }
}

/// Descriptions with values no robot has are refused by joint and key:
/// an infinite inertia or a 1e300 kg link (`lint` passed them, `run`
/// panicked in the SVD), a NaN origin in a URDF (`model inspect` never
/// returned).
#[test]
fn impossible_bodies_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let load = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        dynamics::load_robot(&p).unwrap_err().to_string()
    };
    let toml = std::fs::read_to_string(fixture("robots/arm3.toml")).unwrap();
    for (edit, says) in [
        (("ixx = 3.6", "ixx = inf"), "joint 2 (`j2`): its link's inertia = inf"),
        (
            ("mass = 40.0", "mass = 1e300"),
            "joint 2 (`j2`): its link's mass = 1e300",
        ),
    ] {
        assert!(toml.contains(edit.0));
        let e = load("arm3.toml", &toml.replacen(edit.0, edit.1, 1));
        assert!(e.contains(says), "{e}");
    }
    // The first joint's origin, its x made NaN.
    let urdf = std::fs::read_to_string(fixture("robots/ur5.urdf")).unwrap();
    let joint = urdf.find("<joint").unwrap();
    let at = joint + urdf[joint..].find("<origin xyz=\"").unwrap() + "<origin xyz=\"".len();
    let x = urdf[at..].find(' ').unwrap();
    // Refused as it is read, naming the element, its line and attribute.
    let e = load("ur5.urdf", &format!("{}nan{}", &urdf[..at], &urdf[at + x..]));
    assert!(
        e.contains("<origin> (line 34), attribute `xyz`") && e.contains("not finite"),
        "{e}"
    );
}

/// A link's extent from its URDF shapes, in its frame: a box placed and
/// turned by its origin, a sphere on a link lumped in by a fixed joint, a
/// binary STL mesh found by `package://`; a link whose mesh is missing has
/// none. Corners worked out by hand.
#[test]
fn link_extents_come_from_the_urdf_shapes() {
    let dir = tempfile::tempdir().unwrap();
    // One triangle spanning (0,0,0)–(0.1,0.2,0.3).
    let mut stl = vec![0u8; 80];
    stl.extend(1u32.to_le_bytes());
    stl.extend([0u8; 12]);
    for v in [[0.0f32, 0.0, 0.0], [0.1, 0.2, 0.0], [0.0, 0.0, 0.3]] {
        for x in v {
            stl.extend(x.to_le_bytes());
        }
    }
    stl.extend([0u8; 2]);
    std::fs::create_dir_all(dir.path().join("meshes")).unwrap();
    std::fs::write(dir.path().join("meshes/l2.stl"), &stl).unwrap();
    let inertial =
        r#"<inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>"#;
    let urdf = format!(
        r#"<robot name="r">
  <link name="base"/>
  <link name="l1">{inertial}
    <collision><origin xyz="0 0 0.5" rpy="0 0 1.5707963267948966"/><geometry><box size="0.2 0.4 1.0"/></geometry></collision>
    <visual><geometry><sphere radius="9"/></geometry></visual>
  </link>
  <link name="tool">{inertial}<collision><origin xyz="0 0 1.2"/><geometry><sphere radius="0.1"/></geometry></collision></link>
  <link name="l2">{inertial}<visual><origin xyz="1 0 0"/><geometry><mesh filename="package://desc/meshes/l2.stl" scale="2 2 2"/></geometry></visual></link>
  <link name="l3">{inertial}<collision><geometry><mesh filename="package://desc/meshes/missing.stl"/></geometry></collision></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="fix" type="fixed"><parent link="l1"/><child link="tool"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 1"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/><origin xyz="1 0 0"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>"#
    );
    let path = dir.path().join("r.urdf");
    std::fs::write(&path, &urdf).unwrap();
    let m = dynamics::load_urdf(&path).unwrap();
    let close = |a: nalgebra::Vector3<f64>, b: [f64; 3]| (a - nalgebra::Vector3::from(b)).amax() < 1e-6;
    // l1: the box turned 90° about z (0.4 along x, 0.2 along y), z 0..1;
    // the tool's sphere at z = 1.2 (radius 0.1) lumped in; not the visual.
    let e = m.extent(0).unwrap();
    assert!(
        close(e.min, [-0.2, -0.1, 0.0]) && close(e.max, [0.2, 0.1, 1.3]),
        "{e:?}"
    );
    // l2: the mesh scaled 2×, 1 m along x.
    let e = m.extent(1).unwrap();
    assert!(close(e.min, [1.0, 0.0, 0.0]) && close(e.max, [1.2, 0.4, 0.6]), "{e:?}");
    assert_eq!(m.extent(2), None);
}
