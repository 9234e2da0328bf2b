//! `ikid.Tracker`: the core's causal Kalman tracker (angles, velocities, accelerations,
//! torques per frame). Conversion only.

use crate::body::subject;
use crate::conv::{calibration_arg, model_arg, number_arg, with_f64_rows, with_frame_f64};
use crate::errors::{IntoPy, input};
use crate::model::Model;
use ikid::body::{MARKER_FRAME_LEN, N_COORDINATES};
use ikid::tracker::{
    DEFAULT_JERK_NOISE, REFINED_SD_SCALE_Q, REFINED_SD_SCALE_TAU, REFINER_GATE_NOISE, RIGID_TOLERANCE_M,
    RIGID_TOLERANCE_REL, SD_SCALE_TAU, Tracker as CoreTracker, TrackerOutput, TrackerSettings, refiner_outputs,
};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use pyo3::types::{PyString, PyTuple};

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Tracker>()?;
    m.add_class::<TrackerEstimate>()?;
    m.add("DEFAULT_JERK_NOISE", DEFAULT_JERK_NOISE)?;
    m.add("GAP_PERIODS", ikid::stream::GAP_PERIODS)?;
    m.add("SD_SCALE_TAU", SD_SCALE_TAU)?;
    m.add("REFINER_OUTPUTS", refiner_outputs())?;
    m.add("REFINER_GATE_NOISE", REFINER_GATE_NOISE)?;
    m.add("REFINED_SD_SCALE_Q", REFINED_SD_SCALE_Q)?;
    m.add("REFINED_SD_SCALE_TAU", REFINED_SD_SCALE_TAU)?;
    m.add("RIGID_TOLERANCE_M", RIGID_TOLERANCE_M)?;
    m.add("RIGID_TOLERANCE_REL", RIGID_TOLERANCE_REL)?;
    Ok(())
}

/// Causal tracking of one subject's wrist, frame by frame: an extended Kalman filter over the
/// body model that learns each marker coordinate's noise as it goes (see the core's
/// `tracker` module). Gives angles (rad), velocities (rad/s), accelerations (rad/s²) and
/// torques (N·m) for every frame once a frame with every marker has started it; a missing
/// marker (NaN) simply corrects nothing.
///
/// Without a ``calibration`` the markers are read at the body model's placement, and nothing
/// here checks that they sit there: ``ikid.check_default_placement(frames)`` does (what
/// ``ikid track`` and ``ikid stream`` check first); uncalibrated real markers read 50-170° off,
/// flagged ``outside_training`` or ``implausible`` at best.
///
/// Arguments (all optional):
///
/// - ``length_scale``, ``mass_scale``: the subject's segment lengths (and marker offsets) and
///   masses relative to the default subject (1.0).
/// - ``marker_shift``: ``(6, 3)`` metres added to each marker's offset in its segment's frame
///   (frame order), or None.
/// - ``rate_hz``: the rate frames are pushed at, Hz. Required: velocities, accelerations and
///   torques scale with it, and nothing in the markers can tell a wrong one.
/// - ``jerk_noise``: spectral density of the joint jerk the motion model allows, rad²/s⁵
///   (``ikid.DEFAULT_JERK_NOISE``): larger follows faster moves with less lag and passes
///   more noise.
/// - ``noise_memory_s``: how far back the marker-noise estimate looks, seconds.
/// - ``initial_marker_noise``: marker noise (standard deviation, m) assumed before any has
///   been measured.
/// - ``refiner``: a ``refine`` model (``ikid.load("wrist-track")``, or its name or file) whose
///   network over the tracker's recent states corrects q and q̈; None for the filter alone.
/// - ``calibration``: an ``ikid.Calibration`` of the subject's marker placement (from
///   ``ikid.calibrate`` or ``ikid.load_calibration``), or the path of its file; turns
///   ``relative_hand`` on.
/// - ``relative_hand``: measure the hand by its orientation only (for real subjects, whose
///   wrist centre the body model does not know).
/// - ``up``: the lab's up direction in the markers' coordinates: an axis (``"+y"``, the
///   default and ikid's lab; ``"+z"`` for Vicon and Qualisys labs) or three numbers. Only the
///   torques depend on it (gravity), and they are wrong by it silently.
#[pyclass(module = "ikid")]
pub struct Tracker {
    inner: CoreTracker,
}

