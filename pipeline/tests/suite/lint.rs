//! `robotid lint` knows, before reading a sample, every problem that can be
//! known without one: each case below is a pipeline that used to pass lint
//! and then failed or gave garbage. Each is rejected with its place.

use std::path::Path;

use robotid::error::Place;
use robotid::{Pipeline, Problems};
use robotid_tests::workspace;

/// The KUKA example pipeline (valid), with `edit` applied to its text.
fn lint(dir: &Path, edit: impl Fn(String) -> String) -> Result<(), Problems> {
    let file = dir.join("pipelines/kuka_axis3.toml");
    let text = edit(std::fs::read_to_string(&file).unwrap());
    let case = dir.join("pipelines/case.toml");
    std::fs::write(&case, text).unwrap();
    match Pipeline::from_path(&case).and_then(|p| p.lint().map(|_| ())) {
        Ok(()) => Ok(()),
        Err(robotid::Error::Problems(p)) => Err(p),
        Err(e) => panic!("not a lint problem: {e}"),
    }
}

fn stage_key(kind: &str, key: &str) -> impl Fn(&Problems) -> bool {
    let (kind, key) = (kind.to_string(), key.to_string());
    move |p: &Problems| p.at_stage(&kind, &key)
}

#[test]
fn every_case_is_refused_with_its_place() {
    let ws = workspace(&["kuka_axis3"]);
    let dir = ws.path();
    lint(dir, |t| t).expect("the example pipeline is valid");
    std::fs::write(dir.join("recordings/log.bin"), "0 0 0\n").unwrap();
    std::fs::write(dir.join("recordings/log.csv"), "time,q_a3,current_a3\n0,0,0\n").unwrap();
    let without_noise = |t: String| t.replace("[[stage]]\nkind = \"noise\"\n", "");
    type Case = (
        &'static str,
        Box<dyn Fn(String) -> String>,
        Box<dyn Fn(&Problems) -> bool>,
    );
    let cases: Vec<Case> = vec![
        (
            "a regressor configuration its model refuses (decoupled with the default rotor)",
            Box::new(|t| t.replace("rotor = true\n", "model = \"decoupled\"\n")),
            Box::new(stage_key("regressor", "")),
        ),
        (
            "[read] joints that are not the robot's",
            Box::new(|t| t.replace("[read]\n", "[read]\njoints = [\"a9\"]\n")),
            Box::new(|p: &Problems| p.at(&Place::Read("joints".into()))),
        ),
        (
            "maximum likelihood without a noise stage",
            Box::new(move |t| without_noise(t).replace("method = \"ols\"", "method = \"ml\"")),
            Box::new(stage_key("estimate", "method")),
        ),
        (
            "weighted least squares without variances",
            Box::new(move |t| without_noise(t).replace("method = \"ols\"", "method = \"wls\"")),
            Box::new(stage_key("estimate", "method")),
        ),
        (
            "a known file that does not exist",
            Box::new(|t| t.replace("confidence = 0.95", "confidence = 0.95\nknown = \"missing.parquet\"")),
            Box::new(stage_key("estimate", "known")),
        ),
        (
            "physical together with known",
            Box::new(|t| {
                t.replace(
                    "confidence = 0.95",
                    "confidence = 0.95\nknown = \"k.parquet\"\nphysical = true",
                )
            }),
            Box::new(stage_key("estimate", "physical")),
        ),
        (
            "a source no reader takes",
            Box::new(|t| t.replace("kuka_axis3/kuka_axis3.mcap", "log.bin")),
            Box::new(|p: &Problems| p.at(&Place::Source)),
        ),
        (
            "no harmonics at all",
            Box::new(|t| t.replace("kind = \"noise\"\n", "kind = \"noise\"\nharmonics = []\n")),
            Box::new(stage_key("noise", "harmonics")),
        ),
        (
            "a period of 2e9 samples",
            Box::new(|t| {
                t.replace(
                    "kind = \"align\"\n",
                    "kind = \"align\"\nsamples_per_period = 2000000000\n",
                )
            }),
            Box::new(stage_key("align", "samples_per_period")),
        ),
        (
            // The period is found in the record (align infers it); the
            // excited harmonics are not yet.
            "harmonics missing for a source without provenance (CSV)",
            Box::new(|t| {
                t.replace("kuka_axis3/kuka_axis3.mcap", "log.csv")
                    .replace("reference_trajectory = \"../sims/kuka_axis3.toml\"\n", "")
                    .replace(
                        "effort = { topic = \"/motor_current\", field = \"current\", unit = \"A\" }\n",
                        "",
                    )
                    .replace(
                        "reference = { topic = \"/joint_reference\", field = \"position\", unit = \"rad\" }\n",
                        "",
                    )
            }),
            Box::new(|p: &Problems| p.at_stage("noise", "harmonics") && !p.at_stage("align", "period_s")),
        ),
    ];
    for (what, edit, place) in &cases {
        let problems = lint(dir, edit).expect_err(what);
        assert!(place(&problems), "{what}: not at its place: {problems}");
    }
    // A robot file that fails to load is said once, as itself, not as "set `robot`".
    std::fs::write(dir.join("robots/broken.toml"), "name = 3\n").unwrap();
    let p = lint(dir, |t| {
        t.replace("kuka_axis3.toml\"\n\n[source]", "broken.toml\"\n\n[source]")
    })
    .unwrap_err();
    assert!(p.at(&Place::Key("robot".into())), "{p}");
    assert!(!p.0.iter().any(|x| x.message.contains("set `robot`")), "{p}");
    assert_eq!(p.0.len(), 1, "{p}");
    // Several problems at once, each in its place.
    let p = lint(dir, |t| {
        without_noise(t)
            .replace("method = \"ols\"", "method = \"wls\"")
            .replace(
                "kind = \"align\"\n",
                "kind = \"align\"\nsamples_per_period = 2000000000\n",
            )
            .replace("rotor = true\n", "model = \"decoupled\"\n")
    })
    .unwrap_err();
    assert!(p.0.len() >= 2, "{p}");
    assert!(p.at_stage("align", "samples_per_period"), "{p}");
}
