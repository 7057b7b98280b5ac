//! Pictures of one recording's run (`robotid run --plot DIR`), as SVG:
//! - `signals.svg`: positions and torques, a few recorded periods (grey)
//!   under their average (black);
//! - `spectrum.svg`: torque and position spectra of the whole record, the
//!   excited harmonics marked;
//! - `noise.svg`: noise standard deviation of the averaged torque per sample;
//! - `derivatives.svg`: velocities and accelerations;
//!
//! and `report.md`, a short summary with links to them.

use robotid::{Error, Result};
use std::path::{Path, PathBuf};

use plotters::prelude::*;
use robotid_schemas::{Kinematics, NoiseTable, PeriodMean};
use robotid_stages::formats::write_atomic;
use robotid_stages::signal::Spectra;
use robotid_stages::stage::noise::ChannelNoise;
use robotid_stages::stage::Periods;

use robotid_stages::stage::Report;

/// What a run produced for one recording.
pub struct Inputs<'a> {
    pub name: &'a str,
    pub periods: Option<&'a Periods>,
    pub mean: Option<&'a PeriodMean>,
    pub noise: Option<&'a NoiseTable>,
    pub kinematics: Option<&'a Kinematics>,
    pub harmonics: &'a [u32],
    pub spectra: &'a Spectra,
}

pub(crate) type Series<'a> = (Vec<(f64, f64)>, RGBColor, &'a str);

/// Points drawn as dots of one colour, with their legend's label.
#[derive(Clone, Copy)]
pub(crate) struct Dots<'a> {
    pub pts: &'a [(f64, f64)],
    pub color: RGBColor,
    pub size: u32,
    pub label: &'a str,
}

pub(crate) const GREY: RGBColor = RGBColor(170, 170, 170);
pub(crate) const BLUE_: RGBColor = RGBColor(31, 119, 180);
pub(crate) const ORANGE: RGBColor = RGBColor(255, 127, 14);

/// The axes' ranges over the finite points, padded; unit ones
/// where there are none (an axis over ±f64::MAX spun the tick search).
fn range<'p>(points: impl Iterator<Item = &'p [(f64, f64)]>) -> (f64, f64, f64, f64) {
    let mut r = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for pts in points {
        for &(x, y) in pts.iter().filter(|p| p.0.is_finite() && p.1.is_finite()) {
            r = (r.0.min(x), r.1.max(x), r.2.min(y), r.3.max(y));
        }
    }
    if r.0 > r.1 {
        r = (0.0, 1.0, 0.0, 1.0);
    }
    if r.0 >= r.1 {
        r.1 = r.0 + 1.0;
    }
    let pad = ((r.3 - r.2) * 0.05).clamp(1e-12, 1e300);
    (r.0, r.1, r.2 - pad, r.3 + pad)
}

/// A tick label with the decimals its spacing needs (`250`, `0.5`,
/// `-0.02`; never `-0.000`, `250.000` or `0.00e0`), in scientific
/// notation (`2.5e-4`) where plain numbers would run long or round away.
pub(crate) fn tick(v: f64, lo: f64, hi: f64) -> String {
    let span = (hi - lo).abs().max(1e-300);
    // plotters puts at most ten ticks on an axis, at the smallest step of
    // 1, 2 or 5 × 10^k that keeps to that; its decimals are 10^k's.
    let k = (span / 10.0).log10().floor() as i32;
    let k = if [1.0, 2.0, 5.0].iter().any(|m| m * 10f64.powi(k) >= span / 10.0) {
        k
    } else {
        k + 1
    };
    let big = lo.abs().max(hi.abs()).max(1e-300);
    let e = big.log10().floor() as i32;
    let s = if (-3..5).contains(&e) {
        // The decimals the value itself needs (plotters may step finer
        // than a tenth of the span: 0.5 on a span of 5.6).
        let exact = (0..8).find(|&d| {
            let p = 10f64.powi(d);
            ((v * p).round() / p - v).abs() <= 1e-9 * span
        });
        format!("{v:.*}", exact.map_or((-k).max(0) as usize, |d| d as usize))
    } else {
        let m = v / 10f64.powi(e);
        format!("{m:.*}e{e}", (e - k).max(0) as usize)
    };
    // A value that rounds to zero is 0, without a sign or an exponent.
    if s.trim_start_matches('-')
        .chars()
        .take_while(|c| *c != 'e')
        .all(|c| c == '0' || c == '.')
    {
        "0".into()
    } else {
        s
    }
}

