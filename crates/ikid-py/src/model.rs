//! `Model` and `Stream`: thin wrappers over the core's, NumPy in and out.

use crate::conv::{calibration_arg, number_arg, with_floats, with_frame};
use crate::errors::{IntoPy, input};
use ikid::ModelCard;
use ikid::net::{Affine, Dense, Mlp};
use nalgebra::{DMatrix, DVector};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyBytes;
use std::path::PathBuf;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Model>()?;
    m.add_class::<Stream>()?;
    m.add_function(wrap_pyfunction!(build_model, m)?)?;
    Ok(())
}

/// A loaded, validated model. Immutable; share it between threads freely.
#[pyclass(module = "ikid", frozen)]
pub struct Model {
    pub(crate) inner: ikid::Model,
}

#[pymethods]
impl Model {
    /// Loads and validates a `.safetensors` model file, verifying its checksum; a file
    /// without one (`has_checksum` false) is refused unless `allow_unchecked`.
    #[staticmethod]
    #[pyo3(signature = (path, *, allow_unchecked = false))]
    fn load(py: Python<'_>, path: PathBuf, allow_unchecked: bool) -> PyResult<Self> {
        let inner = py
            .detach(|| {
                if allow_unchecked { ikid::Model::load_allowing_unchecked(&path) } else { ikid::Model::load(&path) }
            })
            .py_err()?;
        Ok(Model { inner })
    }

    /// Validates a model from the bytes of a `.safetensors` file (checksum as for `load`).
    #[staticmethod]
    #[pyo3(signature = (data, *, allow_unchecked = false))]
    fn from_bytes(data: &[u8], allow_unchecked: bool) -> PyResult<Self> {
        let inner = if allow_unchecked {
            ikid::Model::from_bytes_allowing_unchecked(data)
        } else {
            ikid::Model::from_bytes(data)
        };
        Ok(Model { inner: inner.py_err()? })
    }

