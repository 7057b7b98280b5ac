//! CSV and Parquet logs share the column mapping; CSV is streamed line by
//! line, keeping only the mapped columns.

use robotid_schemas::metadata;
use std::collections::BTreeMap;
use std::io::BufRead;
use std::path::Path;

use super::{column_name, Column, Columns, Decimal, Log, OneColumn, ReadConfig, Separator};
use crate::{Error, Result};

/// Column names the mapping asks for, resolved against a header.
pub(crate) struct Mapping {
    /// None: stamped by `sample_rate_hz`.
    pub time: Option<String>,
    pub position: Vec<String>,
    pub effort: Vec<String>,
    pub reference: Option<Vec<String>>,
    /// Unit implied by a defaulted effort column (`torque_…` → N·m).
    pub effort_unit: Option<&'static str>,
}

/// A log's column names, its joints and its name, for resolving channels.
struct Header<'a> {
    header: &'a [String],
    joints: &'a [String],
    source: &'a str,
}

impl Header<'_> {
    fn has(&self, n: &str) -> bool {
        self.header.iter().any(|h| h == n)
    }

    fn err(&self, kind: &str, msg: String) -> Error {
        Error::Data {
            source_name: self.source.to_string(),
            channel: kind.to_string(),
            sample: None,
            msg,
        }
    }

    /// A column the log does not have, and what it has.
    fn missing(&self, col: &str) -> Error {
        let header = self.header;
        let msg = if header.first().is_some_and(|h| h.starts_with(HEADERLESS)) {
            format!(
                "missing column: the log has no header line ({} columns of numbers); name columns by 0-based number, e.g. `time = {{ column = 0, unit = \"s\" }}`, `position = {{ column = [1, 2, 3], unit = \"rad\" }}`",
                header.len()
            )
        } else {
            let names: Vec<String> = header.iter().map(|h| super::shown(h)).collect();
            format!("missing column; the log has: {}", names.join(", "))
        };
        self.err(&super::shown(col), msg)
    }

    fn by_index(&self, kind: &str, i: usize) -> Result<String> {
        self.header.get(i).cloned().ok_or_else(|| {
            self.err(
                kind,
                format!(
                    "column {i} does not exist: the log has {} columns (0 to {})",
                    self.header.len(),
                    self.header.len().saturating_sub(1)
                ),
            )
        })
    }

    fn one(&self, kind: &str, c: &OneColumn, j: usize, joint: &str) -> Result<String> {
        match c {
            OneColumn::Index(i) => self.by_index(kind, *i),
            OneColumn::Name(t) => Ok(column_name(t, j, joint)),
        }
    }

    /// The columns of a per-joint channel, or None when it is not given.
    fn per_joint(&self, ch: &Option<super::Channel>, kind: &str) -> Result<Option<Vec<String>>> {
        let joints = self.joints;
        let Some(c) = ch else { return Ok(None) };
        match (&c.column, &c.topic) {
            (Some(Column::Each(list)), _) => {
                if list.len() != joints.len() {
                    return Err(self.err(
                        kind,
                        format!("lists {} columns for {} joints", list.len(), joints.len()),
                    ));
                }
                list.iter()
                    .enumerate()
                    .map(|(j, c)| self.one(kind, c, j, &joints[j]))
                    .collect::<Result<Vec<_>>>()
                    .map(Some)
            }
            (Some(Column::Index(i)), _) if joints.len() == 1 => Ok(Some(vec![self.by_index(kind, *i)?])),
            (Some(Column::Index(_)), _) => Err(self.err(
                kind,
                format!(
                    "one column number for {} joints: give one per joint, e.g. `column = [1, 2, 3]`",
                    joints.len()
                ),
            )),
            (Some(Column::Name(t)), _) => Ok(Some(self.names(t))),
            (None, Some(_)) => Err(self.err(
                kind,
                "`topic` applies to MCAP logs; give `column` for text and Parquet logs".into(),
            )),
            (None, None) => Ok(None),
        }
    }

    /// `cols`, when the log has every one.
    fn require(&self, cols: Vec<String>) -> Result<Vec<String>> {
        match cols.iter().find(|c| !self.has(c)) {
            Some(c) => Err(self.missing(c)),
            None => Ok(cols),
        }
    }

    /// A template's column per joint.
    fn names(&self, template: &str) -> Vec<String> {
        self.joints
            .iter()
            .enumerate()
            .map(|(j, name)| column_name(template, j, name))
            .collect()
    }
}

