//! The core's one error type: every failure names the field, tensor or value at fault.

use thiserror::Error;

/// Result alias used throughout the core.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Everything that can go wrong in the core, each with a message a user can act on.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum Error {
    /// The model file could not be read from disk.
    #[error("cannot read model file {path}: {source}")]
    Io {
        /// Path that was opened.
        path: String,
        /// Underlying I/O error.
        source: std::io::Error,
    },
    /// The bytes are not a valid safetensors container (truncated, corrupt header, ...).
    #[error("not a valid safetensors model file: {0}")]
    Container(String),
    /// The `__metadata__` model card is missing, is not JSON, or breaks the schema.
    #[error("model card: {0}")]
    ModelCard(String),
    /// The model card's format version is not one this build understands.
    #[error("model card format_version {found} is not supported (this build reads version {supported})")]
    UnsupportedVersion {
        /// Version found in the file.
        found: u64,
        /// Version this build reads.
        supported: u64,
    },
    /// The model card names a feature set this build does not know.
    #[error("unknown feature set {name:?} (known: {known})")]
    UnknownFeatureSet {
        /// Name found.
        name: String,
        /// Comma-separated list of known names.
        known: String,
    },
    /// A tensor the model card refers to is not in the file.
    #[error("tensor {name:?} is missing from the model file")]
    MissingTensor {
        /// Tensor name.
        name: String,
    },
    /// A tensor in the file is not referred to by the model card (tampered or mismatched file).
    #[error("tensor {name:?} is in the file but not used by the model card")]
    UnexpectedTensor {
        /// Tensor name.
        name: String,
    },
    /// A tensor has a dtype other than F32.
    #[error("tensor {name:?} has dtype {dtype}, expected F32")]
    WrongDtype {
        /// Tensor name.
        name: String,
        /// Dtype found.
        dtype: String,
    },
    /// A tensor's shape does not fit the network.
    #[error("tensor {name:?} has shape {found:?}, expected {expected:?}")]
    ShapeMismatch {
        /// Tensor name.
        name: String,
        /// Shape found.
        found: Vec<usize>,
        /// Shape expected.
        expected: Vec<usize>,
    },
    /// A tensor holds NaN or infinity.
    #[error("tensor {name:?} holds a non-finite value ({value}) at flat index {index}")]
    NonFiniteWeight {
        /// Tensor name.
        name: String,
        /// Flat index of the first bad value.
        index: usize,
        /// The value.
        value: f32,
    },
    /// A frame (one time step of input) has the wrong number of values.
    #[error("frame has {found} values, the model's feature set {feature_set:?} expects {expected}")]
    FrameLength {
        /// Feature set of the model.
        feature_set: &'static str,
        /// Length given.
        found: usize,
        /// Length expected.
        expected: usize,
    },
    /// A frame holds NaN or infinity (e.g. an occluded marker); no output is computed from it.
    #[error("frame {frame}: value {field} is {value} (missing or non-finite); no output computed")]
    NonFiniteInput {
        /// Index of the frame within the call (0 for a single pushed frame).
        frame: usize,
        /// Name of the offending field, e.g. `"MC2.y"`.
        field: String,
        /// The value found.
        value: f32,
    },
    /// Markers are missing and the stream's policy could not fill them (see [`crate::gaps`]).
    #[error("frame {frame}: missing marker(s) {markers} not filled: {reason}; no output computed")]
    MissingMarkers {
        /// Index of the frame within the call.
        frame: usize,
        /// Comma-separated names of the missing markers.
        markers: String,
        /// Why they could not be filled.
        reason: &'static str,
    },
    /// A marker is far from where its segment's other markers put it (it jumped, or two
    /// labels swapped), and the stream's policy could not replace it.
    #[error("frame {frame}: marker(s) {markers} inconsistent with the rigid segment ({detail}); no output computed")]
    OutlierMarker {
        /// Index of the frame within the call.
        frame: usize,
        /// Comma-separated names of the suspect markers.
        markers: String,
        /// The distance that gave it away.
        detail: String,
    },
    /// A segment's three markers are (nearly) collinear or coincident, so no frame can be fitted.
    #[error("frame {frame}: the {segment} markers are collinear or coincident; cannot build a segment frame")]
    DegenerateSegment {
        /// Index of the frame within the call.
        frame: usize,
        /// Segment name.
        segment: &'static str,
    },
    /// The network's prediction is not finite: the input lies far outside anything the
    /// model was trained on (e.g. millimetres given to a metre model).
    #[error("frame {frame}: the prediction is not finite ({value}); the input is far outside the model's training range (units?)")]
    NonFiniteOutput {
        /// Index of the frame within the call.
        frame: usize,
        /// The first non-finite output.
        value: f32,
    },
    /// An array argument has a length that is not a whole number of rows, or an output buffer is too small.
    #[error("{what}: {detail}")]
    BadArgument {
        /// Which argument.
        what: &'static str,
        /// What is wrong with it.
        detail: String,
    },
}

impl Error {
    /// The same error attributed to frame `frame` of a larger call (per-frame errors only).
    pub fn renumbered(self, frame: usize) -> Self {
        match self {
            Error::NonFiniteInput { field, value, .. } => Error::NonFiniteInput { frame, field, value },
            Error::DegenerateSegment { segment, .. } => Error::DegenerateSegment { frame, segment },
            Error::MissingMarkers { markers, reason, .. } => Error::MissingMarkers { frame, markers, reason },
            Error::OutlierMarker { markers, detail, .. } => Error::OutlierMarker { frame, markers, detail },
            Error::NonFiniteOutput { value, .. } => Error::NonFiniteOutput { frame, value },
            other => other,
        }
    }
}