/// One chart of line series (and optional red markers) in `area`. A grey
/// series is the measurement: drawn wide, under the others, so that it
/// shows where they lie on it. The legend sits right of the plot, off the
/// curves.
pub(crate) fn chart(
    area: &DrawingArea<SVGBackend, plotters::coord::Shift>,
    title: &str,
    x_desc: &str,
    y_desc: &str,
    series: &[Series],
    dots: Option<Dots>,
) -> Result<()> {
    let (x0, x1, y0, y1) = range(series.iter().map(|s| s.0.as_slice()).chain(dots.map(|d| d.pts)));
    let e = |e: &dyn std::fmt::Display| picture(e);
    let labelled = dots.is_some() || series.iter().any(|s| !s.2.is_empty());
    let mut c = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 16))
        .margin(8)
        .margin_right(if labelled { 150 } else { 8 })
        .x_label_area_size(32)
        .y_label_area_size(64)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(|x| e(&x))?;
    let fx = move |v: &f64| tick(*v, x0, x1);
    let fy = move |v: &f64| tick(*v, y0, y1);
    c.configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .x_label_formatter(&fx)
        .y_label_formatter(&fy)
        .draw()
        .map_err(|x| e(&x))?;
    // Dots under the lines: a line drawn through a cloud is the model of it.
    if let Some(d) = dots {
        c.draw_series(
            d.pts
                .iter()
                .map(|&(x, y)| Circle::new((x, y), d.size, d.color.filled())),
        )
        .map_err(|x| e(&x))?;
    }
    for (pts, color, _) in series {
        let width = if *color == GREY { 3 } else { 1 };
        c.draw_series(LineSeries::new(pts.iter().copied(), color.stroke_width(width)))
            .map_err(|x| e(&x))?;
    }
    // The legend in the right margin, drawn on the whole area (plotters
    // keeps its own legend inside the plot, over the curves).
    if labelled {
        let (w, _) = area.dim_in_pixel();
        let x = w as i32 - 140;
        let mut y = 40;
        for (_, color, label) in series.iter().filter(|s| !s.2.is_empty()) {
            let width = if *color == GREY { 3 } else { 1 };
            area.draw(&PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(width)))
                .map_err(|x| e(&x))?;
            area.draw(&Text::new(label.to_string(), (x + 24, y - 6), ("sans-serif", 12)))
                .map_err(|x| e(&x))?;
            y += 18;
        }
        if let Some(d) = dots {
            area.draw(&Circle::new((x + 9, y), 3, d.color.filled()))
                .map_err(|x| e(&x))?;
            area.draw(&Text::new(d.label, (x + 24, y - 6), ("sans-serif", 12)))
                .map_err(|x| e(&x))?;
        }
    }
    Ok(())
}

/// Renders a figure of `rows × cols` charts into `path`, atomically.
pub(crate) fn figure(
    path: &Path,
    rows: usize,
    cols: usize,
    draw: impl Fn(&[DrawingArea<SVGBackend, plotters::coord::Shift>]) -> Result<()>,
) -> Result<()> {
    let svg = figure_svg(rows, cols, draw)?;
    write_text(path, &svg)
}

/// A figure of `rows × cols` charts as SVG text.
pub(crate) fn figure_svg(
    rows: usize,
    cols: usize,
    draw: impl Fn(&[DrawingArea<SVGBackend, plotters::coord::Shift>]) -> Result<()>,
) -> Result<String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (720 * cols as u32, 260 * rows as u32)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| picture(&e))?;
        let areas = root.split_evenly((rows, cols));
        draw(&areas)?;
        root.present().map_err(|e| picture(&e))?;
    }
    Ok(svg)
}

/// Writes a text file atomically.
pub fn write_text(path: &Path, text: &str) -> Result<()> {
    write_atomic(path, |w| {
        use std::io::Write;
        w.write_all(text.as_bytes())
            .map_err(|e| robotid_stages::Error::io(path, e))
    })
    .map_err(|e| picture(&e))
}

/// Each joint's noise standard deviation of the average, position and
/// torque, against time in the period.
fn noise_figure(path: &Path, noise: &NoiseTable, m: &PeriodMean) -> Result<()> {
    figure(path, noise.joints.len(), 2, |areas| {
        for j in 0..noise.joints.len() {
            for (k, (v, what, unit)) in [
                (&noise.var_q[j], "position", "rad"),
                (&noise.var_torque[j], "torque", "N·m"),
            ]
            .into_iter()
            .enumerate()
            {
                let pts = m.time.iter().zip(v.iter()).map(|(t, v)| (*t, v.sqrt())).collect();
                chart(
                    &areas[2 * j + k],
                    &format!("{} {what}: noise std of the average", noise.joints[j]),
                    "time in period [s]",
                    unit,
                    &[(pts, ORANGE, "")],
                    None,
                )?;
            }
        }
        Ok(())
    })
}

