use crate::Problem;
use serde::{Deserialize, Serialize};

/// Dedicated experiments (Bona §3.2): one joint moves back and forth over a
/// range at constant velocities, the others hold still. Each pass is a
/// trapezoid in velocity: accelerate at `acceleration`, cruise at ±v,
/// brake; at each end the joint rests for `dwell_s`. The cruise parts show
/// gravity plus the friction at ±v (no inertia, Bona's slope trajectories);
/// with a range too short to reach v, a pass is bang-bang in acceleration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sweeps {
    /// Index of the moving joint.
    pub joint: usize,
    /// Every joint's position at rest, rad; the moving joint starts at `range[0]`.
    pub hold: Vec<f64>,
    /// The moving joint's range, rad.
    pub range: [f64; 2],
    /// Cruise speeds, rad/s: each gives a pass out (+v) and back (−v).
    pub velocities: Vec<f64>,
    /// rad/s².
    pub acceleration: f64,
    #[serde(default)]
    pub dwell_s: f64,
}

impl Sweeps {
    pub fn validate(&self) -> Result<(), Problem> {
        if self.joint >= self.hold.len() {
            return Err(Problem::new(
                "joint",
                format!(
                    "joint {} is not among the {} held positions",
                    self.joint,
                    self.hold.len()
                ),
            ));
        }
        if !(self.range[1] > self.range[0]) {
            return Err(Problem::new("range", "range must be [low, high] with high > low"));
        }
        if self.velocities.is_empty() || self.velocities.iter().any(|v| !(*v > 0.0)) {
            return Err(Problem::new(
                "velocities",
                "velocities must be a non-empty list of speeds > 0",
            ));
        }
        if !(self.acceleration > 0.0) || !(self.dwell_s >= 0.0) {
            return Err(Problem::new("acceleration", "acceleration must be > 0 and dwell_s ≥ 0"));
        }
        Ok(())
    }

    /// Duration of one pass at speed v: (time, reached speed).
    fn pass(&self, v: f64) -> (f64, f64) {
        let d = self.range[1] - self.range[0];
        let a = self.acceleration;
        let ramp = v * v / a; // distance of both ramps
        if ramp >= d {
            let vp = (d * a).sqrt();
            (2.0 * vp / a, vp)
        } else {
            (2.0 * v / a + (d - ramp) / v, v)
        }
    }

    pub fn duration(&self) -> f64 {
        self.dwell_s
            + self
                .velocities
                .iter()
                .map(|&v| 2.0 * (self.pass(v).0 + self.dwell_s))
                .sum::<f64>()
    }

    pub fn eval(&self, t: f64, q: &mut [f64], qd: &mut [f64], qdd: &mut [f64]) {
        q.copy_from_slice(&self.hold);
        qd.iter_mut().for_each(|x| *x = 0.0);
        qdd.iter_mut().for_each(|x| *x = 0.0);
        let j = self.joint;
        let (lo, hi) = (self.range[0], self.range[1]);
        q[j] = lo;
        let mut start = self.dwell_s;
        for &v in &self.velocities {
            let (dur, vp) = self.pass(v);
            for (from, dir) in [(lo, 1.0), (hi, -1.0)] {
                if t < start {
                    q[j] = from;
                    return;
                }
                if t < start + dur {
                    let s = t - start;
                    let a = self.acceleration;
                    let ta = vp / a;
                    let (p, vel, acc) = if s < ta {
                        (0.5 * a * s * s, a * s, a)
                    } else if s < dur - ta {
                        (0.5 * a * ta * ta + vp * (s - ta), vp, 0.0)
                    } else {
                        let r = dur - s;
                        (hi - lo - 0.5 * a * r * r, a * r, -a)
                    };
                    q[j] = from + dir * p;
                    qd[j] = dir * vel;
                    qdd[j] = dir * acc;
                    return;
                }
                start += dur + self.dwell_s;
                q[j] = if dir > 0.0 { hi } else { lo };
            }
        }
        q[j] = lo;
    }

    /// Whether the commanded motion cruises at constant speed at time t.
    pub fn cruising(&self, t: f64) -> bool {
        let (mut q, mut qd, mut qdd) = (self.hold.clone(), self.hold.clone(), self.hold.clone());
        self.eval(t, &mut q, &mut qd, &mut qdd);
        qdd[self.joint] == 0.0 && qd[self.joint] != 0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trapezoids_cover_the_range_and_come_back() {
        let s = Sweeps {
            joint: 1,
            hold: vec![0.3, 0.0],
            range: [-1.0, 1.0],
            velocities: vec![0.5, 4.0],
            acceleration: 2.0,
            dwell_s: 0.5,
        };
        s.validate().unwrap();
        let (mut q, mut qd, mut qdd) = ([0.0; 2], [0.0; 2], [0.0; 2]);
        // Pass 1 at 0.5 rad/s: ramps 0.25 s, cruise 3.75 s.
        s.eval(0.5 + 2.0, &mut q, &mut qd, &mut qdd);
        assert_eq!(q[0], 0.3);
        assert!((qd[1] - 0.5).abs() < 1e-12 && qdd[1] == 0.0);
        s.eval(0.5 + 4.25 - 1e-9, &mut q, &mut qd, &mut qdd);
        assert!((q[1] - 1.0).abs() < 1e-8, "{}", q[1]);
        // 4 rad/s is never reached on 2 rad at 2 rad/s²: bang-bang, peak 2 rad/s.
        let (dur, vp) = s.pass(4.0);
        assert!((vp - 2.0).abs() < 1e-12 && (dur - 2.0).abs() < 1e-12);
        // Numerical derivative of q matches qd.
        let h = 1e-6;
        for t in [1.0, 3.0, 7.0, 9.6, 11.0] {
            let (mut a, mut b) = ([0.0; 2], [0.0; 2]);
            s.eval(t + h, &mut a, &mut qd, &mut qdd);
            s.eval(t - h, &mut b, &mut qd, &mut qdd);
            s.eval(t, &mut q, &mut qd, &mut qdd);
            assert!(((a[1] - b[1]) / (2.0 * h) - qd[1]).abs() < 1e-5, "t {t}");
        }
        s.eval(s.duration() + 1.0, &mut q, &mut qd, &mut qdd);
        assert_eq!(q[1], -1.0);
    }
}