    /// The model card as a dict.
    #[getter]
    fn card<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        py.import("json")?.call_method1("loads", (self.inner.card().to_json(),))
    }

    #[getter]
    fn name(&self) -> &str {
        &self.inner.card().name
    }

    #[getter]
    fn task(&self) -> &str {
        &self.inner.card().task
    }

    #[getter]
    fn feature_set(&self) -> &'static str {
        self.inner.feature_set().name()
    }

    /// What one input frame holds: "markers", "joint_state" or "tracker_state".
    #[getter]
    fn frame_kind(&self) -> &'static str {
        self.inner.feature_set().frame_kind().name()
    }

    #[getter]
    fn window(&self) -> usize {
        self.inner.window()
    }

    #[getter]
    fn frame_len(&self) -> usize {
        self.inner.frame_len()
    }

    #[getter]
    fn frame_names(&self) -> Vec<String> {
        self.inner.feature_set().frame_names()
    }

    #[getter]
    fn n_outputs(&self) -> usize {
        self.inner.n_outputs()
    }

    #[getter]
    fn output_names(&self) -> Vec<String> {
        self.inner.card().outputs.iter().map(|o| o.name.clone()).collect()
    }

    #[getter]
    fn output_units(&self) -> Vec<String> {
        self.inner.card().outputs.iter().map(|o| o.unit.clone()).collect()
    }

    #[getter]
    fn frame_rate_hz(&self) -> f64 {
        self.inner.card().frame_rate_hz
    }

    #[getter]
    fn layer_widths(&self) -> Vec<usize> {
        self.inner.mlp().widths()
    }

    /// True if the file carried a checksum of its tensors (verified on load); False for files
    /// written before checksums existed, loaded with `allow_unchecked=True`.
    #[getter]
    fn has_checksum(&self) -> bool {
        self.inner.has_checksum()
    }

    /// `ikid.FRAME_STATUS` bits for outputs `(n, n_outputs)` given for frames whose newest
    /// features are `features` `(n, feature_len)`: outside the training envelope, implausible.
    /// All zero for a model without an envelope.
    fn frame_status<'py>(
        &self,
        py: Python<'py>,
        features: &Bound<'py, PyAny>,
        outputs: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<u16>>> {
        let (nf, no) = (self.inner.feature_set().feature_len(), self.inner.n_outputs());
        let features: Vec<f32> = with_floats(features, "features", 2, |v, shape| {
            if shape[1] != nf {
                return Err(input(format!("features: {} columns, the model's feature set has {nf}", shape[1])));
            }
            Ok(v.to_vec())
        })?;
        let outputs: Vec<f32> = with_floats(outputs, "outputs", 2, |v, shape| {
            if shape[1] != no {
                return Err(input(format!("outputs: {} columns, the model has {no} outputs", shape[1])));
            }
            Ok(v.to_vec())
        })?;
        if features.len() / nf != outputs.len() / no {
            return Err(input(format!(
                "features has {} rows, outputs {}: one row of each per frame",
                features.len() / nf,
                outputs.len() / no
            )));
        }
        let bits: Vec<u16> = features
            .chunks_exact(nf)
            .zip(outputs.chunks_exact(no))
            .map(|(f, o)| self.inner.frame_status(f, o))
            .collect();
        Ok(bits.into_pyarray(py))
    }

    /// Predictions for a whole recording `(n, frame_len)`: `(n - window + 1, n_outputs)`,
    /// row `i` for frame `i + window - 1`. Runs on `threads` threads (default: all cores;
    /// every count gives bit-identical results). Releases the GIL.
    ///
    /// The network's raw outputs: no check that the markers sit where the model reads them
    /// (uncalibrated real markers read 50-170° off) and no status per row. For a recording as
    /// `ikid ik` runs it — checked, each row flagged, an implausible one not given — use
    /// `ikid.pipeline.run_model`; `frame_status` gives the envelope bits of these rows.
    #[pyo3(signature = (frames, threads = None))]
    fn predict<'py>(
        &self,
        py: Python<'py>,
        frames: &Bound<'py, PyAny>,
        threads: Option<usize>,
    ) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let (fl, no) = (self.inner.frame_len(), self.inner.n_outputs());
        with_floats(frames, "frames", 2, |values, shape| {
            if shape[1] != fl {
                return Err(input(format!(
                    "frames: {} columns, the model's feature set {:?} takes {fl} per frame",
                    shape[1],
                    self.inner.feature_set().name()
                )));
            }
            let rows = self.inner.n_predictions(shape[0]);
            let mut out = vec![0f32; rows * no];
            py.detach(|| match threads {
                None => self.inner.predict(values, &mut out),
                Some(t) => self.inner.predict_with_threads(values, &mut out, t.max(1)),
            })
            .py_err()?;
            out.into_pyarray(py).reshape([rows, no])
        })
    }

    /// What a stream does with a missing marker by default: `"refuse"` or `"fill"` (the card's).
    #[getter]
    fn missing_markers(&self) -> &'static str {
        self.inner.missing_markers().name()
    }

    /// A new frame-by-frame stream over this model; `missing_markers` (`"refuse"` or
    /// `"fill"`) overrides the card's policy; `calibration` (a `Calibration`, or the path of its file) moves each
    /// frame's markers to the body model's placement before the network sees them;
    /// `early_outputs` (correcting models only): the per-frame solution, flagged `per_frame`,
    /// for every frame while the window fills; `up`: the lab's up direction in the frames'
    /// coordinates, an axis (`"+y"`, ikid's lab, by default; `"+z"` for Vicon and Qualisys
    /// labs) or three numbers: a model that reads gravity (`wrist-chain`) depends on it.
    /// Without a calibration the markers are read at the body model's placement, unchecked:
    /// `ikid.check_default_placement(frames)` checks them, as `ikid stream` does first.
    #[pyo3(signature = (missing_markers = None, calibration = None, early_outputs = false, up = None))]
    fn stream(
        &self,
        missing_markers: Option<&str>,
        calibration: Option<&Bound<'_, PyAny>>,
        early_outputs: bool,
        up: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Stream> {
        let mut inner = self.inner.stream();
        if let Some(up) = up {
            inner.set_lab_up(crate::tracker::lab_up(up)?).py_err()?;
        }
        inner.set_early_outputs(early_outputs).py_err()?;
        if let Some(name) = missing_markers {
            let policy = ikid::MissingMarkers::from_name(name).map_err(|e| input(e.to_string()))?;
            inner.set_missing_markers(policy).py_err()?;
        }
        if let Some(c) = calibration {
            inner.set_calibration(Some(calibration_arg(c, "calibration")?.get().inner)).py_err()?;
        }
        Ok(Stream { inner })
    }

    /// This model with its card's `uncertainty` (the per-frame standard deviations'
    /// coefficients, JSON; `None` removes it), checked as a loaded card is; tensors and their
    /// checksum unchanged. `save` it to keep it.
    #[pyo3(signature = (uncertainty))]
    fn with_uncertainty(&self, uncertainty: Option<&str>) -> PyResult<Self> {
        let card = match uncertainty {
            None => None,
            Some(json) => Some(ikid::model::SdCard::from_json(json).py_err()?),
        };
        Ok(Model { inner: self.inner.with_uncertainty(card).py_err()? })
    }

    /// Writes the model file (atomically: never a partial file).
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        py.detach(|| self.inner.save(&path)).py_err()
    }

    /// The bytes of the model's `.safetensors` file.
    fn to_bytes<'py>(&self, py: Python<'py>) -> Bound<'py, PyBytes> {
        PyBytes::new(py, &self.inner.to_bytes())
    }

    fn __repr__(&self) -> String {
        let c = self.inner.card();
        format!(
            "Model(name={:?}, task={:?}, feature_set={:?}, window={}, layers={:?}, outputs={:?})",
            c.name,
            c.task,
            c.feature_set,
            c.window,
            self.inner.mlp().widths(),
            c.outputs.iter().map(|o| o.name.as_str()).collect::<Vec<_>>()
        )
    }
}

