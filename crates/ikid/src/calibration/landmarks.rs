//! Segment frames from anatomical landmarks: the forearm's ISB frame from the epicondyles and
//! styloids, the hand's from the metacarpal heads (used by [`Calibration::from_neutral`]).

use super::*;

/// The forearm's ISB anatomical frame from its landmarks (mirrored into a right arm's for a
/// left one): `T_f`, and what the landmarks measured.
pub(super) fn forearm_from_landmarks(trial: LandmarkTrial<'_>, side: Side) -> Result<(Rotation3<f64>, LandmarkReport)> {
    let mut markers = whole_frames(trial.markers, MARKER_FRAME_LEN, "landmark trial markers")?.to_vec();
    let mut landmarks = whole_frames(trial.landmarks, LANDMARK_FRAME_LEN, "landmarks")?.to_vec();
    let n = markers.len() / MARKER_FRAME_LEN;
    if landmarks.len() / LANDMARK_FRAME_LEN != n {
        return Err(bad(format!(
            "{} landmark frames for {n} marker frames: give one landmark frame per marker frame",
            landmarks.len() / LANDMARK_FRAME_LEN
        )));
    }
    side.to_right(&mut markers);
    side.to_right(&mut landmarks);
    let mut sums = [Vector3::zeros(); 4];
    let mut counts = [0usize; 4];
    // The cluster's own shape in its technical frame, over the same frames.
    let mut cluster = [Vector3::zeros(); 3];
    let mut cluster_frames = 0usize;
    let mut seen_anywhere = [0usize; 4];
    for (i, (f, l)) in
        markers.chunks_exact(MARKER_FRAME_LEN).zip(landmarks.chunks_exact(LANDMARK_FRAME_LEN)).enumerate()
    {
        let seen: [bool; 4] = std::array::from_fn(|k| l[3 * k..3 * k + 3].iter().all(|v| v.is_finite()));
        for k in 0..4 {
            seen_anywhere[k] += seen[k] as usize;
        }
        if !f[..9].iter().all(|v| v.is_finite()) || !seen.iter().any(|&s| s) {
            continue;
        }
        let (origin, b) = technical_frame(f, Segment::Forearm, i)?;
        for (k, c) in cluster.iter_mut().enumerate() {
            let p = Vector3::new(f[3 * k] as f64, f[3 * k + 1] as f64, f[3 * k + 2] as f64);
            *c += b.transpose() * (p - origin);
        }
        cluster_frames += 1;
        for k in (0..4).filter(|&k| seen[k]) {
            let p = Vector3::new(l[3 * k] as f64, l[3 * k + 1] as f64, l[3 * k + 2] as f64);
            sums[k] += b.transpose() * (p - origin);
            counts[k] += 1;
        }
    }
    if let Some(k) = (0..4).find(|&k| counts[k] == 0) {
        let how = if seen_anywhere[k] == 0 {
            "is missing in every one".to_string()
        } else {
            format!("is seen in {} but never with the forearm's three markers", seen_anywhere[k])
        };
        return Err(bad(format!(
            "landmark {} ({}) {how} of the {n} calibration frames: record it (a marker on it in the static \
             trial, or a point probed relative to the forearm cluster) in frames where the forearm's \
             markers are seen, or calibrate from the neutral posture alone",
            LANDMARKS[k].name, LANDMARKS[k].description
        )));
    }
    let [le, me, rs, us]: [Vector3<f64>; 4] = std::array::from_fn(|k| sums[k] / counts[k] as f64);
    let long = (le + me) / 2.0 - (rs + us) / 2.0;
    let across = rs - us;
    let what_to_record = "record the epicondyles at the elbow and the styloids either side of the wrist, each \
                          labelled as the marker map says";
    if long.norm() < MIN_FOREARM_AXIS_M {
        return Err(bad(format!(
            "the mid-styloids are {:.0} mm from the mid-epicondyles (at least {:.0}): the landmarks do not \
             span the forearm; {what_to_record}",
            1e3 * long.norm(),
            1e3 * MIN_FOREARM_AXIS_M
        )));
    }
    if across.norm() < MIN_STYLOID_SPAN_M {
        return Err(bad(format!(
            "the radial and ulnar styloids are {:.1} mm apart (at least {:.0}); {what_to_record}",
            1e3 * across.norm(),
            1e3 * MIN_STYLOID_SPAN_M
        )));
    }
    // The markers the landmarks are measured against must be on the forearm they span: their
    // centroid, the technical frame's origin, near the segment from the mid-styloids (`distal`)
    // to the mid-epicondyles.
    let distal = (rs + us) / 2.0;
    let along = (-distal.dot(&long) / long.norm_squared()).clamp(0.0, 1.0);
    let off_forearm = (distal + along * long).norm();
    if off_forearm > MAX_CLUSTER_FROM_FOREARM_M {
        return Err(bad(format!(
            "the forearm's markers are {:.0} mm from the forearm its landmarks span (the line from the \
             mid-styloids to the mid-epicondyles; at most {:.0} mm): the landmarks are not on the arm those \
             markers are on (another arm's, or another subject's labels); name in [landmarks] the landmarks \
             of the arm whose markers [markers] names",
            1e3 * off_forearm,
            1e3 * MAX_CLUSTER_FROM_FOREARM_M
        )));
    }
    let styloid_axis_deg = long.angle(&across).to_degrees();
    if styloid_axis_deg.min(180.0 - styloid_axis_deg) < MIN_LANDMARK_ANGLE_DEG {
        return Err(bad(format!(
            "the landmarks are nearly collinear: the styloid line is {styloid_axis_deg:.0}° from the forearm's \
             long axis (at least {MIN_LANDMARK_ANGLE_DEG}° from it); {what_to_record}"
        )));
    }
    let y = long.normalize();
    if let Some(turn) = forearm_turn_deg(&y, &(le - me), &across)
        && (MIRRORED_TURN_DEG.0..MIRRORED_TURN_DEG.1).contains(&turn)
    {
        return Err(bad(format!(
            "the styloid line (ulnar to radial) is turned {turn:.0}° from the epicondyle line (medial to \
             lateral) about the forearm's long axis, the other way than a {side} forearm turns it (0° supinated \
             to 180° pronated): the radial and ulnar styloids, or the lateral and medial epicondyles, are \
             under each other's labels, or the arm is not a {side} one; every flexion and deviation would \
             read mirrored. Check the [landmarks] labels and the map's side",
            side = side.name()
        )));
    }
    let x = y.cross(&across).normalize();
    let z = x.cross(&y);
    // Columns: the anatomical axes in technical coordinates, A; T_f = Aᵀ.
    let axes = Matrix3::from_columns(&[x, y, z]);
    let report = LandmarkReport {
        frames: counts,
        long_axis_mm: 1e3 * long.norm(),
        styloid_span_mm: 1e3 * across.norm(),
        epicondyle_span_mm: 1e3 * (le - me).norm(),
        styloid_axis_deg,
        length_scale: long.norm() / body::BodyModel::default().forearm.length,
        hand: None,
        geometry: ForearmGeometry {
            cluster: cluster.map(|c| c / cluster_frames as f64),
            landmarks: [le, me, rs, us].map(Some),
        },
    };
    Ok((Rotation3::from_matrix_unchecked(axes.transpose()), report))
}

