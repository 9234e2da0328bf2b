//! The loaded model: its card, the network in both forms (the nalgebra oracle and the
//! [`Network`] it runs: packed kernel, output offset, finiteness check), shared cheaply between
//! streams and threads.

use super::card::{Bounds, Envelope, ModelCard};
use super::file;
use crate::body::N_COORDINATES;
use crate::error::{Error, Result};
use crate::features::FeatureSet;
use crate::gaps::MissingMarkers;
use crate::net::{Mlp, Network, NewestFeatures};
use crate::status;
use std::path::Path;
use std::sync::Arc;

/// A loaded, validated model. Cheap to clone (shared); `Send + Sync`: many threads may
/// share one model, each with its own [`Stream`](crate::Stream).
#[derive(Debug, Clone)]
pub struct Model {
    inner: Arc<Inner>,
}

#[derive(Debug)]
struct Inner {
    card: ModelCard,
    feature_set: FeatureSet,
    mlp: Mlp,
    net: Network,
    limits: Option<Limits>,
    /// The outputs are the wrist angles in coordinate order, in radians (the IK family).
    outputs_are_angles: bool,
}

/// How far past its training range a feature may go, in widths of that range, before the
/// frame is flagged [`status::OUTSIDE_TRAINING`]: the training data's extremes are samples,
/// not walls.
pub const ENVELOPE_MARGIN: f64 = 0.1;
/// How far past its training range the mean of a window's features may go, in widths of that
/// range, before a model that corrects the newest frame's features stops correcting them (see
/// [`NewestFeatures`]): 2 %, the margin at which simulated trials' own extremes stop
/// triggering it.
pub const CORRECTION_MARGIN: f64 = 0.02;
/// How much faster than its card's `window_change` (the speed of all but the fastest 0.1 % of
/// its training windows) a correcting model's window may move before it stops correcting it
/// (see [`NewestFeatures`]): 10 %.
pub const CHANGE_MARGIN: f64 = 0.1;
/// How far past its training range an output may go, in widths of that range, before it is
/// [`status::IMPLAUSIBLE`]: twice the range the model ever learned to give.
pub const IMPLAUSIBLE_MARGIN: f64 = 1.0;

/// The card's envelope widened by the margins, as f32 to compare with the stream's values.
#[derive(Debug)]
struct Limits {
    input: (Vec<f32>, Vec<f32>),
    output: (Vec<f32>, Vec<f32>),
}

/// `b` widened on each side by `margin` of its width (and a hair more, for rounding), as f32.
fn widen(b: &Bounds, margin: f64) -> (Vec<f32>, Vec<f32>) {
    let pad = |i: usize| margin * (b.max[i] - b.min[i]) + 1e-6 * b.min[i].abs().max(b.max[i].abs()).max(1.0);
    let lo = (0..b.min.len()).map(|i| (b.min[i] - pad(i)) as f32).collect();
    let hi = (0..b.max.len()).map(|i| (b.max[i] + pad(i)) as f32).collect();
    (lo, hi)
}

impl Limits {
    fn new(envelope: &Envelope) -> Self {
        Limits { input: widen(&envelope.inputs, ENVELOPE_MARGIN), output: widen(&envelope.outputs, IMPLAUSIBLE_MARGIN) }
    }
}

fn outside(values: &[f32], (lo, hi): &(Vec<f32>, Vec<f32>)) -> bool {
    values.iter().zip(lo.iter().zip(hi)).any(|(v, (l, h))| !(v >= l && v <= h))
}