/// Two arrays (`Stream.sd_terms`).
type Pair<'py> = (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>);

/// A causal frame-by-frame stream. One thread at a time.
#[pyclass(module = "ikid")]
pub struct Stream {
    inner: ikid::Stream,
}

#[pymethods]
impl Stream {
    /// Pushes one frame; returns `None` until the window is full, then the prediction for
    /// this frame (float32 array of `n_outputs`). A refused frame leaves the window as it was.
    /// With `time` (seconds), a gap of more than 1.5 frame periods (up to 1 s) restarts the
    /// window; a stamp that jumps (further ahead, or not after the last) is refused alone
    /// unless three in a row continue from each other (`time_reanchors`). Holds the GIL (a push takes microseconds);
    /// `push_many` releases it.
    #[pyo3(signature = (frame, time = None))]
    fn push<'py>(
        &mut self,
        py: Python<'py>,
        frame: &Bound<'py, PyAny>,
        time: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Option<Bound<'py, PyArray1<f32>>>> {
        let time = time.map(|t| number_arg(t, "time", "the frame's time in seconds")).transpose()?;
        let stream = &mut self.inner;
        with_frame(frame, |values| {
            // The GIL stays held: releasing and re-taking it costs more than the few
            // microseconds of work (measured: +0.3–0.8 µs per push on the thesis net).
            let out = match time {
                None => stream.push(values),
                Some(t) => stream.push_at(t, values),
            };
            let produced = out.map(|o| o.is_some()).py_err()?;
            Ok(produced.then(|| PyArray1::from_slice(py, stream.output())))
        })
    }

    /// Times `push(..., time=)` restarted the window after a gap in time.
    #[getter]
    fn gap_restarts(&self) -> u64 {
        self.inner.gap_restarts()
    }

    /// Times `push(..., time=)` took a jumped clock as the source's new one (three stamps in
    /// a row that continue from each other after a jump).
    #[getter]
    fn time_reanchors(&self) -> u64 {
        self.inner.time_reanchors()
    }

    /// Times the gap filler took a new place as real after three frames in a row that were
    /// refused for moving too far (a stall, or frames lost without time stamps).
    #[getter]
    fn reanchors(&self) -> u64 {
        self.inner.gap_filler().reanchors()
    }

    /// Pushes a block of frames `(n, frame_len)`; returns the predictions of the frames that
    /// completed a window, `(k, n_outputs)`. Stops at the first refused frame: its error is
    /// raised, the frames before it stay pushed and their predictions are the error's
    /// `outputs` `(j, n_outputs)`. Releases the GIL.
    fn push_many<'py>(&mut self, py: Python<'py>, frames: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let stream = &mut self.inner;
        let (fl, no) = (stream.model().frame_len(), stream.model().n_outputs());
        with_floats(frames, "frames", 2, |values, shape| {
            if shape[1] != fl {
                return Err(input(format!("frames: {} columns, the model takes {fl} per frame", shape[1])));
            }
            let mut out = vec![0f32; stream.rows_for(shape[0]) * no];
            match py.detach(|| stream.push_many(values, &mut out)) {
                Ok(rows) => out.into_pyarray(py).reshape([rows, no]),
                Err(e) => {
                    // The frames before the refused one stay pushed: their rows go with the error.
                    let rows = stream.rows_before_refusal();
                    out.truncate(rows * no);
                    let err = crate::errors::to_py(e);
                    err.value(py).setattr("outputs", out.into_pyarray(py).reshape([rows, no])?)?;
                    Err(err)
                }
            }
        })
    }

    /// Forgets every frame held.
    fn reset(&mut self) {
        self.inner.reset();
    }

    /// Frames held (up to the window length).
    #[getter]
    fn filled(&self) -> usize {
        self.inner.filled()
    }

    /// The missing-marker policy this stream applies: `"refuse"` or `"fill"`.
    #[getter]
    fn missing_markers(&self) -> &'static str {
        self.inner.missing_markers().name()
    }

    /// `ikid.FRAME_STATUS` bits of the last output: a filled marker, inputs outside the model's
    /// training envelope, an implausible output (write it as missing).
    #[getter]
    fn status(&self) -> u16 {
        self.inner.status()
    }

    /// Names of the markers filled in the last accepted frame (empty when it was complete):
    /// the flag on an output that rests on filled positions.
    #[getter]
    fn filled_markers(&self) -> Vec<&'static str> {
        ikid::body::marker_names(self.inner.filled_markers()).collect()
    }

    /// The model this stream runs.
    #[getter]
    fn model(&self) -> Model {
        Model { inner: self.inner.model().clone() }
    }

    /// Standard deviation of each output of the last push (float64, output units), or `None`:
    /// the model's card has no `uncertainty`, the push gave no output, or too few frames came
    /// since the window (re)started to tell the markers' noise.
    #[getter]
    fn output_sd<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray1<f64>>> {
        self.inner.output_sd().map(|sd| PyArray1::from_slice(py, sd))
    }

    /// The running means behind `output_sd`: `(angle noise variances (3,), mean squared
    /// corrections (3,))`, rad², for studies fitting a card's `uncertainty`; `None` for a model
    /// that does not read per-frame angles, or before enough frames.
    #[getter]
    fn sd_terms<'py>(&self, py: Python<'py>) -> Option<Pair<'py>> {
        self.inner.sd_terms().map(|(n, d)| (PyArray1::from_slice(py, &n), PyArray1::from_slice(py, &d)))
    }
}

