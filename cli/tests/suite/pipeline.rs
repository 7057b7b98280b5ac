//! Pipelines end to end on freshly simulated recordings, laid out as in
//! fixtures/ (robots/, pipelines/, recordings/) inside a temporary folder.

use robotid_schemas::metadata;
use std::path::Path;
use std::process::Command;

use robotid::run::RecordingResult;
use robotid::{Pipeline, RunOptions};
use robotid_schemas::{Kinematics, PeriodMean};
use robotid_stages::dynamics::load_robot;
use robotid_stages::formats::parquet::read_parquet;
use robotid_tests::{fixture, workspace};

/// Renders a page in headless Chromium (installed by scripts/setup.sh):
/// the DOM it built holds the page's verdicts and figures, and its
/// screenshot is not blank (a blank 1100 × 1400 page compresses to ~7 kB;
/// this one, with tables and curves, to well over 100 kB).
fn rendered_in_a_browser(html: &Path) {
    let Some(chromium) = ["chromium", "chromium-browser"].iter().find(|c| {
        Command::new(c)
            .arg("--version")
            .output()
            .is_ok_and(|o| o.status.success())
    }) else {
        robotid_tests::absent("no Chromium here (bash scripts/setup.sh installs it)");
        return;
    };
    let profile = tempfile::tempdir().unwrap();
    let png = html.with_extension("png");
    let url = format!("file://{}", html.canonicalize().unwrap().display());
    let browser = |extra: &[&str]| {
        let out = Command::new(chromium)
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-quic",
                "--no-first-run",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                "--hide-scrollbars",
                "--window-size=1100,1400",
            ])
            .arg(format!("--user-data-dir={}", profile.path().display()))
            .args(extra)
            .arg(&url)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "chromium: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        out.stdout
    };
    let dom = String::from_utf8(browser(&["--dump-dom"])).unwrap();
    assert!(
        dom.contains("Verdicts") && dom.contains("class=\"ok\""),
        "verdicts not rendered"
    );
    // A validation run that does not repeat is judged on the excitation's
    // floor, not left "noise floor unknown".
    assert!(!dom.contains("noise floor unknown"), "a verdict missing");
    assert!(dom.contains("Bodies for simulators"), "the bodies not rendered");
    assert_eq!(dom.matches("<svg").count(), 7, "figures in the rendered page");
    browser(&[&format!("--screenshot={}", png.display())]);
    let bytes = std::fs::read(&png).unwrap();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    let (w, h) = (
        u32::from_be_bytes(bytes[16..20].try_into().unwrap()),
        u32::from_be_bytes(bytes[20..24].try_into().unwrap()),
    );
    assert_eq!((w, h), (1100, 1400));
    assert!(
        bytes.len() > 100_000,
        "screenshot of {} bytes: a blank page?",
        bytes.len()
    );
}

/// Runs a pipeline through the one run flow (`Built::run`, what `robotid
/// run` calls): its recordings, then its estimate when all succeeded.
fn run_pipeline(file: &Path, out: &Path, threads: Option<usize>) -> Vec<RecordingResult> {
    let built = Pipeline::from_path(file).unwrap().build().unwrap();
    let opts = RunOptions {
        out: out.to_path_buf(),
        threads,
        plot: None,
    };
    built.run(&opts).unwrap().recordings
}

/// One recording failing: it says why, the others are run, and nothing is
/// written (a run's outputs appear together or not at all).
#[test]
fn a_failing_recording_writes_nothing_and_others_go_on() {
    let ws = workspace(&["kuka_axis3"]);
    let rec = ws.path().join("recordings/kuka_axis3");
    // A second log beside the good one, truncated.
    let bytes = std::fs::read(rec.join("kuka_axis3.mcap")).unwrap();
    std::fs::write(rec.join("broken.mcap"), &bytes[..bytes.len() / 3]).unwrap();
    let file = ws.path().join("pipelines/kuka_axis3.toml");
    let text = std::fs::read_to_string(&file)
        .unwrap()
        .replace("kuka_axis3/kuka_axis3.mcap", "kuka_axis3/*.mcap");
    std::fs::write(&file, text).unwrap();
    let out = ws.path().join("out");
    let results = run_pipeline(&file, &out, None);
    assert_eq!(results.len(), 2);
    let broken = results.iter().find(|r| r.name == "broken").unwrap();
    let err = broken.outcome.as_ref().unwrap_err().to_string();
    assert!(
        err.contains("broken.mcap") && (err.contains("truncated") || err.contains("corrupt")),
        "{err}"
    );
    let good = results.iter().find(|r| r.name == "kuka_axis3").unwrap();
    assert!(good.outcome.is_ok(), "{:?}", good.outcome);
    assert!(!out.exists(), "a run with a failed recording wrote {out:?}");
    // Inputs are untouched.
    assert_eq!(std::fs::read(rec.join("kuka_axis3.mcap")).unwrap(), bytes);
}

#[test]
fn a_pipeline_can_start_from_an_averaged_table() {
    let ws = workspace(&["kuka_axis3"]);
    let out = ws.path().join("out");
    run_pipeline(&ws.path().join("pipelines/kuka_axis3.toml"), &out, None);
    let chained = ws.path().join("pipelines/chained.toml");
    std::fs::write(
        &chained,
        "version = 1\n[read]\njoints = [\"a3\"]\n[source]\npath = \"../out/kuka_axis3/period_mean.parquet\"\n[[stage]]\nkind = \"differentiate\"\nmethod = \"dft\"\nbandwidth_hz = 15.0\n[output]\ntables = [\"kinematics\"]\n",
    )
    .unwrap();
    let out2 = ws.path().join("out2");
    let r = run_pipeline(&chained, &out2, None);
    assert!(r[0].outcome.is_ok(), "{:?}", r[0].outcome);
    let a = Kinematics::from_record_batch(&read_parquet(&out.join("kuka_axis3/kinematics.parquet")).unwrap()).unwrap();
    let b =
        Kinematics::from_record_batch(&read_parquet(&out2.join("period_mean/kinematics.parquet")).unwrap()).unwrap();
    assert_eq!(a.qdd, b.qdd);
    let pm =
        PeriodMean::from_record_batch(&read_parquet(&out.join("kuka_axis3/period_mean.parquet")).unwrap()).unwrap();
    assert_eq!(pm.torque, b.torque.unwrap());
}

