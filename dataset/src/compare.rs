//! Dataset-level regression test: every table of two output trees, joined
//! on its keys and compared cell by cell. A cell passes when
//! |a − b| ≤ atol + rtol·|b| (B is the reference); NaN equals NaN, null
//! equals null.

use std::path::{Path, PathBuf};

use polars::prelude::*;
use serde::Deserialize;

use crate::error::{io, Error, Result};
use crate::runs::parquet_files;
use robotid_schemas::metadata;

/// Tolerances: defaults, then the first matching per-column rule, and which
/// columns to compare.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Tolerances {
    // `rel`/`abs`: the names of the tolerance files of robotid ≤ 0.1's
    // hand-written comparison.
    #[serde(default = "default_rtol", alias = "rel")]
    pub rtol: f64,
    #[serde(default = "default_atol", alias = "abs")]
    pub atol: f64,
    /// Rules by column-name pattern (`*` matches any run of characters).
    #[serde(default)]
    pub column: Vec<ColumnRule>,
    /// Only columns matching one of these patterns are compared (keys are
    /// always joined on); empty: every column.
    #[serde(default)]
    pub columns: Vec<String>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ColumnRule {
    pub pattern: String,
    #[serde(alias = "rel")]
    pub rtol: f64,
    #[serde(alias = "abs")]
    pub atol: f64,
}

fn default_rtol() -> f64 {
    1e-9
}
fn default_atol() -> f64 {
    1e-12
}

impl Default for Tolerances {
    fn default() -> Self {
        Tolerances {
            rtol: default_rtol(),
            atol: default_atol(),
            column: Vec::new(),
            columns: Vec::new(),
        }
    }
}

impl Tolerances {
    fn for_column(&self, name: &str) -> (f64, f64) {
        self.column
            .iter()
            .find(|c| matches(&c.pattern, name))
            .map_or((self.rtol, self.atol), |c| (c.rtol, c.atol))
    }

    fn selected(&self, name: &str) -> bool {
        self.columns.is_empty() || self.columns.iter().any(|p| matches(p, name))
    }
}

/// `*` matches any run of characters; everything else literally.
pub fn matches(pattern: &str, name: &str) -> bool {
    let parts: Vec<&str> = pattern.split('*').collect();
    let [first, middle @ .., last] = parts.as_slice() else {
        return pattern == name;
    };
    if parts.len() == 1 {
        return pattern == name;
    }
    let Some(mut rest) = name.strip_prefix(first) else {
        return false;
    };
    for p in middle {
        match rest.find(p) {
            Some(k) => rest = &rest[k + p.len()..],
            None => return false,
        }
    }
    rest.ends_with(last)
}

/// The columns that identify a row of each table kind; kinds without such
/// columns (sample tables) are joined on the row's position.
fn keys_of(kind: Option<&str>) -> &'static [&'static str] {
    match kind {
        Some("regressor") => &["recording", "sample", "joint"],
        Some("period_mean" | "noise") => &["sample"],
        Some("r_factor") => &["row"],
        Some("parameters") => &["name"],
        Some("dataset_summary") => &["run", "recording", "joint"],
        Some("parameter_drift") => &["parameter", "run"],
        _ => &[],
    }
}

/// The name of the position key when a table has no key columns.
const POSITION: &str = "row";

/// One compared column of one table.
#[derive(Debug, Clone)]
pub struct ColumnDiff {
    pub column: String,
    pub rtol: f64,
    pub atol: f64,
    /// Cells not bit-for-bit equal.
    pub differing: usize,
    /// Cells over the tolerance.
    pub over: usize,
    /// Largest |a − b| / (atol + rtol·|b|); > 1 fails.
    pub worst_ratio: f64,
    /// The worst cell: its keys and both values.
    pub worst_key: String,
    pub a: String,
    pub b: String,
}

/// One table present in both trees.
#[derive(Debug, Clone, Default)]
pub struct TableDiff {
    /// Path relative to the trees' roots.
    pub table: PathBuf,
    pub kind: Option<String>,
    pub keys: Vec<String>,
    /// Rows present in both, and compared.
    pub rows: usize,
    /// Keys of rows only in A / only in B (at most [`EXAMPLES`] of each),
    /// and their counts.
    pub only_a: (usize, Vec<String>),
    pub only_b: (usize, Vec<String>),
    /// Every compared column, worst first.
    pub columns: Vec<ColumnDiff>,
    /// Schema differences: columns only in one, types that differ.
    pub problems: Vec<String>,
}