/// The turn of the styloid line `across` (ulnar to radial) from the epicondyle line
/// `epicondyles` (medial to lateral) about the forearm's long axis `y` (unit, proximal),
/// degrees in (-180, 180], positive the way a right forearm pronates; `None` when the
/// epicondyles do not span [`MIN_EPICONDYLE_SPAN_M`] across the axis.
fn forearm_turn_deg(y: &Vector3<f64>, epicondyles: &Vector3<f64>, across: &Vector3<f64>) -> Option<f64> {
    let e = epicondyles - y * y.dot(epicondyles);
    let s = across - y * y.dot(across);
    (e.norm() >= MIN_EPICONDYLE_SPAN_M).then(|| y.dot(&e.cross(&s)).atan2(e.dot(&s)).to_degrees())
}

/// The hand's anatomical frame from its landmarks and the styloids (mirrored into a right
/// arm's for a left one): `T_h`, and what the landmarks measured (its neutral offset left 0).
pub(super) fn hand_from_landmarks(
    trial: LandmarkTrial<'_>,
    side: Side,
) -> Result<(Rotation3<f64>, HandLandmarkReport)> {
    let hand_points = trial.hand_landmarks.expect("called with hand landmarks");
    let n = trial.markers.len() / MARKER_FRAME_LEN;
    let mut hand_points = whole_frames(hand_points, HAND_LANDMARK_FRAME_LEN, "hand landmarks")?.to_vec();
    if hand_points.len() / HAND_LANDMARK_FRAME_LEN != n {
        return Err(bad(format!(
            "{} hand landmark frames for {n} marker frames: give one per marker frame",
            hand_points.len() / HAND_LANDMARK_FRAME_LEN
        )));
    }
    let mut markers = trial.markers.to_vec();
    let mut landmarks = trial.landmarks.to_vec();
    side.to_right(&mut markers);
    side.to_right(&mut landmarks);
    side.to_right(&mut hand_points);
    let point = |v: &[f32], k: usize| Vector3::new(v[3 * k] as f64, v[3 * k + 1] as f64, v[3 * k + 2] as f64);
    let seen = |v: &[f32], k: usize| v[3 * k..3 * k + 3].iter().all(|x| x.is_finite());
    let (mut wrist, mut second, mut fifth, mut count) = (Vector3::zeros(), Vector3::zeros(), Vector3::zeros(), 0usize);
    for (i, ((f, l), h)) in markers
        .chunks_exact(MARKER_FRAME_LEN)
        .zip(landmarks.chunks_exact(LANDMARK_FRAME_LEN))
        .zip(hand_points.chunks_exact(HAND_LANDMARK_FRAME_LEN))
        .enumerate()
    {
        if !(f[9..].iter().all(|v| v.is_finite()) && seen(l, 2) && seen(l, 3) && seen(h, 0) && seen(h, 1)) {
            continue;
        }
        let (origin, b) = technical_frame(f, Segment::Hand, i)?;
        let local = |p: Vector3<f64>| b.transpose() * (p - origin);
        wrist += local((point(l, 2) + point(l, 3)) / 2.0);
        second += local(point(h, 0));
        fifth += local(point(h, 1));
        count += 1;
    }
    let what_to_record = "record the second and fifth metacarpal heads (knuckles) with the styloids and the \
                          hand's three markers in the same frames, or leave the hand landmarks out (the hand then \
                          equals the forearm at the neutral posture)";
    if count == 0 {
        return Err(bad(format!(
            "no frame of the {n} has the hand's three markers, both metacarpal heads and both styloids; \
             {what_to_record}"
        )));
    }
    let (wrist, second, fifth) = (wrist / count as f64, second / count as f64, fifth / count as f64);
    let long = wrist - (second + fifth) / 2.0;
    let across = second - fifth;
    if long.norm() < MIN_HAND_AXIS_M || across.norm() < MIN_STYLOID_SPAN_M {
        return Err(bad(format!(
            "the metacarpal heads are {:.0} mm from the mid-styloids and {:.1} mm apart (at least {:.0} and \
             {:.0}): they do not span the hand; {what_to_record}",
            1e3 * long.norm(),
            1e3 * across.norm(),
            1e3 * MIN_HAND_AXIS_M,
            1e3 * MIN_STYLOID_SPAN_M
        )));
    }
    let angle = long.angle(&across).to_degrees();
    if angle.min(180.0 - angle) < MIN_LANDMARK_ANGLE_DEG {
        return Err(bad(format!(
            "the hand's landmarks are nearly collinear: the metacarpal heads' line is {angle:.0}° from the \
             hand's long axis (at least {MIN_LANDMARK_ANGLE_DEG}° from it); {what_to_record}"
        )));
    }
    let y = long.normalize();
    let x = y.cross(&across).normalize();
    let z = x.cross(&y);
    let report = HandLandmarkReport {
        frames: count,
        long_axis_mm: 1e3 * long.norm(),
        metacarpal_span_mm: 1e3 * across.norm(),
        neutral_offset_deg: 0.0,
    };
    Ok((Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z]).transpose()), report))
}
