//! The regressor of a `filtered` chain (a record that does not repeat):
//! columns made at the samples from the motion, then put through the data
//! filter the torque goes through (`stage::motion`), and the rows near a
//! joint's starts and stops left out: there the encoder cannot tell when
//! the joint began to move, and a hard Coulomb step lands within a few
//! samples of where the positions say (on the foreign UR5's point-to-point
//! record, 30–200× the noise floor from those stretches alone).

use std::collections::BTreeMap;

use nalgebra::DMatrix;
use robotid_schemas::{metadata, Kinematics};

use crate::signal::{apply_table, gain_table, AnalogFilter, Complex64, FilterSpec, Spectra};
use crate::{Error, Result};

/// What a `filtered` chain's kinematics say the regressor must do.
pub struct ColumnFilter {
    filter: AnalogFilter,
    fs: f64,
    /// Per joint (the kinematics' order), where it may move unseen.
    unseen: Vec<Vec<[usize; 2]>>,
    /// Per joint, the noise floor of the filtered torque on this record.
    floor: Option<Vec<f64>>,
    /// Samples left out on each side of a start or stop, and at the ends.
    margin: usize,
    /// The floor's degrees of freedom.
    floor_dof: Option<f64>,
}

/// Where the ratio of two variance estimates of one variance, with `d1`
/// and `d2` degrees of freedom, stays under as often as a normal variable
/// stays under 3 standard deviations: Fisher's F quantile by Paulson's
/// approximation (each estimate's cube root near normal, after Wilson and
/// Hilferty; within 0.05 % of the exact quantile from 100 degrees of
/// freedom, 0.5 % from 10; statrs's inverse CDF did not return for 10⁹).
/// Infinite when there is nothing to tell.
fn ratio_quantile(d1: f64, d2: f64) -> f64 {
    const Z: f64 = 3.0;
    if !(d1 > 0.0 && d2 > 0.0) {
        return f64::INFINITY;
    }
    let (c1, c2) = (2.0 / (9.0 * d1), 2.0 / (9.0 * d2));
    let (a, b) = (1.0 - c2, 1.0 - c1);
    let lead = a * a - Z * Z * c2;
    let disc = a * a * b * b - lead * (b * b - Z * Z * c1);
    if !(lead > 0.0 && disc >= 0.0) {
        return f64::INFINITY;
    }
    ((a * b + disc.sqrt()) / lead).powi(3)
}

