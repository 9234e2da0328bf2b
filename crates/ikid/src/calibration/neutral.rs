//! The neutral posture, and the landmarks method built on it ([`Calibration::from_neutral`]):
//! the hand held still, the forearm from its landmarks or at the body model's placement
//! (refused where its markers do not sit there).

use super::*;

impl Calibration {
    /// Measures the calibration from frames of the neutral posture (a static trial, or chosen
    /// frames of any trial; all wrist angles read zero there) and, when given, the forearm's
    /// landmarks ([`Method::Landmarks`]); without them the forearm keeps the body model's
    /// placement ([`Method::Neutral`]). With the hand's landmarks too (the second and fifth
    /// metacarpal heads), the hand's frame is its own: `y` from the mid-heads to the
    /// mid-styloids, `x = y × (fifth → second head)`, `z = x × y`, as the forearm's; the
    /// neutral posture then reads what the anatomical frames say, not zero. Frames may miss markers (NaN): the hand's neutral
    /// posture is averaged over the frames with all six markers, each landmark over the
    /// frames where it and the forearm's three markers are seen. Clusters may sit at any
    /// orientation. `side` is the arm the frames show (a left one is mirrored, see the module
    /// documentation).
    pub fn from_neutral(
        neutral: &[f32],
        landmarks: Option<LandmarkTrial<'_>>,
        side: Side,
    ) -> Result<(Self, CalibrationReport)> {
        let frames = neutral;
        let held = neutral_posture(frames, side)?;
        let neutral = held.mean;
        let default = Self::body_model();
        let (method, forearm, mut landmark_report) = match landmarks {
            None => {
                check_forearm_placement(frames)?;
                (Method::Neutral, default.forearm, None)
            }
            Some(trial) => {
                let (forearm, report) = forearm_from_landmarks(trial, side)?;
                (Method::Landmarks, forearm, Some(report))
            }
        };
        let mut hand = forearm * neutral;
        if let (Some(trial), Some(report)) = (landmarks, landmark_report.as_mut())
            && trial.hand_landmarks.is_some()
        {
            let (own, mut hand_report) = hand_from_landmarks(trial, side)?;
            hand_report.neutral_offset_deg = angle_deg(&(own * hand.inverse()));
            hand = own;
            report.hand = Some(hand_report);
        }
        let report = CalibrationReport {
            method,
            side,
            movements: Vec::new(),
            placement_deg: Calibration { forearm, hand, side, shapes: None }.placement_deg(),
            axis_skew_deg: 0.0,
            neutral_frames: held.frames,
            neutral_spread_deg: held.spread_deg,
            neutral_noise_deg: held.noise_deg,
            neutral_uncertainty_deg: held.uncertainty_deg,
            landmarks: landmark_report,
            functional: None,
            mirror: None,
        };
        Ok((Calibration { forearm, hand, side, shapes: None }, report))
    }
}

/// The hand's rotation in the forearm (`B_fᵀB_h`, technical frames) at the neutral posture:
/// held over the frames with all six markers (a left arm's mirrored first; [`HeldPosture`]).
/// Refused when fewer than [`MIN_NEUTRAL_FRAMES`] are complete or the hand moves more than
/// [`MAX_STATIC_SPREAD_DEG`].
pub(super) fn neutral_posture(neutral: &[f32], side: Side) -> Result<HeldPosture> {
    let mut frames = whole_frames(neutral, MARKER_FRAME_LEN, "neutral frames")?.to_vec();
    side.to_right(&mut frames);
    let n = frames.len() / MARKER_FRAME_LEN;
    let mut relative = Vec::new();
    let mut unseen = [0usize; 6];
    for (i, f) in frames.chunks_exact(MARKER_FRAME_LEN).enumerate() {
        let mut complete = true;
        for (m, count) in unseen.iter_mut().enumerate() {
            if !f[3 * m..3 * m + 3].iter().all(|v| v.is_finite()) {
                *count += 1;
                complete = false;
            }
        }
        if complete {
            let (_, b_f) = technical_frame(f, Segment::Forearm, i)?;
            let (_, b_h) = technical_frame(f, Segment::Hand, i)?;
            relative.push(Rotation3::from_matrix_unchecked(b_f.transpose() * b_h));
        }
    }
    let missing: Vec<String> = unseen
        .iter()
        .enumerate()
        .filter(|&(_, &c)| c > 0)
        .map(|(m, c)| format!("{} in {c}", body::MARKERS[m].name))
        .collect();
    if relative.is_empty() {
        return Err(bad(format!(
            "no usable neutral frame: none of the {n} has all six markers (missing: {}); choose frames of \
             the neutral posture where every marker is seen, or record a static trial with all six",
            if missing.is_empty() { "none, but there are no frames".to_string() } else { missing.join(", ") }
        )));
    }
    if relative.len() < MIN_NEUTRAL_FRAMES {
        let counted = if missing.is_empty() {
            format!(
                "{n} neutral frame{}",
                if n == 1 { ", with all six markers" } else { "s, each with all six markers" }
            )
        } else {
            format!("{} of the {n} neutral frames have all six markers", relative.len())
        };
        let lost = if missing.is_empty() { String::new() } else { format!("; missing: {}", missing.join(", ")) };
        return Err(bad(format!(
            "{counted} (at least {MIN_NEUTRAL_FRAMES} are needed: one frame's noise would be the calibration's \
             error{lost}); choose more frames of the neutral posture where every marker is seen (a task \
             trial's, if the static trial lost a marker), or record a static trial of a second or more with all \
             six"
        )));
    }
    let held = HeldPosture::of(&relative);
    if held.spread_deg > MAX_STATIC_SPREAD_DEG {
        return Err(bad(format!(
            "the hand moves {:.1}° within the neutral frames, its markers' noise ({:.1}° a frame) averaged out \
             (at most {MAX_STATIC_SPREAD_DEG}°): choose frames where the wrist holds one posture",
            held.spread_deg, held.noise_deg
        )));
    }
    Ok(held)
}

