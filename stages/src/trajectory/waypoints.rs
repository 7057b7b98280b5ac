use crate::Problem;
use serde::{Deserialize, Serialize};

/// One duration for every move, or a list with one per move.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Durations {
    All(f64),
    Each(Vec<f64>),
}

/// Rest-to-rest moves through waypoints, each a quintic in time (zero
/// velocity and acceleration at both ends), with an optional dwell at each
/// point: a non-periodic validation trajectory in the spirit of Swevers'
/// "20 points, full stop at each".
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Waypoints {
    /// Joint positions, rad, `[point][joint]`; the first is the start.
    pub points: Vec<Vec<f64>>,
    /// Duration of each move, s: one number for all moves, or one per move.
    pub segment_s: Durations,
    /// Rest at each point before moving on, s.
    #[serde(default)]
    pub dwell_s: f64,
}

impl Waypoints {
    pub fn validate(&self) -> Result<(), Problem> {
        if self.points.len() < 2 {
            return Err(Problem::new("points", "at least two waypoints are needed"));
        }
        let n = self.points[0].len();
        if n == 0 || self.points.iter().any(|p| p.len() != n) {
            return Err(Problem::new(
                "points",
                "every waypoint must list one position per joint",
            ));
        }
        let moves = self.points.len() - 1;
        let list: &[f64] = match &self.segment_s {
            Durations::All(d) => std::slice::from_ref(d),
            Durations::Each(v) if v.len() == moves => v,
            Durations::Each(v) => {
                return Err(Problem::new(
                    "segment_s",
                    format!("segment_s lists {} durations for {moves} moves", v.len()),
                ))
            }
        };
        if list.iter().any(|d| !(*d > 0.0)) || !(self.dwell_s >= 0.0) {
            return Err(Problem::new("segment_s", "durations must be > 0 and dwell_s ≥ 0"));
        }
        Ok(())
    }

    fn segment(&self, k: usize) -> f64 {
        match &self.segment_s {
            Durations::All(d) => *d,
            Durations::Each(v) => v[k],
        }
    }

    /// Total duration: dwell, move, dwell, move, …, dwell.
    pub fn duration(&self) -> f64 {
        let moves = self.points.len() - 1;
        (0..moves).map(|k| self.segment(k)).sum::<f64>() + self.dwell_s * self.points.len() as f64
    }

    pub fn eval(&self, t: f64, q: &mut [f64], qd: &mut [f64], qdd: &mut [f64]) {
        let mut start = 0.0;
        let moves = self.points.len() - 1;
        for k in 0..moves {
            let d = self.segment(k);
            let move_start = start + self.dwell_s;
            if t < move_start {
                return hold(&self.points[k], q, qd, qdd);
            }
            if t < move_start + d {
                let s = (t - move_start) / d;
                // Quintic 10s³ − 15s⁴ + 6s⁵ and its derivatives.
                let p = s * s * s * (10.0 + s * (-15.0 + 6.0 * s));
                let v = 30.0 * s * s * (1.0 - s) * (1.0 - s) / d;
                let a = 60.0 * s * (1.0 - s) * (1.0 - 2.0 * s) / (d * d);
                for i in 0..q.len() {
                    let delta = self.points[k + 1][i] - self.points[k][i];
                    q[i] = self.points[k][i] + delta * p;
                    qd[i] = delta * v;
                    qdd[i] = delta * a;
                }
                return;
            }
            start = move_start + d;
        }
        hold(&self.points[moves], q, qd, qdd);
    }
}

fn hold(p: &[f64], q: &mut [f64], qd: &mut [f64], qdd: &mut [f64]) {
    q.copy_from_slice(p);
    qd.iter_mut().for_each(|v| *v = 0.0);
    qdd.iter_mut().for_each(|v| *v = 0.0);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn passes_through_points_at_rest() {
        let w = Waypoints {
            points: vec![vec![0.0, 1.0], vec![1.0, -1.0], vec![0.5, 0.0]],
            segment_s: Durations::All(2.0),
            dwell_s: 0.5,
        };
        w.validate().unwrap();
        assert!((w.duration() - 5.5).abs() < 1e-15);
        let (mut q, mut qd, mut qdd) = ([0.0; 2], [0.0; 2], [0.0; 2]);
        w.eval(2.5, &mut q, &mut qd, &mut qdd);
        assert!((q[0] - 1.0).abs() < 1e-12 && qd[0].abs() < 1e-12 && qdd[0].abs() < 1e-9);
        w.eval(1.5, &mut q, &mut qd, &mut qdd);
        assert!((q[0] - 0.5).abs() < 1e-12 && (qd[0] - 30.0 / 16.0 / 2.0).abs() < 1e-12);
        w.eval(99.0, &mut q, &mut qd, &mut qdd);
        assert_eq!(q, [0.5, 0.0]);
    }
}
