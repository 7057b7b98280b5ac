//! The regressor's rows made on demand, a block at a time, against A made
//! whole, on the UR5 (6 joints, the SIMD chain kernel) and the 3-joint
//! arm: the same rows bit for bit from any range of samples, and so the
//! same condition number, torque check, estimate summary and table.

use nalgebra::DVector;
use robotid_stages::estimation::Summary;
use robotid_stages::formats::parquet::content_crc32;
use robotid_stages::signal::Spectra;
use robotid_stages::stage::regressor::regressor_rows;
use robotid_tests::regressor_case;

#[test]
fn rows_made_in_blocks_are_the_rows_of_the_whole_matrix() {
    for robot in ["robots/ur5.urdf", "robots/arm3.toml"] {
        let (base, _, kin) = regressor_case(robot, 1337);
        let n = base.model.dof();
        let whole = base.matrix(&kin);
        // Ranges that start and end off the kernel's lanes and chunks.
        for (start, len) in [(0, 1337), (1, 5), (3, 256), (257, 700), (1336, 1), (600, 0)] {
            let part = base.matrix_of(&kin.q, &kin.qd, &kin.qdd, start..start + len);
            assert_eq!(part.shape(), (len * n, base.parameters()));
            assert!(
                part == whole.rows(start * n, len * n),
                "{robot}: samples {start}..{}",
                start + len
            );
        }
    }
}

#[test]
fn an_estimate_and_table_from_rows_made_on_demand_equal_those_from_a_whole() {
    for robot in ["robots/ur5.urdf", "robots/arm3.toml"] {
        // Over four blocks of rows, the last one short.
        let (base, cfg, kin) = regressor_case(robot, 1700);
        let spectra = Spectra::new();
        let rows = |on_demand| regressor_rows(&kin, None, None, &base, &cfg, None, &spectra, "r", on_demand).unwrap();
        let (whole, made) = (rows(false), rows(true));
        assert!(whole.maker.is_none() && made.maker.is_some());
        assert_eq!(made.system.a.shape(), (0, base.parameters()), "A not kept");
        assert!(made.source().block(0, made.system.rows()) == whole.system.a);
        assert_eq!(made.condition, whole.condition, "{robot}");
        assert!(whole.condition.is_finite() && whole.condition > 1.0);
        // The torque is 1.1× the file's: no warning either way.
        assert_eq!((&made.torque_note, &whole.torque_note), (&None, &None));
        let w = DVector::from_fn(whole.system.rows(), |i, _| 1.0 + (i % 7) as f64);
        for weights in [None, Some(&w)] {
            let from_whole = Summary::of(&whole.system, weights).unwrap();
            let from_made = Summary::of_rows(&made.system, made.source(), weights).unwrap();
            assert!(from_whole == from_made, "{robot}: the summaries, bit for bit");
        }
        // The table in row groups, each made when asked, is the whole table.
        let group = made.group_rows();
        assert_eq!(group, 512 * base.model.dof());
        let table = whole.clone().into_record_batch().unwrap();
        let (schema, groups) = made.clone().into_groups().unwrap();
        assert_eq!(schema, table.schema());
        let groups: Vec<_> = groups.map(Result::unwrap).collect();
        assert_eq!(groups.len(), 4);
        let joined = arrow::compute::concat_batches(&schema, &groups).unwrap();
        assert_eq!(joined, table);
        assert_eq!(content_crc32(&joined), content_crc32(&table));
    }
}

/// A torque 4× what the robot file predicts is flagged on every joint the
/// file's rigid-body part explains, with rows made in blocks as whole (the
/// check reads the motion, not the rows).
#[test]
fn the_torque_check_sees_the_same_from_blocks() {
    let (base, cfg, mut kin) = regressor_case("robots/ur5.urdf", 1100);
    for series in kin.torque.as_mut().unwrap() {
        series.iter_mut().for_each(|t| *t *= 4.0);
    }
    let spectra = Spectra::new();
    let rows = |on_demand| regressor_rows(&kin, None, None, &base, &cfg, None, &spectra, "r", on_demand).unwrap();
    let (whole, made) = (rows(false), rows(true));
    let note = whole.torque_note.clone().expect("a warning");
    assert!(
        note.starts_with("warning: against the robot file: ")
            && note
                .matches("measures 4.400× the torque the robot file predicts")
                .count()
                >= 4,
        "{note}"
    );
    assert_eq!(made.torque_note, Some(note));
}