/// Refuses neutral frames whose forearm markers do not sit where the body model puts RSP, USP
/// and FAP — the neutral method keeps that placement for the forearm, so it cannot know any
/// other: the median distance between two of the forearm's markers must be the model's, for a
/// subject of any size the scale of the triangle fits within [`SUBJECT_SCALES`], each within
/// [`PLACEMENT_DISTANCE_SHARE`] (+ [`PLACEMENT_DISTANCE_SLACK_M`]), as the uncalibrated path
/// checks. A cluster (a plate's 4 cm sides against the model's 17 cm) is refused with what to
/// record instead.
pub(super) fn check_forearm_placement(frames: &[f32]) -> Result<()> {
    let body = body::BodyModel::default();
    let complete: Vec<&[f32]> =
        frames.chunks_exact(MARKER_FRAME_LEN).filter(|f| f[..9].iter().all(|v| v.is_finite())).collect();
    if complete.is_empty() {
        return Ok(()); // neutral_posture has refused these frames already
    }
    let pairs = [(0, 1), (0, 2), (1, 2)];
    let point = |f: &[f32], m: usize| Vector3::new(f[3 * m] as f64, f[3 * m + 1] as f64, f[3 * m + 2] as f64);
    let seen: [f64; 3] = pairs.map(|(i, j)| {
        let mut d: Vec<f64> = complete.iter().map(|f| (point(f, i) - point(f, j)).norm()).collect();
        let mid = d.len() / 2;
        *d.select_nth_unstable_by(mid, f64::total_cmp).1
    });
    let model: [f64; 3] =
        pairs.map(|(i, j)| (Vector3::from(body.marker_offsets[i]) - Vector3::from(body.marker_offsets[j])).norm());
    let fitted = seen.iter().zip(&model).map(|(s, m)| s * m).sum::<f64>() / model.iter().map(|m| m * m).sum::<f64>();
    let scale = fitted.clamp(SUBJECT_SCALES.0, SUBJECT_SCALES.1);
    for (k, (i, j)) in pairs.into_iter().enumerate() {
        let expected = scale * model[k];
        if (seen[k] - expected).abs() > PLACEMENT_DISTANCE_SHARE * expected + PLACEMENT_DISTANCE_SLACK_M {
            return Err(bad(format!(
                "the neutral method keeps the body model's placement of the forearm's markers, and these do not \
                 sit there: {} and {} are {:.0} mm apart where the model puts them {:.0} mm apart (for a subject \
                 {scale:.2}× its size), so the forearm's axes cannot be known from them. Record the epicondyles \
                 and styloids (markers in a static trial, or points probed relative to the forearm's markers) \
                 and calibrate with --method landmarks, or record the wrist moving through flexion and \
                 deviation together with the forearm still (--method functional)",
                body::MARKERS[i].name,
                body::MARKERS[j].name,
                1e3 * seen[k],
                1e3 * expected
            )));
        }
    }
    Ok(())
}

/// Sizes of subjects the neutral method's placement check allows, as the body model's length
/// factor: from a small adult's forearm to a tall one's.
pub const SUBJECT_SCALES: (f64, f64) = (0.75, 1.35);
