use std::io::Write;
use std::path::Path;

use robotid_schemas::RawSamples;

use super::write_atomic;
use crate::{Error, Result};

/// Writes a `raw_samples` table as CSV with the same column names as its
/// Parquet form (units are those of the table kind: s, rad, A or N·m,
/// counts). Floats use the shortest text that reads back to the same f64.
pub fn write_raw_csv(path: &Path, raw: &RawSamples) -> Result<()> {
    raw.check_shape()?;
    let batch = raw.to_record_batch()?;
    let header: Vec<String> = batch.schema().fields().iter().map(|f| f.name().clone()).collect();
    let io = |e| Error::io(path, e);
    write_atomic(path, |w| {
        writeln!(w, "{}", header.join(",")).map_err(io)?;
        let mut line = String::new();
        for k in 0..raw.len() {
            line.clear();
            use std::fmt::Write as _;
            push_f64(&mut line, raw.time[k]);
            for col in raw.q.iter().chain(&raw.effort).chain(raw.reference.iter().flatten()) {
                line.push(',');
                push_f64(&mut line, col[k]);
            }
            for col in raw.counts.iter().flatten() {
                let _ = write!(line, ",{}", col[k]);
            }
            writeln!(w, "{line}").map_err(io)?;
        }
        Ok(())
    })
}

/// Shortest text that parses back to the same f64; exponent form for very
/// small or large magnitudes so columns stay short.
pub fn push_f64(out: &mut String, x: f64) {
    use std::fmt::Write as _;
    let a = x.abs();
    if a == 0.0 || (1e-4..1e15).contains(&a) {
        let _ = write!(out, "{}", x + 0.0);
    } else {
        let _ = write!(out, "{x:e}");
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn floats_round_trip() {
        for x in [0.0, -0.0, 1.5, -1.518792859292714e-5, 6.02e23, 123456.789, -3.0e-300] {
            let mut s = String::new();
            super::push_f64(&mut s, x);
            assert_eq!(s.parse::<f64>().unwrap(), x, "{s}");
            assert!(!s.starts_with("-0") || s.starts_with("-0."), "{s}");
        }
    }
}