/// A lab's up direction as Python gives it: an axis (`"+z"`) or three numbers.
pub fn lab_up(up: &Bound<'_, PyAny>) -> PyResult<[f64; 3]> {
    if up.is_instance_of::<PyString>() {
        return ikid::body::up_axis(&up.extract::<String>()?).py_err();
    }
    up.extract::<[f64; 3]>().map_err(|_| {
        let given = up.repr().map_or_else(|_| "?".into(), |r| r.to_string());
        input(format!("up: expected an axis such as \"+z\" or three numbers, got {given}"))
    })
}

fn rows(out: &TrackerOutput) -> [[f64; N_COORDINATES]; 4] {
    [out.state.q, out.state.qd, out.state.qdd, out.tau]
}

#[pymethods]
impl Tracker {
    #[new]
    #[pyo3(signature = (length_scale=1.0, mass_scale=1.0, marker_shift=None, rate_hz=None, jerk_noise=DEFAULT_JERK_NOISE, noise_memory_s=10.0, initial_marker_noise=1e-3, refiner=None, calibration=None, relative_hand=false, up=None))]
    // jerk_noise's default written out for help() (pyo3 shows a constant as `...`); a test
    // checks it is DEFAULT_JERK_NOISE.
    #[pyo3(
        text_signature = "(length_scale=1.0, mass_scale=1.0, marker_shift=None, rate_hz=None, jerk_noise=3000.0, noise_memory_s=10.0, initial_marker_noise=0.001, refiner=None, calibration=None, relative_hand=False, up=None)"
    )]
    #[allow(clippy::too_many_arguments)]
    fn new(
        length_scale: f64,
        mass_scale: f64,
        marker_shift: Option<&Bound<'_, PyAny>>,
        rate_hz: Option<&Bound<'_, PyAny>>,
        jerk_noise: f64,
        noise_memory_s: f64,
        initial_marker_noise: f64,
        refiner: Option<&Bound<'_, PyAny>>,
        calibration: Option<&Bound<'_, PyAny>>,
        relative_hand: bool,
        up: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        // No default: a 100 Hz recording tracked as 1 kHz gave velocities 9x and torques 5x too
        // large with every status 0 (a new-user review); the rate is an input, never a guess.
        // `True` is a number to Python: refused, not taken as 1 Hz.
        let rate_hz = rate_hz.map(|r| number_arg(r, "rate_hz", "the frames' rate in Hz")).transpose()?;
        let Some(rate_hz) = rate_hz else {
            return Err(ikid::Error::BadArgument {
                what: "rate_hz",
                detail: "is required: the rate the frames come at, in Hz (a recording's rate_hz); tracked at \
                         another rate, every velocity, acceleration and torque is wrong and nothing in the \
                         markers can say so"
                    .into(),
            })
            .py_err();
        };
        let body = subject(length_scale, mass_scale, marker_shift)?;
        let up = match up {
            None => TrackerSettings::new(rate_hz).up,
            Some(u) => lab_up(u)?,
        };
        let settings = TrackerSettings { rate_hz, jerk_noise, noise_memory_s, initial_marker_noise, relative_hand, up };
        let mut inner = CoreTracker::new(body, settings).py_err()?;
        let calibration = calibration.map(|c| calibration_arg(c, "calibration")).transpose()?;
        inner.set_calibration(calibration.map(|c| c.get().inner));
        let refiner = refiner.map(|m| model_arg(m, "refiner")).transpose()?;
        inner.set_refiner(refiner.map(|m| m.get().inner.clone())).py_err()?;
        Ok(Tracker { inner })
    }

    /// The refinement model, or None.
    #[getter]
    fn refiner(&self) -> Option<Model> {
        self.inner.refiner().map(|m| Model { inner: m.clone() })
    }

    /// Push one marker frame: ``frame`` holds 18 values (the six markers' x, y, z in metres in
    /// the lab frame, ``ikid.MARKERS`` order; NaN = missing, float32 or float64). Returns a
    /// ``TrackerEstimate`` (``q``, ``qd``, ``qdd``, ``tau``, the ``status`` bits of
    /// ``ikid.FRAME_STATUS``, ``missing``, ``noise``, ``refined``; ``numpy.asarray`` of it is the
    /// ``(4, 3)`` array of the four rows), or None until a frame with every marker started
    /// the filter. Holds the GIL (a push takes microseconds).
    ///
    /// ``time``: the frame's acquisition time, seconds (any origin), for a source that can lose
    /// frames: a stamp more than 1.5 periods after the last one carries the filter through the
    /// frames lost when they are fewer than 30 ms (``bridged_frames`` counts them), and
    /// restarts it otherwise, or when the stamp is not after the last one (keeping what it
    /// learned of the subject; ``gap_restarts`` counts it); one less than half a period after
    /// it is refused.
    #[pyo3(signature = (frame, time=None))]
    fn push<'py>(
        &mut self,
        frame: &Bound<'py, PyAny>,
        time: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Option<TrackerEstimate>> {
        let time = time.map(|t| number_arg(t, "time", "the frame's time in seconds")).transpose()?;
        let tracker = &mut self.inner;
        with_frame_f64(frame, |values| {
            let out = match time {
                Some(t) => tracker.push_at(t, values),
                None => tracker.push(values),
            };
            Ok(out.py_err()?.map(|out| TrackerEstimate::from(&out)))
        })
    }

    /// Standard deviations of the last estimate from the filter's covariance: a `(2, 3)`
    /// float64 array, rows `q` (rad) and `tau` (N·m, linearised), or `None` before the start.
    /// They measure the filter's own state, not a refiner's correction.
    #[getter]
    fn output_sd<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray2<f64>>> {
        let sd = self.inner.output_sd()?;
        Some(PyArray2::from_owned_array(py, numpy::ndarray::Array2::from(vec![sd.q, sd.tau])))
    }

    /// Every frame of `frames` `(n, 18)` in order; returns a dict of `(n, 3)` float64 arrays
    /// `q`, `qd`, `qdd`, `tau`, with ``sd=True`` their standard deviations `q_sd`, `tau_sd`
    /// (``output_sd`` after each frame; off by default: it costs several times the filter), the `(n,)` uint8 `missing` (bit i: marker i missing), `(n,)`
    /// `noise` (mean learned hand-marker noise, m; NaN before the start), `refined` (bool) and
    /// `status` (uint16 bits, ``ikid.FRAME_STATUS``: markers rejected, poses held, restarts,
    /// implausible angles), and `start`,
    /// the first frame with an estimate (rows before it are NaN: the filter waits for a frame
    /// with every marker). Continues from the tracker's state. ``times``: each frame's time,
    /// seconds, as ``push``'s ``time`` (lost frames restart the filter). Releases the GIL.
    #[pyo3(signature = (frames, sd=false, times=None))]
    fn run<'py>(
        &mut self,
        py: Python<'py>,
        frames: &Bound<'py, PyAny>,
        sd: bool,
        times: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let with_sd = sd;
        let times: Option<Vec<f64>> =
            times.map(|t| t.extract()).transpose().map_err(|e| input(format!("times: {e}")))?;
        let tracker = &mut self.inner;
        let (out, sd, missing, noise, refined, status, start, n) =
            with_f64_rows(frames, "frames", MARKER_FRAME_LEN, |values, n| {
                // The core's `run` does the work; here its per-frame results are laid out as
                // four (n, 3) blocks and three (n,) arrays.
                let mut out = vec![f64::NAN; 4 * n * N_COORDINATES];
                let mut sd = vec![f64::NAN; if with_sd { 2 * n * N_COORDINATES } else { 0 }];
                let mut missing = vec![0u8; n];
                let mut noise = vec![f64::NAN; n];
                let mut refined = vec![false; n];
                let mut status = vec![0u16; n];
                let start = py
                    .detach(|| {
                        tracker.run_with_sd(values, times.as_deref(), with_sd, |i, o, s, _| {
                            for (k, row) in rows(o).iter().enumerate() {
                                out[(k * n + i) * N_COORDINATES..(k * n + i + 1) * N_COORDINATES].copy_from_slice(row);
                            }
                            if let Some(s) = s {
                                for (k, row) in [s.q, s.tau].iter().enumerate() {
                                    sd[(k * n + i) * N_COORDINATES..(k * n + i + 1) * N_COORDINATES]
                                        .copy_from_slice(row);
                                }
                            }
                            missing[i] = o.missing;
                            noise[i] = o.noise;
                            refined[i] = o.refined;
                            status[i] = o.status;
                        })
                    })
                    .py_err()?;
                if start.is_none() {
                    // Say why, where the core can: markers in the wrong units, most often.
                    ikid::body::check_recording_span(values).py_err()?;
                }
                Ok((out, sd, missing, noise, refined, status, start, n))
            })?;
        let Some(start) = start else {
            return Err(input(format!(
                "frames: none of the {n} frames has every marker present and consistent, so the tracker never started"
            )));
        };
        let d = PyDict::new(py);
        for (k, name) in ["q", "qd", "qdd", "tau"].iter().enumerate() {
            let block = out[k * n * N_COORDINATES..(k + 1) * n * N_COORDINATES].to_vec();
            d.set_item(*name, block.into_pyarray(py).reshape([n, N_COORDINATES])?)?;
        }
        for (k, name) in ["q_sd", "tau_sd"].iter().enumerate().filter(|_| with_sd) {
            let block = sd[k * n * N_COORDINATES..(k + 1) * n * N_COORDINATES].to_vec();
            d.set_item(*name, block.into_pyarray(py).reshape([n, N_COORDINATES])?)?;
        }
        d.set_item("missing", missing.into_pyarray(py))?;
        d.set_item("noise", noise.into_pyarray(py))?;
        d.set_item("refined", refined.into_pyarray(py))?;
        d.set_item("status", status.into_pyarray(py))?;
        d.set_item("start", start)?;
        Ok(d)
    }

    /// How many times the tracker lost the hand (every usable marker rejected for a while) and
    /// restarted from a frame's own solution.
    #[getter]
    fn restarts(&self) -> usize {
        self.inner.restarts()
    }

    /// How many times ``push(..., time=)`` or ``run(..., times=)`` restarted the filter after a
    /// time gap (frames lost, or the source's clock restarted).
    #[getter]
    fn gap_restarts(&self) -> usize {
        self.inner.gap_restarts()
    }

    /// How many lost frames ``push(..., time=)`` or ``run(..., times=)`` carried the filter
    /// through (fewer than 30 ms of them in a row: bridged, not restarted).
    #[getter]
    fn bridged_frames(&self) -> usize {
        self.inner.bridged_frames()
    }

    /// Forget everything seen (state, forearm pose, noise estimates).
    fn reset(&mut self) {
        self.inner.reset();
    }

    /// Current noise estimate of each hand marker coordinate (standard deviation, m; MC2.x
    /// first), `(9,)` float64.
    #[getter]
    fn marker_noise<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.inner.marker_noise())
    }

    /// The settings in use: `rate_hz`, `jerk_noise`, `noise_memory_s`, `initial_marker_noise`,
    /// `up`.
    #[getter]
    fn settings<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let s = self.inner.settings();
        let d = PyDict::new(py);
        d.set_item("rate_hz", s.rate_hz)?;
        d.set_item("jerk_noise", s.jerk_noise)?;
        d.set_item("noise_memory_s", s.noise_memory_s)?;
        d.set_item("initial_marker_noise", s.initial_marker_noise)?;
        d.set_item("up", s.up.to_vec())?;
        Ok(d)
    }

    fn __repr__(&self) -> String {
        let s = self.inner.settings();
        format!("Tracker(rate_hz={}, jerk_noise={:e})", s.rate_hz, s.jerk_noise)
    }
}

