//! `identify.sh`: what identify ran, as the commands that do it step by
//! step, for the user to pin and edit.

use std::ffi::OsStr;
use std::os::unix::ffi::OsStrExt;
use std::path::{Path, PathBuf};

/// The script, one command per step, its paths relative to the output
/// folder.
pub struct Script {
    text: String,
    robot: String,
}

impl Script {
    pub fn new(robot: &Path) -> Script {
        Script {
            text: String::from(
                "#!/usr/bin/env bash\n# What `robotid identify` ran, as commands to pin and edit (from this folder).\nset -euo pipefail\ncd \"$(dirname \"$0\")\"\n",
            ),
            robot: quoted(robot.as_os_str()),
        }
    }

    fn line(&mut self, line: String) {
        self.text.push_str(&line);
        self.text.push('\n');
    }

    pub fn run(&mut self, name: &str) {
        let toml = quoted(OsStr::new(&format!("pipelines/{name}.toml")));
        self.line(format!("robotid run {toml} --out {}", quoted(OsStr::new(name))));
    }

    pub fn estimate(&mut self, tables: &[PathBuf], physical: Option<&str>) {
        let (flag, covariance, out) = match physical {
            None => ("", "robust", "parameters.parquet"),
            Some(c) => (" --physical", c, "parameters_physical.parquet"),
        };
        self.line(format!(
            "robotid estimate {} --robot {}{flag} --covariance {covariance} -o {out}",
            joined(tables),
            self.robot
        ));
    }

    pub fn validate(&mut self, parameters: &str, tables: &[PathBuf]) {
        if !tables.is_empty() {
            self.line(format!("robotid validate -p {parameters} {}", joined(tables)));
        }
    }

    pub fn export(&mut self, mjcf: Option<&Path>) {
        let mjcf = mjcf
            .map(|m| format!(" --mjcf {}", quoted(m.as_os_str())))
            .unwrap_or_default();
        self.line(format!(
            "robotid export --robot {} -p parameters_physical.parquet --format urdf,mjcf,sidecar{mjcf} -o identified",
            self.robot
        ));
    }

    /// The report as identify wrote it: rollouts always (the robot is
    /// known), the physical estimate beside when `physical`, the export in
    /// MuJoCo with `mujoco`, the payload with `payload`, the closed loop
    /// under a controller on raw tables.
    pub fn report(
        &mut self,
        (excitation, validation): (&[PathBuf], &[PathBuf]),
        physical: bool,
        mujoco: bool,
        payload: bool,
        closed_loop: Option<(&Path, &[PathBuf])>,
    ) {
        let validation = if validation.is_empty() {
            String::new()
        } else {
            format!(" --validation {}", joined(validation))
        };
        let physical = match (physical, mujoco) {
            (false, _) => String::new(),
            (true, false) => " --physical parameters_physical.parquet".to_string(),
            (true, true) => " --physical parameters_physical.parquet --mujoco identified.xml".to_string(),
        };
        let payload = if payload { " --payload payload.parquet" } else { "" };
        let closed_loop = closed_loop.map_or(String::new(), |(c, raw)| {
            format!(" --controller {} --closed-loop {}", quoted(c.as_os_str()), joined(raw))
        });
        self.line(format!(
            "robotid report -p parameters.parquet --excitation {}{validation} --robot {} --rollout{physical}{payload}{closed_loop} -o report.html",
            joined(excitation),
            self.robot
        ));
    }

    pub fn text(&self) -> &str {
        &self.text
    }
}

/// Tables as the script names them, each one word to the shell.
fn joined(tables: &[PathBuf]) -> String {
    tables
        .iter()
        .map(|t| quoted(t.as_os_str()))
        .collect::<Vec<_>>()
        .join(" ")
}

/// `word` as one word to bash whatever its bytes: a recording's name is
/// the user's (or an attacker's), and an unquoted `$(…)` or `;` in it
/// would run. Printable UTF-8 goes in single quotes (inside which only
/// `'` is special, written `'\''`); anything else (control characters,
/// bytes that are not UTF-8) in ANSI-C `$'…'` with each byte escaped, so
/// the script stays text and the path stays exact.
pub fn quoted(word: &OsStr) -> String {
    let bytes = word.as_bytes();
    match std::str::from_utf8(bytes) {
        Ok(text) if !text.chars().any(char::is_control) => {
            format!("'{}'", text.replace('\'', "'\\''"))
        }
        _ => {
            let mut out = String::from("$'");
            for &b in bytes {
                match b {
                    b'\'' | b'\\' => {
                        out.push('\\');
                        out.push(b as char);
                    }
                    0x20..=0x7e => out.push(b as char),
                    _ => out.push_str(&format!("\\x{b:02x}")),
                }
            }
            out.push('\'');
            out
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::ffi::OsString;
    use std::os::unix::ffi::OsStringExt;

    /// bash itself reads each quoted word back to the very bytes, and runs
    /// nothing inside it.
    #[test]
    fn bash_reads_every_quoted_word_back_exactly() {
        let dir = std::env::temp_dir().join(format!("robotid-quote-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let canary = dir.join("PWNED");
        let hostile: Vec<Vec<u8>> = vec![
            b"k $(touch PWNED).csv".to_vec(),
            b"k;touch PWNED;.csv".to_vec(),
            b"it's \"quoted\" `touch PWNED`".to_vec(),
            b"line\nbreak\ttab".to_vec(),
            b"\xff\xfe not utf-8 \x80'$(touch PWNED)".to_vec(),
            b"back\\slash $HOME ${PATH} !! *?[a]".to_vec(),
            "ünïcødé – $(touch PWNED)".as_bytes().to_vec(),
            b"-rf".to_vec(),
            b"".to_vec(),
        ];
        // A seeded generator of random bytes (no zero: a path cannot hold one).
        let mut state: u64 = 0x2545_f491_4f6c_dd1d;
        let mut random = Vec::new();
        for _ in 0..100 {
            let mut w = Vec::new();
            for _ in 0..(state % 24) {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                w.push((state % 255) as u8 + 1);
            }
            random.push(w);
        }
        let words: Vec<Vec<u8>> = hostile.into_iter().chain(random).collect();
        let mut script = b"cd \"$1\"\nprintf '%s\\0'".to_vec();
        for w in &words {
            script.push(b' ');
            script.extend_from_slice(quoted(&OsString::from_vec(w.clone())).as_bytes());
        }
        script.push(b'\n');
        let file = dir.join("script.sh");
        std::fs::write(&file, &script).unwrap();
        let out = std::process::Command::new("bash")
            .arg(&file)
            .arg(&dir)
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let back: Vec<&[u8]> = out.stdout.split(|&b| b == 0).collect();
        assert_eq!(back.len(), words.len() + 1);
        for (w, b) in words.iter().zip(&back) {
            assert_eq!(w.as_slice(), *b, "{w:?}");
        }
        assert!(!canary.exists(), "a quoted word ran a command");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
