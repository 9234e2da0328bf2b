//! `Calibration`: the core's, NumPy in and out.

use crate::conv::{with_f64_rows, with_floats};
use crate::errors::{IntoPy, input};
use ikid::body::{COORDINATES, MARKER_FRAME_LEN};
use ikid::calibration::{
    ForearmGeometry, HAND_LANDMARK_FRAME_LEN, HAND_LANDMARKS, LANDMARK_FRAME_LEN, LANDMARKS, LandmarkTrial, Method,
    Side,
};
use nalgebra::{Matrix3, Vector3};
use numpy::{IntoPyArray, PyArray2, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyDictMethods};

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Calibration>()?;
    m.add_function(wrap_pyfunction!(check_default_placement, m)?)
}

/// Refuses (`ArgumentError` saying what to do) a recording `(n, 18)` (metres) that the body
/// model's own marker placement cannot read: its markers' distances, or the median posture
/// read that way, are not a wrist's, or they are the mirror image of a `side` arm's (the other
/// arm's). What every uncalibrated run checks first.
#[pyfunction]
#[pyo3(signature = (frames, length_scale = 1.0, side = "right"))]
fn check_default_placement(frames: &Bound<'_, PyAny>, length_scale: f64, side: &str) -> PyResult<()> {
    let body = ikid::body::BodyModel::try_scaled(length_scale, 1.0).py_err()?;
    let side = ikid::calibration::Side::from_name(side).py_err()?;
    with_f64_rows(frames, "frames", MARKER_FRAME_LEN, |v, _| {
        ikid::calibration::check_default_placement(v, &body, side).py_err()
    })
}

/// The subject's marker placement: each segment's technical frame (from its markers) in its
/// anatomical frame, and the arm's side. Measure it with `Calibration.from_neutral`
/// (landmarks and/or neutral frames) or `Calibration.from_trials`; give it to `Model.stream`.
#[pyclass(module = "ikid", frozen, skip_from_py_object)]
#[derive(Clone)]
pub struct Calibration {
    pub inner: ikid::Calibration,
    report: Option<ikid::calibration::CalibrationReport>,
    method: Method,
}

fn side_of(name: &str) -> PyResult<Side> {
    Side::from_name(name).py_err()
}

fn matrix<'py>(py: Python<'py>, m: &Matrix3<f64>) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let rows: Vec<f64> = (0..3).flat_map(|r| (0..3).map(move |c| m[(r, c)])).collect();
    rows.into_pyarray(py).reshape([3, 3])
}