/// The column each channel is read from: as `cfg` says, else the defaults
/// (`time`, `q_{joint}`, `current_{joint}` or else `torque_{joint}`, and
/// `ref_{joint}` when the log has them all), each checked to exist.
pub(crate) fn resolve(header: &[String], cfg: &ReadConfig, joints: &[String], source: &str) -> Result<Mapping> {
    let h = Header { header, joints, source };
    let time = match cfg.time.as_ref().and_then(|c| c.column.as_ref()) {
        Some(Column::Index(i)) => Some(h.by_index("time", *i)?),
        Some(Column::Name(n)) => Some(n.clone()),
        Some(Column::Each(_)) => return Err(h.err("time", "is one column, not a list".into())),
        None if cfg.sample_rate_hz.is_some() => None,
        None => Some("time".into()),
    };
    if let Some(time) = time.as_ref().filter(|t| !h.has(t)) {
        let mut e = h.missing(time);
        if let Error::Data { msg, .. } = &mut e {
            msg.push_str("; a log without one is stamped by its rate: `sample_rate_hz` in `[read]`");
        }
        return Err(e);
    }
    let position = h.require(
        h.per_joint(&cfg.position, "position")?
            .unwrap_or_else(|| h.names("q_{joint}")),
    )?;
    let (effort, effort_unit) = match h.per_joint(&cfg.effort, "effort")? {
        Some(cols) => (h.require(cols)?, None),
        None => {
            // Currents if the log has any, else torques; the error names
            // the first missing column of the set in use.
            let current = h.names("current_{joint}");
            if current.iter().any(|c| h.has(c)) {
                (h.require(current)?, Some("A"))
            } else {
                (h.require(h.names("torque_{joint}"))?, Some("N*m"))
            }
        }
    };
    let reference = match h.per_joint(&cfg.reference, "reference")? {
        Some(cols) => Some(h.require(cols)?),
        None => {
            let r = h.names("ref_{joint}");
            r.iter().all(|c| h.has(c)).then_some(r)
        }
    };
    Ok(Mapping {
        time,
        position,
        effort,
        reference,
        effort_unit: if cfg.effort.is_some() { None } else { effort_unit },
    })
}

pub(crate) fn into_columns(
    m: Mapping,
    mut get: impl FnMut(&str) -> Vec<f64>,
    mut metadata: BTreeMap<String, String>,
) -> Columns {
    if let Some(u) = m.effort_unit {
        metadata.insert(metadata::READ_EFFORT_UNIT.into(), u.into());
    }
    Columns {
        time: m.time.as_deref().map(&mut get).unwrap_or_default(),
        position: m.position.iter().map(|c| get(c)).collect(),
        effort: m.effort.iter().map(|c| get(c)).collect(),
        reference: m.reference.as_ref().map(|r| r.iter().map(|c| get(c)).collect()),
        names: [
            m.position.clone(),
            m.effort.clone(),
            m.reference.clone().unwrap_or_default(),
        ],
        metadata,
    }
}

/// Names given to the columns of a log without a header line: `column 0`, …
pub(crate) const HEADERLESS: &str = "column ";

/// Whether a line is a comment: `#`, `%` or `//` first.
fn comment(t: &str) -> bool {
    let t = t.trim_start();
    t.starts_with('#') || t.starts_with('%') || t.starts_with("//")
}

/// The separator a line uses: a semicolon or a tab where there is one
/// (runs of tabs: whitespace), a comma unless the commas sit inside
/// whitespace-separated numbers (decimal commas), else whitespace.
fn separator_of(line: &str) -> Separator {
    let t = line.trim();
    if t.contains(';') {
        Separator::Semicolon
    } else if t.contains('\t') {
        if t.contains("\t\t") || t.contains(" \t") || t.contains("\t ") {
            Separator::Whitespace
        } else {
            Separator::Tab
        }
    } else if t.contains(',') {
        let words: Vec<&str> = t.split_whitespace().collect();
        if words.len() > 1
            && words
                .iter()
                .all(|w| number(w, Decimal::Comma).is_some() && !w.ends_with(','))
        {
            Separator::Whitespace
        } else {
            Separator::Comma
        }
    } else {
        Separator::Whitespace
    }
}

