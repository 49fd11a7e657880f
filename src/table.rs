//! Numeric CSV tables: a header row of column names, then rows of numbers.

use std::fmt::Write as _;
use std::io::{BufWriter, Write as _};
use std::path::{Path, PathBuf};

use flexdyn_runtime::Time;

pub use crate::codegen::{check_output, write_atomic, OutputFiles};

/// Largest input file the commands read (inputs and prescriptions CSV,
/// states JSON, motion files, URDF): 64 MiB.
pub const MAX_INPUT_BYTES: u64 = 64 << 20;

/// The text of an input file, read up to [`MAX_INPUT_BYTES`]; errors name
/// the file, `what` it is and the limit.
pub fn read_input(path: &Path, what: &str) -> Result<String, String> {
    crate::codegen::read_limited(path, MAX_INPUT_BYTES, what)
        .map_err(|e| format!("{}: {e}", path.display()))
}

/// The most characters of a file's text an error message quotes.
pub const SHOWN_CHARS: usize = 80;

/// `text` as an error message quotes it: at most [`SHOWN_CHARS`]
/// characters, control characters escaped, `...` where it was cut.
fn shown(text: &str) -> String {
    let mut out: String = text
        .chars()
        .take(SHOWN_CHARS)
        .flat_map(char::escape_debug)
        .collect();
    if text.chars().nth(SHOWN_CHARS).is_some() {
        out.push_str("...");
    }
    out
}

/// A table of numbers with named columns.
#[derive(Debug, Clone, PartialEq)]
pub struct Table {
    /// Column names.
    pub columns: Vec<String>,
    /// Rows, each as long as `columns`.
    pub rows: Vec<Vec<f64>>,
}

impl Table {
    /// An empty table with the given columns.
    pub fn new(columns: &[&str]) -> Table {
        Table {
            columns: columns.iter().map(|c| (*c).to_owned()).collect(),
            rows: Vec::new(),
        }
    }

    /// Append a row (its length must match the columns).
    pub fn push(&mut self, row: Vec<f64>) {
        debug_assert_eq!(row.len(), self.columns.len());
        self.rows.push(row);
    }

    /// The values of a column.
    pub fn column(&self, name: &str) -> Result<Vec<f64>, String> {
        let k = self.columns.iter().position(|c| c == name).ok_or_else(|| {
            format!(
                "no column `{name}` (columns: {})",
                shown(&self.columns.join(", "))
            )
        })?;
        Ok(self.rows.iter().map(|r| r[k]).collect())
    }

    /// The column `t` of a table read from `file`, checked to be non-empty and
    /// strictly increasing; errors name the file and the line.
    pub fn times(&self, file: &Path) -> Result<Vec<f64>, String> {
        let file = file.display();
        let t = self.column("t").map_err(|_| {
            format!(
                "{file}: no column `t` (columns: {})",
                shown(&self.columns.join(", "))
            )
        })?;
        if t.is_empty() {
            return Err(format!("{file}: no rows"));
        }
        if let Some(k) = (1..t.len()).find(|&k| t[k] <= t[k - 1]) {
            return Err(format!(
                "{file}: line {}: t = {} does not increase (previous row: {})",
                k + 2,
                t[k],
                t[k - 1]
            ));
        }
        Ok(t)
    }

    /// CSV text; numbers in shortest round-trip form.
    pub fn to_csv(&self) -> String {
        let mut s = self.columns.join(",");
        s.push('\n');
        for r in &self.rows {
            csv_row(&mut s, r);
        }
        s
    }

    /// Write the table to `path` (all or nothing: [`write_atomic`]).
    pub fn write(&self, path: &Path) -> Result<(), String> {
        write_atomic(path, &self.to_csv())
    }

    /// Read a table; errors name the file and line.
    pub fn read(path: &Path) -> Result<Table, String> {
        let text = read_input(path, "CSV file")?;
        Table::parse(&text).map_err(|e| format!("{}:{e}", path.display()))
    }