/// Each joint's recorded periods (up to 8) and their average, position
/// and torque, against time in the period.
fn signals_figure(path: &Path, p: &Periods, m: &PeriodMean) -> Result<()> {
    let n = p.samples_per_period;
    let nj = p.joints.len();
    let t: Vec<f64> = m.time.clone();
    figure(path, nj, 2, |areas| {
        for j in 0..nj {
            for (k, (col, avg, what, unit)) in [
                (&p.q[j], &m.q[j], "position", "rad"),
                (&p.torque[j], &m.torque[j], "torque", "N·m"),
            ]
            .into_iter()
            .enumerate()
            {
                let mut series: Vec<Series> = (0..p.periods.min(8))
                    .map(|r| {
                        (
                            t.iter().zip(&col[r * n..(r + 1) * n]).map(|(a, b)| (*a, *b)).collect(),
                            GREY,
                            "",
                        )
                    })
                    .collect();
                series.push((t.iter().zip(avg).map(|(a, b)| (*a, *b)).collect(), BLACK, "average"));
                if let Some(l) = series.first_mut() {
                    l.2 = "recorded periods";
                }
                chart(
                    &areas[2 * j + k],
                    &format!("{} {what}", p.joints[j]),
                    "time in period [s]",
                    unit,
                    &series,
                    None,
                )?;
            }
        }
        Ok(())
    })
}

/// Writes the pictures of one recording into `dir`; returns the files.
pub fn plot_recording(dir: &Path, inp: &Inputs) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|source| Error::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let mut files = Vec::new();
    if let (Some(p), Some(m)) = (inp.periods, inp.mean) {
        let nj = p.joints.len();
        let path = dir.join("signals.svg");
        signals_figure(&path, p, m)?;
        files.push(path);

        let path = dir.join("spectrum.svg");
        let df = 1.0 / (p.periods as f64 * p.period_s);
        let top = inp.harmonics.iter().copied().max().unwrap_or(5) as f64 * 4.0 / p.period_s;
        figure(&path, nj, 2, |areas| {
            for j in 0..nj {
                for (k, (col, what)) in [(&p.q[j], "position"), (&p.torque[j], "torque")]
                    .into_iter()
                    .enumerate()
                {
                    let spec = inp.spectra.forward(col);
                    let scale = 2.0 / col.len() as f64;
                    let level = |i: usize| (spec[i].norm() * scale).max(1e-300).log10();
                    let kmax = ((top / df) as usize).min(spec.len() - 1);
                    let pts: Vec<(f64, f64)> = (1..=kmax).map(|i| (i as f64 * df, level(i))).collect();
                    let marks: Vec<(f64, f64)> = inp
                        .harmonics
                        .iter()
                        .map(|&h| h as usize * p.periods)
                        .filter(|&i| i <= kmax)
                        .map(|i| (i as f64 * df, level(i)))
                        .collect();
                    chart(
                        &areas[2 * j + k],
                        &format!("{} {what} spectrum", p.joints[j]),
                        "frequency [Hz]",
                        "log10 amplitude",
                        &[(pts, BLUE_, "")],
                        Some(Dots {
                            pts: &marks,
                            color: RED,
                            size: 3,
                            label: "excited harmonics",
                        }),
                    )?;
                }
            }
            Ok(())
        })?;
        files.push(path);
    }
    if let (Some(noise), Some(m)) = (inp.noise, inp.mean) {
        let path = dir.join("noise.svg");
        noise_figure(&path, noise, m)?;
        files.push(path);
    }
    if let Some(kin) = inp.kinematics {
        let path = dir.join("derivatives.svg");
        kinematics_figure(&path, kin, false)?;
        files.push(path);
    }
    Ok(files)
}

/// Velocities and accelerations (and positions, if asked) of every joint
/// against time, one row of charts per joint.
fn kinematics_figure(path: &Path, kin: &Kinematics, positions: bool) -> Result<()> {
    let nj = kin.joints.len();
    let mut quantities = Vec::new();
    if positions {
        quantities.push((0, "position", "rad"));
    }
    quantities.extend([(1, "velocity", "rad/s"), (2, "acceleration", "rad/s²")]);
    let cols = quantities.len();
    figure(path, nj, cols, |areas| {
        for j in 0..nj {
            for (k, &(which, what, unit)) in quantities.iter().enumerate() {
                let v = match which {
                    0 => &kin.q[j],
                    1 => &kin.qd[j],
                    _ => &kin.qdd[j],
                };
                let pts = kin.time.iter().zip(v.iter()).map(|(t, v)| (*t, *v)).collect();
                chart(
                    &areas[cols * j + k],
                    &format!("{} {what}", kin.joints[j]),
                    "time [s]",
                    unit,
                    &[(pts, BLUE_, "")],
                    None,
                )?;
            }
        }
        Ok(())
    })
}

