//! Validation as people read it: the per-joint residue table, pooled
//! relative errors per recording.

use nalgebra::DVector;
use robotid::validation::JointResidue;
use robotid_stages::estimation::System;

/// The residue table as text.
pub fn table(stats: &[JointResidue]) -> String {
    let mut s = format!(
        "{:<10} {:>7} {:>12} {:>14} {:>10} {:>12} {:>14} {:>9} {:>9} {:>7}  verdict\n",
        "joint", "rows", "rms τ N·m", "MSR (N·m)²", "rel. %", "mean N·m", "noise floor", "skew", "kurt-3", "KS"
    );
    for r in stats {
        s.push_str(&format!(
            "{:<10} {:>7} {:>12.4} {:>14.4e} {:>10.3} {:>12.3e} {:>14} {:>9.3} {:>9.3} {:>7.4}  {}\n",
            r.joint,
            r.rows,
            r.measured_rms,
            r.msr,
            100.0 * r.msr.sqrt() / r.measured_rms,
            r.mean,
            r.noise_floor.map_or("-".into(), |f| format!("{f:.4e}")),
            r.skewness,
            r.excess_kurtosis,
            r.ks,
            r.verdict().name()
        ));
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
    let mut s = String::new();
    for (r, name) in sys.recordings.iter().enumerate() {
        let rows: Vec<usize> = (0..sys.rows()).filter(|&i| sys.recording[i] == r).collect();
        let residue = rows.iter().map(|&i| (sys.b[i] - predicted[i]).powi(2)).sum();
        let torque = rows.iter().map(|&i| sys.b[i].powi(2)).sum();
        let floor = rows.iter().map(|&i| sys.var[i]).sum::<f64>();
        s.push_str(&format!(
            "{name}: {}\n",
            pooled(residue, torque, floor.is_finite().then_some(floor))
        ));
    }
    s
}