#[test]
fn lint_reports_every_problem_with_its_place() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.toml");
    std::fs::write(
        &bad,
        "version = 2\n[source]\npath = \"x.mcap\"\n[read]\neffort = { column = \"c\", unit = \"furlong\" }\n[[stage]]\nkind = \"alin\"\n[[stage]]\nkind = \"align\"\ncolour = 1\n[[stage]]\nkind = \"differentiate\"\nmethod = \"fourier_fit\"\nbandwidth_hz = 2.0\n[output]\ntables = [\"bogus\"]\n",
    )
    .unwrap();
    let validate = |file: &Path| {
        let out = Command::new(env!("CARGO_BIN_EXE_robotid"))
            .arg("lint")
            .arg(file)
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(1));
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let err = validate(&bad);
    for needle in [
        "6 problem(s)",
        "`version`: 2 is not supported",
        "[read] effort.unit: `effort.unit` must be one of A, mA, N*m, not `furlong`",
        "stage 1 (`alin`, line 6): unknown variant `alin`",
        "stage 2 (`align`, line 8): unknown field `colour`",
        "stage 3 (`differentiate`, line 11) `bandwidth_hz`: applies to method = \"dft\"",
        "unknown table `bogus`",
    ] {
        assert!(err.contains(needle), "missing `{needle}` in {err}");
    }
    // Context: a chain that does not fit, a missing source.
    std::fs::write(
        &bad,
        "version = 1\n[read]\njoints = [\"a\"]\n[source]\npath = \"none/*.csv\"\n[[stage]]\nkind = \"average\"\n",
    )
    .unwrap();
    let err = validate(&bad);
    assert!(
        err.contains("names no log file") && err.contains("stage 1 (`average`, line 6): needs aligned periods"),
        "{err}"
    );
}

/// What `run` refused only after reading the data (or ran to garbage),
/// `lint` refuses first, each with its place: bands and harmonics beyond
/// the Nyquist frequency (the MCAP summary's rate, 150 Hz), channels given
/// the other format's way, an MCAP topic or JointState field the file has
/// not, another robot's reference trajectory, a pipeline that writes
/// nothing. The bad-input campaign's 11 lint holes.
#[test]
fn lint_refuses_what_run_would() {
    let ws = workspace(&["kuka_axis3"]);
    let w = ws.path();
    let base = std::fs::read_to_string(w.join("pipelines/kuka_axis3.toml")).unwrap();
    let lint = |name: &str, text: &str| {
        let file = w.join(format!("pipelines/{name}.toml"));
        std::fs::write(&file, text).unwrap();
        let o = Command::new(env!("CARGO_BIN_EXE_robotid"))
            .arg("lint")
            .arg(&file)
            .output()
            .unwrap();
        (
            o.status.code(),
            format!(
                "{}{}",
                String::from_utf8_lossy(&o.stdout),
                String::from_utf8_lossy(&o.stderr)
            ),
        )
    };
    let (code, said) = lint("good", &base);
    assert_eq!(code, Some(0), "{said}");
    std::fs::write(w.join("recordings/tiny.csv"), "time,q_a3,torque_a3\n0,0,0\n0.01,0,0\n").unwrap();
    let edit = |pairs: &[(&str, &str)]| {
        pairs.iter().fold(base.clone(), |t, (a, b)| {
            assert!(t.contains(a), "no `{a}`");
            t.replacen(a, b, 1)
        })
    };
    let nothing = format!(
        "{}[output]\ntables = []\n",
        base.split("[[stage]]\nkind = \"estimate\"").next().unwrap()
    );
    let cases: Vec<(&str, String, &str)> = vec![
        (
            "differentiation band beyond Nyquist",
            edit(&[("bandwidth_hz = 15.0", "bandwidth_hz = 90.0")]),
            "`bandwidth_hz`: 90 Hz is beyond the Nyquist frequency, 75",
        ),
        (
            "inverse filter beyond Nyquist",
            edit(&[("cutoff_hz = 20.0", "cutoff_hz = 120.0")]),
            "`filter.cutoff_hz`: 120 Hz is beyond the Nyquist",
        ),
        (
            "harmonics beyond the record",
            edit(&[
                ("kind = \"align\"", "kind = \"align\"\nperiod_s = 10.0"),
                ("kind = \"noise\"", "kind = \"noise\"\nharmonics = [1, 2, 900]"),
            ]),
            "harmonic 900 of the 10 s period",
        ),
        (
            "a column on an MCAP log",
            edit(&[("[read]\n", "[read]\nposition = { column = 3 }\n")]),
            "[read] position: `column` on the MCAP log",
        ),
        (
            "a time column on an MCAP log",
            edit(&[("[read]\n", "[read]\ntime = { column = \"time_s\" }\n")]),
            "[read] time: `column` on the MCAP log",
        ),
        (
            "an MCAP topic the file has not",
            edit(&[("/motor_current", "/motor_currents")]),
            "topic `/motor_currents` is not in",
        ),
        (
            "an MCAP field the file has not",
            edit(&[("field = \"current\"", "field = \"currents\"")]),
            "field `currents` is not in `/motor_current`",
        ),
        (
            "a JointState field",
            edit(&[("[read]\n", "[read]\nposition = { field = \"positions\" }\n")]),
            "a JointState has position, velocity and effort",
        ),
        (
            "a topic on a CSV log",
            edit(&[("../recordings/kuka_axis3/kuka_axis3.mcap", "../recordings/tiny.csv")]),
            "[read] effort: `topic` or `field` on",
        ),
        (
            "another robot's trajectory",
            edit(&[("../sims/kuka_axis3.toml", "../sims/arm3.toml")]),
            "holds a trajectory of 3 joints; robot `kuka_ir361_axis3` has 1",
        ),
        ("a pipeline that writes nothing", nothing, "the pipeline writes nothing"),
    ];
    for (i, (name, text, says)) in cases.iter().enumerate() {
        let (code, said) = lint(&format!("case{i}"), text);
        assert_eq!(code, Some(1), "{name}: lint passed:\n{said}");
        assert!(said.contains(says), "{name}: no `{says}` in\n{said}");
    }
}

