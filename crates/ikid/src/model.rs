//! Model files: one `.safetensors` holding the MLP's tensors and a JSON model card.
//!
//! Tensors (all F32, looked up by name, torch layout):
//! `layers.{k}.weight` `[out, in]`, `layers.{k}.bias` `[out]` for `k = 0..n_layers`,
//! `input.scale`, `input.shift` `[window × features]`, `output.scale`, `output.shift` `[outputs]`.
//! The network computes `y = out(L_n(…L_1(x ∘ input.scale + input.shift)))` with
//! `out(h) = h ∘ output.scale + output.shift`; `x` is the window of per-frame features,
//! oldest frame first. The card ([`ModelCard`]) is JSON under the metadata key
//! [`CARD_KEY`]. The loader checks everything and names what is wrong.

use crate::body::MARKER_FRAME_LEN;
use crate::error::{Error, Result};
use crate::features::FeatureSet;
use crate::gaps::{GapFiller, MissingMarkers};
use crate::net::{Activation, Affine, BATCH, Dense, Mlp, PackedMlp};
use crate::stream::Stream;
use nalgebra::{DMatrix, DVector};
use safetensors::{Dtype, SafeTensors, tensor::TensorView};
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, HashMap};
use std::path::Path;
use std::sync::{Arc, Mutex, PoisonError};

/// Metadata key holding the model card.
pub const CARD_KEY: &str = "ikid";
/// Value of the card's `format` field.
pub const FORMAT: &str = "ikid-model";
/// The model card version this build reads and writes.
pub const FORMAT_VERSION: u64 = 1;
/// Tasks a model card may declare.
pub const TASKS: [&str; 4] = ["ik", "id", "chain", "refine"];
/// The card's `output_offset` value that adds the newest frame's features to the outputs.
pub const NEWEST_FEATURES: &str = "newest_features";
/// Longest window accepted (frames); guards against absurd allocations from tampered cards.
pub const MAX_WINDOW: usize = 4096;

/// One network output: its name and SI unit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputSpec {
    /// E.g. `"ra_wr_s_p"`.
    pub name: String,
    /// E.g. `"rad"` or `"N*m"`.
    pub unit: String,
}

/// The model card: what the network is, how to feed it, where it came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelCard {
    /// Always [`FORMAT`].
    pub format: String,
    /// Always [`FORMAT_VERSION`] for files this build reads.
    pub format_version: u64,
    /// Short model name, e.g. `"wrist-ik"`.
    pub name: String,
    /// One of [`TASKS`].
    pub task: String,
    /// A [`FeatureSet`] name.
    pub feature_set: String,
    /// The feature set's per-frame feature names, in order (checked against the build's).
    pub feature_names: Vec<String>,
    /// Frames per window (≥ 1).
    pub window: usize,
    /// Which frame of the window is predicted; only `"newest"` (causal) exists now.
    pub predicted_frame: String,
    /// Frame rate the model was trained at, Hz.
    pub frame_rate_hz: f64,
    /// Outputs, in order.
    pub outputs: Vec<OutputSpec>,
    /// What a stream does with a missing marker: a [`MissingMarkers`] name (`"refuse"` or
    /// `"fill"`); `"refuse"` when absent. A model trained on filled frames says `"fill"`.
    #[serde(default = "refuse")]
    pub missing_markers: String,
    /// Activation after each dense layer: `"relu"` or `"identity"`.
    pub activations: Vec<String>,
    /// [`NEWEST_FEATURES`]: output `k` is the network's output plus the newest frame's feature
    /// of the same quantity (feature `k`, named `<kind>.<output name>`), so the network learns
    /// a correction to it (e.g. denoising per-frame angles) rather than the whole value.
    /// Absent: the network's output is the prediction.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub output_offset: Option<String>,
    /// How the scaling tensors were fitted (informational), e.g. `{"input": "minmax(-1,1)"}`.
    #[serde(default)]
    pub scaling: BTreeMap<String, String>,
    /// Training data provenance (simulator version, seed, hash, ...), free-form.
    #[serde(default)]
    pub provenance: serde_json::Map<String, serde_json::Value>,
    /// Evaluation metrics the model shipped with, free-form.
    #[serde(default)]
    pub metrics: serde_json::Map<String, serde_json::Value>,
}