fn fields(line: &str, sep: Separator) -> Box<dyn Iterator<Item = &str> + '_> {
    match sep {
        Separator::Comma => Box::new(line.split(',')),
        Separator::Semicolon => Box::new(line.split(';')),
        Separator::Tab => Box::new(line.split('\t')),
        Separator::Whitespace => Box::new(line.split_whitespace()),
    }
}

/// A number with either decimal mark, parsed without allocating.
fn number(text: &str, decimal: Decimal) -> Option<f64> {
    let text = text.trim().trim_matches('"');
    if decimal == Decimal::Point || !text.contains(',') {
        return text.parse().ok();
    }
    let mut buf = [0u8; 64];
    let bytes = text.as_bytes();
    if bytes.len() > buf.len() {
        return None;
    }
    for (b, &c) in buf.iter_mut().zip(bytes) {
        *b = if c == b',' { b'.' } else { c };
    }
    std::str::from_utf8(&buf[..bytes.len()]).ok()?.parse().ok()
}

/// The longest line a text log may have: a log of hundreds of channels
/// writes some kilobytes; a file without line ends is not read whole.
const MAX_LINE: usize = 1 << 20;

/// Appends the next line (its end kept) to `line` and returns the bytes
/// read, 0 at the end. A line ends at "\n", "\r\n" or a lone "\r" (old
/// Mac logs, which `read_line` would take as one line); one of over
/// [`MAX_LINE`] bytes is an `InvalidInput` error.
fn read_record(reader: &mut impl BufRead, line: &mut String) -> std::io::Result<usize> {
    let mut bytes = Vec::new();
    let mut end = None;
    while end.is_none() {
        let buf = reader.fill_buf()?;
        if buf.is_empty() {
            break;
        }
        let used = match buf.iter().position(|&b| b == b'\n' || b == b'\r') {
            Some(i) => {
                end = Some(buf[i]);
                i + 1
            }
            None => buf.len(),
        };
        bytes.extend_from_slice(&buf[..used]);
        reader.consume(used);
        if bytes.len() > MAX_LINE {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!("over {MAX_LINE} bytes without a line end"),
            ));
        }
    }
    if end == Some(b'\r') && reader.fill_buf()?.first() == Some(&b'\n') {
        bytes.push(b'\n');
        reader.consume(1);
    }
    let read = bytes.len();
    line.push_str(&String::from_utf8(bytes).map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidData, e))?);
    Ok(read)
}

/// A text log's lines as they come: a file streamed, or bytes in memory.
fn reader_of<'a>(log: Log<'a>) -> Result<Box<dyn BufRead + 'a>> {
    Ok(match log {
        Log::File(path) => Box::new(std::io::BufReader::new(
            std::fs::File::open(path).map_err(|e| Error::io(path, e))?,
        )),
        Log::Bytes { bytes, .. } => Box::new(&bytes[..]),
    })
}

/// A text log's first line that is neither blank nor a comment, without
/// its byte-order mark and surrounding space; None for an empty log.
fn first_line(log: Log) -> Result<Option<String>> {
    let path = log.path();
    let mut reader = reader_of(log)?;
    let mut line = String::new();
    loop {
        line.clear();
        let read = read_record(&mut reader, &mut line).map_err(|e| match e.kind() {
            std::io::ErrorKind::InvalidInput | std::io::ErrorKind::InvalidData => Error::Format {
                path: path.to_path_buf(),
                msg: format!("its first line: {e}"),
            },
            _ => Error::io(path, e),
        })?;
        if read == 0 {
            return Ok(None);
        }
        let t = line.trim_start_matches('\u{feff}').trim();
        if !(t.is_empty() || comment(t)) {
            return Ok(Some(t.to_string()));
        }
    }
}