#[test]
fn real_kuka_lwr4_recordings_run_and_say_what_they_could_not_do() {
    if robotid_tests::realdata("kuka_lwr4").is_none() {
        return;
    }
    let file = fixture("").join("pipelines/kuka_lwr4.toml");
    let out = tempfile::tempdir().unwrap();
    let results = run_pipeline(&file, out.path(), None);
    assert_eq!(results.len(), 3);
    for r in &results {
        let o = r.outcome.as_ref().unwrap_or_else(|e| panic!("{}: {e}", r.name));
        assert_eq!(o.report.periods_found, Some(2), "{}", r.name);
        assert_eq!(
            o.report.periods_kept,
            Some(1),
            "{}: the first period holds the start-up transient",
            r.name
        );
        assert!(o.report.notes.iter().any(|n| n.contains("only one full steady period")));
        assert!(o.report.notes.iter().any(|n| n.contains("resampled")));
        let t = o.report.noise.iter().find(|c| c.channel == "torque").unwrap();
        assert!(t.var_time.is_nan() && t.var_freq > 0.0);
    }
}

#[test]
fn plots_and_report_are_written() {
    let ws = workspace(&["kuka_axis3"]);
    let file = ws.path().join("pipelines/kuka_axis3.toml");
    let built = Pipeline::from_path(&file).unwrap().build().unwrap();
    let plots = ws.path().join("plots");
    let opts = RunOptions {
        out: ws.path().join("out"),
        threads: None,
        plot: Some(plots.clone()),
    };
    let r = built.run_recordings(&opts, &robotid_report::Plots);
    assert!(r[0].outcome.is_ok(), "{:?}", r[0].outcome);
    for (f, needle) in [
        ("signals.svg", "a3 torque"),
        ("spectrum.svg", "excited harmonics"),
        ("noise.svg", "noise std of the average"),
        ("derivatives.svg", "a3 acceleration"),
        ("report.md", "steady periods kept: 6 of 6"),
    ] {
        let text = std::fs::read_to_string(plots.join("kuka_axis3").join(f)).unwrap();
        assert!(text.contains(needle), "{f} lacks `{needle}`");
    }
}

/// From a simulated recording to the regressor table, then least squares on
/// it: the five base parameters of Swevers' axis-3 model come back. The
/// averaged torque's noise (σ ≈ 0.78 N·m per row, 1500 rows, condition
/// number ≈ 3) puts the parameter errors at the 1e-3 relative level; what
/// is left (ZZ −0.7 %, Fv −0.4 %) is the derivatives' 8 Hz band limit.
/// A run for tables frees the aligned periods' samples as soon as no later
/// stage reads them (the regressor reads only the torques), never holds A
/// whole (its rows are made per block when read), and moves the regressor
/// rows into their table: the same estimate, bit for bit, and the same
/// tables as a run that keeps everything, column for column; written, the
/// same files, byte for byte.
#[test]
fn a_run_for_tables_frees_the_periods_and_makes_the_same_tables() {
    let ws = workspace(&["kuka_axis3"]);
    // Without the band limit, which reworks A whole.
    let text = std::fs::read_to_string(ws.path().join("pipelines/kuka_axis3.toml")).unwrap();
    assert!(text.contains("band_limit_hz = 20.0\n"));
    let file = ws.path().join("pipelines/kuka_axis3_plain.toml");
    std::fs::write(&file, text.replace("band_limit_hz = 20.0\n", "")).unwrap();
    let built = Pipeline::from_path(file).unwrap().build().unwrap();
    let log = &built.logs[0];
    let whole = built.run_log(log, "axis", |_| {}).unwrap();
    let mut lean = built.run_log_for_tables(log, "axis", |_| {}).unwrap();
    let (kept, freed) = (whole.periods.as_ref().unwrap(), lean.periods.as_ref().unwrap());
    assert!(kept.q[0].len() > 1000 && kept.torque[0].len() == kept.q[0].len());
    assert!(freed.q.is_empty() && freed.torque.is_empty() && freed.reference.is_none());
    assert_eq!(
        (freed.periods, freed.samples_per_period),
        (kept.periods, kept.samples_per_period)
    );
    let made = lean.regressor.as_ref().unwrap();
    assert!(made.maker.is_some() && made.system.a.is_empty(), "A not kept");
    assert!(whole.regressor.as_ref().unwrap().maker.is_none());
    assert_eq!(made.condition, whole.regressor.as_ref().unwrap().condition);
    assert_eq!(
        lean.estimate.as_ref().unwrap().summary,
        whole.estimate.as_ref().unwrap().summary
    );
    let written = |chain: &robotid_stages::stage::Chain, dir: &str| {
        let dir = ws.path().join(dir);
        let rows = chain.regressor.clone();
        robotid::run::write_tables(chain, rows, &built.plan.tables, &built.provenance(), &dir).unwrap();
        let mut files: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().path()).collect();
        files.sort();
        files.iter().map(|f| std::fs::read(f).unwrap()).collect::<Vec<_>>()
    };
    let (from_whole, from_made) = (written(&whole, "whole"), written(&lean, "made"));
    assert_eq!(from_whole.len(), 5);
    assert!(from_whole == from_made, "the same bytes");
    let copied = built.tables(&whole).unwrap();
    let moved = built.take_tables(&mut lean).unwrap();
    assert!(lean.regressor.is_none(), "the rows moved into the table");
    assert_eq!(copied.len(), 5);
    for ((k1, a), (k2, b)) in copied.iter().zip(&moved) {
        assert_eq!(k1, k2);
        assert_eq!(a, b, "the {k1} table");
    }
    let regressor = &moved.iter().find(|(k, _)| k.name() == "regressor").unwrap().1;
    assert!(
        regressor.schema().field_with_name("torque_p1").is_ok(),
        "period torques kept"
    );
}