const EXAMPLES: usize = 5;

impl TableDiff {
    pub fn passed(&self) -> bool {
        self.problems.is_empty() && self.only_a.0 == 0 && self.only_b.0 == 0 && self.columns.iter().all(|c| c.over == 0)
    }
    pub fn identical(&self) -> bool {
        self.passed() && self.columns.iter().all(|c| c.differing == 0)
    }
    pub fn cells(&self) -> usize {
        self.rows * self.columns.len()
    }
}

/// The comparison of two trees.
#[derive(Debug, Clone, Default)]
pub struct Report {
    pub tables: Vec<TableDiff>,
    /// Tables only in one tree.
    pub problems: Vec<String>,
}

impl Report {
    pub fn passed(&self) -> bool {
        self.problems.is_empty() && self.tables.iter().all(TableDiff::passed)
    }
    pub fn identical(&self) -> bool {
        self.problems.is_empty() && self.tables.iter().all(TableDiff::identical)
    }
    /// Every cell over its tolerance: (table, column, keys, a, b) of the
    /// worst cell of each failing column.
    pub fn failing(&self) -> impl Iterator<Item = (&TableDiff, &ColumnDiff)> {
        self.tables
            .iter()
            .flat_map(|t| t.columns.iter().filter(|c| c.over > 0).map(move |c| (t, c)))
    }
}

/// Compares every table of tree `a` with the same path in tree `b` (the
/// reference). Either root may also be a single Parquet file.
pub fn compare(a: &Path, b: &Path, tol: &Tolerances) -> Result<Report> {
    // A single table on either side: the same file name in the other
    // side's folder, if that is one.
    let single = a.is_file() || b.is_file();
    let (files_a, files_b) = if single {
        let file = if b.is_file() { b } else { a };
        let name = PathBuf::from(file.file_name().unwrap_or_default());
        (vec![name.clone()], vec![name])
    } else {
        (parquet_files(a)?, parquet_files(b)?)
    };
    let path = |root: &Path, f: &Path| {
        if root.is_file() {
            root.to_path_buf()
        } else {
            root.join(f)
        }
    };
    let mut report = Report::default();
    if files_b.is_empty() {
        report.problems.push(format!("{}: no tables", b.display()));
    }
    for f in &files_a {
        if !files_b.contains(f) {
            report
                .problems
                .push(format!("{}: only in {}", f.display(), a.display()));
        }
    }
    for f in &files_b {
        if !files_a.contains(f) {
            report
                .problems
                .push(format!("{}: only in {}", f.display(), b.display()));
            continue;
        }
        match compare_table(&path(a, f), &path(b, f), tol) {
            Ok(mut t) => {
                t.table = f.clone();
                if !t.columns.is_empty() || !t.problems.is_empty() || t.only_a.0 + t.only_b.0 > 0 {
                    report.tables.push(t);
                }
            }
            // A table that cannot be read is an error (exit 2), not a
            // difference (exit 1): docs/dataset.md.
            Err(e) => return Err(e),
        }
    }
    if !tol.columns.is_empty() && report.problems.is_empty() && report.tables.iter().all(|t| t.columns.is_empty()) {
        return Err(Error::Setting(format!(
            "no column matches --columns {}",
            tol.columns.join(",")
        )));
    }
    Ok(report)
}

fn read(path: &Path) -> Result<(DataFrame, Option<String>)> {
    // A table robotid wrote carries its content's CRC: checked first (a
    // flipped reference cell passed as a difference, or as none).
    robotid_stages::formats::parquet::read_parquet(path)?;
    let file = std::fs::File::open(path).map_err(io(path))?;
    let mut reader = ParquetReader::new(file);
    let kind = reader
        .get_metadata()
        .map_err(|source| Error::Read {
            path: path.to_path_buf(),
            source,
        })?
        .key_value_metadata()
        .as_ref()
        .and_then(|kv| kv.iter().find(|k| k.key == metadata::TABLE))
        .and_then(|k| k.value.clone());
    let df = reader.finish().map_err(|source| Error::Read {
        path: path.to_path_buf(),
        source,
    })?;
    Ok((df, kind))
}

