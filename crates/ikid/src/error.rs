//! The core's one error type: every failure names the field, tensor or value at fault, and
//! is classified here once — its [`ErrorKind`], a stable [`code`](Error::code), the frame and
//! the markers it concerns — so that Python's exception classes, C's status codes and any
//! caller's counting all derive from the same facts instead of from message text.

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
    /// A model file read from disk is invalid: `source` says how, this names the file.
    #[error("model file {path}: {source}")]
    InModelFile {
        /// Path that was read.
        path: String,
        /// What is wrong with its content (a model-file error).
        source: Box<Error>,
    },
    /// The bytes are not a valid safetensors container (truncated, corrupt header, ...).
    #[error("not a valid safetensors model file: {0}")]
    Container(String),
    /// The `__metadata__` model card is missing, is not JSON, or breaks the schema.
    #[error("model card: {0}")]
    ModelCard(String),
    /// The tensors' bytes do not match the checksum the card was written with: the file was
    /// damaged after it was written (a flipped bit moves the outputs without any other sign).
    #[error(
        "the weights are corrupt: their SHA-256 is {found}, the model card says {expected}; restore the file from its source"
    )]
    ChecksumMismatch {
        /// The card's `tensor_sha256`.
        expected: String,
        /// The checksum of the tensors read.
        found: String,
    },
    /// The card carries no `tensor_sha256`: the file was written before model files carried a
    /// checksum of their weights, so a corrupted copy cannot be told from a good one. Refused
    /// unless the caller opts in ([`Model::load_allowing_unchecked`](crate::Model::load_allowing_unchecked)).
    #[error(
        "the model card has no checksum of the weights (\"tensor_sha256\"): the file was written before model files carried one, so a corrupted copy cannot be told from a good one; add one with `python -m ikid_training.export --restamp FILE` (ikid-training)"
    )]
    MissingChecksum,
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
    /// A frame (one time step of input) has the wrong number of values. The message names
    /// what the caller gives (a marker frame for every model that reads markers), not the
    /// features the model computes from it.
    #[error("frame has {found} values, expected {expected}: {}", frame_of(feature_set))]
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
    #[error("frame {frame}: marker(s) {markers} out of place ({detail}); no output computed")]
    OutlierMarker {
        /// Index of the frame within the call.
        frame: usize,
        /// Comma-separated names of the suspect markers.
        markers: String,
        /// The distance that gave it away.
        detail: String,
    },
    /// The markers are spread over a distance no forearm and hand can span (see
    /// [`crate::body::MARKER_SPAN_M`]): most likely the wrong units.
    #[error("frame {frame}: {detail}")]
    ImplausibleMarkers {
        /// Index of the frame within the call.
        frame: usize,
        /// What is implausible and its likely cause.
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
    #[error(
        "frame {frame}: the prediction is not finite ({value}); the input is far outside the model's training range (units?)"
    )]
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

/// What kind of failure an [`Error`](enum@Error) is; each binding maps every kind (exhaustively) to its
/// own notion: a Python exception class, a C status code.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ErrorKind {
    /// A frame, or an array of frames, is unusable: wrong length, a missing or non-finite
    /// value, degenerate or jumping markers, or an input so far outside the training range
    /// that the prediction is not finite. Per-frame errors of this kind carry the frame.
    Input,
    /// An argument other than frame data is out of its range: a buffer size, a setting, a
    /// name, a calibration, a time stamp.
    Argument,
    /// A model file is corrupt, truncated, or does not fit its model card.
    ModelFile,
    /// A file could not be read: not found, not a regular file, too large, no permission.
    Io,
}

impl ErrorKind {
    /// Every kind, in the order documented to users.
    pub const ALL: [ErrorKind; 4] = [ErrorKind::Input, ErrorKind::Argument, ErrorKind::ModelFile, ErrorKind::Io];

    /// The kind's stable name (`"input"`, `"argument"`, `"model_file"`, `"io"`).
    pub fn name(self) -> &'static str {
        match self {
            ErrorKind::Input => "input",
            ErrorKind::Argument => "argument",
            ErrorKind::ModelFile => "model_file",
            ErrorKind::Io => "io",
        }
    }
}

impl Error {
    /// The kind of failure: what a binding maps to an exception class or a status code.
    pub fn kind(&self) -> ErrorKind {
        match self {
            Error::Io { .. } => ErrorKind::Io,
            Error::InModelFile { source, .. } => source.kind(),
            Error::Container(_)
            | Error::ModelCard(_)
            | Error::UnsupportedVersion { .. }
            | Error::UnknownFeatureSet { .. }
            | Error::MissingTensor { .. }
            | Error::UnexpectedTensor { .. }
            | Error::WrongDtype { .. }
            | Error::ShapeMismatch { .. }
            | Error::NonFiniteWeight { .. }
            | Error::ChecksumMismatch { .. }
            | Error::MissingChecksum => ErrorKind::ModelFile,
            Error::FrameLength { .. }
            | Error::NonFiniteInput { .. }
            | Error::MissingMarkers { .. }
            | Error::OutlierMarker { .. }
            | Error::DegenerateSegment { .. }
            | Error::ImplausibleMarkers { .. }
            | Error::NonFiniteOutput { .. } => ErrorKind::Input,
            Error::BadArgument { .. } => ErrorKind::Argument,
        }
    }

