//! Numeric CSV tables: a header row of column names, then rows of numbers.

use std::ffi::OsString;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

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
        let k =
            self.columns.iter().position(|c| c == name).ok_or_else(|| {
                format!("no column `{name}` (columns: {})", self.columns.join(", "))
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
                self.columns.join(", ")
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
            for (k, x) in r.iter().enumerate() {
                if k > 0 {
                    s.push(',');
                }
                let _ = write!(s, "{x:?}");
            }
            s.push('\n');
        }
        s
    }

    /// Write the table to `path` (through a temporary file: no partial output).
    pub fn write(&self, path: &Path) -> Result<(), String> {
        write_atomic(path, &self.to_csv())
    }

    /// Read a table; errors name the file and line.
    pub fn read(path: &Path) -> Result<Table, String> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
        Table::parse(&text).map_err(|e| format!("{}:{e}", path.display()))
    }

    /// Parse CSV text (errors start with the line number).
    pub fn parse(text: &str) -> Result<Table, String> {
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
                                columns[k],
                                c.trim()
                            )
                        })
                })
                .collect::<Result<Vec<f64>, String>>()?;
            rows.push(row);
        }
        Ok(Table { columns, rows })
    }
}

/// Write `text` to `path` through a temporary file and a rename, so that a
/// failure never leaves a partial file behind.
pub fn write_atomic(path: &Path, text: &str) -> Result<(), String> {
    let tmp = path.with_extension("partial");
    std::fs::write(&tmp, text)
        .and_then(|()| std::fs::rename(&tmp, path))
        .map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            format!("cannot write {}: {e}", path.display())
        })
}

/// Output files of one command, all or nothing: each is written under a
/// temporary name next to its destination (keeping the extension, which picks
/// a plot's format) and moved into place by [`Outputs::commit`] only once all
/// of them have been written. If the command fails first, dropping this
/// removes the temporary files, so no output (partial or complete) is left.
#[derive(Debug, Default)]
pub struct Outputs {
    /// (temporary file, destination), in order.
    staged: Vec<(PathBuf, PathBuf)>,
}

impl Outputs {
    /// Write the output destined for `path` through `write`, which is called
    /// with the temporary path; errors name `path`.
    pub fn write(
        &mut self,
        path: &Path,
        write: impl FnOnce(&Path) -> Result<(), String>,
    ) -> Result<(), String> {
        if path.is_dir() {
            return Err(format!(
                "cannot write {}: it is a directory",
                path.display()
            ));
        }
        let name = path
            .file_name()
            .ok_or_else(|| format!("cannot write {}: not a file name", path.display()))?;
        let mut tmp_name = OsString::from(format!(
            ".flexdyn-{}-{}-",
            std::process::id(),
            self.staged.len()
        ));
        tmp_name.push(name);
        let tmp = path.with_file_name(tmp_name);
        // Registered before writing, so that a partly written file is removed too.
        self.staged.push((tmp.clone(), path.to_path_buf()));
        write(&tmp).map_err(|e| e.replace(&tmp.display().to_string(), &path.display().to_string()))
    }

    /// Move every output into place.
    pub fn commit(mut self) -> Result<(), String> {
        for (tmp, path) in std::mem::take(&mut self.staged) {
            std::fs::rename(&tmp, &path).map_err(|e| {
                let _ = std::fs::remove_file(&tmp);
                format!("cannot write {}: {e}", path.display())
            })?;
        }
        Ok(())
    }
}

impl Drop for Outputs {
    fn drop(&mut self) {
        for (tmp, _) in &self.staged {
            let _ = std::fs::remove_file(tmp);
        }
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
    }

    #[test]
    fn outputs_are_all_or_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.csv"), dir.path().join("b.csv"));
        let listing = || std::fs::read_dir(dir.path()).unwrap().count();
        // The second output fails: the first is not left behind.
        let mut outputs = Outputs::default();
        outputs.write(&a, |tmp| write_atomic(tmp, "x")).unwrap();
        let e = outputs
            .write(&b, |tmp| {
                std::fs::write(tmp, "partial").unwrap();
                Err(format!("cannot plot to {}", tmp.display()))
            })
            .unwrap_err();
        assert_eq!(e, format!("cannot plot to {}", b.display()));
        drop(outputs);
        assert_eq!(listing(), 0);
        // Both succeed: both are in place, nothing else.
        let mut outputs = Outputs::default();
        outputs.write(&a, |tmp| write_atomic(tmp, "x")).unwrap();
        outputs.write(&b, |tmp| write_atomic(tmp, "y")).unwrap();
        outputs.commit().unwrap();
        assert_eq!(std::fs::read_to_string(&b).unwrap(), "y");
        assert_eq!(listing(), 2);
        // A directory is refused before anything is written.
        let mut outputs = Outputs::default();
        let e = outputs.write(dir.path(), |_| Ok(())).unwrap_err();
        assert!(e.contains("is a directory"), "{e}");
    }
}