impl ModelCard {
    /// A card with the required fields and empty provenance/metrics.
    pub fn new(
        name: &str,
        task: &str,
        feature_set: FeatureSet,
        window: usize,
        frame_rate_hz: f64,
        outputs: Vec<OutputSpec>,
        activations: &[Activation],
    ) -> Self {
        ModelCard {
            format: FORMAT.into(),
            format_version: FORMAT_VERSION,
            name: name.into(),
            task: task.into(),
            feature_set: feature_set.name().into(),
            feature_names: feature_set.feature_names(),
            window,
            predicted_frame: "newest".into(),
            frame_rate_hz,
            outputs,
            missing_markers: MissingMarkers::Refuse.name().into(),
            activations: activations.iter().map(|a| a.name().into()).collect(),
            output_offset: None,
            scaling: BTreeMap::new(),
            provenance: Default::default(),
            metrics: Default::default(),
        }
    }

    /// Parses and checks a card (everything that does not need the tensors).
    pub fn from_json(json: &str) -> Result<Self> {
        let value: serde_json::Value =
            serde_json::from_str(json).map_err(|e| Error::ModelCard(format!("not valid JSON: {e}")))?;
        match value.get("format").and_then(|v| v.as_str()) {
            Some(FORMAT) => {}
            other => return Err(Error::ModelCard(format!("field \"format\" is {other:?}, expected {FORMAT:?}"))),
        }
        match value.get("format_version").and_then(|v| v.as_u64()) {
            Some(FORMAT_VERSION) => {}
            Some(found) => return Err(Error::UnsupportedVersion { found, supported: FORMAT_VERSION }),
            None => return Err(Error::ModelCard("field \"format_version\" is missing or not an integer".into())),
        }
        let card: ModelCard = serde_json::from_value(value).map_err(|e| Error::ModelCard(e.to_string()))?;
        card.validate()?;
        Ok(card)
    }

    /// The card as JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).expect("a model card always serialises")
    }

    /// The activations as the kernel's enum (validated with the card).
    pub fn parsed_activations(&self) -> Result<Vec<Activation>> {
        self.activations
            .iter()
            .enumerate()
            .map(|(k, a)| {
                parse_activation(a).map_err(|_| {
                    Error::ModelCard(format!("field \"activations\"[{k}] is {a:?}, expected \"relu\" or \"identity\""))
                })
            })
            .collect()
    }

    fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::ModelCard(m));
        if !TASKS.contains(&self.task.as_str()) {
            return bad(format!("field \"task\" is {:?}, expected one of {TASKS:?}", self.task));
        }
        let set = FeatureSet::from_name(&self.feature_set)?;
        let names = set.feature_names();
        if self.feature_names != names {
            let i = (0..names.len().max(self.feature_names.len()))
                .find(|&i| self.feature_names.get(i) != names.get(i))
                .unwrap_or(0);
            return bad(format!(
                "field \"feature_names\"[{i}] is {:?}, feature set {:?} has {:?} ({} names)",
                self.feature_names.get(i),
                self.feature_set,
                names.get(i),
                names.len()
            ));
        }
        if !(1..=MAX_WINDOW).contains(&self.window) {
            return bad(format!("field \"window\" is {}, expected 1..={MAX_WINDOW}", self.window));
        }
        if self.predicted_frame != "newest" {
            return bad(format!("field \"predicted_frame\" is {:?}, expected \"newest\"", self.predicted_frame));
        }
        if !(self.frame_rate_hz.is_finite() && self.frame_rate_hz > 0.0) {
            return bad(format!("field \"frame_rate_hz\" is {}, expected a positive number", self.frame_rate_hz));
        }
        let policy = MissingMarkers::from_name(&self.missing_markers).map_err(|_| {
            Error::ModelCard(format!(
                "field \"missing_markers\" is {:?}, expected one of {:?}",
                self.missing_markers,
                MissingMarkers::ALL.map(|p| p.name())
            ))
        })?;
        if policy == MissingMarkers::Fill && set.frame_len() != MARKER_FRAME_LEN {
            return bad(format!(
                "field \"missing_markers\" is \"fill\" but feature set {:?} does not take marker frames",
                self.feature_set
            ));
        }
        if self.outputs.is_empty() {
            return bad("field \"outputs\" is empty".into());
        }
        if self.activations.is_empty() {
            return bad("field \"activations\" is empty: the model has no layers".into());
        }
        if let Some(offset) = &self.output_offset {
            if offset != NEWEST_FEATURES {
                return bad(format!("field \"output_offset\" is {offset:?}, expected {NEWEST_FEATURES:?} or no field"));
            }
            for (k, out) in self.outputs.iter().enumerate() {
                let same = names.get(k).and_then(|f| f.split_once('.')).is_some_and(|(_, q)| q == out.name);
                if !same {
                    return bad(format!(
                        "field \"output_offset\" adds feature {k} ({:?}) to output {k} ({:?}): they must be the same quantity",
                        names.get(k),
                        out.name
                    ));
                }
            }
        }
        self.parsed_activations().map(|_| ())
    }
}