    /// A stable, machine-readable reason (one per variant; `"not_found"` for a missing file),
    /// for callers that count or branch on errors: rewording a message never changes it.
    pub fn code(&self) -> &'static str {
        match self {
            Error::Io { source, .. } if source.kind() == std::io::ErrorKind::NotFound => "not_found",
            Error::Io { .. } => "io",
            Error::InModelFile { source, .. } => source.code(),
            Error::Container(_) => "container",
            Error::ModelCard(_) => "model_card",
            Error::UnsupportedVersion { .. } => "unsupported_version",
            Error::UnknownFeatureSet { .. } => "unknown_feature_set",
            Error::MissingTensor { .. } => "missing_tensor",
            Error::UnexpectedTensor { .. } => "unexpected_tensor",
            Error::WrongDtype { .. } => "wrong_dtype",
            Error::ShapeMismatch { .. } => "shape_mismatch",
            Error::NonFiniteWeight { .. } => "non_finite_weight",
            Error::ChecksumMismatch { .. } => "checksum_mismatch",
            Error::MissingChecksum => "missing_checksum",
            Error::ImplausibleMarkers { .. } => "implausible_markers",
            Error::FrameLength { .. } => "frame_length",
            Error::NonFiniteInput { .. } => "non_finite_input",
            Error::MissingMarkers { .. } => "missing_markers",
            Error::OutlierMarker { .. } => "outlier_marker",
            Error::DegenerateSegment { .. } => "degenerate_segment",
            Error::NonFiniteOutput { .. } => "non_finite_output",
            Error::BadArgument { .. } => "bad_argument",
        }
    }

    /// The frame a per-frame error concerns (its index within the call or stream), if any.
    pub fn frame(&self) -> Option<usize> {
        match self {
            Error::NonFiniteInput { frame, .. }
            | Error::MissingMarkers { frame, .. }
            | Error::OutlierMarker { frame, .. }
            | Error::DegenerateSegment { frame, .. }
            | Error::ImplausibleMarkers { frame, .. }
            | Error::NonFiniteOutput { frame, .. } => Some(*frame),
            _ => None,
        }
    }

    /// The markers an error concerns ([`crate::body::MARKERS`] names), empty if none.
    pub fn markers(&self) -> Vec<&str> {
        match self {
            Error::MissingMarkers { markers, .. } | Error::OutlierMarker { markers, .. } => {
                markers.split(", ").collect()
            }
            // A marker's values are named `NAME.x`, `NAME.y`, `NAME.z` (`FeatureSet::frame_names`,
            // the reference IK, the tracker) and no other frame value ends in a single axis:
            // the name says which marker, without this module reading the body model's list
            // (`error` is the core's bottom layer; `features`' tests check every frame name).
            Error::NonFiniteInput { field, .. } => match field.rsplit_once('.') {
                Some((marker, "x" | "y" | "z")) if !marker.is_empty() && !marker.contains('.') => vec![marker],
                _ => Vec::new(),
            },
            _ => Vec::new(),
        }
    }

    /// The message without its `frame N: ` prefix: what went wrong, for a caller that reports
    /// the frame in its own numbering (a file's line, a stream's count).
    pub fn message_without_frame(&self) -> String {
        let message = self.to_string();
        match self.frame() {
            Some(frame) => message.strip_prefix(&format!("frame {frame}: ")).map_or(message.clone(), str::to_string),
            None => message,
        }
    }

    /// The same error attributed to frame `frame` of a larger call (per-frame errors only).
    pub fn renumbered(self, frame: usize) -> Self {
        match self {
            Error::NonFiniteInput { field, value, .. } => Error::NonFiniteInput { frame, field, value },
            Error::DegenerateSegment { segment, .. } => Error::DegenerateSegment { frame, segment },
            Error::ImplausibleMarkers { detail, .. } => Error::ImplausibleMarkers { frame, detail },
            Error::MissingMarkers { markers, reason, .. } => Error::MissingMarkers { frame, markers, reason },
            Error::OutlierMarker { markers, detail, .. } => Error::OutlierMarker { frame, markers, detail },
            Error::NonFiniteOutput { value, .. } => Error::NonFiniteOutput { frame, value },
            other => other,
        }
    }
}