#[test]
fn least_squares_on_the_regressor_table_recovers_the_axis() {
    use robotid_stages::formats::parquet::read_parquet;
    let ws = workspace(&["kuka_axis3"]);
    let out = ws.path().join("out");
    let file = ws.path().join("pipelines/kuka_axis3.toml");
    let r = run_pipeline(&file, &out, None);
    assert!(r[0].outcome.is_ok(), "{:?}", r[0].outcome);
    let batch = read_parquet(&out.join("kuka_axis3/regressor.parquet")).unwrap();
    let schema = batch.schema();
    assert_eq!(
        schema.metadata().get(metadata::BASE_PARAMETERS).map(String::as_str),
        Some("5")
    );
    let params: Vec<String> =
        robotid_stages::stage::regressor::columns_of(&schema, robotid_stages::stage::regressor::PARAMETER_COLUMN)
            .into_iter()
            .map(|i| schema.field(i).name().clone())
            .collect();
    assert_eq!(params, ["ZZ_a3", "MX_a3", "MY_a3", "Fv_a3", "Fc_a3"]);
    assert_eq!(
        schema.field(6).metadata().get("expression").map(String::as_str),
        Some("ZZ_a3 + Ia_a3")
    );
    let col = |name: &str| {
        let a = batch.column(schema.index_of(name).unwrap());
        a.as_any()
            .downcast_ref::<arrow::array::Float64Array>()
            .unwrap()
            .values()
            .to_vec()
    };
    let b = nalgebra::DVector::from_vec(col("torque"));
    let a = nalgebra::DMatrix::from_fn(b.len(), params.len(), |i, j| col(&params[j])[i]);
    let theta = a.svd(true, true).solve(&b, 1e-12).unwrap();
    // The R-factor table, solved on its own, gives the same estimate.
    let rf = read_parquet(&out.join("kuka_axis3/r_factor.parquet")).unwrap();
    let rs = rf.schema();
    assert_eq!(rs.metadata().get(metadata::TABLE).map(String::as_str), Some("r_factor"));
    let rcol = |name: &str| {
        let a = rf.column(rs.index_of(name).unwrap());
        a.as_any()
            .downcast_ref::<arrow::array::Float64Array>()
            .unwrap()
            .values()
            .to_vec()
    };
    let r = nalgebra::DMatrix::from_fn(5, 5, |i, j| rcol(&params[j])[i]);
    let z = nalgebra::DVector::from_vec(rcol("z"));
    let theta_r = r.solve_upper_triangular(&z).unwrap();
    assert!((&theta_r - &theta).amax() < 1e-9 * theta.amax(), "{theta_r} vs {theta}");
    let truth = [8.348, 26.2, 0.02349, 3.676, 15.8927];
    println!(
        "least squares: {:?} (truth {truth:?}), condition {}",
        theta.as_slice(),
        schema.metadata()["robotid.condition_number"]
    );
    for (i, (est, t)) in theta.iter().zip(truth).enumerate() {
        let tol = [0.015 * 8.348, 0.002 * 26.2, 0.02, 0.03 * 3.676, 0.01 * 15.89][i];
        assert!((est - t).abs() < tol, "{}: {est} vs {t}", params[i]);
    }
}