/// `report.md`: what the run found, what it could not do, the pictures.
pub fn write_report(dir: &Path, name: &str, o: &Report, pictures: &[PathBuf]) -> Result<PathBuf> {
    let mut r = format!("# {name}\n\n");
    r.push_str(&format!("- samples read: {}\n", o.samples));
    if let (Some(k), Some(f)) = (o.periods_kept, o.periods_found) {
        r.push_str(&format!("- steady periods kept: {k} of {f} whole periods\n"));
    }
    if let Some(d) = o.dropped_s {
        r.push_str(&format!("- dropped as start-up transient: {d:.3} s\n"));
    }
    if let Some(j) = o.jitter_rms_s {
        r.push_str(&format!("- timestamp jitter (RMS off a uniform grid): {j:.2e} s\n"));
    }
    if !o.noise.is_empty() {
        r.push_str("\n| joint | channel | variance, time domain | variance, frequency domain | skewness | excess kurtosis | KS p-value | band edge / middle |\n|---|---|---|---|---|---|---|---|\n");
        for c in &o.noise {
            let ChannelNoise {
                joint,
                channel,
                var_time,
                var_freq,
                skewness,
                excess_kurtosis,
                ks_p_value,
                band_edge_ratio,
                ..
            } = c;
            let edge = band_edge_ratio.map_or("-".into(), |r| format!("{r:.2}"));
            r.push_str(&format!(
                "| {joint} | {channel} | {var_time:.3e} | {var_freq:.3e} | {skewness:.3} | {excess_kurtosis:.3} | {ks_p_value:.3} | {edge} |\n"
            ));
        }
    }
    if !o.notes.is_empty() {
        r.push_str("\n## Notes\n\n");
        for n in &o.notes {
            r.push_str(&format!("- {n}\n"));
        }
    }
    if !pictures.is_empty() {
        r.push_str("\n## Pictures\n\n");
        for p in pictures {
            let f = p
                .file_name()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
            r.push_str(&format!("![{f}]({f})\n\n"));
        }
    }
    let path = dir.join("report.md");
    write_atomic(&path, |w| {
        use std::io::Write;
        w.write_all(r.as_bytes())
            .map_err(|e| robotid_stages::Error::io(&path, e))
    })
    .map_err(|e| picture(&e))?;
    Ok(path)
}

/// Measured (grey, wide, underneath) and predicted (blue) torque per
/// joint, and below each its residue on an axis of its own (on the
/// torque's axis it is a flat line).
pub fn torques_svg(sys: &robotid_stages::estimation::System, predicted: &nalgebra::DVector<f64>) -> Result<String> {
    let nj = sys.joints.len();
    // Recordings one after another on the time axis.
    let mut offset = vec![0.0; sys.recordings.len()];
    let mut end = 0.0f64;
    for r in 0..sys.recordings.len() {
        offset[r] = end;
        let last = (0..sys.rows())
            .filter(|&i| sys.recording[i] == r)
            .map(|i| sys.time[i])
            .fold(f64::MIN, f64::max);
        if last > f64::MIN {
            end += last;
        }
    }
    let rows_of = |j: usize| (0..sys.rows()).filter(move |&i| sys.joint[i] == j);
    let at = |i: usize| offset[sys.recording[i]] + sys.time[i];
    figure_svg(2 * nj, 1, |areas| {
        for j in 0..nj {
            let measured: Vec<(f64, f64)> = rows_of(j).map(|i| (at(i), sys.b[i])).collect();
            let pred: Vec<(f64, f64)> = rows_of(j).map(|i| (at(i), predicted[i])).collect();
            let residue: Vec<(f64, f64)> = rows_of(j).map(|i| (at(i), sys.b[i] - predicted[i])).collect();
            chart(
                &areas[2 * j],
                &format!("{}: measured and predicted torque", sys.joints[j]),
                "time, s",
                "N·m",
                &[(measured, GREY, "measured"), (pred, BLUE_, "predicted")],
                None,
            )?;
            chart(
                &areas[2 * j + 1],
                &format!("{}: residue, measured − predicted", sys.joints[j]),
                "time, s",
                "N·m",
                &[(residue, ORANGE, "residue")],
                None,
            )?;
        }
        Ok(())
    })
}