fn unique_keys(df: &DataFrame, keys: &[String]) -> PolarsResult<bool> {
    let groups = df
        .clone()
        .lazy()
        .group_by(keys.iter().map(|k| col(k.as_str())).collect::<Vec<_>>())
        .agg([len()])
        .collect()?;
    Ok(groups.height() == df.height())
}

fn tag(side: &str, name: &str) -> String {
    format!("{side}\u{1}{name}")
}

/// Formats row `i` of the key columns as `k=v k=v`.
fn key_text(df: &DataFrame, keys: &[String], i: usize) -> PolarsResult<String> {
    let mut parts = Vec::with_capacity(keys.len());
    for k in keys {
        parts.push(format!("{k}={}", plain(&df.column(k)?.get(i)?)));
    }
    Ok(parts.join(" "))
}

fn plain(v: &AnyValue) -> String {
    match v {
        AnyValue::String(s) => s.to_string(),
        AnyValue::StringOwned(s) => s.to_string(),
        AnyValue::Null => "null".into(),
        AnyValue::Float64(x) => format!("{x:e}"),
        other => other.to_string(),
    }
}

/// The rows of the full join present on one side only: counted into `t`,
/// a few keys kept as examples.
fn one_side_only(joined: &DataFrame, keys: &[String], t: &mut TableDiff) -> Result<()> {
    let present_a = joined.column(&tag("a", ""))?.is_not_null();
    let present_b = joined.column(&tag("b", ""))?.is_not_null();
    for (i, (pa, pb)) in present_a.iter().zip(present_b.iter()).enumerate() {
        let (pa, pb) = (pa.unwrap_or(false), pb.unwrap_or(false));
        let slot = match (pa, pb) {
            (true, false) => &mut t.only_a,
            (false, true) => &mut t.only_b,
            _ => continue,
        };
        slot.0 += 1;
        if slot.1.len() < EXAMPLES {
            slot.1.push(key_text(joined, keys, i)?);
        }
    }
    Ok(())
}

/// Per cell of column `c`, the ratio of its difference to what is allowed
/// (0 for equal cells, ∞ where a NaN or null meets a value).
fn ratio_of(c: &str, numeric: bool, tol: &Tolerances) -> Expr {
    let (a, b) = (col(tag("a", c)), col(tag("b", c)));
    let inf = lit(f64::INFINITY);
    if numeric {
        let (rtol, atol) = tol.for_column(c);
        let (a, b) = (a.cast(DataType::Float64), b.cast(DataType::Float64));
        let same = a
            .clone()
            .eq_missing(b.clone())
            .or(a.clone().is_nan().and(b.clone().is_nan()))
            .fill_null(lit(false));
        let allowed = lit(atol) + lit(rtol) * b.clone().abs();
        when(same)
            .then(lit(0.0))
            .otherwise(((a - b).abs() / allowed).fill_nan(inf.clone()).fill_null(inf.clone()))
    } else {
        when(a.eq_missing(b)).then(lit(0.0)).otherwise(inf.clone())
    }
}

/// The columns of both sides to compare (not keys, selected by `tol`, of
/// one type on both), and whether each is numeric; columns in one side
/// only or of two types into `problems`.
fn comparable(
    sa: &Schema,
    sb: &Schema,
    keys: &[String],
    tol: &Tolerances,
    problems: &mut Vec<String>,
) -> Vec<(String, bool)> {
    for name in sa.iter_names() {
        if !sb.contains(name) {
            problems.push(format!("column `{name}` only in A"));
        }
    }
    for name in sb.iter_names() {
        if !sa.contains(name) {
            problems.push(format!("column `{name}` only in B (the reference)"));
        }
    }
    let mut compared = Vec::new();
    for (name, dtype) in sb.iter() {
        let name = name.as_str();
        if keys.iter().any(|k| k == name) || !tol.selected(name) {
            continue;
        }
        let Some(dtype_a) = sa.get(name) else { continue };
        if dtype_a != dtype {
            problems.push(format!("column `{name}`: type {dtype_a}, reference has {dtype}"));
            continue;
        }
        compared.push((name.to_string(), dtype.is_primitive_numeric()));
    }
    compared
}