/// Issue 5's acceptance on the KUKA axis: the pipeline's `estimate` stage
/// gives Swevers' Table 1 values within their 95 % intervals, and on the
/// non-periodic validation run the mean squared residue is at the noise
/// floor: within 5 % of the residue left by the true parameters on the same
/// rows (the best any parameter set can do with that noise and filtering).
#[test]
fn kuka_axis3_estimate_matches_the_truth_and_validates_at_the_noise_floor() {
    use robotid_stages::estimation::{parameters_from_table, System};
    use robotid_stages::stage::regressor::RegressorConfig;
    let ws = workspace(&["kuka_axis3", "kuka_axis3_validation"]);
    let out = ws.path().join("out");
    let run_cli = |args: &[&str]| {
        let o = Command::new(env!("CARGO_BIN_EXE_robotid")).args(args).output().unwrap();
        let text = String::from_utf8_lossy(&o.stdout).into_owned();
        assert!(
            o.status.success(),
            "{args:?}: {}{}",
            text,
            String::from_utf8_lossy(&o.stderr)
        );
        text
    };
    let p = |rel: &str| ws.path().join(rel).display().to_string();
    let ex = out.join("ex").display().to_string();
    let va = out.join("va").display().to_string();
    let run_plots = out.join("run_plots").display().to_string();
    println!(
        "{}",
        run_cli(&[
            "run",
            &p("pipelines/kuka_axis3.toml"),
            "--out",
            &ex,
            "--plot",
            &run_plots
        ])
    );
    // With --plot, a run with an `estimate` stage writes its report too,
    // naming the parameters table where the run put it (not the staging
    // folder it was read from while the run was under way).
    let page = std::fs::read_to_string(out.join("run_plots/report.html")).unwrap();
    assert!(page.contains(&out.join("ex/parameters.parquet").display().to_string()));
    assert!(
        !page.contains(".robotid-staging"),
        "the report names the staging folder"
    );
    run_cli(&["run", &p("pipelines/validation.toml"), "--out", &va]);
    let params_path = out.join("ex/parameters.parquet");
    let params = parameters_from_table(&read_parquet(&params_path).unwrap()).unwrap();
    assert_eq!(params.names, ["ZZ_a3", "MX_a3", "MY_a3", "Fv_a3", "Fc_a3"]);
    let truth = [8.348, 26.2, 0.02349, 3.676, 15.8927];
    let level: f64 = params.metadata["robotid.estimate.confidence"].parse().unwrap();
    assert_eq!(level, 0.95);
    let batch = read_parquet(&params_path).unwrap();
    let col = |name: &str| {
        batch
            .column_by_name(name)
            .unwrap()
            .as_any()
            .downcast_ref::<arrow::array::Float64Array>()
            .unwrap()
            .values()
            .to_vec()
    };
    let (lo, hi) = (col("ci_low"), col("ci_high"));
    for i in 0..5 {
        println!(
            "{}: {} in [{}, {}], truth {}",
            params.names[i], params.values[i], lo[i], hi[i], truth[i]
        );
        assert!(
            lo[i] <= truth[i] && truth[i] <= hi[i],
            "{} misses the truth",
            params.names[i]
        );
    }
    // Validation: the CLI's table, and the floor computed here.
    let reg = out.join("va/kuka_axis3_validation/regressor.parquet");
    let plots = out.join("plots").display().to_string();
    let text = run_cli(&[
        "validate",
        "-p",
        &params_path.display().to_string(),
        &reg.display().to_string(),
        "--plot",
        &plots,
    ]);
    println!("{text}");
    assert!(out.join("plots/validation_residues.svg").is_file());
    let sys = System::from_tables(&[("va".into(), read_parquet(&reg).unwrap())]).unwrap();
    let msr = |theta: &nalgebra::DVector<f64>| (&sys.b - &sys.a * theta).norm_squared() / sys.rows() as f64;
    let model = load_robot(&ws.path().join("robots/kuka_axis3.toml")).unwrap();
    let rc: RegressorConfig = serde_json::from_str(&params.metadata["robotid.regressor_config"]).unwrap();
    let true_base = rc.base_regressor(&model).unwrap().base_values(&model).unwrap();
    let (est, floor) = (msr(&params.values), msr(&true_base));
    println!("validation MSR {est:.4} (N·m)², floor (true parameters) {floor:.4}");
    assert!(est < 1.05 * floor, "validation MSR {est} above the floor {floor}");
    // `robotid predict` on the validation kinematics gives the same torques
    // as the estimate applied to the regressor rows.
    let pred = out.join("predicted.parquet");
    run_cli(&[
        "predict",
        "--robot",
        &p("robots/kuka_axis3.toml"),
        "-p",
        &params_path.display().to_string(),
        &out.join("va/kuka_axis3_validation/kinematics.parquet")
            .display()
            .to_string(),
        "-o",
        &pred.display().to_string(),
    ]);
    // (The regressor rows of this non-periodic record are filtered after
    // they are made; predict gives the model's torque at the samples.)
    let k = Kinematics::from_record_batch(&read_parquet(&pred).unwrap()).unwrap();
    let tau = &k.torque.unwrap()[0];
    let kin =
        Kinematics::from_record_batch(&read_parquet(&out.join("va/kuka_axis3_validation/kinematics.parquet")).unwrap())
            .unwrap();
    let rows = rc.base_regressor(&model).unwrap().matrix(&kin) * &params.values;
    let worst = (0..tau.len()).map(|i| (tau[i] - rows[i]).abs()).fold(0.0, f64::max);
    assert!(worst < 1e-9 * rows.amax(), "predict differs by {worst}");
    // `robotid export`: the least-squares estimate is refused; the
    // physically consistent one (`robotid estimate --physical`) goes to
    // URDF, MJCF and sidecar, and MuJoCo and Pinocchio give robotid's
    // torques for it (a 1-dof axis whose gravity is −x).
    let refused = Command::new(env!("CARGO_BIN_EXE_robotid"))
        .args(["export", "--robot", &p("robots/kuka_axis3.toml"), "-p"])
        .arg(&params_path)
        .output()
        .unwrap();
    assert!(!refused.status.success());
    let physical = out.join("physical.parquet");
    run_cli(&[
        "estimate",
        &out.join("ex/kuka_axis3/regressor.parquet").display().to_string(),
        "--robot",
        &p("robots/kuka_axis3.toml"),
        "--physical",
        "-o",
        &physical.display().to_string(),
    ]);
    let (mujoco, pinocchio) = robotid_tests::export_checked_in_simulators(
        Path::new(env!("CARGO_BIN_EXE_robotid")),
        &ws.path().join("robots/kuka_axis3.toml"),
        &physical,
        &out,
    );
    assert!(
        mujoco < 1e-9 && pinocchio < 1e-9,
        "MuJoCo {mujoco:e}, Pinocchio {pinocchio:e}"
    );
    // `robotid report`: one self-contained page, the physical estimate
    // beside the least-squares one.
    let html = out.join("report.html");
    run_cli(&[
        "report",
        "-p",
        &params_path.display().to_string(),
        "--excitation",
        &out.join("ex/kuka_axis3/regressor.parquet").display().to_string(),
        "--validation",
        &reg.display().to_string(),
        "--physical",
        &physical.display().to_string(),
        "--robot",
        &p("robots/kuka_axis3.toml"),
        "-o",
        &html.display().to_string(),
    ]);
    let page = std::fs::read_to_string(&html).unwrap();
    for name in &params.names {
        assert!(page.contains(name.as_str()), "{name} missing from the report");
    }
    // Excitation: torques, residues, friction, noise; validation: torques,
    // residues, friction.
    assert_eq!(page.matches("<svg").count(), 7);
    assert!(page.contains("95.0 % interval") && page.contains("ZZ_a3 + Ia_a3"));
    // The verdicts lead, and no raw JSON is shown.
    assert!(page.find("Verdicts").unwrap() < page.find("Parameters").unwrap());
    assert!(!page.contains("{\""), "raw JSON in the report");
    // The physical estimate beside it: its errors, its body.
    assert!(page.contains("Bodies for simulators") && page.contains("physically consistent</th>"));
    rendered_in_a_browser(&html);
    // The robot file's URDF-less terms: the exported URDF, read back, has
    // the same inertials, and its base parameters are the estimate's.
    let exported = load_robot(&out.join("identified.urdf")).unwrap();
    let mut rc_sym = rc.clone();
    rc_sym.coulomb_transition_rad_s = Some(0.01);
    let back = rc_sym
        .base_regressor(&exported)
        .unwrap()
        .base_values(&exported)
        .unwrap();
    let phys = robotid_stages::estimation::parameters_from_table(&read_parquet(&physical).unwrap()).unwrap();
    for i in 0..5 {
        assert!(
            (back[i] - phys.values[i]).abs() < 1e-3 * phys.std[i].max(1e-9) + 1e-9 * phys.values[i].abs(),
            "{}: exported {} vs estimate {}",
            phys.names[i],
            back[i],
            phys.values[i]
        );
    }
}

/// Dedicated experiments from the command line: the sweeps pipeline, then
/// `robotid sweeps` (gravity and friction), then `robotid estimate --known`
/// (friction compensated): the inertial parameters come back and the
/// friction columns are gone.
#[test]
fn sweeps_then_estimate_with_known_friction() {
    use robotid_stages::estimation::parameters_from_table;
    let ws = workspace(&["kuka_axis3", "kuka_axis3_sweeps"]);
    let out = ws.path().join("out");
    let cli = |args: &[&str]| {
        let o = Command::new(env!("CARGO_BIN_EXE_robotid")).args(args).output().unwrap();
        assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stdout).into_owned()
    };
    let p = |rel: &str| ws.path().join(rel).display().to_string();
    let o = |rel: &str| out.join(rel).display().to_string();
    cli(&["run", &p("pipelines/kuka_axis3.toml"), "--out", &o("ex")]);
    cli(&["run", &p("pipelines/kuka_axis3_sweeps.toml"), "--out", &o("sw")]);
    let text = cli(&[
        "sweeps",
        &o("sw/kuka_axis3_sweeps/kinematics.parquet"),
        "--joint",
        "a3",
        "--friction",
        "symmetric",
        "-o",
        &o("gf.parquet"),
    ]);
    println!("{text}");
    let gf = parameters_from_table(&read_parquet(&out.join("gf.parquet")).unwrap()).unwrap();
    assert_eq!(gf.names, ["Gs_a3", "Gc_a3", "Fv_a3", "Fc_a3"]);
    assert!((gf.values[3] - 15.8927).abs() < 3.0 * gf.std[3], "Fc {}", gf.values[3]);
    cli(&[
        "estimate",
        &o("ex/kuka_axis3/regressor.parquet"),
        "--known",
        &o("gf.parquet"),
        "-o",
        &o("p.parquet"),
    ]);
    let est = parameters_from_table(&read_parquet(&out.join("p.parquet")).unwrap()).unwrap();
    assert_eq!(est.names, ["ZZ_a3", "MX_a3", "MY_a3"]);
    assert!((est.values[0] - 8.348).abs() < 4.0 * est.std[0], "ZZ {}", est.values[0]);
    assert_eq!(
        est.metadata.get(metadata::KNOWN).map(String::as_str),
        Some("Fv_a3,Fc_a3")
    );
}

