//! The model card: the JSON under the file's metadata key [`CARD_KEY`] that says what a
//! network reads and gives, and its checks.

use super::uncertainty::SdCard;
use crate::body::MARKER_FRAME_LEN;
use crate::error::{Error, Result};
use crate::features::FeatureSet;
use crate::gaps::MissingMarkers;
use crate::net::Activation;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

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

/// The range of each of a list of values on the training data.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Bounds {
    /// Smallest value seen, per value.
    pub min: Vec<f64>,
    /// Largest value seen, per value.
    pub max: Vec<f64>,
}

/// Where a model knows what it is doing: the ranges of its per-frame features and of its
/// outputs on its training data. A frame outside it is flagged
/// ([`status::OUTSIDE_TRAINING`](crate::status::OUTSIDE_TRAINING)), an output far outside it
/// is [`status::IMPLAUSIBLE`](crate::status::IMPLAUSIBLE) (see [`Model::frame_status`](crate::Model::frame_status)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Envelope {
    /// Per feature of one frame (the feature set's `feature_names`).
    pub inputs: Bounds,
    /// Per output.
    pub outputs: Bounds,
    /// Per feature, how much its mean changes from the older half of a training window to the
    /// newer half (halves of `window / 2` frames), at the 99.9th percentile of the training
    /// windows: how fast the model learned each feature to move, noise averaged out. A
    /// correcting model (`output_offset`) does not correct a window that changes faster (see
    /// [`crate::net::NewestFeatures`]). Absent in older files.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub window_change: Option<Vec<f64>>,
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
    /// The training data's ranges (written by training); absent in older files, whose frames
    /// are then never flagged as outside training.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub envelope: Option<Envelope>,
    /// SHA-256 of the tensors (lowercase hex; see [`tensor_sha256`](super::tensor_sha256)),
    /// written by the writer and verified by the loader. Absent in files written before it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tensor_sha256: Option<String>,
    /// How the outputs' per-frame standard deviations are computed ([`SdCard`]); absent: the
    /// model gives none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncertainty: Option<SdCard>,
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
            envelope: None,
            tensor_sha256: None,
            uncertainty: None,
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
        if let Some(envelope) = &self.envelope {
            for (what, bounds, n) in
                [("inputs", &envelope.inputs, set.feature_len()), ("outputs", &envelope.outputs, self.outputs.len())]
            {
                if bounds.min.len() != n || bounds.max.len() != n {
                    return bad(format!(
                        "field \"envelope\".{what} has {} minima and {} maxima, expected {n} each",
                        bounds.min.len(),
                        bounds.max.len()
                    ));
                }
                if let Some(i) = (0..n).find(|&i| !(bounds.min[i].is_finite() && bounds.max[i] >= bounds.min[i])) {
                    return bad(format!(
                        "field \"envelope\".{what}[{i}] is [{}, {}], expected finite min <= max",
                        bounds.min[i], bounds.max[i]
                    ));
                }
                if let Some(i) = (0..n).find(|&i| !bounds.max[i].is_finite()) {
                    return bad(format!("field \"envelope\".{what}[{i}] has a non-finite max"));
                }
            }
            if let Some(change) = &envelope.window_change {
                if change.len() != set.feature_len() {
                    return bad(format!(
                        "field \"envelope\".window_change has {} values, expected {} (one per feature)",
                        change.len(),
                        set.feature_len()
                    ));
                }
                if let Some(i) = change.iter().position(|v| !(v.is_finite() && *v >= 0.0)) {
                    return bad(format!(
                        "field \"envelope\".window_change[{i}] is {}, expected a finite change >= 0",
                        change[i]
                    ));
                }
            }
        }
        if let Some(sum) = &self.tensor_sha256
            && !(sum.len() == 64 && sum.bytes().all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b)))
        {
            return bad(format!("field \"tensor_sha256\" is {sum:?}, expected 64 lowercase hex digits"));
        }
        if let Some(sd) = &self.uncertainty {
            sd.validate(self.outputs.len(), &self.feature_set, self.output_offset.is_some())?;
        }
        self.parsed_activations().map(|_| ())
    }
}

fn refuse() -> String {
    MissingMarkers::Refuse.name().into()
}

pub(super) fn parse_activation(name: &str) -> Result<Activation, ()> {
    match name {
        "relu" => Ok(Activation::Relu),
        "identity" => Ok(Activation::Identity),
        _ => Err(()),
    }
}