/// One joint's friction as the data show it and as the model has it.
pub(crate) struct FrictionSeen {
    pub joint: usize,
    /// (q̇, the friction seen): at most 600 samples, evenly by velocity.
    pub samples: Vec<(f64, f64)>,
    /// Per sign of q̇: bins of equal count, each (mean q̇, the model's
    /// mean friction, the mean friction seen).
    pub sides: Vec<Vec<(f64, f64, f64)>>,
}

/// The friction the data show, per joint that has friction columns: the
/// measured torque less every other column's share (the residue plus the
/// model's friction) against the joint's velocity, with its means and
/// the model's friction's over the same velocity bins (each sign on its
/// own, so a Coulomb step is not smeared across zero). Means, not the law
/// drawn: the columns may be filtered as the torque is, so the model's
/// friction is not a function of the velocity sample by sample. A joint
/// without a viscous column to read its velocity from (`Fv` holds q̇,
/// `Fv±` its two signs) is left out, and every joint where the rows are
/// projected equations rather than samples.
pub(crate) fn friction_seen(
    sys: &robotid_stages::estimation::System,
    theta: &nalgebra::DVector<f64>,
    predicted: &nalgebra::DVector<f64>,
) -> Vec<FrictionSeen> {
    if sys.equations.is_some() {
        return Vec::new();
    }
    let columns = |joint: &str, kinds: &[&str]| -> Vec<usize> {
        kinds
            .iter()
            .filter_map(|k| sys.names.iter().position(|n| *n == format!("{k}_{joint}")))
            .collect()
    };
    let mut out = Vec::new();
    for (j, joint) in sys.joints.iter().enumerate() {
        let velocity = columns(joint, &["Fv", "Fv+", "Fv-"]);
        if velocity.is_empty() {
            continue;
        }
        let friction = columns(joint, &["Fv", "Fv+", "Fv-", "Fc", "Fc+", "Fc-", "Fs", "Fs+", "Fs-"]);
        // (q̇, the model's friction, the friction seen), by velocity.
        let mut rows: Vec<(f64, f64, f64)> = (0..sys.rows())
            .filter(|&i| sys.joint[i] == j)
            .map(|i| {
                let qd: f64 = velocity.iter().map(|&c| sys.a[(i, c)]).sum();
                let model: f64 = friction.iter().map(|&c| sys.a[(i, c)] * theta[c]).sum();
                (qd, model, sys.b[i] - predicted[i] + model)
            })
            .filter(|r| r.0.is_finite() && r.2.is_finite())
            .collect();
        rows.sort_by(|a, b| a.0.total_cmp(&b.0));
        let every = rows.len().div_ceil(600).max(1);
        let samples = rows.iter().step_by(every).map(|r| (r.0, r.2)).collect();
        let zero = rows.partition_point(|r| r.0 < 0.0);
        let sides = [&rows[..zero], &rows[zero..]]
            .into_iter()
            .filter(|side| !side.is_empty())
            .map(|side| {
                // 25 bins a side, as many samples in each.
                let bin = side.len().div_ceil(25).max(5);
                side.chunks(bin)
                    .filter(|c| c.len() >= 5)
                    .map(|c| {
                        let n = c.len() as f64;
                        let sum = c.iter().fold((0.0, 0.0, 0.0), |s, r| (s.0 + r.0, s.1 + r.1, s.2 + r.2));
                        (sum.0 / n, sum.1 / n, sum.2 / n)
                    })
                    .collect()
            })
            .collect();
        out.push(FrictionSeen {
            joint: j,
            samples,
            sides,
        });
    }
    out
}

/// [`friction_seen`] drawn, one chart per joint (`predicted`: A·θ); None
/// where no joint has it.
pub fn friction_svg(
    sys: &robotid_stages::estimation::System,
    theta: &nalgebra::DVector<f64>,
    predicted: &nalgebra::DVector<f64>,
) -> Result<Option<String>> {
    let seen = friction_seen(sys, theta, predicted);
    if seen.is_empty() {
        return Ok(None);
    }
    let svg = figure_svg(seen.len(), 1, |areas| {
        for (area, f) in areas.iter().zip(&seen) {
            let mut series: Vec<Series> = Vec::new();
            for (k, side) in f.sides.iter().enumerate() {
                let (seen, model) = if k == 0 {
                    ("seen, bin means", "the model's, bin means")
                } else {
                    ("", "")
                };
                series.push((side.iter().map(|m| (m.0, m.2)).collect(), ORANGE, seen));
                series.push((side.iter().map(|m| (m.0, m.1)).collect(), BLUE_, model));
            }
            chart(
                area,
                &format!("{}: friction, measured − the rest of the model", sys.joints[f.joint]),
                "joint velocity [rad/s]",
                "N·m",
                &series,
                Some(Dots {
                    pts: &f.samples,
                    color: GREY,
                    size: 1,
                    label: "seen, samples",
                }),
            )?;
        }
        Ok(())
    })?;
    Ok(Some(svg))
}

