//! Large synthetic recordings for benchmarks: closed-form periodic positions
//! and torques plus white noise, on an exact grid. Not physics (use the
//! simulator for that): cheap to make at any size.

use std::collections::BTreeMap;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use robotid_schemas::{metadata, RawSamples, TorqueChannel};

/// `joints` joints at `rate_hz` for `duration_s`, period `period_s`, five
/// harmonics; torques in N·m.
pub fn synthetic_recording(joints: usize, rate_hz: f64, duration_s: f64, period_s: f64, seed: u64) -> RawSamples {
    let n = (duration_s * rate_hz).round() as usize;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let w0 = 2.0 * std::f64::consts::PI / period_s;
    let time: Vec<f64> = (0..n).map(|k| k as f64 / rate_hz).collect();
    let mut q = Vec::with_capacity(joints);
    let mut tau = Vec::with_capacity(joints);
    for j in 0..joints {
        let amp = 0.3 + 0.05 * j as f64;
        let (mut qj, mut tj) = (Vec::with_capacity(n), Vec::with_capacity(n));
        for &t in &time {
            let mut p = 0.0;
            let mut a = 0.0;
            for h in 1..=5 {
                let w = w0 * h as f64;
                let (s, c) = (w * t + j as f64).sin_cos();
                p += amp / h as f64 * s;
                a -= amp * w * w / h as f64 * s + 0.1 * c;
            }
            let nq: f64 = rng.sample(StandardNormal);
            let nt: f64 = rng.sample(StandardNormal);
            qj.push(p + 1e-5 * nq);
            tj.push(5.0 * a + 20.0 * p.sin() + 0.5 * nt);
        }
        q.push(qj);
        tau.push(tj);
    }
    RawSamples {
        joints: (1..=joints).map(|j| format!("j{j}")).collect(),
        time,
        q,
        effort_kind: TorqueChannel::Torque,
        effort: tau,
        reference: None,
        counts: None,
        metadata: BTreeMap::from([
            (metadata::SAMPLE_RATE_HZ.to_string(), rate_hz.to_string()),
            (metadata::PERIOD_S.to_string(), period_s.to_string()),
            (metadata::HARMONICS.to_string(), "1,2,3,4,5".to_string()),
        ]),
    }
}