/// The names on a text log's first line, or None when it holds numbers
/// (no header).
pub(crate) fn header_of(log: Log) -> Result<Option<Vec<String>>> {
    let Some(t) = first_line(log)? else { return Ok(None) };
    let names: Vec<String> = fields(&t, separator_of(&t))
        .map(|f| f.trim().trim_matches('"').to_string())
        .collect();
    let numeric = names.iter().all(|f| {
        number(f, Decimal::Point)
            .or_else(|| number(f, Decimal::Comma))
            .is_some()
    });
    Ok((!numeric).then_some(names))
}

/// The number of fields on a text log's first line (header or data).
pub(crate) fn width_of(log: Log) -> Result<Option<usize>> {
    Ok(first_line(log)?.map(|t| fields(&t, separator_of(&t)).count()))
}

/// Delimited text: CSV, semicolon, tab or whitespace separated, with or
/// without a header line, comment lines and a UTF-8 byte-order mark
/// skipped, either decimal mark. Streamed line by line; only the mapped
/// columns are kept.
pub(crate) fn read_text(log: Log, cfg: &ReadConfig, joints: &[String]) -> Result<Columns> {
    let path = log.path();
    let source = path.display().to_string();
    let reader = reader_of(log)?;
    let mut lines = Lines {
        reader,
        path,
        line: String::new(),
        no: 0,
    };
    if !lines.next()? {
        return Err(lines.format("empty file (no line of data)".into()));
    }
    let layout = Layout::of(&lines, cfg)?;
    let mapping = resolve(&layout.header, cfg, joints, &source)?;
    let wanted: Vec<String> = mapping
        .time
        .iter()
        .cloned()
        .chain(mapping.position.iter().cloned())
        .chain(mapping.effort.iter().cloned())
        .chain(mapping.reference.iter().flatten().cloned())
        .collect();
    // For each header column, the slots (wanted entries) it feeds.
    let mut slots: Vec<Vec<usize>> = vec![Vec::new(); layout.header.len()];
    for (k, w) in wanted.iter().enumerate() {
        slots[layout.header.iter().position(|h| h == w).expect("resolved")].push(k);
    }
    let mut data: Vec<Vec<f64>> = vec![Vec::new(); wanted.len()];
    let notes = layout.rows(&mut lines, &slots, &mut data, cfg, &source)?;
    let by_name: BTreeMap<String, usize> = wanted.iter().enumerate().map(|(k, w)| (w.clone(), k)).collect();
    let mut md = BTreeMap::new();
    if !notes.is_empty() {
        md.insert(metadata::READ_NOTES.into(), notes.join("; "));
    }
    Ok(into_columns(mapping, |name| data[by_name[name]].clone(), md))
}

/// A text log's lines, blank and comment lines skipped: the current one
/// and its number (from 1, counting every line of the file).
struct Lines<'a> {
    reader: Box<dyn BufRead + 'a>,
    path: &'a Path,
    line: String,
    no: usize,
}

impl Lines<'_> {
    /// The next non-empty, non-comment line into `line`; false at the end.
    fn next(&mut self) -> Result<bool> {
        loop {
            self.line.clear();
            let read = read_record(&mut self.reader, &mut self.line).map_err(|e| match e.kind() {
                std::io::ErrorKind::InvalidData => {
                    self.format(format!("line {}: not UTF-8 text (is it a binary file?)", self.no + 1))
                }
                std::io::ErrorKind::InvalidInput => {
                    self.format(format!("line {}: {e} (is it a text log?)", self.no + 1))
                }
                _ => Error::io(self.path, e),
            })?;
            if read == 0 {
                return Ok(false);
            }
            self.no += 1;
            if self.no == 1 && self.line.starts_with('\u{feff}') {
                self.line.drain(..'\u{feff}'.len_utf8());
            }
            let t = self.line.trim_end_matches(['\n', '\r']);
            if !t.trim().is_empty() && !comment(t) {
                let len = t.len();
                self.line.truncate(len);
                return Ok(true);
            }
        }
    }

    fn format(&self, msg: String) -> Error {
        Error::Format {
            path: self.path.to_path_buf(),
            msg,
        }
    }
}

/// How a text log is laid out, read off its first line and the settings.
struct Layout {
    sep: Separator,
    decimal: Decimal,
    has_header: bool,
    /// The columns' names: the header's, or `HEADERLESS`0, 1, … without one.
    header: Vec<String>,
}