/// Density of `values` per joint (a 40-bin histogram over ±4 std) against
/// the Gaussian of the same mean and spread.
pub fn density_svg(joints: &[String], values: &[Vec<f64>], what: &str) -> Result<String> {
    let nj = joints.len();
    figure_svg(nj, 1, |areas| {
        for j in 0..nj {
            let r = &values[j];
            let n = r.len().max(1) as f64;
            let mean = r.iter().sum::<f64>() / n;
            let sd = (r.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n)
                .sqrt()
                .max(1e-300);
            let bins = 40usize;
            let (lo, hi) = (mean - 4.0 * sd, mean + 4.0 * sd);
            let w = (hi - lo) / bins as f64;
            let mut count = vec![0usize; bins];
            for x in r {
                let b = ((x - lo) / w).floor();
                if b >= 0.0 && (b as usize) < bins {
                    count[b as usize] += 1;
                }
            }
            let mut hist = Vec::with_capacity(2 * bins);
            for (b, c) in count.iter().enumerate() {
                let d = *c as f64 / (n * w);
                hist.push((lo + b as f64 * w, d));
                hist.push((lo + (b + 1) as f64 * w, d));
            }
            let gauss: Vec<(f64, f64)> = (0..=200)
                .map(|k| {
                    let x = lo + (hi - lo) * k as f64 / 200.0;
                    let z = (x - mean) / sd;
                    (x, (-0.5 * z * z).exp() / (sd * (2.0 * std::f64::consts::PI).sqrt()))
                })
                .collect();
            chart(
                &areas[j],
                &format!("{}: {what} density", joints[j]),
                &format!("{what} [N·m]"),
                "1/(N·m)",
                &[(hist, BLUE_, what), (gauss, ORANGE, "Gaussian, same mean and std")],
                None,
            )?;
        }
        Ok(())
    })
}

/// Residues b − Aθ per joint.
pub fn residues_by_joint(
    sys: &robotid_stages::estimation::System,
    predicted: &nalgebra::DVector<f64>,
) -> Vec<Vec<f64>> {
    (0..sys.joints.len())
        .map(|j| {
            (0..sys.rows())
                .filter(|&i| sys.joint[i] == j)
                .map(|i| sys.b[i] - predicted[i])
                .collect()
        })
        .collect()
}

/// Pictures of a validation (`robotid validate --plot DIR`):
/// `validation_torques.svg` (measured in grey, predicted in blue, per
/// joint), `validation_residues.svg` (residue density against the Gaussian
/// of the same mean and spread) and `validation.md`.
pub fn plot_validation(
    dir: &Path,
    sys: &robotid_stages::estimation::System,
    predicted: &nalgebra::DVector<f64>,
    stats: &[robotid::validation::JointResidue],
) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|source| Error::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let torques = dir.join("validation_torques.svg");
    write_text(&torques, &torques_svg(sys, predicted)?)?;
    let residues = dir.join("validation_residues.svg");
    write_text(
        &residues,
        &density_svg(&sys.joints, &residues_by_joint(sys, predicted), "residue")?,
    )?;
    let report = dir.join("validation.md");
    let text = format!(
        "# Validation\n\nRecordings: {}\n\n```\n{}```\n\nMSR: mean squared residue (Swevers' figure); noise floor: mean torque noise variance from the noise stage (an MSR at the floor means the model explains all but the noise). KS: Kolmogorov–Smirnov distance of the standardised residue to a Gaussian.\n\n![torques](validation_torques.svg)\n\n![residues](validation_residues.svg)\n",
        sys.recordings.join(", "),
        crate::validation::table(stats)
    );
    write_text(&report, &text)?;
    Ok(vec![torques, residues, report])
}

