//! The mirror method ([`Calibration::mirrored`]): an arm without the landmarks its forearm's
//! frame needs takes the other arm's, when both forearms carry the same cluster mounted alike.
//!
//! Both arms are measured as right arms (a left one mirrored, see the module documentation), so
//! a cluster mounted on the left forearm as the mirror image of the right one's sits, once
//! mirrored, on its forearm as the right one sits on the right forearm: the forearm's technical
//! frame lies in the anatomical frame as the other arm's does, and `T_f` is the other arm's. The
//! hand takes this arm's own neutral posture, as the landmarks method does.
//!
//! What it cannot take on trust, it checks against this arm's own markers:
//! - the cluster's shape: each marker, in the technical frame, within [`MAX_MIRROR_CLUSTER_M`]
//!   of its match in the other arm's (not the same cluster otherwise);
//! - which marker matches which: a cluster that looks the same under another pairing of its
//!   markers (a plate's equilateral triangle: three ways round, and three mirrored) needs a
//!   landmark recorded on this arm too (the lateral epicondyle, say), which must lie within
//!   [`MAX_MIRROR_LANDMARK_DEG`], seen from the cluster, of where the other arm's frame puts it,
//!   and nearer there than under any other pairing the shape allows.

use super::*;

/// Largest distance, metres, between a marker of this arm's forearm cluster (in its technical
/// frame) and its match in the other arm's: more, and the two are not the same cluster.
pub const MAX_MIRROR_CLUSTER_M: f64 = 0.005;
/// Largest angle, degrees, seen from the forearm cluster's centre, between a landmark of this
/// arm and where the other arm's calibration puts it: more, and the clusters are not mounted
/// alike on the two forearms (the mirrored frame would be off by about that much).
pub const MAX_MIRROR_LANDMARK_DEG: f64 = 20.0;

/// A forearm's cluster and landmarks in its technical frame (metres; the arm mirrored into a
/// right arm's): what [`Calibration::mirrored`] takes from the other arm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForearmGeometry {
    /// RSP, USP, FAP (the cluster's three markers).
    pub cluster: [Vector3<f64>; 3],
    /// [`LANDMARKS`], `None` where not measured.
    pub landmarks: [Option<Vector3<f64>>; 4],
}

/// How the two arms matched in [`Calibration::mirrored`].
#[derive(Debug, Clone, PartialEq)]
pub struct MirrorReport {
    /// The arm whose calibration was taken.
    pub from: Side,
    /// Frames of this arm the cluster (and its landmarks) were averaged over.
    pub frames: usize,
    /// Largest distance between a marker of this arm's cluster and its match in the other's, mm.
    pub cluster_mm: f64,
    /// Each landmark of this arm compared ([`LANDMARKS`] index), its distance from where the
    /// other arm's calibration puts it (mm) and the angle between the two seen from the
    /// cluster's centre (degrees).
    pub landmarks: Vec<(usize, f64, f64)>,
    /// Other pairings of this cluster's markers that the shape alone allows (0 for a cluster
    /// whose shape says which marker is which).
    pub other_pairings: usize,
    /// Of those, the smallest landmark angle (degrees; `None` without landmarks): how clearly
    /// the landmarks told the pairing.
    pub next_pairing_deg: Option<f64>,
}

/// The six ways to pair this arm's three forearm markers with the other arm's: `p[k]` is the
/// marker of this arm (in the map's order) that plays the other arm's marker `k`.
const PAIRINGS: [[usize; 3]; 6] = [[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]];

/// This arm's cluster and landmarks, averaged in the technical frame the markers build when
/// taken in the order `pairing`.
struct Seen {
    cluster: [Vector3<f64>; 3],
    landmarks: [Option<Vector3<f64>>; 4],
    frames: usize,
}