fn read_matrix(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Matrix3<f64>> {
    with_f64_rows(obj, what, 3, |v, n| {
        if n != 3 {
            return Err(input(format!("{what}: expected a 3×3 matrix, got {n} rows")));
        }
        Ok(Matrix3::from_row_slice(v))
    })
}

#[pymethods]
impl Calibration {
    /// Measures the calibration from a static trial in the neutral pose `(n, 18)` and
    /// movements of single coordinates, `{coordinate name: frames (n, 18)}` (at least two
    /// coordinates). Frames must be complete (fill gaps first). Releases the GIL.
    #[staticmethod]
    fn from_trials(py: Python<'_>, static_frames: &Bound<'_, PyAny>, movements: &Bound<'_, PyDict>) -> PyResult<Self> {
        let statics = frames_of(static_frames, "static_frames")?;
        let mut moves: Vec<(usize, Vec<f32>)> = Vec::new();
        for (key, value) in movements.iter() {
            let name: String = key.extract().map_err(|_| input("movements: keys must be coordinate names"))?;
            let j = ikid::body::coordinate_index(&name).map_err(|e| input(format!("movements: {e}")))?;
            moves.push((j, frames_of(&value, &format!("movements[{name:?}]"))?));
        }
        let refs: Vec<(usize, &[f32])> = moves.iter().map(|(j, f)| (*j, f.as_slice())).collect();
        let (inner, report) = py.detach(|| ikid::Calibration::from_trials(&statics, &refs)).py_err()?;
        Ok(Calibration { inner, report: Some(report), method: Method::Movements })
    }

    /// Measures the calibration from frames of the neutral posture `(n, 18)` (a static trial
    /// or chosen frames of any trial; NaN = missing) and, when given, the forearm's landmarks
    /// `(m, 12)` (`Calibration.LANDMARKS` order, NaN = not seen) seen with the marker frames
    /// `landmark_frames` `(m, 18)` (default: the neutral frames): the ISB forearm frame, the
    /// hand equal to the forearm at neutral. Without landmarks the forearm keeps the body
    /// model's placement. `hand_landmarks` `(m, 6)` (`Calibration.HAND_LANDMARKS` order: the
    /// second and fifth metacarpal heads; NaN = not seen), with the landmarks: the hand's own
    /// frame. `side`: "right" or "left" (mirrored). Releases the GIL.
    #[staticmethod]
    #[pyo3(signature = (neutral_frames, landmarks = None, landmark_frames = None, side = "right", hand_landmarks = None))]
    fn from_neutral(
        py: Python<'_>,
        neutral_frames: &Bound<'_, PyAny>,
        landmarks: Option<&Bound<'_, PyAny>>,
        landmark_frames: Option<&Bound<'_, PyAny>>,
        side: &str,
        hand_landmarks: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let side = side_of(side)?;
        let neutral = frames_of(neutral_frames, "neutral_frames")?;
        let points = match landmarks {
            Some(l) => Some(with_floats(l, "landmarks", 2, |values, shape| {
                if shape[1] != LANDMARK_FRAME_LEN {
                    return Err(input(format!(
                        "landmarks: {} columns, a landmark frame has {LANDMARK_FRAME_LEN} (x, y, z of {})",
                        shape[1],
                        LANDMARKS.map(|l| l.name).join(", ")
                    )));
                }
                Ok(values.to_vec())
            })?),
            None => None,
        };
        let hand_points = match (hand_landmarks, &points) {
            (Some(h), Some(_)) => Some(with_floats(h, "hand_landmarks", 2, |values, shape| {
                if shape[1] != HAND_LANDMARK_FRAME_LEN {
                    return Err(input(format!(
                        "hand_landmarks: {} columns, a hand landmark frame has {HAND_LANDMARK_FRAME_LEN} (x, y, z of {})",
                        shape[1],
                        HAND_LANDMARKS.map(|l| l.name).join(", ")
                    )));
                }
                Ok(values.to_vec())
            })?),
            (Some(_), None) => {
                return Err(input("hand_landmarks need the forearm's landmarks too (the styloids give the wrist)"));
            }
            (None, _) => None,
        };
        let beside = match (landmark_frames, &points) {
            (Some(f), Some(_)) => Some(frames_of(f, "landmark_frames")?),
            (Some(_), None) => return Err(input("landmark_frames given without landmarks")),
            (None, _) => None,
        };
        let (inner, report) = py
            .detach(|| {
                let trial = points.as_ref().map(|l| LandmarkTrial {
                    markers: beside.as_deref().unwrap_or(&neutral),
                    landmarks: l,
                    hand_landmarks: hand_points.as_deref(),
                });
                ikid::Calibration::from_neutral(&neutral, trial, side)
            })
            .py_err()?;
        Ok(Calibration { inner, method: report.method, report: Some(report) })
    }

    /// Measures the calibration from frames of the neutral posture `(n, 18)` and a movement
    /// `(m, 18)` mixing flexion-extension and deviation in any proportion, the forearm's
    /// rotation held (a least-squares functional fit of the two axes; NaN = missing, such
    /// frames skipped). `side`: "right" or "left". Releases the GIL.
    #[staticmethod]
    #[pyo3(signature = (neutral_frames, movement_frames, side = "right"))]
    fn functional(
        py: Python<'_>,
        neutral_frames: &Bound<'_, PyAny>,
        movement_frames: &Bound<'_, PyAny>,
        side: &str,
    ) -> PyResult<Self> {
        let side = side_of(side)?;
        let neutral = frames_of(neutral_frames, "neutral_frames")?;
        let movement = frames_of(movement_frames, "movement_frames")?;
        let (inner, report) = py.detach(|| ikid::Calibration::functional(&neutral, &movement, side)).py_err()?;
        Ok(Calibration { inner, method: report.method, report: Some(report) })
    }

    /// Takes the forearm's frame from the other arm's calibration `other` for a forearm carrying
    /// the same cluster mounted alike (the mirror method), the hand's from this arm's neutral
    /// frames `(n, 18)`. `cluster` `(3, 3)`: the other arm's RSP, USP, FAP in its forearm's
    /// technical frame, metres; `other_landmarks` `(4, 3)`: its landmarks there
    /// (`Calibration.LANDMARKS` order, NaN = not measured) — both as its calibration's report
    /// records them (`report["landmarks"]["geometry"]`, in mm). `landmarks` `(m, 12)` with
    /// `landmark_frames` `(m, 18)` (default: the neutral frames): this arm's landmarks, NaN where
    /// not recorded (one is enough to tell how the cluster's markers pair). `side`: this arm.
    /// Releases the GIL.
    #[staticmethod]
    #[pyo3(signature = (other, cluster, other_landmarks, neutral_frames, landmarks = None, landmark_frames = None, side = "left"))]
    #[allow(clippy::too_many_arguments)]
    fn mirrored(
        py: Python<'_>,
        other: &Calibration,
        cluster: &Bound<'_, PyAny>,
        other_landmarks: &Bound<'_, PyAny>,
        neutral_frames: &Bound<'_, PyAny>,
        landmarks: Option<&Bound<'_, PyAny>>,
        landmark_frames: Option<&Bound<'_, PyAny>>,
        side: &str,
    ) -> PyResult<Self> {
        let side = side_of(side)?;
        let points3 = |obj: &Bound<'_, PyAny>, what: &str, rows: usize| {
            with_f64_rows(obj, what, 3, |v, n| {
                if n != rows {
                    return Err(input(format!("{what}: expected {rows} rows of x, y, z, got {n}")));
                }
                Ok((0..rows).map(|r| Vector3::new(v[3 * r], v[3 * r + 1], v[3 * r + 2])).collect::<Vec<_>>())
            })
        };
        let c = points3(cluster, "cluster", 3)?;
        if c.iter().any(|p| !p.iter().all(|v| v.is_finite())) {
            return Err(input("cluster: every marker of the other arm's cluster must be finite"));
        }
        let l = points3(other_landmarks, "other_landmarks", 4)?;
        let geometry = ForearmGeometry {
            cluster: [c[0], c[1], c[2]],
            landmarks: std::array::from_fn(|k| l[k].iter().all(|v| v.is_finite()).then_some(l[k])),
        };
        let neutral = frames_of(neutral_frames, "neutral_frames")?;
        let points = match landmarks {
            Some(l) => Some(with_floats(l, "landmarks", 2, |values, shape| {
                if shape[1] != LANDMARK_FRAME_LEN {
                    return Err(input(format!(
                        "landmarks: {} columns, a landmark frame has {LANDMARK_FRAME_LEN}",
                        shape[1]
                    )));
                }
                Ok(values.to_vec())
            })?),
            None => None,
        };
        let beside = match (landmark_frames, &points) {
            (Some(f), Some(_)) => Some(frames_of(f, "landmark_frames")?),
            (Some(_), None) => return Err(input("landmark_frames given without landmarks")),
            (None, _) => None,
        };
        let other = other.inner;
        let (inner, report) = py
            .detach(|| {
                let trial = points.as_ref().map(|l| LandmarkTrial {
                    markers: beside.as_deref().unwrap_or(&neutral),
                    landmarks: l,
                    hand_landmarks: None,
                });
                ikid::Calibration::mirrored(&other, &geometry, &neutral, trial, side)
            })
            .py_err()?;
        Ok(Calibration { inner, method: report.method, report: Some(report) })
    }

    /// The body model's own placement (what an uncalibrated stream assumes).
    #[staticmethod]
    fn body_model() -> Self {
        Calibration { inner: ikid::Calibration::body_model(), report: None, method: Method::BodyModel }
    }

    /// From its two 3×3 rotation matrices (as `forearm` and `hand` give them) and the arm.
    #[staticmethod]
    #[pyo3(signature = (forearm, hand, side = "right"))]
    fn from_matrices(forearm: &Bound<'_, PyAny>, hand: &Bound<'_, PyAny>, side: &str) -> PyResult<Self> {
        let inner = ikid::Calibration::from_matrices_for(
            read_matrix(forearm, "forearm")?,
            read_matrix(hand, "hand")?,
            side_of(side)?,
        )
        .py_err()?;
        Ok(Calibration { inner, report: None, method: Method::Matrices })
    }

    /// This calibration with each segment's marker shape taken from `frames` `(n, 18)`, the
    /// neutral frames it was measured on (those with all six markers, averaged): a stream
    /// fits its segments to them and the Tracker takes them as its template, instead of
    /// learning them from a trial's first 0.5 s (skin markers slide: a trial that starts in
    /// another posture than the calibration's would read every angle off by as much).
    fn with_shapes_of(&self, frames: &Bound<'_, PyAny>) -> PyResult<Self> {
        let shapes = with_f64_rows(frames, "frames", MARKER_FRAME_LEN, |v, _| {
            let narrow: Vec<f32> = v.iter().map(|&x| x as f32).collect();
            ikid::marker_shapes(&narrow, self.inner.side).py_err()
        })?;
        Ok(Calibration { inner: self.inner.with_shapes(Some(shapes)), ..self.clone() })
    }

    /// This calibration with `shapes` as `marker_shapes` gives them (`(6, 3)`, metres), or
    /// without any (`None`: learned from each trial's first frames).
    fn with_marker_shapes(&self, shapes: Option<&Bound<'_, PyAny>>) -> PyResult<Self> {
        let shapes = match shapes {
            None => None,
            Some(obj) => Some(with_f64_rows(obj, "marker_shapes", 3, |v, n| {
                if n != 6 {
                    return Err(input(format!(
                        "marker_shapes: expected 6 rows (forearm's three markers, then the hand's), got {n}"
                    )));
                }
                ikid::calibration::shapes_from_rows(v).py_err()
            })?),
        };
        Ok(Calibration { inner: self.inner.with_shapes(shapes), ..self.clone() })
    }

    /// Each segment's three markers in its technical frame (origin their centroid), the
    /// forearm's then the hand's, `(6, 3)` metres, as measured at the calibration's neutral
    /// frames; `None` when each trial's first frames give them.
    #[getter]
    fn marker_shapes<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArray2<f64>>>> {
        let Some(shapes) = self.inner.shapes else { return Ok(None) };
        let rows: Vec<f64> = shapes.iter().flatten().flat_map(|p| [p.x, p.y, p.z]).collect();
        Ok(Some(rows.into_pyarray(py).reshape([6, 3])?))
    }

    /// The landmarks `from_neutral` reads, in the order of a landmark frame: (name, where).
    #[classattr]
    #[allow(non_snake_case)]
    fn LANDMARKS() -> Vec<(&'static str, &'static str)> {
        LANDMARKS.iter().map(|l| (l.name, l.description)).collect()
    }

    /// The hand's optional landmarks `(name, description)`, in a hand landmark frame's order.
    #[classattr]
    #[allow(non_snake_case)]
    fn HAND_LANDMARKS() -> Vec<(&'static str, &'static str)> {
        HAND_LANDMARKS.iter().map(|l| (l.name, l.description)).collect()
    }

    /// "right" or "left": a left arm's frames are mirrored into a right arm's.
    #[getter]
    fn side(&self) -> &'static str {
        self.inner.side.name()
    }

    /// How it was measured: "landmarks", "neutral", "movements", "matrices" (given, e.g. read
    /// from a file: the file records how it was measured) or "body_model".
    #[getter]
    fn method(&self) -> &'static str {
        self.method.name()
    }

    /// `T_f`: the forearm's technical frame in its anatomical frame (3×3).
    #[getter]
    fn forearm<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        matrix(py, self.inner.forearm.matrix())
    }

    /// `T_h`: the hand's technical frame in its anatomical frame (3×3).
    #[getter]
    fn hand<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        matrix(py, self.inner.hand.matrix())
    }

    /// What `from_trials`/`from_neutral` measured: method and side; per movement its range
    /// (degrees) and the share of it about one axis; the placement's difference from the body
    /// model's (degrees); the largest skew between measured axes (degrees); the neutral frames
    /// used, their spread with the markers' noise averaged out, that noise per frame and the
    /// standard error of the neutral posture taken (degrees); the landmarks (frames each was seen in, distances in
    /// mm, styloid line to long axis in degrees) or None. `None` for other calibrations.
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(r) = &self.report else { return Ok(None) };
        let d = PyDict::new(py);
        d.set_item("method", r.method.name())?;
        d.set_item("side", r.side.name())?;
        d.set_item("neutral_frames", r.neutral_frames)?;
        d.set_item("neutral_spread_deg", r.neutral_spread_deg)?;
        d.set_item("neutral_noise_deg", r.neutral_noise_deg)?;
        d.set_item("neutral_uncertainty_deg", r.neutral_uncertainty_deg)?;
        match &r.landmarks {
            Some(l) => {
                let ld = PyDict::new(py);
                let frames = PyDict::new(py);
                for (lm, n) in LANDMARKS.iter().zip(l.frames) {
                    frames.set_item(lm.name, n)?;
                }
                ld.set_item("frames", frames)?;
                ld.set_item("long_axis_mm", l.long_axis_mm)?;
                ld.set_item("styloid_span_mm", l.styloid_span_mm)?;
                ld.set_item("epicondyle_span_mm", l.epicondyle_span_mm)?;
                ld.set_item("styloid_axis_deg", l.styloid_axis_deg)?;
                ld.set_item("length_scale", l.length_scale)?;
                let g = PyDict::new(py);
                let mm = |v: &Vector3<f64>| [1e3 * v.x, 1e3 * v.y, 1e3 * v.z];
                g.set_item("cluster_mm", l.geometry.cluster.iter().map(mm).collect::<Vec<_>>())?;
                let at = PyDict::new(py);
                for (lm, p) in LANDMARKS.iter().zip(&l.geometry.landmarks) {
                    at.set_item(lm.name, p.as_ref().map(mm))?;
                }
                g.set_item("landmarks_mm", at)?;
                ld.set_item("geometry", g)?;
                match &l.hand {
                    Some(h) => {
                        let hd = PyDict::new(py);
                        hd.set_item("frames", h.frames)?;
                        hd.set_item("long_axis_mm", h.long_axis_mm)?;
                        hd.set_item("metacarpal_span_mm", h.metacarpal_span_mm)?;
                        hd.set_item("neutral_offset_deg", h.neutral_offset_deg)?;
                        ld.set_item("hand", hd)?;
                    }
                    None => ld.set_item("hand", py.None())?,
                }
                d.set_item("landmarks", ld)?;
            }
            None => d.set_item("landmarks", py.None())?,
        }
        match &r.functional {
            Some(f) => {
                let fd = PyDict::new(py);
                fd.set_item("frames", f.frames)?;
                fd.set_item("supination_held_deg", f.supination_held_deg)?;
                fd.set_item("flexion_range_deg", f.flexion_range_deg)?;
                fd.set_item("deviation_range_deg", f.deviation_range_deg)?;
                fd.set_item("residual_deg", f.residual_deg)?;
                fd.set_item("noise_deg", f.noise_deg)?;
                d.set_item("functional", fd)?;
            }
            None => d.set_item("functional", py.None())?,
        }
        match &r.mirror {
            Some(m) => {
                let md = PyDict::new(py);
                md.set_item("from", m.from.name())?;
                md.set_item("frames", m.frames)?;
                md.set_item("cluster_mm", m.cluster_mm)?;
                let at = PyDict::new(py);
                for &(k, mm, deg) in &m.landmarks {
                    let one = PyDict::new(py);
                    one.set_item("mm", mm)?;
                    one.set_item("deg", deg)?;
                    at.set_item(LANDMARKS[k].name, one)?;
                }
                md.set_item("landmarks", at)?;
                md.set_item("other_pairings", m.other_pairings)?;
                md.set_item("next_pairing_deg", m.next_pairing_deg)?;
                d.set_item("mirror", md)?;
            }
            None => d.set_item("mirror", py.None())?,
        }
        let moves = PyDict::new(py);
        for (j, range, purity) in &r.movements {
            let m = PyDict::new(py);
            m.set_item("range_deg", range)?;
            m.set_item("single_axis_share", purity)?;
            moves.set_item(COORDINATES[*j].name, m)?;
        }
        d.set_item("movements", moves)?;
        d.set_item("placement_deg", (r.placement_deg[0], r.placement_deg[1]))?;
        d.set_item("axis_skew_deg", r.axis_skew_deg)?;
        Ok(Some(d))
    }

    /// Markers `(n, 18)` moved to the body model's placement (float32). Frames must be
    /// complete.
    fn apply<'py>(&self, py: Python<'py>, frames: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let mut values = frames_of(frames, "frames")?;
        let n = values.len() / MARKER_FRAME_LEN;
        py.detach(|| self.inner.apply_rows(&mut values)).py_err()?;
        values.into_pyarray(py).reshape([n, MARKER_FRAME_LEN])
    }

    fn __repr__(&self) -> String {
        let [forearm, hand] = self.inner.placement_deg();
        format!(
            "Calibration({}, {} arm; forearm {forearm:.1}°, hand {hand:.1}° from the body model's placement)",
            self.method.name(),
            self.inner.side.name(),
        )
    }
}

fn frames_of(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec<f32>> {
    with_floats(obj, what, 2, |values, shape| {
        if shape[1] != MARKER_FRAME_LEN {
            return Err(input(format!("{what}: {} columns, a marker frame has {MARKER_FRAME_LEN}", shape[1])));
        }
        Ok(values.to_vec())
    })
}