/// Pictures of rollouts (`robotid validate --rollout --plot DIR`): per
/// record, `rollout_<k>.svg`, each joint's measured angle (grey, wide,
/// underneath), the estimate's simulated one (blue) and the robot file's
/// (orange), every window restarted from the measured state; a simulated
/// angle beyond the measured span by half of it is drawn at that edge.
pub fn plot_rollouts(dir: &Path, rolled: &[robotid::validation::RolledOut]) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|source| Error::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let mut files = Vec::new();
    for (k, r) in rolled.iter().enumerate() {
        let path = dir.join(format!("rollout_{k}.svg"));
        write_text(&path, &rollout_svg(r)?)?;
        files.push(path);
    }
    Ok(files)
}

/// One record's rollout picture (see [`plot_rollouts`]), as SVG text.
pub fn rollout_svg(r: &robotid::validation::RolledOut) -> Result<String> {
    angles_svg(
        (&r.joints, &r.time, &r.measured),
        [
            r.estimate.as_ref().ok().map(|e| &e.q),
            r.prior.as_ref().and_then(|p| p.as_ref().ok()).map(|p| &p.q),
        ],
        &format!("{:.2} s windows", r.window_s),
    )
}

/// One recording's closed-loop errors: per joint, the identified and
/// the robot file's model's simulated angle less the measured, mrad (the
/// feedback holds both within a few mrad of the measurement: their
/// angles would lie on it).
pub fn closed_loop_svg(r: &robotid::validation::ClosedLoopRun) -> Result<String> {
    let error = |q: &[Vec<f64>], j: usize| -> Vec<(f64, f64)> {
        r.time
            .iter()
            .zip(q[j].iter().zip(&r.measured[j]))
            .map(|(&t, (s, m))| (t, 1e3 * (s - m)))
            .collect()
    };
    figure_svg(r.joints.len(), 1, |areas| {
        for (j, joint) in r.joints.iter().enumerate() {
            let mut lines = Vec::new();
            if let Ok(e) = &r.estimate {
                lines.push((error(&e.q, j), BLUE_, "identified model"));
            }
            if let Some(Ok(p)) = &r.prior {
                lines.push((error(&p.q, j), ORANGE, "robot file's model"));
            }
            chart(
                &areas[j],
                &format!("{joint}: closed-loop angle less the measured"),
                "time, s",
                "mrad",
                &lines,
                None,
            )?;
        }
        Ok(())
    })
}

/// Per joint, the measured angle and the identified and robot file's
/// models' simulated ones (`how` they were simulated, in the titles).
fn angles_svg(
    (joints, time, measured): (&[String], &[f64], &[Vec<f64>]),
    [estimate, prior]: [Option<&Vec<Vec<f64>>>; 2],
    how: &str,
) -> Result<String> {
    // Simulated angles held to the measured span's ±50 % (a model far
    // off would otherwise flatten the measured curve).
    let series = |q: &[Vec<f64>], j: usize| -> Vec<(f64, f64)> {
        let (lo, hi) = measured[j]
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
        let pad = 0.5 * (hi - lo).max(1e-3);
        time.iter()
            .copied()
            .zip(q[j].iter().map(|x| x.clamp(lo - pad, hi + pad)))
            .collect()
    };
    figure_svg(joints.len(), 1, |areas| {
        for (j, joint) in joints.iter().enumerate() {
            let mut lines = vec![(series(measured, j), GREY, "measured")];
            if let Some(q) = estimate {
                lines.push((series(q, j), BLUE_, "identified model"));
            }
            if let Some(q) = prior {
                lines.push((series(q, j), ORANGE, "robot file's model"));
            }
            chart(
                &areas[j],
                &format!("{joint}: joint angle, measured and simulated ({how})"),
                "time, s",
                "rad",
                &lines,
                None,
            )?;
        }
        Ok(())
    })
}

/// Pictures of a designed excitation: `excitation.svg` (q, q̇, q̈ per
/// joint over one period) and `end_effector.svg` (its path seen from above
/// and from the side).
pub fn plot_excitation(dir: &Path, kin: &Kinematics, ee: &[nalgebra::Vector3<f64>]) -> Result<Vec<PathBuf>> {
    let path = dir.join("excitation.svg");
    kinematics_figure(&path, kin, true)?;
    let ee_path = dir.join("end_effector.svg");
    figure(&ee_path, 1, 2, |areas| {
        let top: Vec<(f64, f64)> = ee.iter().map(|p| (p.x, p.y)).collect();
        let side: Vec<(f64, f64)> = ee.iter().map(|p| ((p.x * p.x + p.y * p.y).sqrt(), p.z)).collect();
        chart(
            &areas[0],
            "end effector, seen from above",
            "x [m]",
            "y [m]",
            &[(top, BLUE_, "")],
            None,
        )?;
        chart(
            &areas[1],
            "end effector, distance from axis 1 and height",
            "r [m]",
            "z [m]",
            &[(side, ORANGE, "")],
            None,
        )?;
        Ok(())
    })?;
    Ok(vec![path, ee_path])
}