/// One frame's estimate from ``Tracker.push``: ``q``, ``qd``, ``qdd``, ``tau`` (``(3,)``
/// float64 each: rad, rad/s, rad/s², N·m, ``ikid.COORDINATES`` order), ``status`` (bits of
/// ``ikid.FRAME_STATUS``: markers rejected, a pose held, a restart, an implausible angle),
/// ``missing`` (bit i: marker i was missing), ``noise`` (mean learned hand-marker noise, m)
/// and ``refined``. As an array (``numpy.asarray(estimate)``, indexing, unpacking
/// ``q, qd, qdd, tau = estimate``) it is the ``(4, 3)`` float64 array of the four rows.
#[pyclass(module = "ikid", frozen)]
pub struct TrackerEstimate {
    rows: [[f64; N_COORDINATES]; 4],
    /// ``ikid.FRAME_STATUS`` bits of this estimate.
    #[pyo3(get)]
    status: u32,
    /// Bit i set: marker i (``ikid.MARKERS`` order) was missing in this frame.
    #[pyo3(get)]
    missing: u32,
    /// Mean noise (standard deviation) of the hand markers measured so far, m.
    #[pyo3(get)]
    noise: f64,
    /// Whether the refiner corrected this estimate.
    #[pyo3(get)]
    refined: bool,
}