fn seen_with(markers: &[f32], landmarks: Option<&[f32]>, pairing: [usize; 3]) -> Result<Seen> {
    let mut cluster = [Vector3::zeros(); 3];
    let mut sums = [Vector3::zeros(); 4];
    let mut counts = [0usize; 4];
    let mut frames = 0usize;
    let mut permuted = [0f32; MARKER_FRAME_LEN];
    for (i, f) in markers.chunks_exact(MARKER_FRAME_LEN).enumerate() {
        if !f[..9].iter().all(|v| v.is_finite()) {
            continue;
        }
        for (k, &m) in pairing.iter().enumerate() {
            permuted[3 * k..3 * k + 3].copy_from_slice(&f[3 * m..3 * m + 3]);
        }
        let (origin, b) = technical_frame(&permuted, Segment::Forearm, i)?;
        let local = |v: &[f32], k: usize| {
            b.transpose() * (Vector3::new(v[3 * k] as f64, v[3 * k + 1] as f64, v[3 * k + 2] as f64) - origin)
        };
        for (k, c) in cluster.iter_mut().enumerate() {
            *c += local(&permuted, k);
        }
        frames += 1;
        if let Some(l) = landmarks {
            let l = &l[i * LANDMARK_FRAME_LEN..(i + 1) * LANDMARK_FRAME_LEN];
            for k in (0..4).filter(|&k| l[3 * k..3 * k + 3].iter().all(|v| v.is_finite())) {
                sums[k] += local(l, k);
                counts[k] += 1;
            }
        }
    }
    Ok(Seen {
        cluster: cluster.map(|c| c / frames.max(1) as f64),
        landmarks: std::array::from_fn(|k| (counts[k] > 0).then(|| sums[k] / counts[k] as f64)),
        frames,
    })
}

/// Largest distance between this arm's cluster and the other's, metres.
fn cluster_mismatch(seen: &Seen, other: &ForearmGeometry) -> f64 {
    (0..3).map(|k| (seen.cluster[k] - other.cluster[k]).norm()).fold(0.0, f64::max)
}

/// Each landmark both arms have: (index, distance m, angle from the cluster's centre, degrees).
fn landmark_mismatch(seen: &Seen, other: &ForearmGeometry) -> Vec<(usize, f64, f64)> {
    (0..4)
        .filter_map(|k| {
            let (mine, theirs) = (seen.landmarks[k]?, other.landmarks[k]?);
            Some((k, (mine - theirs).norm(), mine.angle(&theirs).to_degrees()))
        })
        .collect()
}

fn worst_angle(found: &[(usize, f64, f64)]) -> f64 {
    found.iter().map(|l| l.2).fold(0.0, f64::max)
}

/// "give RSP the label now given to FAP, ..." for a pairing other than the map's.
fn remap(pairing: [usize; 3]) -> String {
    let name = |k: usize| body::MARKERS[body::first_marker(Segment::Forearm) + k].name;
    let moves: Vec<String> = (0..3)
        .filter(|&k| pairing[k] != k)
        .map(|k| format!("give {} the label now given to {}", name(k), name(pairing[k])))
        .collect();
    moves.join(", ")
}