impl Model {
    /// Loads and validates a `.safetensors` model file. Reads only a regular file of at most
    /// [`MAX_MODEL_FILE_BYTES`](file::MAX_MODEL_FILE_BYTES): a directory, a named pipe or a device (`/dev/zero`) is refused
    /// before it is opened, so a wrong path never hangs or fills memory. The card's checksum of
    /// the weights is verified; a file without one is refused ([`Error::MissingChecksum`]; see
    /// [`load_allowing_unchecked`](Self::load_allowing_unchecked)).
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        Self::load_with(path.as_ref(), false)
    }

    /// [`load`](Self::load), but a file written before model files carried a checksum (its
    /// card has no `tensor_sha256`) is accepted: the caller's explicit opt-in, since nothing
    /// then tells a corrupted copy from a good one ([`has_checksum`](Self::has_checksum) is
    /// false; warn the user). A file that has a checksum is still verified against it.
    pub fn load_allowing_unchecked(path: impl AsRef<Path>) -> Result<Self> {
        Self::load_with(path.as_ref(), true)
    }

    fn load_with(path: &Path, allow_unchecked: bool) -> Result<Self> {
        let name = || path.display().to_string();
        let bytes = file::read_bounded(path, file::MAX_MODEL_FILE_BYTES)
            .map_err(|source| Error::Io { path: name(), source })?;
        Self::parse_bytes(&bytes, allow_unchecked).map_err(|e| Error::InModelFile { path: name(), source: Box::new(e) })
    }

    /// Validates a model held in memory (the bytes of a `.safetensors` file), checksum
    /// required as by [`load`](Self::load).
    pub fn from_bytes(bytes: &[u8]) -> Result<Self> {
        Self::parse_bytes(bytes, false)
    }

    /// [`from_bytes`](Self::from_bytes) accepting a card without a checksum, as
    /// [`load_allowing_unchecked`](Self::load_allowing_unchecked) does.
    pub fn from_bytes_allowing_unchecked(bytes: &[u8]) -> Result<Self> {
        Self::parse_bytes(bytes, true)
    }

    fn parse_bytes(bytes: &[u8], allow_unchecked: bool) -> Result<Self> {
        let (card, set, mlp) = file::parse(bytes)?;
        let model = Self::assemble(card, set, mlp)?;
        // Last, so a file that is wrong in itself is named for that first.
        if !allow_unchecked && !model.has_checksum() {
            return Err(Error::MissingChecksum);
        }
        Ok(model)
    }

    /// Builds a model from a card and a network (e.g. random weights for benchmarks),
    /// checking that they fit each other.
    pub fn from_parts(card: ModelCard, mlp: Mlp) -> Result<Self> {
        // One validation path: write and re-read.
        Self::from_bytes(&file::to_bytes(&card, &mlp)?)
    }

    fn assemble(card: ModelCard, feature_set: FeatureSet, mlp: Mlp) -> Result<Self> {
        // The card's output offset: the newest frame's features, corrected only inside the
        // training range widened by CORRECTION_MARGIN (see `NewestFeatures`).
        let offset = card.output_offset.is_some().then(|| NewestFeatures {
            features: feature_set.feature_len(),
            trained: card.envelope.as_ref().map(|e| widen(&e.inputs, CORRECTION_MARGIN)),
            change: card
                .envelope
                .as_ref()
                .and_then(|e| e.window_change.as_ref())
                .map(|s| s.iter().map(|v| (v * (1.0 + CHANGE_MARGIN)) as f32).collect()),
        });
        // Finite tensors can still overflow once the scaling is folded in: refused here.
        let net = Network::new(&mlp, offset)?;
        let limits = card.envelope.as_ref().map(Limits::new);
        // Named as the coordinates and in radians: torque models name theirs alike, in N*m.
        let outputs_are_angles = card
            .outputs
            .iter()
            .map(|o| (o.name.as_str(), o.unit.as_str()))
            .eq(crate::body::COORDINATES.iter().map(|c| (c.name, "rad")));
        Ok(Model { inner: Arc::new(Inner { card, feature_set, mlp, net, limits, outputs_are_angles }) })
    }

    /// This model with its card's `uncertainty` replaced by `uncertainty` (`None` removes it):
    /// the per-frame standard deviations' coefficients ([`SdCard`](super::SdCard)), checked
    /// as a loaded card is. The tensors, and so their checksum, are unchanged.
    pub fn with_uncertainty(&self, uncertainty: Option<super::SdCard>) -> Result<Self> {
        let card = ModelCard { uncertainty, ..self.inner.card.clone() };
        Self::from_parts(card, self.inner.mlp.clone())
    }

    /// The model as the bytes of a `.safetensors` file.
    pub fn to_bytes(&self) -> Vec<u8> {
        file::to_bytes(&self.inner.card, &self.inner.mlp).expect("a loaded model always serialises")
    }

    /// Writes the model file atomically (a temporary file renamed into place), so a failure
    /// never leaves a partial file at `path`.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        let io = |source| Error::Io { path: path.display().to_string(), source };
        let tmp = path.with_extension("safetensors.partial");
        // The bytes must be on the disk before the rename makes them the file (a full disk
        // or a power cut must not leave a truncated model under the final name).
        let written = std::fs::File::create(&tmp).and_then(|mut f| {
            std::io::Write::write_all(&mut f, &self.to_bytes())?;
            f.sync_all()
        });
        if let Err(e) = written {
            let _ = std::fs::remove_file(&tmp);
            return Err(io(e));
        }
        std::fs::rename(&tmp, path).map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            io(e)
        })
    }

    /// [`status`] bits for one output: [`status::OUTSIDE_TRAINING`] if a feature of the newest
    /// frame (`newest`, [`FeatureSet::feature_len`] values) lies beyond the card's envelope by
    /// more than [`ENVELOPE_MARGIN`] of its range, [`status::IMPLAUSIBLE`] if an output (`outputs`)
    /// lies beyond it by more than [`IMPLAUSIBLE_MARGIN`], and [`status::TURNED_OVER`] (with
    /// `IMPLAUSIBLE`) if the newest frame's angles (a feature set that
    /// [leads with them](FeatureSet::leads_with_angles)) or the outputs (the IK family's) turn
    /// the hand past [`status::TURNED_OVER_DEG`] (a [`Stream`](crate::Stream) also keeps the
    /// flag until the hand reads upright again, [`status::TurnedOverWatch`]). Allocation-free,
    /// a few dozen comparisons: cheap enough for every push.
    pub fn frame_status(&self, newest: &[f32], outputs: &[f32]) -> u16 {
        self.frame_status_of(newest, outputs, true)
    }

    /// [`frame_status`](Self::frame_status), the newest frame's angles left out unless
    /// `check_newest_angles` (a [`Stream`](crate::Stream) watches them itself).
    pub(crate) fn frame_status_of(&self, newest: &[f32], outputs: &[f32], check_newest_angles: bool) -> u16 {
        let mut bits = 0;
        let turned = |q: &[f32]| status::turned_over(&std::array::from_fn(|c| f64::from(q[c])));
        let newest_angles = check_newest_angles && self.inner.feature_set.leads_with_angles();
        if (newest_angles && newest.len() >= N_COORDINATES && turned(newest))
            || (self.inner.outputs_are_angles && outputs.len() == N_COORDINATES && turned(outputs))
        {
            bits |= status::TURNED_OVER | status::IMPLAUSIBLE;
        }
        let Some(limits) = &self.inner.limits else { return bits };
        if outside(newest, &limits.input) {
            bits |= status::OUTSIDE_TRAINING;
        }
        if outside(outputs, &limits.output) {
            bits |= status::IMPLAUSIBLE;
        }
        bits
    }

    /// True if the file carried a checksum of its tensors (verified when it was loaded); files
    /// written before checksums existed have none.
    pub fn has_checksum(&self) -> bool {
        self.inner.card.tensor_sha256.is_some()
    }

    /// The model card.
    pub fn card(&self) -> &ModelCard {
        &self.inner.card
    }

    /// The network (plain nalgebra form, scaling not folded).
    pub fn mlp(&self) -> &Mlp {
        &self.inner.mlp
    }

    /// The network this model runs (packed kernel, output offset, finiteness check): what a
    /// stream and [`predict`](Self::predict) call.
    pub fn net(&self) -> &Network {
        &self.inner.net
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
    /// `output_offset`; see [`NEWEST_FEATURES`](super::NEWEST_FEATURES)).
    pub fn adds_newest_features(&self) -> bool {
        self.inner.card.output_offset.is_some()
    }
}
