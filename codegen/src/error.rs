//! Errors that point at the place in a scene file that caused them.

use std::fmt;
use std::path::{Path, PathBuf};

/// A problem with a scene, located in its file.
#[derive(Debug, Clone, PartialEq)]
pub struct Error {
    /// The scene file.
    pub file: PathBuf,
    /// 1-based line, 0 when the problem has no position (I/O errors).
    pub line: usize,
    /// 1-based column, 0 when the problem has no position.
    pub column: usize,
    /// The component, constraint or section the problem belongs to, if any.
    pub context: Option<String>,
    /// What is wrong.
    pub message: String,
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file.display())?;
        if self.line > 0 {
            write!(f, ":{}:{}", self.line, self.column)?;
        }
        write!(f, ": ")?;
        if let Some(ctx) = &self.context {
            write!(f, "in {ctx}: ")?;
        }
        write!(f, "{}", self.message)
    }
}

impl std::error::Error for Error {}

impl Error {
    /// An error about `file` as a whole, without a position in it (I/O,
    /// settings of the builder, checks of the derived model).
    pub fn unplaced(
        file: impl Into<PathBuf>,
        context: Option<&str>,
        message: impl Into<String>,
    ) -> Error {
        Error {
            file: file.into(),
            line: 0,
            column: 0,
            context: context.map(str::to_owned),
            message: message.into(),
        }
    }
}

/// Maps byte offsets of a scene file to lines and columns.
#[derive(Debug, Clone)]
pub struct Source {
    path: PathBuf,
    text: String,
    line_starts: Vec<usize>,
}

impl Source {
    /// A source file with its text.
    pub fn new(path: &Path, text: String) -> Source {
        let mut line_starts = vec![0];
        line_starts.extend(text.match_indices('\n').map(|(i, _)| i + 1));
        Source {
            path: path.to_path_buf(),
            text,
            line_starts,
        }
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The file's text.
    pub fn text(&self) -> &str {
        &self.text
    }

    /// 1-based line and column (in characters) of a byte offset.
    pub fn line_column(&self, offset: usize) -> (usize, usize) {
        let offset = offset.min(self.text.len());
        let line = self.line_starts.partition_point(|&s| s <= offset);
        let start = self.line_starts[line - 1];
        let column = self
            .text
            .get(start..offset)
            .map_or(offset - start, |s| s.chars().count())
            + 1;
        (line, column)
    }

    /// An error at a byte offset.
    pub fn error_at(
        &self,
        offset: usize,
        context: Option<&str>,
        message: impl Into<String>,
    ) -> Error {
        let (line, column) = self.line_column(offset);
        Error {
            file: self.path.clone(),
            line,
            column,
            context: context.map(str::to_owned),
            message: message.into(),
        }
    }

    /// An error without a position in the file.
    pub fn error(&self, message: impl Into<String>) -> Error {
        Error::unplaced(self.path.clone(), None, message)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offsets_map_to_lines_and_columns() {
        let s = Source::new(Path::new("a.toml"), "ab\ncdé\nf".into());
        assert_eq!(s.line_column(0), (1, 1));
        assert_eq!(s.line_column(1), (1, 2));
        assert_eq!(s.line_column(3), (2, 1));
        assert_eq!(s.line_column(8), (3, 1));
        let e = s.error_at(4, Some("component `x`"), "bad");
        assert_eq!(e.to_string(), "a.toml:2:2: in component `x`: bad");
    }
}