/// Each compared column's difference from the per-column statistics `s`
/// (`d`, `o`, `m`, `w` by index), with its worst cell's keys and values.
fn column_diffs(
    s: &DataFrame,
    both: &DataFrame,
    keys: &[String],
    compared: &[(String, bool)],
    tol: &Tolerances,
) -> Result<Vec<ColumnDiff>> {
    let get_usize = |name: &str| -> PolarsResult<usize> {
        Ok(s.column(name)?.cast(&DataType::UInt64)?.u64()?.get(0).unwrap_or(0) as usize)
    };
    let mut diffs = Vec::new();
    for (k, (c, _)) in compared.iter().enumerate() {
        let (rtol, atol) = tol.for_column(c);
        let differing = get_usize(&format!("d{k}"))?;
        let mut diff = ColumnDiff {
            column: c.clone(),
            rtol,
            atol,
            differing,
            over: get_usize(&format!("o{k}"))?,
            worst_ratio: s.column(&format!("m{k}"))?.f64()?.get(0).unwrap_or(0.0),
            worst_key: String::new(),
            a: String::new(),
            b: String::new(),
        };
        if differing > 0 {
            let w = get_usize(&format!("w{k}"))?;
            diff.worst_key = key_text(both, keys, w)?;
            diff.a = plain(&both.column(&tag("a", c))?.get(w)?);
            diff.b = plain(&both.column(&tag("b", c))?.get(w)?);
        }
        diffs.push(diff);
    }
    Ok(diffs)
}

fn compare_table(pa: &Path, pb: &Path, tol: &Tolerances) -> Result<TableDiff> {
    let (da, kind_a) = read(pa)?;
    let (db, kind_b) = read(pb)?;
    // A table rewritten by another tool may have lost its kind: reported,
    // and its values still compared under the kind the other side names.
    let kind = kind_b.clone().or_else(|| kind_a.clone());
    let mut t = TableDiff {
        kind: kind.clone(),
        ..Default::default()
    };
    if kind_a != kind_b {
        let name = |k: &Option<String>| k.clone().unwrap_or_else(|| "none (no robotid.table key)".into());
        t.problems
            .push(format!("table kind {}, reference has {}", name(&kind_a), name(&kind_b)));
        if kind_a.is_some() && kind_b.is_some() {
            return Ok(t);
        }
    }
    let (sa, sb) = (da.schema().clone(), db.schema().clone());
    let mut keys: Vec<String> = keys_of(kind.as_deref())
        .iter()
        .filter(|k| sa.contains(k) && sb.contains(k))
        .map(|k| k.to_string())
        .collect();
    let (mut da, mut db) = (da, db);
    if keys.is_empty() || !unique_keys(&da, &keys)? || !unique_keys(&db, &keys)? {
        let name = if sa.contains(POSITION) { "#row" } else { POSITION };
        da = da.with_row_index(name.into(), None)?;
        db = db.with_row_index(name.into(), None)?;
        keys = vec![name.to_string()];
    }
    let compared = comparable(&sa, &sb, &keys, tol, &mut t.problems);
    let side = |df: &DataFrame, s: &str| -> LazyFrame {
        let mut exprs: Vec<Expr> = keys.iter().map(|k| col(k.as_str())).collect();
        exprs.extend(compared.iter().map(|(c, _)| col(c.as_str()).alias(tag(s, c))));
        exprs.push(lit(true).alias(tag(s, "")));
        df.clone().lazy().select(exprs)
    };
    let key_exprs: Vec<Expr> = keys.iter().map(|k| col(k.as_str())).collect();
    let joined = side(&da, "a")
        .join(
            side(&db, "b"),
            key_exprs.clone(),
            key_exprs,
            JoinArgs::new(JoinType::Full).with_coalesce(JoinCoalesce::CoalesceColumns),
        )
        .sort(keys.clone(), SortMultipleOptions::default().with_maintain_order(true))
        .collect()?;
    one_side_only(&joined, &keys, &mut t)?;
    let both = joined
        .lazy()
        .filter(col(tag("a", "")).is_not_null().and(col(tag("b", "")).is_not_null()))
        .collect()?;
    t.rows = both.height();
    t.keys = keys.clone();
    if compared.is_empty() || t.rows == 0 {
        return Ok(t);
    }
    let mut stats = Vec::new();
    for (k, (c, numeric)) in compared.iter().enumerate() {
        let ratio = ratio_of(c, *numeric, tol);
        stats.push(ratio.clone().gt(lit(0.0)).sum().alias(format!("d{k}")));
        stats.push(ratio.clone().gt(lit(1.0)).sum().alias(format!("o{k}")));
        stats.push(ratio.clone().max().alias(format!("m{k}")));
        stats.push(ratio.arg_max().alias(format!("w{k}")));
    }
    let s = both.clone().lazy().select(stats).collect()?;
    t.columns = column_diffs(&s, &both, &keys, &compared, tol)?;
    t.columns
        .sort_by(|x, y| y.worst_ratio.total_cmp(&x.worst_ratio).then(x.column.cmp(&y.column)));
    Ok(t)
}

