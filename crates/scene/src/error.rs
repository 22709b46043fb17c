//! Why a scene could not be loaded. Every problem a file can have is a value here, never a panic
//! (a corrupt file never panics); problems in a file name the file and, where the
//! format has lines, the line.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },

    #[error(
        "'{0}' is neither a built-in scene (bracara, bracara-textured, cornell) nor a scene file"
    )]
    UnknownScene(String),

    #[error("{}: {message}", file.display())]
    Toml { file: PathBuf, message: String },

    #[error("{}: the scene file names no OBJ (`obj = \"...\"`)", file.display())]
    NoObj { file: PathBuf },

    #[error("{}:{line}: {message}", file.display())]
    Syntax {
        file: PathBuf,
        line: usize,
        message: String,
    },

    #[error("{}:{line}: non-finite number (NaN or infinity)", file.display())]
    NonFinite { file: PathBuf, line: usize },

    #[error("{}:{line}: {what} index {index} out of range ({count} defined before this line)", file.display())]
    IndexOutOfRange {
        file: PathBuf,
        line: usize,
        what: &'static str,
        index: i64,
        count: usize,
    },

    /// tobj refused the file for a reason the line check did not foresee.
    #[error("{}: {message}", file.display())]
    Obj { file: PathBuf, message: String },

    #[error("invalid scene settings: {0}")]
    Settings(String),

    /// A scene built in code refers to a vertex or material it never defined, or has a
    /// non-finite vertex: a bug in that code, reported rather than panicking.
    #[error("scene builder: {0}")]
    Builder(String),

    #[error("the scene has no triangles left after validation")]
    Empty,
}
