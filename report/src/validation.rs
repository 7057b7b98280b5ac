//! Validation as people read it: the per-joint residue table, pooled
//! relative errors per recording.

use nalgebra::DVector;
use robotid::validation::JointResidue;
use robotid_stages::estimation::System;

/// Three significant digits, plain where that reads well (`174.7`,
/// `0.446`, `0`), else scientific (`6.07e-4`).
pub fn sig(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return if x == 0.0 { "0".into() } else { format!("{x}") };
    }
    let e = x.abs().log10().floor() as i32;
    if (-3..5).contains(&e) {
        format!("{x:.*}", (2 - e).max(0) as usize)
    } else {
        format!("{x:.2e}")
    }
}

/// The residue table as text, three significant digits; a floor taken
/// from the excitation is starred and said below.
pub fn table(stats: &[JointResidue]) -> String {
    let mut s = format!(
        "{:<20} {:>7} {:>10} {:>10} {:>7} {:>10} {:>11} {:>6} {:>6} {:>6}  verdict\n",
        "joint", "rows", "rms τ N·m", "MSR (N·m)²", "rel. %", "mean N·m", "noise floor", "skew", "kurt-3", "KS"
    );
    for r in stats {
        s.push_str(&format!(
            "{:<20} {:>7} {:>10} {:>10} {:>7} {:>10} {:>11} {:>6.2} {:>6.2} {:>6.3}  {}\n",
            r.joint,
            r.rows,
            sig(r.measured_rms),
            sig(r.msr),
            sig(100.0 * r.msr.sqrt() / r.measured_rms),
            sig(r.mean),
            r.noise_floor.map_or("-".into(), |f| format!(
                "{}{}",
                sig(f),
                if r.floor_borrowed { "*" } else { "" }
            )),
            r.skewness,
            r.excess_kurtosis,
            r.ks,
            r.verdict().name()
        ));
    }
    if stats.iter().any(|r| r.floor_borrowed) {
        s.push_str("* the excitation's noise floor (its averaged torque's noise variance times the periods averaged, times the share this data's low-pass lets through): this data does not repeat and has no still stretch (every joint's encoder still) to measure its own on\n");
    }
    // Pooled over every row: what one number says about the data.
    let sum = |f: &dyn Fn(&JointResidue) -> f64| stats.iter().map(|r| r.rows as f64 * f(r)).sum::<f64>();
    let floor = stats
        .iter()
        .map(|r| r.noise_floor.map(|f| r.rows as f64 * f))
        .sum::<Option<f64>>();
    s.push_str(&format!(
        "all joints: {}\n",
        pooled(sum(&|r| r.msr), sum(&|r| r.measured_rms.powi(2)), floor)
    ));
    s
}

/// Relative error (and residue over the noise floor) from sums over rows
/// of the squared residue, the squared torque and the noise variance.
fn pooled(residue: f64, torque: f64, floor: Option<f64>) -> String {
    format!(
        "relative error {:.2} % (√(Σ squared residue / Σ squared torque) over all rows){}",
        100.0 * (residue / torque).sqrt(),
        floor.map_or(String::new(), |f| format!(
            ", mean squared residue {:.2}× the noise floor",
            residue / f
        ))
    )
}

/// The pooled figures of each recording of `sys`, one line each, when
/// it holds more than one.
pub fn per_recording(sys: &System, predicted: &DVector<f64>) -> String {
    if sys.recordings.len() < 2 {
        return String::new();
    }
    robotid::validation::per_recording(sys, predicted)
        .iter()
        .map(|r| format!("{}: {}\n", r.name, pooled(r.residue, r.torque, r.floor)))
        .collect()
}
