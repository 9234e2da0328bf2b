//! Feature sets: the same computation training and inference use.

use crate::conv::with_floats;
use crate::errors::{IntoPy, input};
use ikid::FeatureSet;
use ikid::features::FEATURE_SETS;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("FEATURE_SETS", FEATURE_SETS.map(FeatureSet::name).to_vec())?;
    m.add_function(wrap_pyfunction!(feature_set_info, m)?)?;
    m.add_function(wrap_pyfunction!(compute_features, m)?)?;
    m.add_function(wrap_pyfunction!(fill_gaps, m)?)?;
    m.add_class::<LabelCheck>()?;
    Ok(())
}

/// Sizes and names of a feature set: `frame_len`, `feature_len`, `frame_names`, `feature_names`.
#[pyfunction]
fn feature_set_info<'py>(py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyDict>> {
    let set = feature_set(name)?;
    let d = PyDict::new(py);
    d.set_item("name", set.name())?;
    d.set_item("frame_kind", set.frame_kind().name())?;
    d.set_item("frame_len", set.frame_len())?;
    d.set_item("feature_len", set.feature_len())?;
    d.set_item("frame_names", set.frame_names())?;
    d.set_item("feature_names", set.feature_names())?;
    Ok(d)
}

/// Features of every frame: `frames` is `(n, frame_len)`, the result `(n, feature_len)` float32.
#[pyfunction]
fn compute_features<'py>(
    py: Python<'py>,
    frames: &Bound<'py, PyAny>,
    feature_set: &str,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let set = self::feature_set(feature_set)?;
    with_floats(frames, "frames", 2, |values, shape| {
        if shape[1] != set.frame_len() {
            return Err(input(format!(
                "frames: {} columns, feature set {:?} takes {}",
                shape[1],
                set.name(),
                set.frame_len()
            )));
        }
        let mut out = vec![0f32; shape[0] * set.feature_len()];
        py.detach(|| set.compute_rows(values, &mut out)).py_err()?;
        out.into_pyarray(py).reshape([shape[0], set.feature_len()])
    })
}

/// Filled frames `(n, 18)` and the mask of markers filled per frame `(n,)`.
type FilledFrames<'py> = (Bound<'py, PyArray2<f32>>, Bound<'py, PyArray1<u8>>);

/// Runs a fresh gap filler (what a `"fill"` stream does) over a recording `(n, 18)`: the
/// filled frames (float32) and per frame the bit mask of markers filled (uint8, bit `i` =
/// marker `i`). A frame it cannot fill raises (`unfillable="raise"`) or stays missing with
/// mask 0 (`unfillable="keep"`). `rate_hz`: the frames' rate (the filler's time constants are
/// in seconds).
#[pyfunction]
#[pyo3(signature = (frames, unfillable = "raise", rate_hz = 1000.0))]
fn fill_gaps<'py>(
    py: Python<'py>,
    frames: &Bound<'py, PyAny>,
    unfillable: &str,
    rate_hz: f64,
) -> PyResult<FilledFrames<'py>> {
    let keep = match unfillable {
        "raise" => false,
        "keep" => true,
        other => return Err(input(format!("unfillable: {other:?} is not \"raise\" or \"keep\""))),
    };
    with_floats(frames, "frames", 2, |values, shape| {
        if shape[1] != ikid::body::MARKER_FRAME_LEN {
            return Err(input(format!(
                "frames: {} columns, marker frames have {}",
                shape[1],
                ikid::body::MARKER_FRAME_LEN
            )));
        }
        let (filled, masks) = py.detach(|| ikid::gaps::fill_gaps(values, keep, rate_hz)).py_err()?;
        Ok((filled.into_pyarray(py).reshape([shape[0], shape[1]])?, masks.into_pyarray(py)))
    })
}

/// Finds swapped marker labels frame by frame, as a `"fill"` stream's gap filler does, for
/// frames that are resampled before a stream sees them (`ikid.pipeline`): a swap must be found
/// at the frames' own rate. Its state carries from call to call.
#[pyclass(module = "ikid")]
pub struct LabelCheck {
    filler: ikid::gaps::GapFiller,
    index: usize,
}

#[pymethods]
impl LabelCheck {
    /// A check for frames at `rate_hz`.
    #[new]
    fn new(rate_hz: f64) -> PyResult<Self> {
        if !(rate_hz.is_finite() && rate_hz > 0.0) {
            return Err(input(format!("rate_hz: {rate_hz}: expected a rate in Hz greater than 0")));
        }
        Ok(LabelCheck { filler: ikid::gaps::GapFiller::at_rate(rate_hz), index: 0 })
    }

    /// For marker frames `(n, 18)` (metres; the ones after those of the calls before): per frame
    /// and label, the marker (0-5, as the frame came) that belongs under it, or -1 for none,
    /// `(n, 6)` int8 — the identity unless labels were swapped.
    fn labels<'py>(&mut self, py: Python<'py>, frames: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray2<i8>>> {
        const LEN: usize = ikid::body::MARKER_FRAME_LEN;
        with_floats(frames, "frames", 2, |values, shape| {
            if shape[1] != LEN {
                return Err(input(format!("frames: {} columns, marker frames have {LEN}", shape[1])));
            }
            let mut out = Vec::with_capacity(shape[0] * 6);
            let mut buf = [0f32; LEN];
            for frame in values.chunks_exact(LEN) {
                buf.copy_from_slice(frame);
                // A frame the filler refuses keeps its labels (the stream decides about it).
                let labels = match self.filler.fill(&mut buf, self.index) {
                    Ok(_) => self.filler.labels(),
                    Err(_) => [0, 1, 2, 3, 4, 5],
                };
                self.index += 1;
                out.extend(labels.map(|l| if l == ikid::gaps::NO_MARKER { -1 } else { l as i8 }));
            }
            out.into_pyarray(py).reshape([shape[0], 6])
        })
    }
}

/// A feature set named by the caller: an unknown name is the caller's input error here (in a
/// model file it is a model-file error).
fn feature_set(name: &str) -> PyResult<FeatureSet> {
    FeatureSet::from_name(name).map_err(|e| input(e.to_string()))
}