    /// Parse CSV text (errors start with the line number and quote at most
    /// [`SHOWN_CHARS`] characters of the file); a leading byte-order mark
    /// (as spreadsheets write) is skipped.
    pub fn parse(text: &str) -> Result<Table, String> {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let mut lines = text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty());
        let (_, header) = lines.next().ok_or("1: empty file, expected a header row")?;
        let columns: Vec<String> = header.split(',').map(|c| c.trim().to_owned()).collect();
        if columns.iter().any(String::is_empty) {
            return Err("1: empty column name in the header".into());
        }
        let mut rows = Vec::new();
        for (i, line) in lines {
            let cells: Vec<&str> = line.split(',').collect();
            if cells.len() != columns.len() {
                return Err(format!(
                    "{}: expected {} values, found {}",
                    i + 1,
                    columns.len(),
                    cells.len()
                ));
            }
            let row = cells
                .iter()
                .enumerate()
                .map(|(k, c)| {
                    c.trim()
                        .parse::<f64>()
                        .ok()
                        .filter(|x| x.is_finite())
                        .ok_or_else(|| {
                            format!(
                                "{}: column `{}`: `{}` is not a finite number",
                                i + 1,
                                shown(&columns[k]),
                                shown(c.trim())
                            )
                        })
                })
                .collect::<Result<Vec<f64>, String>>()?;
            rows.push(row);
        }
        Ok(Table { columns, rows })
    }
}

/// Append one CSV line of `row` to `s`: numbers in shortest round-trip
/// form, comma-separated.
fn csv_row(s: &mut String, row: &[f64]) {
    for (k, x) in row.iter().enumerate() {
        if k > 0 {
            s.push(',');
        }
        let _ = write!(s, "{x:?}");
    }
    s.push('\n');
}

/// A text output written piece by piece as a run produces it (never all
/// in memory), through [`OutputFiles::create`]: a regular file appears
/// whole when the outputs are committed, or not at all; a device or FIFO
/// gets the text as it comes. While one exists, an interrupt (SIGINT,
/// SIGTERM) does not kill the process: the next write fails (and the run
/// with it, leaving no partial temporary file); a second one kills it.
pub struct TextWriter {
    out: BufWriter<std::fs::File>,
    path: PathBuf,
}

impl TextWriter {
    /// Open the output `path` in `outputs`; errors name `path`.
    pub fn create(outputs: &mut OutputFiles, path: &Path) -> Result<TextWriter, String> {
        let writer = TextWriter {
            out: BufWriter::new(outputs.create(path)?),
            path: path.to_path_buf(),
        };
        interrupt::catch(true);
        Ok(writer)
    }

    /// Append `text`, the output at time `t` when given (the error after an
    /// interrupt names it).
    pub fn write(&mut self, text: &str, t: Option<f64>) -> Result<(), String> {
        if interrupt::caught() {
            return Err(format!(
                "interrupted at t = {} s: {} not written",
                t.map_or(String::new(), |t| Time(t).to_string()),
                self.path.display()
            ));
        }
        self.out
            .write_all(text.as_bytes())
            .map_err(|e| self.failed(e))
    }

    /// Write out what is buffered; the writer is done.
    pub fn finish(mut self) -> Result<(), String> {
        self.out.flush().map_err(|e| self.failed(e))
    }

    fn failed(&self, e: std::io::Error) -> String {
        format!("cannot write {}: {e}", self.path.display())
    }
}

impl Drop for TextWriter {
    fn drop(&mut self) {
        interrupt::catch(false);
    }
}

/// A CSV written row by row as a run produces it (the text of
/// [`Table::to_csv`]), a [`TextWriter`].
pub struct CsvWriter {
    text: TextWriter,
    line: String,
}

impl CsvWriter {
    /// Open the output `path` in `outputs` and write the header of
    /// `columns`; errors name `path`.
    pub fn create(
        outputs: &mut OutputFiles,
        path: &Path,
        columns: &[String],
    ) -> Result<CsvWriter, String> {
        let mut text = TextWriter::create(outputs, path)?;
        text.write(&(columns.join(",") + "\n"), None)?;
        Ok(CsvWriter {
            text,
            line: String::new(),
        })
    }

    /// Append a row (as long as the columns); an error after an interrupt.
    pub fn row(&mut self, row: &[f64]) -> Result<(), String> {
        self.line.clear();
        csv_row(&mut self.line, row);
        self.text.write(&self.line, row.first().copied())
    }

