use std::fmt;

/// A position in model source text: 1-based line and column (columns count characters).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Pos {
    /// Line, from 1.
    pub line: u32,
    /// Column, from 1.
    pub col: u32,
}

impl fmt::Display for Pos {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "line {}, column {}", self.line, self.col)
    }
}

/// Errors of the F-rep layer.
#[derive(Debug, thiserror::Error)]
pub enum FrepError {
    /// The model text is not valid syntax.
    #[error("syntax error at {pos}: {message}")]
    Syntax {
        /// Where.
        pos: Pos,
        /// What is wrong.
        message: String,
    },
    /// The model is syntactically valid but cannot be compiled (unknown function, wrong
    /// number or kind of arguments, undefined variable, array index out of range, recursion,
    /// a loop that does not end within the iteration limit, a model too large).
    #[error("error at {pos}: {message}")]
    Compile {
        /// Where.
        pos: Pos,
        /// What is wrong.
        message: String,
    },
    /// An argument of a library call is outside what it accepts (a non-positive grid size,
    /// an empty box, a radius of influence that is not positive, …).
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
    /// A data-dependent `while` loop had not ended after its pass budget at some sampled
    /// points (their values would be NaN).
    #[error(
        "the loop at {pos} had not ended after {passes} passes at {points} of the sampled \
         points (their values would be NaN); a data-dependent loop is unrolled at most \
         {passes} times: bound it by a counter known at compile time, or sample elsewhere"
    )]
    LoopBudget {
        /// Position of the `while`.
        pos: Pos,
        /// The pass budget.
        passes: usize,
        /// Sampled points where the loop was still running.
        points: usize,
    },
    /// Every sampled value is NaN (on a grid, or along a picture's rays): the function is
    /// undefined wherever it was sampled.
    #[error(
        "every one of the {points} sampled values is NaN: the function is undefined wherever \
         it was sampled (check the bounds, the parameters, and divisions or roots of negative \
         numbers)"
    )]
    AllNan {
        /// Number of samples.
        points: usize,
    },
    /// Writing or building a volume failed.
    #[error(transparent)]
    Volume(#[from] volmorph_volume::VolumeError),
    /// Isosurface extraction failed.
    #[error(transparent)]
    Contour(#[from] volmorph_contour::ContourError),
    /// Image or camera error.
    #[error(transparent)]
    Render(#[from] volmorph_render::RenderError),
    /// Writing a mesh failed.
    #[error(transparent)]
    Mesh(#[from] volmorph_mesh::MeshError),
    /// A space map failed.
    #[error(transparent)]
    Deform(#[from] volmorph_deform::DeformError),
    /// An error in a file (a model, a specification), naming it.
    #[error("{path}: {source}")]
    InFile {
        /// The file.
        path: String,
        /// What is wrong in it.
        source: Box<FrepError>,
    },
    /// A mapping specification is not valid: the JSON path of the bad field and why.
    #[error("{}{message}", if path.is_empty() { String::new() } else { format!("{path}: ") })]
    Spec {
        /// JSON path of the field, e.g. `mappings[2].points[0].radius` (empty for the whole
        /// document).
        path: String,
        /// What is wrong.
        message: String,
    },
    /// Reading a file failed, or a size exceeds the memory budget.
    #[error(transparent)]
    Io(#[from] volmorph_io::IoError),
    /// The caller asked the work to stop through its [`volmorph_io::Progress`]; nothing was
    /// written.
    #[error("stopped on request")]
    Cancelled(#[from] volmorph_io::Cancelled),
}

impl FrepError {
    pub(crate) fn syntax(pos: Pos, message: impl Into<String>) -> Self {
        Self::Syntax {
            pos,
            message: message.into(),
        }
    }

    pub(crate) fn compile(pos: Pos, message: impl Into<String>) -> Self {
        Self::Compile {
            pos,
            message: message.into(),
        }
    }

    /// The source position of a syntax or compile error.
    #[must_use]
    pub fn pos(&self) -> Option<Pos> {
        match self {
            Self::Syntax { pos, .. } | Self::Compile { pos, .. } => Some(*pos),
            _ => None,
        }
    }
}