/// What a frame of the feature set `feature_set` holds, for [`Error::FrameLength`]'s message:
/// the joint-state and tracker-state sets read their own frames, every other set reads
/// marker frames (`crate::features::FrameKind`; a test there checks each set's name here).
pub fn frame_of(feature_set: &str) -> &'static str {
    match feature_set {
        "joint_state" => "a joint state (q, q̇, q̈ of the three coordinates)",
        "tracker_state" => "a tracker state (its q, q̇, q̈ and marker noise)",
        _ => "a marker frame (six markers' x, y, z in metres: RSP, USP, FAP, MC2, MC5, MCB)",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An error and the kind, code, frame and markers a user relies on for it.
    type Expected = (Error, ErrorKind, &'static str, Option<usize>, Vec<&'static str>);

    /// One error of every variant.
    fn every_variant() -> Vec<Expected> {
        let io = |kind| Error::Io { path: "m.safetensors".into(), source: std::io::Error::from(kind) };
        use ErrorKind::*;
        vec![
            (io(std::io::ErrorKind::NotFound), Io, "not_found", None, vec![]),
            (io(std::io::ErrorKind::PermissionDenied), Io, "io", None, vec![]),
            (Error::Container("bad header".into()), ModelFile, "container", None, vec![]),
            (
                Error::InModelFile {
                    path: "m.safetensors".into(),
                    source: Box::new(Error::MissingTensor { name: "b".into() }),
                },
                ModelFile,
                "missing_tensor",
                None,
                vec![],
            ),
            (Error::ModelCard("no task".into()), ModelFile, "model_card", None, vec![]),
            (Error::UnsupportedVersion { found: 9, supported: 1 }, ModelFile, "unsupported_version", None, vec![]),
            (
                Error::UnknownFeatureSet { name: "x".into(), known: "markers".into() },
                ModelFile,
                "unknown_feature_set",
                None,
                vec![],
            ),
            (Error::MissingTensor { name: "a".into() }, ModelFile, "missing_tensor", None, vec![]),
            (Error::UnexpectedTensor { name: "a".into() }, ModelFile, "unexpected_tensor", None, vec![]),
            (Error::WrongDtype { name: "a".into(), dtype: "F16".into() }, ModelFile, "wrong_dtype", None, vec![]),
            (
                Error::ShapeMismatch { name: "a".into(), found: vec![1], expected: vec![2] },
                ModelFile,
                "shape_mismatch",
                None,
                vec![],
            ),
            (
                Error::NonFiniteWeight { name: "a".into(), index: 3, value: f32::NAN },
                ModelFile,
                "non_finite_weight",
                None,
                vec![],
            ),
            (
                Error::FrameLength { feature_set: "markers", found: 17, expected: 18 },
                Input,
                "frame_length",
                None,
                vec![],
            ),
            (
                Error::NonFiniteInput { frame: 4, field: "MC5.y".into(), value: f32::NAN },
                Input,
                "non_finite_input",
                Some(4),
                vec!["MC5"],
            ),
            (
                Error::NonFiniteInput { frame: 4, field: "q.ra_wr_s_p".into(), value: f32::NAN },
                Input,
                "non_finite_input",
                Some(4),
                vec![],
            ),
            (
                Error::MissingMarkers { frame: 7, markers: "RSP, MC2".into(), reason: "why" },
                Input,
                "missing_markers",
                Some(7),
                vec!["RSP", "MC2"],
            ),
            (
                Error::OutlierMarker { frame: 8, markers: "FAP".into(), detail: "far".into() },
                Input,
                "outlier_marker",
                Some(8),
                vec!["FAP"],
            ),
            (Error::DegenerateSegment { frame: 9, segment: "hand" }, Input, "degenerate_segment", Some(9), vec![]),
            (Error::NonFiniteOutput { frame: 10, value: f32::INFINITY }, Input, "non_finite_output", Some(10), vec![]),
            (Error::BadArgument { what: "rate_hz", detail: "is 0".into() }, Argument, "bad_argument", None, vec![]),
        ]
    }

    #[test]
    fn every_error_is_classified_with_its_frame_and_markers() {
        let mut codes = std::collections::HashSet::new();
        for (err, kind, code, frame, markers) in every_variant() {
            assert_eq!((err.kind(), err.code(), err.frame(), err.markers()), (kind, code, frame, markers), "{err:?}");
            codes.insert(code);
            let message = err.message_without_frame();
            match frame {
                Some(f) => assert_eq!(format!("frame {f}: {message}"), err.to_string()),
                None => assert_eq!(message, err.to_string()),
            }
        }
        // Codes are unique per variant: one input error appears twice, and a file's error has
        // the code of what is wrong inside it.
        assert_eq!(codes.len(), every_variant().len() - 2);
        assert_eq!(ErrorKind::ALL.map(ErrorKind::name), ["input", "argument", "model_file", "io"]);
    }

    #[test]
    fn renumbering_moves_only_per_frame_errors() {
        for (err, _, code, frame, _) in every_variant() {
            let moved = err.renumbered(42);
            assert_eq!(moved.code(), code);
            assert_eq!(moved.frame(), frame.map(|_| 42));
        }
    }
}