fn refuse() -> String {
    MissingMarkers::Refuse.name().into()
}

fn parse_activation(name: &str) -> Result<Activation, ()> {
    match name {
        "relu" => Ok(Activation::Relu),
        "identity" => Ok(Activation::Identity),
        _ => Err(()),
    }
}

/// A loaded, validated model. Cheap to clone (shared); `Send + Sync`: many threads may
/// share one model, each with its own [`Stream`].
#[derive(Debug, Clone)]
pub struct Model {
    inner: Arc<Inner>,
}

/// Largest model file [`Model::load`] reads, bytes. The thesis' largest network is ~0.5 MB;
/// 256 MiB leaves room for any MLP that could run in real time.
pub const MAX_MODEL_FILE_BYTES: u64 = 256 << 20;

/// The bytes of the regular file at `path`, refusing anything else (directory, pipe, device)
/// and anything larger than `limit` before reading it; a file that grows while being read is
/// cut at `limit + 1` bytes and refused.
pub fn read_bounded(path: &Path, limit: u64) -> std::io::Result<Vec<u8>> {
    use std::io::{Error as IoError, ErrorKind as IoKind, Read};
    let meta = std::fs::metadata(path)?;
    if !meta.is_file() {
        let what = if meta.is_dir() { "a directory" } else { "not a regular file (a pipe, socket or device)" };
        return Err(IoError::new(IoKind::InvalidInput, format!("it is {what}; expected a file")));
    }
    let too_large = |size: u64| {
        IoError::new(IoKind::InvalidData, format!("it is {size} bytes, more than the {limit} bytes accepted"))
    };
    if meta.len() > limit {
        return Err(too_large(meta.len()));
    }
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    std::fs::File::open(path)?.take(limit + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > limit {
        return Err(too_large(bytes.len() as u64));
    }
    Ok(bytes)
}

#[derive(Debug)]
struct Inner {
    card: ModelCard,
    feature_set: FeatureSet,
    mlp: Mlp,
    packed: PackedMlp,
}

impl Model {
    /// Loads and validates a `.safetensors` model file. Reads only a regular file of at most
    /// [`MAX_MODEL_FILE_BYTES`]: a directory, a named pipe or a device (`/dev/zero`) is refused
    /// before it is opened, so a wrong path never hangs or fills memory.
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let name = || path.display().to_string();
        let bytes = read_bounded(path, MAX_MODEL_FILE_BYTES).map_err(|source| Error::Io { path: name(), source })?;
        Self::from_bytes(&bytes).map_err(|e| Error::InModelFile { path: name(), source: Box::new(e) })
    }

    /// Validates a model held in memory (the bytes of a `.safetensors` file).
    pub fn from_bytes(bytes: &[u8]) -> Result<Self> {
        let (_, meta) = SafeTensors::read_metadata(bytes).map_err(|e| Error::Container(e.to_string()))?;
        let tensors = SafeTensors::deserialize(bytes).map_err(|e| Error::Container(e.to_string()))?;
        let json = meta.metadata().as_ref().and_then(|m| m.get(CARD_KEY)).ok_or_else(|| {
            Error::ModelCard(format!("the file's __metadata__ has no {CARD_KEY:?} key: not an ikid model file"))
        })?;
        let card = ModelCard::from_json(json)?;
        let set = FeatureSet::from_name(&card.feature_set)?;
        let n_in = card.window * set.feature_len();
        let n_layers = card.activations.len();

        let mut used = Vec::new();
        let mut get = |name: String, shape: &[Option<usize>]| -> Result<(Vec<usize>, Vec<f32>)> {
            let t = tensors.tensor(&name).map_err(|_| Error::MissingTensor { name: name.clone() })?;
            let v = read_f32(&name, &t, shape)?;
            used.push(name);
            Ok(v)
        };
        let vector = |(_, v): (Vec<usize>, Vec<f32>)| DVector::from_vec(v);

        let input = Affine {
            scale: vector(get("input.scale".into(), &[Some(n_in)])?),
            shift: vector(get("input.shift".into(), &[Some(n_in)])?),
        };
        let mut layers = Vec::with_capacity(n_layers);
        let mut width = n_in;
        for (k, act) in card.activations.iter().enumerate() {
            let expect_out = (k + 1 == n_layers).then_some(card.outputs.len());
            let (shape, w) = get(format!("layers.{k}.weight"), &[expect_out, Some(width)])?;
            let n_out = shape[0];
            let (_, b) = get(format!("layers.{k}.bias"), &[Some(n_out)])?;
            layers.push(Dense {
                weight: DMatrix::from_row_slice(n_out, width, &w),
                bias: DVector::from_vec(b),
                activation: parse_activation(act).expect("validated with the card"),
            });
            width = n_out;
        }
        let output = Affine {
            scale: vector(get("output.scale".into(), &[Some(width)])?),
            shift: vector(get("output.shift".into(), &[Some(width)])?),
        };
        if let Some(extra) = tensors.names().into_iter().find(|n| !used.iter().any(|u| u == *n)) {
            return Err(Error::UnexpectedTensor { name: extra.to_string() });
        }
        let mlp = Mlp::new(input, layers, output)?;
        Self::assemble(card, set, mlp)
    }

    /// Builds a model from a card and a network (e.g. random weights for benchmarks),
    /// checking that they fit each other.
    pub fn from_parts(card: ModelCard, mlp: Mlp) -> Result<Self> {
        // One validation path: write and re-read.
        Self::from_bytes(&to_bytes(&card, &mlp)?)
    }

    fn assemble(card: ModelCard, feature_set: FeatureSet, mlp: Mlp) -> Result<Self> {
        let packed = PackedMlp::new(&mlp);
        // Finite tensors can still overflow once the scaling is folded in.
        if let Some((layer, value)) = packed.first_non_finite() {
            return Err(Error::NonFiniteWeight {
                name: format!("layers.{layer}.weight (scaling folded in)"),
                index: 0,
                value,
            });
        }
        Ok(Model { inner: Arc::new(Inner { card, feature_set, mlp, packed }) })
    }

    /// The model as the bytes of a `.safetensors` file.
    pub fn to_bytes(&self) -> Vec<u8> {
        to_bytes(&self.inner.card, &self.inner.mlp).expect("a loaded model always serialises")
    }

    /// Writes the model file atomically (a temporary file renamed into place), so a failure
    /// never leaves a partial file at `path`.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        let io = |source| Error::Io { path: path.display().to_string(), source };
        let tmp = path.with_extension("safetensors.partial");
        std::fs::write(&tmp, self.to_bytes()).map_err(io)?;
        std::fs::rename(&tmp, path).map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            io(e)
        })
    }

    /// The model card.
    pub fn card(&self) -> &ModelCard {
        &self.inner.card
    }

    /// The network (plain nalgebra form, scaling not folded).
    pub fn mlp(&self) -> &Mlp {
        &self.inner.mlp
    }

    pub(crate) fn packed(&self) -> &PackedMlp {
        &self.inner.packed
    }

    /// How frames are turned into network inputs.
    pub fn feature_set(&self) -> FeatureSet {
        self.inner.feature_set
    }

    /// Frames per window.
    pub fn window(&self) -> usize {
        self.inner.card.window
    }

    /// Values per input frame.
    pub fn frame_len(&self) -> usize {
        self.inner.feature_set.frame_len()
    }

    /// Values per prediction.
    pub fn n_outputs(&self) -> usize {
        self.inner.card.outputs.len()
    }

    /// What a stream of this model does with a missing marker (the card's `missing_markers`).
    pub fn missing_markers(&self) -> MissingMarkers {
        MissingMarkers::from_name(&self.inner.card.missing_markers).expect("validated with the card")
    }

    /// True if each output adds the newest frame's same-named feature (the card's
    /// `output_offset`; see [`NEWEST_FEATURES`]).
    pub fn adds_newest_features(&self) -> bool {
        self.inner.card.output_offset.is_some()
    }

    /// Adds the newest frame's features of `window` (whole frames' features, oldest first) to
    /// `out` when the card asks for it (see [`adds_newest_features`](Self::adds_newest_features)).
    pub(crate) fn add_offset(&self, window: &[f32], out: &mut [f32]) {
        if self.adds_newest_features() {
            let newest = &window[window.len() - self.feature_set().feature_len()..];
            for (o, f) in out.iter_mut().zip(newest) {
                *o += f;
            }
        }
    }

    /// A new stream over this model (allocates its buffers once, here).
    pub fn stream(&self) -> Stream {
        Stream::new(self.clone())
    }

    /// Predictions for a recording of `n` frames: one per full window, `n - window + 1` rows
    /// (row `i` is the prediction for frame `i + window - 1`), or 0 if `n < window`.
    pub fn n_predictions(&self, n_frames: usize) -> usize {
        (n_frames + 1).saturating_sub(self.window())
    }

    /// Predicts a whole recording. `frames` holds `n` frames back to back; `out` receives
    /// [`n_predictions(n)`](Self::n_predictions) rows of [`n_outputs`](Self::n_outputs).
    /// Gives exactly the values a fresh [`Stream`] fed the same frames gives, missing markers
    /// included (filled in one causal pass first when the model's policy is
    /// [`MissingMarkers::Fill`]). Runs on up to
    /// [`std::thread::available_parallelism`] threads. Returns the number of rows.
    pub fn predict(&self, frames: &[f32], out: &mut [f32]) -> Result<usize> {
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
        self.predict_with_threads(frames, out, threads)
    }

    /// [`predict`](Self::predict) on at most `threads` threads (1 = the calling thread only).
    /// Every thread count gives bit-identical results.
    pub fn predict_with_threads(&self, frames: &[f32], out: &mut [f32], threads: usize) -> Result<usize> {
        let set = self.feature_set();
        let (fl, nf, w, no) = (set.frame_len(), set.feature_len(), self.window(), self.n_outputs());
        if !frames.len().is_multiple_of(fl) {
            return Err(Error::BadArgument {
                what: "frames",
                detail: format!("{} values is not a whole number of {fl}-value frames", frames.len()),
            });
        }
        let rows = self.n_predictions(frames.len() / fl);
        if out.len() != rows * no {
            return Err(Error::BadArgument {
                what: "output buffer",
                detail: format!("has {} values, expected {rows} rows × {no} = {}", out.len(), rows * no),
            });
        }
        let filled;
        let frames = if self.missing_markers() == MissingMarkers::Fill && frames.iter().any(|v| !v.is_finite()) {
            filled = fill_gaps(frames, false)?.0;
            &filled[..]
        } else {
            frames
        };
        // Below a few hundred rows a thread costs more than it saves.
        const MIN_ROWS_PER_THREAD: usize = 256;
        let threads = threads.clamp(1, rows.div_ceil(MIN_ROWS_PER_THREAD).max(1));
        // Features, then windows, in blocks that threads claim in turn: a thread slowed by
        // another process takes fewer blocks instead of holding the others up.
        const FRAMES_PER_BLOCK: usize = 512;
        const ROWS_PER_BLOCK: usize = 8 * BATCH;
        let mut features = vec![0f32; frames.len() / fl * nf];
        let blocks = frames.chunks(FRAMES_PER_BLOCK * fl).zip(features.chunks_mut(FRAMES_PER_BLOCK * nf));
        for_each_claimed(
            blocks,
            threads,
            || (),
            |(), b, (frames, features)| {
                for (i, (frame, row)) in frames.chunks_exact(fl).zip(features.chunks_exact_mut(nf)).enumerate() {
                    set.compute(frame, row, b * FRAMES_PER_BLOCK + i)?;
                }
                Ok(())
            },
        )?;
        let net = self.packed();
        // Windows of consecutive frames are contiguous slices of the feature rows.
        let window = |i: usize| &features[i * nf..(i + w) * nf];
        let scratch = || (net.scratch(), net.batch_scratch());
        for_each_claimed(
            out.chunks_mut(ROWS_PER_BLOCK * no),
            threads,
            scratch,
            |(scratch, batch_scratch), b, chunk| {
                let mut row = b * ROWS_PER_BLOCK;
                let mut groups = chunk.chunks_exact_mut(BATCH * no);
                for group in &mut groups {
                    let mut rows = group.chunks_exact_mut(no);
                    let outs = std::array::from_fn(|_| rows.next().expect("BATCH rows per group"));
                    net.forward_batch(std::array::from_fn(|s| window(row + s)), batch_scratch, outs);
                    for (s, out) in group.chunks_exact_mut(no).enumerate() {
                        self.add_offset(window(row + s), out);
                    }
                    row += BATCH;
                }
                for out in groups.into_remainder().chunks_exact_mut(no) {
                    net.forward(window(row), scratch, out);
                    self.add_offset(window(row), out);
                    row += 1;
                }
                Ok(())
            },
        )?;
        if let Some(i) = out.iter().position(|v| !v.is_finite()) {
            // Output row r is the prediction for frame r + window - 1.
            return Err(Error::NonFiniteOutput { frame: i / no + w - 1, value: out[i] });
        }
        Ok(rows)
    }
}