/// The verdict line's end: identical, within tolerance (the worst of
/// `differing`), or how many cells and columns are over.
fn verdict(report: &Report, differing: &[(&TableDiff, &ColumnDiff)]) -> String {
    let over: usize = report.tables.iter().flat_map(|t| &t.columns).map(|c| c.over).sum();
    let failing = report.failing().count();
    if report.identical() {
        "identical".to_string()
    } else if report.passed() {
        let (t, c) = differing[0];
        format!(
            "within tolerance (largest ratio {:.3e}: {} {})",
            c.worst_ratio,
            t.table.display(),
            c.column
        )
    } else {
        let structural = report.problems.len()
            + report
                .tables
                .iter()
                .map(|t| t.problems.len() + usize::from(t.only_a.0 + t.only_b.0 > 0))
                .sum::<usize>();
        format!(
            "DIFFERENT: {over} cell(s) in {failing} column(s) over tolerance, {structural} structural difference(s)"
        )
    }
}

/// The report as text: every differing column, worst first (at most
/// `worst` of them), rows and tables in one tree only, and a verdict line.
pub fn render(report: &Report, a: &Path, b: &Path, tol: &Tolerances, worst: usize) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    let _ = writeln!(
        out,
        "A {} against B {} (the reference): |a − b| ≤ {:e} + {:e}·|b|{}",
        a.display(),
        b.display(),
        tol.atol,
        tol.rtol,
        if tol.column.is_empty() {
            ""
        } else {
            " (per-column rules too)"
        }
    );
    let mut differing: Vec<(&TableDiff, &ColumnDiff)> = report
        .tables
        .iter()
        .flat_map(|t| t.columns.iter().filter(|c| c.differing > 0).map(move |c| (t, c)))
        .collect();
    differing.sort_by(|x, y| y.1.worst_ratio.total_cmp(&x.1.worst_ratio));
    if !differing.is_empty() {
        let _ = writeln!(
            out,
            "{:<40} {:<22} {:>9} {:>9} {:>11}  worst cell: keys, a, b",
            "table", "column", "differing", "over tol", "worst ratio"
        );
    }
    for (t, c) in differing.iter().take(worst) {
        let _ = writeln!(
            out,
            "{:<40} {:<22} {:>9} {:>9} {:>11.3e}  {}: {} vs {}",
            t.table.display(),
            c.column,
            c.differing,
            c.over,
            c.worst_ratio,
            c.worst_key,
            c.a,
            c.b
        );
    }
    if differing.len() > worst {
        let _ = writeln!(out, "… and {} more differing column(s)", differing.len() - worst);
    }
    for t in &report.tables {
        for (side, (n, keys)) in [("A", &t.only_a), ("B", &t.only_b)] {
            if *n > 0 {
                let _ = writeln!(
                    out,
                    "{}: {n} row(s) only in {side}, e.g. {}",
                    t.table.display(),
                    keys.join("; ")
                );
            }
        }
        for p in &t.problems {
            let _ = writeln!(out, "{}: {p}", t.table.display());
        }
    }
    for p in &report.problems {
        let _ = writeln!(out, "{p}");
    }
    let columns: usize = report.tables.iter().map(|t| t.columns.len()).sum();
    let cells: usize = report.tables.iter().map(TableDiff::cells).sum();
    let verdict = verdict(report, &differing);
    let _ = writeln!(
        out,
        "{} table(s), {columns} column(s), {cells} cell(s) compared: {verdict}",
        report.tables.len()
    );
    out
}

#[cfg(test)]
mod tests {
    #[test]
    fn patterns() {
        assert!(super::matches("qdd_*", "qdd_j1"));
        assert!(super::matches("*_j1", "qdd_j1"));
        assert!(super::matches("q*_j*", "qdd_j1"));
        assert!(!super::matches("qd_*", "qdd_j1"));
        assert!(super::matches("time", "time"));
        assert!(!super::matches("time", "times"));
        assert!(super::matches("*", "anything"));
    }
}