/// Builds (and validates) a model from a card and torch-layout arrays; used by the exporter
/// so that the file format has one writer, the core's.
#[pyfunction]
fn build_model(
    card_json: &str,
    weights: Vec<Bound<'_, PyAny>>,
    biases: Vec<Bound<'_, PyAny>>,
    input_scale: &Bound<'_, PyAny>,
    input_shift: &Bound<'_, PyAny>,
    output_scale: &Bound<'_, PyAny>,
    output_shift: &Bound<'_, PyAny>,
) -> PyResult<Model> {
    let card = ModelCard::from_json(card_json).py_err()?;
    let activations = card.parsed_activations().py_err()?;
    if weights.len() != activations.len() || biases.len() != activations.len() {
        return Err(input(format!(
            "the card lists {} layers but {} weights and {} biases were given",
            activations.len(),
            weights.len(),
            biases.len()
        )));
    }
    let vector =
        |obj: &Bound<'_, PyAny>, what: &str| with_floats(obj, what, 1, |v, _| Ok(DVector::from_column_slice(v)));
    let mut layers = Vec::with_capacity(weights.len());
    for (k, ((w, b), act)) in weights.iter().zip(&biases).zip(activations).enumerate() {
        let weight = with_floats(w, &format!("weights[{k}]"), 2, |v, s| Ok(DMatrix::from_row_slice(s[0], s[1], v)))?;
        layers.push(Dense { weight, bias: vector(b, &format!("biases[{k}]"))?, activation: act });
    }
    let mlp = Mlp::new(
        Affine { scale: vector(input_scale, "input_scale")?, shift: vector(input_shift, "input_shift")? },
        layers,
        Affine { scale: vector(output_scale, "output_scale")?, shift: vector(output_shift, "output_shift")? },
    )
    .py_err()?;
    Ok(Model { inner: ikid::Model::from_parts(card, mlp).py_err()? })
}