/// Runs `work` on every item on up to `threads` threads (the calling one included), each
/// thread claiming the next item in order and keeping its own `state`. Returns the error of the
/// earliest failing item: every item before it was claimed and run to the end.
fn for_each_claimed<T: Send, S>(
    items: impl Iterator<Item = T> + Send,
    threads: usize,
    state: impl Fn() -> S + Sync,
    work: impl Fn(&mut S, usize, T) -> Result<()> + Sync,
) -> Result<()> {
    let queue = Mutex::new(items.enumerate());
    let worker = || -> Option<(usize, Error)> {
        let mut state = state();
        loop {
            // Only `next` runs under the lock, and it does not panic: no poisoning to handle.
            let (i, item) = queue.lock().unwrap_or_else(PoisonError::into_inner).next()?;
            if let Err(e) = work(&mut state, i, item) {
                return Some((i, e));
            }
        }
    };
    let failed = if threads <= 1 {
        worker()
    } else {
        std::thread::scope(|scope| {
            let others: Vec<_> = (1..threads).map(|_| scope.spawn(worker)).collect();
            let mine = worker();
            let others = others.into_iter().map(|h| h.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic)));
            others.chain([mine]).flatten().min_by_key(|&(i, _)| i)
        })
    };
    failed.map_or(Ok(()), |(_, e)| Err(e))
}