impl Calibration {
    /// Takes the forearm's frame from the other arm's calibration (`other`, with the geometry its
    /// landmarks measured, `other_geometry`) for a forearm whose cluster is the same and mounted
    /// alike, the hand's from this arm's neutral frames ([`Method::Mirror`]; see the module
    /// `mirror`). `landmarks`: whatever landmarks this arm has (NaN = not seen; one, such as the
    /// lateral epicondyle, is enough), with the marker frames they were seen in; they check the
    /// pairing of the cluster's markers and its mounting. `side`: this arm, the other one's
    /// opposite. Refused, saying what to record or change, when the clusters differ, when their
    /// markers could pair more than one way and no landmark tells which, when the map pairs them
    /// differently from what the landmarks show, or when the landmarks show the clusters mounted
    /// differently.
    pub fn mirrored(
        other: &Calibration,
        other_geometry: &ForearmGeometry,
        neutral: &[f32],
        landmarks: Option<LandmarkTrial<'_>>,
        side: Side,
    ) -> Result<(Self, CalibrationReport)> {
        if other.side == side {
            return Err(bad(format!(
                "the mirror method takes the other arm's calibration, and this one is of the {} arm too: give \
                 the {} arm's calibration (measured from its landmarks)",
                side.name(),
                if side == Side::Left { "right" } else { "left" }
            )));
        }
        let held = neutral_posture(neutral, side)?;
        let (mut markers, mut points) = match landmarks {
            Some(t) => {
                let markers = whole_frames(t.markers, MARKER_FRAME_LEN, "landmark trial markers")?.to_vec();
                let points = whole_frames(t.landmarks, LANDMARK_FRAME_LEN, "landmarks")?.to_vec();
                if points.len() / LANDMARK_FRAME_LEN != markers.len() / MARKER_FRAME_LEN {
                    return Err(bad(format!(
                        "{} landmark frames for {} marker frames: give one landmark frame per marker frame",
                        points.len() / LANDMARK_FRAME_LEN,
                        markers.len() / MARKER_FRAME_LEN
                    )));
                }
                (markers, Some(points))
            }
            None => (neutral.to_vec(), None),
        };
        side.to_right(&mut markers);
        if let Some(p) = points.as_mut() {
            side.to_right(p);
        }
        let seen: Vec<Seen> =
            PAIRINGS.iter().map(|&p| seen_with(&markers, points.as_deref(), p)).collect::<Result<_>>()?;
        if seen[0].frames == 0 {
            return Err(bad(
                "no frame has the forearm's three markers: the cluster cannot be compared with the other arm's"
                    .to_string(),
            ));
        }
        let shape: Vec<f64> = seen.iter().map(|s| cluster_mismatch(s, other_geometry)).collect();
        let fits: Vec<usize> = (0..PAIRINGS.len()).filter(|&p| shape[p] <= MAX_MIRROR_CLUSTER_M).collect();
        let found: Vec<Vec<(usize, f64, f64)>> = seen.iter().map(|s| landmark_mismatch(s, other_geometry)).collect();
        let named = |found: &[(usize, f64, f64)]| {
            found
                .iter()
                .map(|&(k, mm, deg)| format!("{} {:.0} mm ({deg:.0}°)", LANDMARKS[k].name, 1e3 * mm))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let not_alike = "mirror takes the other arm's forearm frame only for the same cluster mounted alike on both \
                         forearms: calibrate this arm from its own landmarks (record the epicondyles and styloids) \
                         or with --method functional";
        if found[0].is_empty() && fits.len() > 1 {
            return Err(bad(format!(
                "the forearm's cluster looks the same with its markers paired {} ways with the other arm's (each \
                 within {:.0} mm), so which marker matches which cannot be known from it: record a landmark of \
                 this arm too (the lateral epicondyle, a marker or a probed point, named in the map's \
                 [landmarks]) in the frames calibrated",
                fits.len(),
                1e3 * MAX_MIRROR_CLUSTER_M
            )));
        }
        // The pairing the landmarks (else the shape) say, among those the shape allows.
        let best = if found[0].is_empty() {
            fits.first().copied()
        } else {
            fits.iter().copied().min_by(|&a, &b| worst_angle(&found[a]).total_cmp(&worst_angle(&found[b])))
        };
        match best {
            None => {
                return Err(bad(format!(
                    "the forearm's cluster is not the other arm's: a marker lies {:.1} mm from its match in the \
                     other's mirrored (at most {:.0}, however its markers are paired); {not_alike}",
                    1e3 * shape.iter().copied().fold(f64::INFINITY, f64::min),
                    1e3 * MAX_MIRROR_CLUSTER_M
                )));
            }
            Some(p) if !found[p].is_empty() && worst_angle(&found[p]) > MAX_MIRROR_LANDMARK_DEG => {
                let other_way =
                    if p == 0 { String::new() } else { format!(" (paired another way, {})", named(&found[p])) };
                return Err(bad(format!(
                    "this arm's {} from where the other arm's calibration puts it{other_way}, at most \
                     {MAX_MIRROR_LANDMARK_DEG}° seen from the cluster: the clusters are not mounted alike; {not_alike}",
                    named(&found[0])
                )));
            }
            Some(p) if p != 0 => {
                let as_mapped = if found[0].is_empty() {
                    format!("as the map pairs them a marker lies {:.1} mm from its match", 1e3 * shape[0])
                } else {
                    format!("as the map pairs them, this arm's {}", named(&found[0]))
                };
                let paired = if found[p].is_empty() {
                    format!("a marker within {:.1} mm", 1e3 * shape[p])
                } else {
                    format!("its {}", named(&found[p]))
                };
                return Err(bad(format!(
                    "the map pairs the forearm's markers differently from the other arm's: {as_mapped} from where \
                     the other arm's calibration puts it; paired as the other arm's, {paired}. In this arm's \
                     map, {} (a mirrored cluster's markers go round the other way)",
                    remap(PAIRINGS[p])
                )));
            }
            Some(_) => {}
        }
        let angle = worst_angle(&found[0]);
        let others: Vec<usize> = fits.iter().copied().filter(|&p| p != 0).collect();
        let next = (!found[0].is_empty())
            .then(|| others.iter().map(|&p| worst_angle(&found[p])).fold(f64::INFINITY, f64::min))
            .filter(|d| d.is_finite());
        if let Some(d) = next
            && d <= MAX_MIRROR_LANDMARK_DEG
        {
            return Err(bad(format!(
                "this arm's landmarks fit the other arm's with the cluster's markers paired as mapped ({angle:.0}°) \
                 and paired another way ({d:.0}°): they do not tell which marker is which; record a landmark \
                 farther from the cluster's symmetry (the lateral epicondyle)"
            )));
        }
        let forearm = other.forearm;
        let hand = forearm * held.mean;
        let calibration = Calibration { forearm, hand, side, shapes: None };
        let report = CalibrationReport {
            method: Method::Mirror,
            side,
            movements: Vec::new(),
            placement_deg: calibration.placement_deg(),
            axis_skew_deg: 0.0,
            neutral_frames: held.frames,
            neutral_spread_deg: held.spread_deg,
            neutral_noise_deg: held.noise_deg,
            neutral_uncertainty_deg: held.uncertainty_deg,
            landmarks: None,
            functional: None,
            mirror: Some(MirrorReport {
                from: other.side,
                frames: seen[0].frames,
                cluster_mm: 1e3 * shape[0],
                landmarks: found[0].iter().map(|&(k, m, d)| (k, 1e3 * m, d)).collect(),
                other_pairings: others.len(),
                next_pairing_deg: next,
            }),
        };
        Ok((calibration, report))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::features::FeatureSet;

    /// An equilateral plate (43 mm sides) on a forearm, its two landmarks (lateral epicondyle,
    /// styloids ...) and a hand plate, built by hand in the anatomical frames so that the truth
    /// is known: the right arm's plate turned by `roll` about its normal relative to the left's
    /// mirror image, and the left arm's angles `q` (flexion etc.) per frame. Returns frames and
    /// landmark frames of each arm (lab; the left arm the mirror image, z negated, of a right
    /// arm placed elsewhere and turned).
    fn plate(centre: Vector3<f64>, normal_turn: f64) -> [Vector3<f64>; 3] {
        // In the forearm's anatomical frame (x volar, y proximal, z radial): the plate on the
        // dorsal side (-x), its triangle in the y-z plane.
        let r = 0.043 / 3f64.sqrt();
        std::array::from_fn(|k| {
            let a = normal_turn + k as f64 * std::f64::consts::TAU / 3.0;
            centre + Vector3::new(0.0, r * a.cos(), r * a.sin())
        })
    }

    #[derive(Debug)]
    struct Arm {
        markers: Vec<f32>,
        landmarks: Vec<f32>,
    }

    /// One arm in the lab, as a right arm (mirror it for a left one): forearm frame `pose`,
    /// landmarks at the ISB places, the hand turned by the angles `q` (ikid's order) each frame.
    fn arm(pose: &Rotation3<f64>, at: Vector3<f64>, turn: f64, q: &[[f64; 3]], mirror: bool) -> Arm {
        let forearm_plate = plate(Vector3::new(-0.03, 0.08, 0.0), turn);
        let hand_plate = plate(Vector3::new(-0.025, -0.06, 0.0), 0.3);
        // Landmarks in the forearm's frame: epicondyles 250 mm proximal, styloids at the origin.
        let lms = [
            Vector3::new(0.0, 0.25, 0.035),
            Vector3::new(0.0, 0.25, -0.035),
            Vector3::new(0.0, 0.0, 0.028),
            Vector3::new(0.0, 0.0, -0.028),
        ];
        let mut markers = Vec::new();
        let mut landmarks = Vec::new();
        let m = if mirror { Vector3::new(1.0, 1.0, -1.0) } else { Vector3::new(1.0, 1.0, 1.0) };
        for qi in q {
            let hand = body::wrist_rotation(qi);
            let lab = |p: Vector3<f64>| (at + pose * p).component_mul(&m);
            for p in forearm_plate {
                markers.extend(lab(p).iter().map(|&v| v as f32));
            }
            for p in hand_plate {
                markers.extend(lab(hand * p).iter().map(|&v| v as f32));
            }
            for p in lms {
                landmarks.extend(lab(p).iter().map(|&v| v as f32));
            }
        }
        Arm { markers, landmarks }
    }

    fn q_path(n: usize) -> Vec<[f64; 3]> {
        (0..n)
            .map(|i| {
                let t = i as f64 / n as f64 * std::f64::consts::TAU;
                [0.4 * t.sin(), 0.7 * (2.0 * t).sin(), 0.25 * t.cos()]
            })
            .collect()
    }

    fn right_calibration(turn: f64) -> (Calibration, ForearmGeometry) {
        let pose = Rotation3::from_euler_angles(0.3, -0.5, 0.8);
        let r = arm(&pose, Vector3::new(0.2, 1.0, 0.3), turn, &[[0.0; 3]; 10], false);
        let trial = LandmarkTrial { markers: &r.markers, landmarks: &r.landmarks, hand_landmarks: None };
        let (cal, report) = Calibration::from_neutral(&r.markers, Some(trial), Side::Right).unwrap();
        (cal, report.landmarks.unwrap().geometry)
    }

    /// The left arm: neutral frames, a movement with known angles, and only its lateral epicondyle.
    fn left(turn: f64, reorder: [usize; 3]) -> (Arm, Arm) {
        let pose = Rotation3::from_euler_angles(-0.6, 0.2, 2.0);
        let at = Vector3::new(-0.1, 0.9, 0.4);
        let mut neutral = arm(&pose, at, turn, &[[0.0; 3]; 10], true);
        let mut moving = arm(&pose, at, turn, &q_path(50), true);
        for a in [&mut neutral, &mut moving] {
            for f in a.markers.chunks_exact_mut(MARKER_FRAME_LEN) {
                let orig: Vec<f32> = f[..9].to_vec();
                for (k, &m) in reorder.iter().enumerate() {
                    f[3 * k..3 * k + 3].copy_from_slice(&orig[3 * m..3 * m + 3]);
                }
            }
            for l in a.landmarks.chunks_exact_mut(LANDMARK_FRAME_LEN) {
                l[3..].fill(f32::NAN); // the left arm has its lateral epicondyle only
            }
        }
        (neutral, moving)
    }

    fn mirror(turn_right: f64, turn_left: f64, reorder: [usize; 3]) -> Result<(Calibration, CalibrationReport, Arm)> {
        let (right, geometry) = right_calibration(turn_right);
        let (neutral, moving) = left(turn_left, reorder);
        let trial = LandmarkTrial { markers: &neutral.markers, landmarks: &neutral.landmarks, hand_landmarks: None };
        let (cal, report) = Calibration::mirrored(&right, &geometry, &neutral.markers, Some(trial), Side::Left)?;
        Ok((cal, report, moving))
    }

    #[test]
    fn a_mirrored_cluster_reads_the_left_arms_true_angles() {
        let (cal, report, moving) = mirror(0.0, 0.0, [0, 1, 2]).unwrap();
        let m = report.mirror.as_ref().unwrap();
        assert_eq!((report.method, m.from, m.frames), (Method::Mirror, Side::Right, 10));
        assert!(m.cluster_mm < 1e-3 && m.landmarks.len() == 1 && m.landmarks[0].2 < 1e-3, "{m:?}");
        // The plate is equilateral: two more pairings fit its shape, the epicondyle tells them apart.
        assert_eq!(m.other_pairings, 5, "{m:?}");
        assert!(m.next_pairing_deg.unwrap() > MAX_MIRROR_LANDMARK_DEG, "{m:?}");
        let q = q_path(50);
        for (i, f) in moving.markers.chunks_exact(MARKER_FRAME_LEN).enumerate() {
            let mut f = f.to_vec();
            cal.apply(&mut f, i).unwrap();
            let mut out = [0f32; 3];
            FeatureSet::Angles.compute(&f, &mut out, i).unwrap();
            for k in 0..3 {
                assert!((out[k] as f64 - q[i][k]).abs() < 1e-4, "frame {i}: {out:?} vs {:?}", q[i]);
            }
        }
    }

    #[test]
    fn a_landmark_is_averaged_over_the_frames_it_is_seen_in() {
        // The left arm's lateral epicondyle unseen in 4 of its 10 frames: taken from the other
        // six, where it sits exactly where the right arm's calibration puts it.
        let (right, geometry) = right_calibration(0.0);
        let (mut neutral, moving) = left(0.0, [0, 1, 2]);
        for l in neutral.landmarks.chunks_exact_mut(LANDMARK_FRAME_LEN).take(4) {
            l[..3].fill(f32::NAN);
        }
        let trial = LandmarkTrial { markers: &neutral.markers, landmarks: &neutral.landmarks, hand_landmarks: None };
        let (cal, report) =
            Calibration::mirrored(&right, &geometry, &neutral.markers, Some(trial), Side::Left).unwrap();
        let m = report.mirror.as_ref().unwrap();
        assert_eq!(m.landmarks.len(), 1, "{m:?}");
        let (k, distance, angle) = m.landmarks[0];
        assert!(k == 0 && distance < 1e-3 && angle < 1e-3, "{m:?}"); // mm and degrees
        let q = q_path(50);
        let mut f = moving.markers[..MARKER_FRAME_LEN].to_vec();
        cal.apply(&mut f, 0).unwrap();
        let mut out = [0f32; 3];
        FeatureSet::Angles.compute(&f, &mut out, 0).unwrap();
        for c in 0..3 {
            assert!((out[c] as f64 - q[0][c]).abs() < 1e-4, "{out:?} vs {:?}", q[0]);
        }
    }

    #[test]
    fn a_map_pairing_the_markers_otherwise_is_told_how_to_pair_them() {
        // The left plate's markers named in the other order: the third where the right's first is.
        let err = mirror(0.0, 0.0, [2, 1, 0]).unwrap_err().to_string();
        assert!(err.contains("the map pairs the forearm's markers differently"), "{err}");
        assert!(err.contains("give RSP the label now given to FAP, give FAP the label now given to RSP"), "{err}");
    }

    #[test]
    fn clusters_mounted_otherwise_are_refused() {
        // The left plate turned 40° about its normal relative to the right's mirror image.
        let err = mirror(0.0, 40f64.to_radians(), [0, 1, 2]).unwrap_err().to_string();
        assert!(err.contains("the clusters are not mounted alike"), "{err}");
        // Turned 25° the other way: the map's pairing is still the closest one (the others read
        // farther off), so the refusal names no other pairing. The epicondyle, 173.6 mm from the
        // plate's normal through its centre (and 30 mm along it), moves by a chord of
        // 2 × 173.6 × sin 12.5° = 75 mm, seen 24.6° off from the plate's centre.
        let err = mirror(0.0, -25f64.to_radians(), [0, 1, 2]).unwrap_err().to_string();
        assert!(
            err.contains(
                "this arm's lateral_epicondyle 75 mm (25°) from where the other arm's calibration puts it, at most 20°"
            ),
            "{err}"
        );
        // Turned 8°: accepted, the angle reported.
        let (_, report, _) = mirror(0.0, 8f64.to_radians(), [0, 1, 2]).unwrap();
        let deg = report.mirror.unwrap().landmarks[0].2;
        assert!((2.0..12.0).contains(&deg), "{deg}");
    }

    #[test]
    fn a_symmetric_cluster_without_a_landmark_is_refused_saying_to_record_one() {
        let (right, geometry) = right_calibration(0.0);
        let (neutral, _) = left(0.0, [0, 1, 2]);
        let err = Calibration::mirrored(&right, &geometry, &neutral.markers, None, Side::Left).unwrap_err().to_string();
        assert!(err.contains("paired 6 ways") && err.contains("record a landmark of this arm too"), "{err}");
    }

    #[test]
    fn another_cluster_and_the_same_side_are_refused() {
        let (right, mut geometry) = right_calibration(0.0);
        geometry.cluster[0].x += 0.01; // one marker 10 mm higher off the plate
        let (neutral, _) = left(0.0, [0, 1, 2]);
        let trial = LandmarkTrial { markers: &neutral.markers, landmarks: &neutral.landmarks, hand_landmarks: None };
        let err = Calibration::mirrored(&right, &geometry, &neutral.markers, Some(trial), Side::Left)
            .unwrap_err()
            .to_string();
        assert!(err.contains("the forearm's cluster is not the other arm's"), "{err}");
        let err = Calibration::mirrored(&right, &geometry, &neutral.markers, Some(trial), Side::Right)
            .unwrap_err()
            .to_string();
        assert!(err.contains("this one is of the right arm too"), "{err}");
    }
}