    /// Write out what is buffered; the writer is done.
    pub fn finish(self) -> Result<(), String> {
        self.text.finish()
    }
}

/// SIGINT and SIGTERM noted instead of killing the process, while a
/// [`TextWriter`] streams (Unix; elsewhere they kill it as before).
mod interrupt {
    use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

    static CAUGHT: AtomicBool = AtomicBool::new(false);

    /// How many writers are streaming.
    static WRITERS: AtomicUsize = AtomicUsize::new(0);

    /// Whether an interrupt arrived since [`catch`]`(true)`.
    pub fn caught() -> bool {
        CAUGHT.load(Ordering::Relaxed)
    }

    #[cfg(unix)]
    extern "C" fn note(_: libc::c_int) {
        CAUGHT.store(true, Ordering::Relaxed);
    }

    /// Note the next interrupt (`on`, by the first writer; the one after it
    /// kills as usual), or restore the default (kill; by the last writer).
    /// A signal the process ignores stays ignored.
    pub fn catch(on: bool) {
        let writers = match on {
            true => WRITERS.fetch_add(1, Ordering::SeqCst) + 1,
            false => WRITERS.fetch_sub(1, Ordering::SeqCst) - 1,
        };
        if writers != usize::from(on) {
            return;
        }
        CAUGHT.store(false, Ordering::Relaxed);
        #[cfg(unix)]
        // SAFETY: `sigaction` reads and sets plain, zero-initialised
        // actions; the handler only stores to an atomic
        // (async-signal-safe).
        unsafe {
            let noted = note as extern "C" fn(libc::c_int) as libc::sighandler_t;
            let (from, to) = match on {
                true => (libc::SIG_DFL, noted),
                false => (noted, libc::SIG_DFL),
            };
            for signal in [libc::SIGINT, libc::SIGTERM] {
                let mut action: libc::sigaction = std::mem::zeroed();
                libc::sigaction(signal, std::ptr::null(), &mut action);
                if action.sa_sigaction == from {
                    action.sa_sigaction = to;
                    action.sa_flags = libc::SA_RESETHAND | libc::SA_RESTART;
                    libc::sigemptyset(&mut action.sa_mask);
                    libc::sigaction(signal, &action, std::ptr::null_mut());
                }
            }
        }
        #[cfg(not(unix))]
        let _ = on;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_errors() {
        let mut t = Table::new(&["t", "x"]);
        t.push(vec![0.0, 0.1]);
        t.push(vec![0.5, -1e-300]);
        let back = Table::parse(&t.to_csv()).unwrap();
        assert_eq!(back, t);
        assert!(Table::parse("t,x\n0,1\n2\n").unwrap_err().starts_with("3:"));
        assert!(Table::parse("t,x\n0,abc\n").unwrap_err().contains("`abc`"));
        assert!(Table::parse("t,x\n0,NaN\n")
            .unwrap_err()
            .contains("not a finite"));
        assert!(Table::parse("").is_err());
        assert!(back.column("y").unwrap_err().contains("no column `y`"));
        // A byte-order mark is skipped; a huge header is quoted in part.
        let bom = Table::parse("\u{feff}t,u\n0,1\n").unwrap();
        assert_eq!(bom.columns, ["t", "u"]);
        let wide = Table::parse(&format!("{}\n", "\0".repeat(100_000))).unwrap();
        let e = wide.column("t").unwrap_err();
        assert!(e.len() < 6 * SHOWN_CHARS && e.ends_with("...)"), "{e}");
        let e = Table::parse(&format!("t\n{}\n", "x".repeat(100_000))).unwrap_err();
        assert!(e.len() < 2 * SHOWN_CHARS, "{e}");
    }

    #[test]
    fn streamed_csv_is_the_tables_text() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.csv");
        let mut t = Table::new(&["t", "x"]);
        t.push(vec![0.0, 0.1]);
        t.push(vec![0.5, -1e-300]);
        let mut outputs = OutputFiles::default();
        let mut csv = CsvWriter::create(&mut outputs, &path, &t.columns).unwrap();
        for r in &t.rows {
            csv.row(r).unwrap();
        }
        csv.finish().unwrap();
        outputs.commit().unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), t.to_csv());
    }
}