/// Runs a fresh [`GapFiller`] over a whole recording of marker frames: the frames with each
/// fillable missing marker filled, and per frame the bit mask of markers filled. A frame that
/// cannot be filled stops the run with its error, or with `keep_unfillable` stays missing
/// (mask 0; markers found to have jumped are set missing).
pub fn fill_gaps(frames: &[f32], keep_unfillable: bool) -> Result<(Vec<f32>, Vec<u8>)> {
    if !frames.len().is_multiple_of(MARKER_FRAME_LEN) {
        return Err(Error::BadArgument {
            what: "frames",
            detail: format!("{} values is not a whole number of {MARKER_FRAME_LEN}-value marker frames", frames.len()),
        });
    }
    let mut filled = frames.to_vec();
    let mut filler = GapFiller::new();
    let masks = filled
        .chunks_exact_mut(MARKER_FRAME_LEN)
        .enumerate()
        .map(|(i, f)| {
            match filler.fill(f, i) {
                Err(Error::MissingMarkers { .. }) if keep_unfillable => Ok(0),
                // Markers that jumped and could not be replaced become missing, never kept (a
                // refused frame leaves the filler as it was, so it names the same markers).
                Err(Error::OutlierMarker { .. }) if keep_unfillable => {
                    let outliers = filler.outliers(f);
                    for m in (0..6).filter(|m| outliers & (1 << m) != 0) {
                        f[3 * m..3 * m + 3].fill(f32::NAN);
                    }
                    Ok(0)
                }
                other => other,
            }
        })
        .collect::<Result<_>>()?;
    Ok((filled, masks))
}