/// A drawing or writing failure of a picture.
fn picture(e: &dyn std::fmt::Display) -> Error {
    Error::Output {
        what: "picture".into(),
        msg: e.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};
    use robotid_stages::estimation::System;

    /// One joint at q̈ = −q̇·ω (a sine's velocity and acceleration), its
    /// torque 0.5·q̈ + 0.1·q̇ + 0.3·sign(q̇) plus `excess`·sign(q̇)·
    /// exp(−(q̇/0.05)²), a Stribeck excess; columns ZZ, Fv, Fc only.
    fn one_joint(excess: f64) -> System {
        let n = 5000;
        let (mut a, mut b) = (DMatrix::zeros(n, 3), DVector::zeros(n));
        for i in 0..n {
            // Half a step off: no sample at rest.
            let phase = std::f64::consts::TAU * (i as f64 + 0.5) / n as f64;
            let (qd, qdd) = (0.5 * phase.sin(), -0.5 * phase.cos());
            let sign = qd.signum() * (qd != 0.0) as u8 as f64;
            a.row_mut(i).copy_from_slice(&[qdd, qd, sign]);
            b[i] = 0.5 * qdd + 0.1 * qd + 0.3 * sign + excess * sign * (-(qd / 0.05).powi(2)).exp();
        }
        let mut sys = System::one_joint(["ZZ_j", "Fv_j", "Fc_j"].map(String::from).to_vec(), a, b, 1e-3);
        sys.units = ["kg*m^2", "N*m*s/rad", "N*m"].map(String::from).to_vec();
        sys
    }

    #[test]
    fn friction_seen_is_the_models_where_the_model_holds() {
        let theta = DVector::from_vec(vec![0.5, 0.1, 0.3]);
        let sys = one_joint(0.0);
        let seen = friction_seen(&sys, &theta, &(&sys.a * &theta));
        assert_eq!(seen.len(), 1);
        let f = &seen[0];
        assert_eq!(f.sides.len(), 2);
        assert!(f.samples.len() <= 600 && f.samples.len() >= 500, "{}", f.samples.len());
        for side in &f.sides {
            assert!(side.len() >= 20, "{}", side.len());
            for &(qd, model, seen) in side {
                // Exact: the model is the data's law.
                assert!((seen - model).abs() < 1e-12, "{qd}: {seen} {model}");
                // The Coulomb step is not smeared: each bin on one side.
                assert!((model - (0.1 * qd + 0.3 * qd.signum())).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn friction_seen_shows_a_stribeck_excess_the_model_lacks() {
        // Fitted without the excess: the slowest bins part from the model's
        // by the excess there (0.2·exp(−(q̇/0.05)²) ≥ 0.135 below
        // |q̇| = 0.031 rad/s, where the slowest bin of a 0.5 rad/s sine's
        // 2500 samples a side ends), the fast ones not at all.
        let theta = DVector::from_vec(vec![0.5, 0.1, 0.3]);
        let sys = one_joint(0.2);
        let predicted = &sys.a * &theta;
        let f = &friction_seen(&sys, &theta, &predicted)[0];
        let (neg, pos) = (&f.sides[0], &f.sides[1]);
        let slow = [neg.last().unwrap(), pos.first().unwrap()];
        for &&(qd, model, seen) in &slow {
            assert!(qd.abs() < 0.031, "{qd}");
            let gap = (seen - model) * qd.signum();
            assert!(gap > 0.135 && gap < 0.2, "{qd}: {gap}");
        }
        for &(qd, model, seen) in neg.iter().chain(pos).filter(|b| b.0.abs() > 0.3) {
            assert!((seen - model).abs() < 1e-12, "{qd}: {seen} {model}");
        }
        // Without a velocity column, or on projected equations: nothing.
        let mut no_velocity = sys.clone();
        no_velocity.names[1] = "Fq_j".into();
        assert!(friction_seen(&no_velocity, &theta, &predicted).is_empty());
        let mut projected = sys.clone();
        projected.equations = Some(100);
        assert!(friction_seen(&projected, &theta, &predicted).is_empty());
        assert!(friction_svg(&sys, &theta, &predicted)
            .unwrap()
            .unwrap()
            .contains("friction, measured"));
    }
}