impl From<&TrackerOutput> for TrackerEstimate {
    fn from(out: &TrackerOutput) -> Self {
        TrackerEstimate {
            rows: rows(out),
            status: u32::from(out.status),
            missing: u32::from(out.missing),
            noise: out.noise,
            refined: out.refined,
        }
    }
}

impl TrackerEstimate {
    fn row<'py>(&self, py: Python<'py>, k: usize) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.rows[k])
    }

    fn array<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        PyArray2::from_owned_array(py, numpy::ndarray::Array2::from(self.rows.to_vec()))
    }
}

#[pymethods]
impl TrackerEstimate {
    /// Joint angles, rad.
    #[getter]
    fn q<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.row(py, 0)
    }

    /// Joint velocities, rad/s.
    #[getter]
    fn qd<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.row(py, 1)
    }

    /// Joint accelerations, rad/s².
    #[getter]
    fn qdd<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.row(py, 2)
    }

    /// Joint torques, N·m.
    #[getter]
    fn tau<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.row(py, 3)
    }

    /// The ``(4, 3)`` float64 array of rows ``q``, ``qd``, ``qdd``, ``tau`` (a new copy).
    #[getter]
    fn values<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        self.array(py)
    }

    /// The ``(4, 3)`` array (``numpy.asarray(estimate)``), in ``dtype`` if given.
    #[pyo3(signature = (dtype=None, copy=None))]
    fn __array__<'py>(
        &self,
        py: Python<'py>,
        dtype: Option<&Bound<'py, PyAny>>,
        copy: Option<bool>,
    ) -> PyResult<Bound<'py, PyAny>> {
        if copy == Some(false) {
            return Err(pyo3::exceptions::PyValueError::new_err(
                "a TrackerEstimate's array is always a new copy (copy=False cannot be honoured)",
            ));
        }
        let array = self.array(py).into_any();
        match dtype {
            Some(dtype) if !dtype.is_none() => array.call_method1("astype", (dtype,)),
            _ => Ok(array),
        }
    }

    /// Indexes the ``(4, 3)`` array (``estimate[0]`` is ``q``).
    fn __getitem__<'py>(&self, py: Python<'py>, key: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
        self.array(py).into_any().get_item(key)
    }

    fn __len__(&self) -> usize {
        self.rows.len()
    }

    /// Unpacks as the four rows: ``q, qd, qdd, tau = estimate``.
    fn __iter__<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let rows: Vec<_> = (0..self.rows.len()).map(|k| self.row(py, k)).collect();
        PyTuple::new(py, rows)?.into_any().try_iter().map(Bound::into_any)
    }

    fn __repr__(&self) -> String {
        let [q, _, _, tau] = self.rows;
        format!(
            "TrackerEstimate(q={q:?}, tau={tau:?}, status={}, missing={}, refined={})",
            self.status,
            self.missing,
            if self.refined { "True" } else { "False" }
        )
    }
}