/// The `estimate` stage with `physical = true` and `method = "ml"`: the
/// KUKA estimate is already consistent, so the physical fit leaves it in
/// place (χ² ≈ 0); ML agrees with OLS here (the position noise is tiny
/// after averaging) to well within the intervals.
#[test]
fn estimate_stage_ml_and_physical_options() {
    use robotid_stages::estimation::parameters_from_table;
    let ws = workspace(&["kuka_axis3"]);
    let file = ws.path().join("pipelines/kuka_axis3.toml");
    let text = std::fs::read_to_string(&file).unwrap();
    let ols_out = ws.path().join("ols");
    run_pipeline(&file, &ols_out, None);
    let ols = parameters_from_table(&read_parquet(&ols_out.join("parameters.parquet")).unwrap()).unwrap();
    for (edit, label) in [
        ("method = \"ml\"", "ml"),
        ("method = \"ols\"\nphysical = true", "physical"),
    ] {
        let f = ws.path().join(format!("pipelines/{label}.toml"));
        std::fs::write(&f, text.replace("method = \"ols\"", edit)).unwrap();
        let out = ws.path().join(label);
        let r = run_pipeline(&f, &out, None);
        assert!(r.iter().all(|r| r.outcome.is_ok()));
        let p = parameters_from_table(&read_parquet(&out.join("parameters.parquet")).unwrap()).unwrap();
        println!(
            "{label}: {:?} (OLS {:?}) {:?}",
            p.values.as_slice(),
            ols.values.as_slice(),
            p.metadata.get(metadata::PHYSICAL)
        );
        for i in 0..5 {
            assert!(
                (p.values[i] - ols.values[i]).abs() < 0.5 * ols.std[i],
                "{label}: {}",
                p.names[i]
            );
        }
        if label == "physical" {
            // Held-out periods find nothing to gain from the data against
            // the robot file (the curve is flat to 1e-2): a large prior
            // weight, which moves the estimate by a fraction of a standard
            // deviation (χ² ≪ 1).
            let note = &p.metadata["robotid.physical"];
            let chi2: f64 = note
                .split("χ² = ")
                .nth(1)
                .unwrap()
                .split(' ')
                .next()
                .unwrap()
                .parse()
                .unwrap();
            assert!(chi2 < 0.01 && note.contains("chosen by held-out periods"), "{note}");
        } else {
            assert_eq!(p.metadata["robotid.estimate.method"], "ml");
        }
    }
}

/// The spread of 4 periods gives the estimate a covariance of rank 3: the
/// physical fit, which needs it whole, refuses it and says why and what to
/// do, rather than "not positive definite".
#[test]
fn physical_fit_refuses_a_covariance_from_too_few_periods() {
    let ws = workspace(&["arm3"]);
    // What `robotid identify` writes for this recording: the fit is at the
    // noise floor, so the covariance is the periods' alone.
    let text = r#"
version = 1
robot = "../robots/arm3.toml"
[source]
path = "../recordings/arm3/arm3.mcap"
[[stage]]
kind = "align"
[[stage]]
kind = "inverse_filter"
filter = { cutoff_hz = 40.0, family = "butterworth", order = 4 }
bandwidth_hz = 32.0
[[stage]]
kind = "average"
[[stage]]
kind = "noise"
[[stage]]
kind = "differentiate"
method = "dft"
bandwidth_hz = 8.55
[[stage]]
kind = "regressor"
offset = true
band_limit_hz = 32.0
coulomb_transition_rad_s = 0.0106
[[stage]]
kind = "estimate"
method = "ols"
covariance = "periods"
physical = true
[output]
tables = ["kinematics"]
"#;
    let f = ws.path().join("pipelines/arm3_physical.toml");
    std::fs::write(&f, text).unwrap();
    let built = Pipeline::from_path(&f).unwrap().build().unwrap();
    let out = ws.path().join("out");
    let results = built.run_recordings(
        &RunOptions {
            out: out.clone(),
            ..Default::default()
        },
        &robotid::Quiet,
    );
    assert!(results[0].outcome.is_ok(), "{:?}", results[0].outcome);
    let err = built.estimate_all(&results, &out).unwrap_err().to_string();
    assert!(
        err.contains("covariance is singular: it comes from the spread of the periods")
            && err.contains("below the 25 parameters"),
        "{err}"
    );
    assert!(err.contains("covariance = \"residual\""), "{err}");
    // Said so, the residual's covariance does it.
    std::fs::write(
        &f,
        text.replace("covariance = \"periods\"", "covariance = \"residual\""),
    )
    .unwrap();
    let built = Pipeline::from_path(&f).unwrap().build().unwrap();
    let out = ws.path().join("out2");
    let results = built.run_recordings(
        &RunOptions {
            out: out.clone(),
            ..Default::default()
        },
        &robotid::Quiet,
    );
    built.estimate_all(&results, &out).unwrap();
}