fn read_f32(name: &str, t: &TensorView<'_>, expected: &[Option<usize>]) -> Result<(Vec<usize>, Vec<f32>)> {
    if t.dtype() != Dtype::F32 {
        return Err(Error::WrongDtype { name: name.into(), dtype: format!("{:?}", t.dtype()) });
    }
    let shape = t.shape().to_vec();
    let fits =
        shape.len() == expected.len() && shape.iter().zip(expected).all(|(s, e)| e.is_none_or(|e| *s == e) && *s > 0);
    if !fits {
        return Err(Error::ShapeMismatch {
            name: name.into(),
            found: shape,
            expected: expected.iter().map(|e| e.unwrap_or(0)).collect(),
        });
    }
    // `fs::read` gives no alignment guarantee: decode each value (weights are copied once).
    let values: Vec<f32> = t.data().chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
    if let Some(index) = values.iter().position(|v| !v.is_finite()) {
        return Err(Error::NonFiniteWeight { name: name.into(), index, value: values[index] });
    }
    Ok((shape, values))
}

/// Serialises a card and network to `.safetensors` bytes (the one writer of the format).
pub fn to_bytes(card: &ModelCard, mlp: &Mlp) -> Result<Vec<u8>> {
    let row_major = |m: &DMatrix<f32>| m.transpose().as_slice().to_vec();
    let mut tensors: Vec<(String, Vec<usize>, Vec<f32>)> = vec![
        ("input.scale".into(), vec![mlp.input.len()], mlp.input.scale.as_slice().to_vec()),
        ("input.shift".into(), vec![mlp.input.len()], mlp.input.shift.as_slice().to_vec()),
        ("output.scale".into(), vec![mlp.output.len()], mlp.output.scale.as_slice().to_vec()),
        ("output.shift".into(), vec![mlp.output.len()], mlp.output.shift.as_slice().to_vec()),
    ];
    for (k, l) in mlp.layers.iter().enumerate() {
        tensors.push((format!("layers.{k}.weight"), vec![l.weight.nrows(), l.weight.ncols()], row_major(&l.weight)));
        tensors.push((format!("layers.{k}.bias"), vec![l.bias.len()], l.bias.as_slice().to_vec()));
    }
    let bytes: Vec<(String, Vec<usize>, Vec<u8>)> =
        tensors.into_iter().map(|(n, s, v)| (n, s, v.iter().flat_map(|x| x.to_le_bytes()).collect())).collect();
    let views = bytes
        .iter()
        .map(|(n, s, b)| {
            Ok((n.as_str(), TensorView::new(Dtype::F32, s.clone(), b).map_err(|e| Error::Container(e.to_string()))?))
        })
        .collect::<Result<Vec<_>>>()?;
    let meta = HashMap::from([(CARD_KEY.to_string(), card.to_json())]);
    safetensors::serialize(views, Some(meta)).map_err(|e| Error::Container(e.to_string()))
}