impl Layout {
    fn of(lines: &Lines, cfg: &ReadConfig) -> Result<Layout> {
        let sep = cfg.separator.unwrap_or_else(|| separator_of(&lines.line));
        let first: Vec<String> = fields(&lines.line, sep)
            .map(|s| s.trim().trim_matches('"').to_string())
            .collect();
        // A comma can be the decimal mark only where it does not separate;
        // there, either mark is read.
        let decimal = cfg.decimal.unwrap_or(if sep == Separator::Comma {
            Decimal::Point
        } else {
            Decimal::Comma
        });
        if sep == Separator::Comma && cfg.decimal == Some(Decimal::Comma) {
            return Err(lines.format("decimal = \"comma\" needs another separator than the comma".into()));
        }
        let numeric = first.iter().all(|f| number(f, decimal).is_some());
        let has_header = cfg.header.unwrap_or(!numeric);
        let header: Vec<String> = if has_header {
            first.clone()
        } else {
            (0..first.len()).map(|i| format!("{HEADERLESS}{i}")).collect()
        };
        if header.len() < 2 {
            return Err(lines.format(format!(
                "line {} has a single field `{}`: the separator is not {} (give `separator` = \"comma\", \"semicolon\", \"tab\" or \"whitespace\")",
                lines.no,
                first.first().map(String::as_str).unwrap_or(""),
                match sep {
                    Separator::Comma => "a comma",
                    Separator::Semicolon => "a semicolon",
                    Separator::Tab => "a tab",
                    Separator::Whitespace => "whitespace",
                }
            )));
        }
        Ok(Layout {
            sep,
            decimal,
            has_header,
            header,
        })
    }

    /// The data lines' numbers into `data`, each column's into the slots
    /// `slots` gives it; the notes on what was dropped.
    fn rows(
        &self,
        lines: &mut Lines,
        slots: &[Vec<usize>],
        data: &mut [Vec<f64>],
        cfg: &ReadConfig,
        source: &str,
    ) -> Result<Vec<String>> {
        let (header, decimal) = (&self.header, self.decimal);
        let mut notes = Vec::new();
        let mut sample = 0usize;
        let mut have = if self.has_header { lines.next()? } else { true };
        while have {
            let this_line = lines.no;
            let mut count = 0usize;
            let mut bad = None;
            for (i, text) in fields(&lines.line, self.sep).enumerate() {
                count += 1;
                if i >= header.len() || slots[i].is_empty() || bad.is_some() {
                    continue;
                }
                match number(text, decimal) {
                    Some(v) => slots[i].iter().for_each(|&k| data[k].push(v)),
                    None => bad = Some((i, text.trim().to_string())),
                }
            }
            let short = count < header.len();
            have = lines.next()?;
            if short && !have && cfg.drop_truncated_last_line {
                // Roll back what the cut line gave.
                let n = sample;
                data.iter_mut().for_each(|c| c.truncate(n));
                notes.push(format!(
                    "dropped the last line ({this_line}): {count} of {} fields, a write cut short",
                    header.len()
                ));
                break;
            }
            if count != header.len() {
                return Err(Error::Data {
                    source_name: source.to_string(),
                    channel: "(row)".into(),
                    sample: Some(sample),
                    msg: format!(
                        "line {this_line} has {count} fields, the {} has {}{}",
                        if self.has_header { "header" } else { "first line" },
                        header.len(),
                        if !have && short {
                            " (truncated file? `drop_truncated_last_line = true` in [read] drops such a last line)"
                        } else {
                            " (truncated or corrupt file?)"
                        }
                    ),
                });
            }
            if let Some((i, text)) = bad {
                let hint = if decimal == Decimal::Point && text.contains(',') {
                    " (a decimal comma? give `decimal = \"comma\"` and a separator other than the comma)"
                } else {
                    ""
                };
                return Err(Error::Data {
                    source_name: source.to_string(),
                    channel: header[i].clone(),
                    sample: Some(sample),
                    msg: format!("line {this_line}, column {i}: `{text}` is not a number{hint}"),
                });
            }
            sample += 1;
        }
        Ok(notes)
    }
}