/// `robotid excite` writes a trajectory the simulator takes as is
/// (`trajectory_file`), with its coefficients, samples and pictures.
#[test]
fn excite_writes_a_trajectory_the_simulator_reads() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ex");
    let cli = |args: &[&str]| {
        let o = Command::new(env!("CARGO_BIN_EXE_robotid")).args(args).output().unwrap();
        assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stdout).into_owned()
    };
    let cfg = fixture("").join("excite/kuka_axis3.toml");
    let text = cli(&[
        "excite",
        &cfg.display().to_string(),
        "-o",
        &out.display().to_string(),
        "--starts",
        "2",
    ]);
    println!("{text}");
    for f in [
        "excitation.toml",
        "coefficients.parquet",
        "trajectory.parquet",
        "excitation.svg",
        "end_effector.svg",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let traj = robotid_stages::trajectory::load_trajectory(&out.join("excitation.toml")).unwrap();
    assert_eq!(traj.period(), Some(10.0));
    // Without -o, each excitation file's design goes to its own folder.
    let o = Command::new(env!("CARGO_BIN_EXE_robotid"))
        .args(["excite", &cfg.display().to_string(), "--starts", "1"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(dir.path().join("out/excite/kuka_axis3/excitation.toml").is_file());
    let sim = dir.path().join("sim.toml");
    std::fs::write(
        &sim,
        format!(
            "robot = \"{}\"\ntrajectory_file = \"ex/excitation.toml\"\n[timing]\nlog_rate_hz = 150.0\ntransient_s = 2.0\nperiods = 2\n[output]\nname = \"optimised\"\nformats = [\"parquet\"]\n",
            fixture("").join("robots/kuka_axis3.toml").display()
        ),
    )
    .unwrap();
    cli(&[
        "simulate",
        &sim.display().to_string(),
        "--out",
        &dir.path().join("rec").display().to_string(),
    ]);
    assert!(dir.path().join("rec/optimised.parquet").is_file());
}

/// The whole KUKA LWR4+ arm from one real recording, validated on the two
/// others: file 2 repeats file 1's trajectory, file 3 is a different one.
/// Held-out relative error √(Σ MSR / Σ rms τ²) over the 7 joints, measured:
/// OLS 2.24 % (file 2) and 12.1 % (file 3, where the small wrist joints are
/// poorly predicted by a 64-parameter model from one period of data); the
/// physically consistent estimate 2.54 % and 6.06 % (6.25 % before its links
/// were bounded by mass and shape): it gives up a little
/// on the trajectory it was fitted to and halves the error on another.
#[test]
fn real_kuka_lwr4_identified_on_one_file_and_validated_on_the_others() {
    use robotid_stages::estimation::{parameters_from_table, System};
    if robotid_tests::realdata("kuka_lwr4").is_none() {
        return;
    }
    let out = tempfile::tempdir().unwrap();
    let held = out.path().join("held");
    for r in run_pipeline(&fixture("pipelines/kuka_lwr4_heldout.toml"), &held, None) {
        r.outcome.unwrap();
    }
    let mut errors = Vec::new();
    for pipeline in ["kuka_lwr4_identify", "kuka_lwr4_physical"] {
        let id = out.path().join(pipeline);
        for r in run_pipeline(&fixture(&format!("pipelines/{pipeline}.toml")), &id, None) {
            r.outcome.unwrap();
        }
        let params = parameters_from_table(&read_parquet(&id.join("parameters.parquet")).unwrap()).unwrap();
        if pipeline == "kuka_lwr4_physical" {
            // Its consistent model loads in MuJoCo and Pinocchio; links the
            // data push past 5× the robot file's mass are held at that
            // bound, and said.
            let urdf = robotid_tests::realdata("kuka_lwr4").unwrap().join("kuka_lwr4.urdf");
            let o = Command::new(env!("CARGO_BIN_EXE_robotid"))
                .args(["export", "--format", "mjcf,sidecar", "--robot"])
                .arg(&urdf)
                .arg("-p")
                .arg(id.join("parameters.parquet"))
                .arg("-o")
                .arg(id.join("identified"))
                .output()
                .unwrap();
            let err = String::from_utf8_lossy(&o.stderr);
            assert!(o.status.success(), "{err}");
            assert!(
                err.contains("warning: the link of") && err.contains("held at its bound"),
                "{err}"
            );
            let agree = robotid_tests::export_checked_in_simulators(
                Path::new(env!("CARGO_BIN_EXE_robotid")),
                &urdf,
                &id.join("parameters.parquet"),
                &id,
            );
            assert!(agree.0 < 1e-9 && agree.1 < 1e-9, "{agree:?}");
        }
        for file in ["measurements_2", "measurements_3"] {
            let path = held.join(file).join("regressor.parquet");
            let sys = System::from_tables(&[(file.to_string(), read_parquet(&path).unwrap())]).unwrap();
            assert_eq!(sys.names, params.names);
            let stats = robotid::validation::residues(&sys, &(&sys.a * &params.values));
            // Far above the noise floor on held-out data: said, per joint.
            assert!(
                stats
                    .iter()
                    .all(|s| s.verdict() == robotid::validation::Verdict::ModelErrorDominates),
                "{file}"
            );
            let msr: f64 = stats.iter().map(|s| s.msr).sum();
            let power: f64 = stats.iter().map(|s| s.measured_rms.powi(2)).sum();
            errors.push(100.0 * (msr / power).sqrt());
        }
    }
    println!(
        "held-out relative error: OLS file 2 {:.2} %, file 3 {:.2} %; physically consistent file 2 {:.2} %, file 3 {:.2} %",
        errors[0], errors[1], errors[2], errors[3]
    );
    assert!(errors[0] < 2.5 && errors[1] < 13.0, "{errors:?}");
    // On the other trajectory the consistent estimate predicts better; on
    // the repeat it may lose what OLS fitted of that trajectory's errors.
    assert!(errors[3] <= 1.1 * errors[1], "{errors:?}");
    assert!(errors[2] <= 1.2 * errors[0], "{errors:?}");
}

/// A single torque sample of 1e200 (finite) would make every spread and
/// variance infinite: the tables are refused, naming the column and row.
#[test]
fn infinities_are_never_written() {
    let dir = tempfile::tempdir().unwrap();
    let toml = "version = 1\n[source]\npath = \"x.parquet\"\n[read]\njoints = [\"j1\", \"j2\"]\n[[stage]]\nkind = \"align\"\nperiod_s = 10.0\n[[stage]]\nkind = \"average\"\n[output]\ntables = [\"period_mean\"]\n";
    std::fs::write(dir.path().join("x.parquet"), b"").unwrap();
    let pipeline = Pipeline::from_toml(toml, dir.path().join("p.toml")).unwrap();
    let resolved = robotid::plan::Resolved {
        model: None,
        robot_sha256: None,
        logs: vec![],
        start: robotid_stages::stage::Product::Raw,
    };
    let built = pipeline.build_with(resolved).unwrap();
    let mut raw = robotid_stages::simulation::synthetic::synthetic_recording(2, 100.0, 40.0, 10.0, 1);
    raw.effort[1][1234] = 1e200;
    let chain = built.run_raw("spike", raw).unwrap();
    let e = built.tables(&chain).unwrap_err();
    assert!(
        matches!(&e, robotid_stages::Error::NotFinite { what, .. } if what.contains("torque_spread_j2")),
        "{e}"
    );
}

/// Declarations the data contradict, on the simulated KUKA axis (its
/// recorder: Chebyshev I, order 8, 20 Hz; effort: motor current in A):
/// each says so with its numbers, where today they pass silently.
#[test]
fn wrong_declarations_are_named_with_their_numbers() {
    let ws = workspace(&["kuka_axis3"]);
    let file = ws.path().join("pipelines/kuka_axis3.toml");
    let text = std::fs::read_to_string(&file).unwrap();
    let right = "filter = { family = \"chebyshev1\", order = 8, cutoff_hz = 20.0, ripple_db = 0.5 }";
    let notes_of = |label: &str, edited: String| {
        assert_ne!(edited, text, "{label}: the edit applies");
        let f = ws.path().join(format!("pipelines/{label}.toml"));
        std::fs::write(&f, edited).unwrap();
        let out = ws.path().join(label);
        let r = run_pipeline(&f, &out, None);
        let outcome = r[0].outcome.as_ref().unwrap();
        let est =
            robotid_stages::estimation::parameters_from_table(&read_parquet(&out.join("parameters.parquet")).unwrap())
                .unwrap();
        (
            outcome.report.notes.join("\n"),
            est.metadata.get(metadata::ADEQUACY).cloned().unwrap_or_default(),
        )
    };
    // The right declarations: no warning, an adequate fit.
    let (notes, adequacy) = notes_of("right", text.replace("method = \"ols\"", "method = \"ols\"\n"));
    assert!(!notes.contains("warning"), "{notes}");
    assert!(adequacy.contains("\"adequate\""), "{adequacy}");
    // Butterworth 4 for Chebyshev 8: the noise tilts up at the band edge
    // (×1.53) and the fit is 7.9× its noise floor.
    let (notes, adequacy) = notes_of(
        "butterworth",
        text.replace(
            right,
            "filter = { family = \"butterworth\", order = 4, cutoff_hz = 20.0 }",
        ),
    );
    assert!(
        notes.contains("torque noise is 1.5") && notes.contains("anti-alias filter"),
        "{notes}"
    );
    assert!(adequacy.contains("model error dominates"), "{adequacy}");
    // A 10 Hz cutoff for 20 Hz: the inverse filter blows the edge up.
    let (notes, _) = notes_of(
        "cutoff",
        text.replace(
            right,
            "filter = { family = \"chebyshev1\", order = 8, cutoff_hz = 10.0, ripple_db = 0.5 }",
        ),
    );
    assert!(notes.contains("anti-alias filter"), "{notes}");
    // The motor current declared as joint torque: 1/72 of what the robot
    // file predicts (gear 80 × torque constant 0.9 N·m/A = 72).
    let (notes, _) = notes_of(
        "current",
        text.replace(
            "field = \"current\", unit = \"A\"",
            "field = \"current\", unit = \"N*m\"",
        ),
    );
    assert!(
        notes.contains("a3 measures 0.01") && notes.contains("N·m at the joint"),
        "{notes}"
    );
}

/// The real KUKA LWR4+ files, with no period given: align finds it in the
/// positions. Files 1 and 2 repeat with 4π s (found to 1e-4, with jittered
/// stamps and a start-up transient in the first period); file 3, another
/// trajectory, already repeats after 2π s, and that is what is found (its
/// three steady 2π s periods average with a time-domain torque noise equal
/// to the spectrum's, 5.2e-3 both: they are periods).
#[test]
fn real_kuka_lwr4_period_found_in_the_record() {
    let Some(data) = robotid_tests::realdata("kuka_lwr4") else {
        return;
    };
    let text = std::fs::read_to_string(fixture("pipelines/kuka_lwr4.toml"))
        .unwrap()
        .replace("../../../shared/realdata/kuka_lwr4/", &format!("{}/", data.display()))
        .replace("period_s = 12.566370614359172\n", "");
    assert!(!text.contains("period_s"));
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("no_period.toml");
    std::fs::write(&file, text).unwrap();
    let out = dir.path().join("out");
    for r in run_pipeline(&file, &out, None) {
        r.outcome.unwrap();
    }
    let four_pi = 4.0 * std::f64::consts::PI;
    for (name, want) in [
        ("measurements_1", four_pi),
        ("measurements_2", four_pi),
        ("measurements_3", four_pi / 2.0),
    ] {
        let md = read_parquet(&out.join(name).join("kinematics.parquet"))
            .unwrap()
            .schema()
            .metadata()
            .clone();
        let period: f64 = md[metadata::PERIOD_S].parse().unwrap();
        println!("{name}: {period} s against {want}");
        assert!((period - want).abs() < 1e-4 * want, "{name}: {period} against {want}");
    }
}

/// A plan written with `Plan::to_toml` and parsed again is the same plan
/// (identify's plans are made in code and written so): every fixture
/// pipeline, which between them hold every stage kind, `[read]`, `[lock]`
/// and relative paths.
#[test]
fn pipeline_files_round_trip() {
    let mut kinds = std::collections::BTreeSet::new();
    for entry in std::fs::read_dir(fixture("pipelines")).unwrap() {
        let path = entry.unwrap().path();
        let plan = Pipeline::from_path(&path).unwrap().plan;
        let text = plan.to_toml().unwrap();
        let again = Pipeline::from_toml(&text, &path).unwrap().plan;
        let key = |p: &robotid::plan::Plan| {
            format!(
                "{:?}",
                (&p.robot, &p.source, &p.read, &p.stages, &p.tables, &p.lock, &p.inferred)
            )
        };
        assert_eq!(key(&again), key(&plan), "{}:\n{text}", path.display());
        kinds.extend(plan.stages.iter().map(|s| s.name()));
    }
    assert!(kinds.len() >= 7, "{kinds:?}");
}