impl ColumnFilter {
    /// The column filter `kin` declares (`robotid.column_filter`), if any.
    pub fn of(kin: &Kinematics) -> Result<Option<ColumnFilter>> {
        let Some(text) = kin.metadata.get(metadata::COLUMN_FILTER) else {
            return Ok(None);
        };
        let spec: FilterSpec =
            serde_json::from_str(text).map_err(|e| Error::setting(metadata::COLUMN_FILTER, "a filter", e))?;
        let filter = AnalogFilter::new(spec).map_err(|e| Error::setting(metadata::COLUMN_FILTER, "a filter", e))?;
        let n = kin.time.len();
        let fs = kin
            .metadata
            .get(metadata::SAMPLE_RATE_HZ)
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| (n - 1) as f64 / (kin.time[n - 1] - kin.time[0]));
        let by_joint = |key: &str| -> Result<Option<Vec<f64>>> {
            let Some(text) = kin.metadata.get(key) else {
                return Ok(None);
            };
            let map: BTreeMap<String, f64> =
                serde_json::from_str(text).map_err(|e| Error::setting(key, "numbers by joint", e))?;
            Ok(kin.joints.iter().map(|j| map.get(j).copied()).collect())
        };
        let unseen: BTreeMap<String, Vec<[usize; 2]>> = match kin.metadata.get(metadata::UNSEEN) {
            Some(text) => {
                serde_json::from_str(text).map_err(|e| Error::setting(metadata::UNSEEN, "sample ranges by joint", e))?
            }
            None => BTreeMap::new(),
        };
        let unseen = kin
            .joints
            .iter()
            .map(|j| unseen.get(j).cloned().unwrap_or_default())
            .collect();
        let margin = (super::super::motion::margin_s(&filter, fs) * fs).ceil() as usize;
        Ok(Some(ColumnFilter {
            filter,
            fs,
            unseen,
            floor: by_joint(metadata::RECORD_FLOOR)?,
            margin,
            floor_dof: kin
                .metadata
                .get(metadata::RECORD_FLOOR_DOF)
                .and_then(|d| d.parse().ok()),
        }))
    }

    /// A's columns (rows sample-major, `torque.len()` joints) and the
    /// torque through |H|², zero phase, each joint's series on its own.
    pub fn apply(&self, a: &mut DMatrix<f64>, torque: &mut [Vec<f64>], spectra: &Spectra) {
        let n = torque.len();
        let samples = torque.first().map_or(0, Vec::len);
        let low = |hz: f64| Complex64::new(self.filter.response(hz).norm_sqr(), 0.0);
        let table = gain_table(crate::signal::extended_len(samples, self.fs, false), self.fs, &low);
        let mut series = vec![0.0; samples];
        for c in 0..a.ncols() {
            for j in 0..n {
                for (k, x) in series.iter_mut().enumerate() {
                    *x = a[(k * n + j, c)];
                }
                for (k, x) in apply_table(&series, self.fs, false, &table, spectra)
                    .into_iter()
                    .enumerate()
                {
                    a[(k * n + j, c)] = x;
                }
            }
        }
        for t in torque.iter_mut() {
            *t = apply_table(t, self.fs, false, &table, spectra);
        }
    }

    /// Per joint, the ratio of mean squared residue to the floor that the
    /// true parameters stay under as often as a normal variable stays
    /// under 3 standard deviations (99.87 %): the quantile of the ratio of
    /// two variances, Fisher's F, with the residue's degrees of freedom
    /// (`rows` per joint, noise through |H|²: 2·B_eq per second, B_eq =
    /// (∫|H|⁴)²/∫|H|⁸) and the floor's (1 + 3 of its standard deviations
    /// would leave the skewed upper tail out: 1.49 where F says 1.64 for
    /// 158 and 143); at least [`crate::estimation::ADEQUATE_RATIO`]. None
    /// without a floor.
    pub fn adequate_within(&self, rows: &[usize]) -> Option<Vec<f64>> {
        let floor_dof = self.floor_dof.filter(|d| *d > 0.0)?;
        let grid = 20_000;
        let df = self.fs / 2.0 / grid as f64;
        let (p4, p8) = (0..grid)
            .map(|k| self.filter.response((k as f64 + 0.5) * df).norm_sqr().powi(2))
            .fold((0.0, 0.0), |(a, b), h4| (a + h4 * df, b + h4 * h4 * df));
        let b_eq = p4 * p4 / p8;
        Some(
            rows.iter()
                .map(|&r| {
                    let dof = 2.0 * b_eq * r as f64 / self.fs;
                    ratio_quantile(dof, floor_dof).max(crate::estimation::ADEQUATE_RATIO)
                })
                .collect(),
        )
    }

    /// Each row's noise variance: this record's floor, or unknown (NaN).
    pub fn variance(&self, n: usize, samples: usize) -> nalgebra::DVector<f64> {
        nalgebra::DVector::from_fn(samples * n, |i, _| {
            self.floor
                .as_ref()
                .and_then(|f| f.get(i % n).copied())
                .unwrap_or(f64::NAN)
        })
    }

    /// `system` with only [`ColumnFilter::kept_rows`], what was left out
    /// and each joint's adequacy bound said in `md`, and the joints'
    /// order (rows left out from its start: not the first rows').
    pub fn keep_rows(
        &self,
        kin: &Kinematics,
        system: &mut crate::estimation::System,
        md: &mut BTreeMap<String, String>,
        names: &[String],
    ) -> Result<()> {
        let (rows, said) = self.kept_rows(kin);
        system.keep_rows(&rows);
        md.insert(metadata::LEFT_OUT.into(), said);
        let per_joint: Vec<usize> = (0..names.len())
            .map(|j| system.joint.iter().filter(|&&x| x == j).count())
            .collect();
        if let Some(within) = self.adequate_within(&per_joint) {
            let map: BTreeMap<&str, f64> = names.iter().map(String::as_str).zip(within).collect();
            md.insert(
                metadata::ADEQUATE_WITHIN.into(),
                serde_json::to_string(&map).map_err(|e| Error::numerical("serde_json", e.to_string()))?,
            );
        }
        md.insert(metadata::JOINTS.into(), names.join(","));
        Ok(())
    }

    /// The rows kept (sample-major): not within the margin of where a
    /// joint may move unseen (its starts and stops), nor of the record's
    /// ends (mirror-extended there); and what was left out, said.
    pub fn kept_rows(&self, kin: &Kinematics) -> (Vec<usize>, String) {
        let (n, samples) = (kin.joints.len(), kin.time.len());
        let mut keep = vec![true; samples * n];
        let m = self.margin;
        for (j, unseen) in self.unseen.iter().enumerate() {
            let mut cut = |from: usize, to: usize| (from..to.min(samples)).for_each(|k| keep[k * n + j] = false);
            cut(0, m);
            cut(samples.saturating_sub(m), samples);
            for [from, to] in unseen {
                cut(from.saturating_sub(m), to + m);
            }
        }
        let rows: Vec<usize> = (0..samples * n).filter(|&i| keep[i]).collect();
        let said = format!(
            "{} of {} rows left out: within {:.3} s of a joint's start or stop (where it may move before its first encoder step or after its last) or of the record's ends, which the data filter ({:?} order {} at {} Hz) spreads",
            samples * n - rows.len(),
            samples * n,
            m as f64 / self.fs,
            self.filter.spec.family,
            self.filter.spec.order,
            self.filter.spec.cutoff_hz,
        );
        (rows, said)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against scipy.stats.f.ppf(0.99865010196837, d1, d2).
    #[test]
    fn the_ratio_bound_is_fishers_quantile() {
        let cases = [
            (158.0, 143.0, 1.641_204_0, 5e-4),
            (158.0, 1e9, 1.371_465_1, 5e-4),
            (500.0, 143.0, 1.526_372_5, 5e-4),
            (2000.0, 2000.0, 1.143_657_2, 5e-4),
            (30.0, 30.0, 3.103_828_4, 5e-3),
            (10.0, 1000.0, 2.908_565_5, 1e-2),
        ];
        for (d1, d2, scipy, tol) in cases {
            let q = ratio_quantile(d1, d2);
            assert!((q / scipy - 1.0).abs() < tol, "F({d1}, {d2}): {q}, scipy {scipy}");
        }
        assert_eq!(ratio_quantile(0.0, 10.0), f64::INFINITY);
    }
}
