//! Whether an uncalibrated recording can be read with the body model's own placement
//! ([`check_default_placement`]).

use super::*;

/// How far a distance between two markers of one segment may differ from the body model's
/// before the model's placement cannot describe the subject: this share of it, plus
/// [`PLACEMENT_DISTANCE_SLACK_M`].
pub const PLACEMENT_DISTANCE_SHARE: f64 = 0.25;
/// Absolute slack of the placement distance check, m.
pub const PLACEMENT_DISTANCE_SLACK_M: f64 = 0.01;
/// How far beyond a coordinate's range the median posture of an uncalibrated recording may
/// lie, rad (15°: ranges are typical active ones, and a few degrees of misplacement are what
/// the networks were trained to absorb).
pub const PLACEMENT_POSTURE_MARGIN_RAD: f64 = 0.2618;
/// How well the mirror image of an uncalibrated recording must fit the body model's hand about
/// its wrist centre, as a share of how the recording fits it as it is, before the recording is
/// refused as the other arm's. Measured RMS of the fit (see [`hand_about_wrist_residual`]): the
/// arm as it is 0–4 mm, mirrored 10–13 mm, on ikid's simulator (subjects 0.85–1.1×, 5 % noise)
/// and on the exam's other wrist models (anatomical and skin markers); the mirror image of
/// either, the other way round.
pub const MIRROR_FIT_SHARE: f64 = 0.5;
/// ...and the recording as it is must fit worse than this, m: below it no marker set is told
/// from its mirror image (a flat hand, the wrist centre in its markers' plane).
pub const MIRROR_MIN_RESIDUAL_M: f64 = 0.006;
/// The most frames the handedness check fits (evenly spaced over the recording).
const MIRROR_CHECK_FRAMES: usize = 2000;

/// Whether a recording's markers (frames back to back, metres) can be read with the body
/// model's own placement (`body`'s markers: what an uncalibrated stream or tracker assumes).
/// Refused, with what to do instead, when the median distance between two markers of a
/// segment differs from the model's by more than [`PLACEMENT_DISTANCE_SHARE`] (+ slack), or
/// when the median posture read that way lies beyond a coordinate's range (a cluster turned
/// on its segment keeps its distances but reads as a wrist bent past what wrists do). Frames
/// missing a marker are skipped; a recording without a complete frame passes (nothing to
/// judge). Uncalibrated real recordings read 46–171° off without this check.
///
/// `frames` are a `side` arm's as recorded (a left arm is mirrored into a right one here, as
/// its stream does). Markers whose mirror image fits the body model better than they do (by
/// [`MIRROR_FIT_SHARE`], see [`hand_about_wrist_residual`]) are the other arm's, refused
/// naming it: a mirrored arm keeps every distance, and read as the wrong side it came out
/// 47° RMS off in s_p and e_f, every frame unflagged (review 7).
pub fn check_default_placement(frames: &[f64], body: &body::BodyModel, side: Side) -> Result<()> {
    let right: Vec<f64> =
        frames.chunks_exact(3).flat_map(|p| [p[0], p[1], if side == Side::Left { -p[2] } else { p[2] }]).collect();
    let complete: Vec<&[f64]> =
        right.chunks_exact(MARKER_FRAME_LEN).filter(|f| f.iter().all(|v| v.is_finite())).collect();
    if complete.is_empty() {
        return Ok(());
    }
    let advice = "calibrate the subject (ikid calibrate with the styloid and epicondyle landmarks of this session's static \
         trial; its neutral frames alone only for markers at the body model's anatomical points) and pass --calibration";
    for segment in [Segment::Forearm, Segment::Hand] {
        let first = body::first_marker(segment);
        for (a, b) in [(0, 1), (0, 2), (1, 2)] {
            let (i, j) = (first + a, first + b);
            let model = (Vector3::from(body.marker_offsets[i]) - Vector3::from(body.marker_offsets[j])).norm();
            let seen = median(
                complete
                    .iter()
                    .map(|f| {
                        (Vector3::new(f[3 * i], f[3 * i + 1], f[3 * i + 2])
                            - Vector3::new(f[3 * j], f[3 * j + 1], f[3 * j + 2]))
                        .norm()
                    })
                    .collect(),
            );
            if (seen - model).abs() > PLACEMENT_DISTANCE_SHARE * model + PLACEMENT_DISTANCE_SLACK_M {
                return Err(bad(format!(
                    "markers {} and {} are {:.0} mm apart, where the body model puts them {:.0} mm apart: they do not sit where an uncalibrated run assumes; {advice}",
                    body::MARKERS[i].name,
                    body::MARKERS[j].name,
                    seen * 1e3,
                    model * 1e3
                )));
            }
        }
    }
    check_handedness(&complete, body, side)?;
    let mut angles = [Vec::new(), Vec::new(), Vec::new()];
    for f in &complete {
        let narrow: [f32; MARKER_FRAME_LEN] = std::array::from_fn(|i| f[i] as f32);
        let mut q = [0f32; N_COORDINATES];
        if crate::features::FeatureSet::Angles.compute(&narrow, &mut q, 0).is_ok() {
            for (c, v) in q.iter().enumerate() {
                angles[c].push(f64::from(*v));
            }
        }
    }
    if angles[0].is_empty() {
        return Ok(());
    }
    let posture: [f64; N_COORDINATES] = std::array::from_fn(|c| median(angles[c].clone()));
    if let Some(c) = (0..N_COORDINATES).find(|&c| {
        let (lo, hi) = COORDINATES[c].range;
        !(lo - PLACEMENT_POSTURE_MARGIN_RAD..=hi + PLACEMENT_POSTURE_MARGIN_RAD).contains(&posture[c])
    }) {
        return Err(bad(format!(
            "read with the body model's marker placement, the recording's median posture has {} = {:.0}° (its range is {:.0}° to {:.0}°): the markers do not sit where an uncalibrated run assumes; {advice}",
            COORDINATES[c].name,
            posture[c].to_degrees(),
            COORDINATES[c].range.0.to_degrees(),
            COORDINATES[c].range.1.to_degrees()
        )));
    }
    Ok(())
}

/// The median of `v` (the upper one of an even count), which must not be empty.
fn median(mut v: Vec<f64>) -> f64 {
    let mid = v.len() / 2;
    *v.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// Refuses frames (a right arm's, complete) whose mirror image fits the body model's hand
/// about its wrist centre better than they do: the other arm's markers (see
/// [`MIRROR_FIT_SHARE`]). `side` is the arm they were given as, to name.
fn check_handedness(complete: &[&[f64]], body: &body::BodyModel, side: Side) -> Result<()> {
    let step = complete.len().div_ceil(MIRROR_CHECK_FRAMES).max(1);
    let mirror =
        |f: &[f64]| -> [f64; MARKER_FRAME_LEN] { std::array::from_fn(|i| if i % 3 == 2 { -f[i] } else { f[i] }) };
    let (mut as_is, mut mirrored) = (Vec::new(), Vec::new());
    for f in complete.iter().step_by(step) {
        as_is.push(hand_about_wrist_residual(f, body));
        mirrored.push(hand_about_wrist_residual(&mirror(f), body));
    }
    let (as_is, mirrored) = (median(as_is), median(mirrored));
    if as_is > MIRROR_MIN_RESIDUAL_M && mirrored < MIRROR_FIT_SHARE * as_is {
        let other = match side {
            Side::Right => Side::Left,
            Side::Left => Side::Right,
        }
        .name();
        return Err(bad(format!(
            "read as a {} arm, the markers are its mirror image: the hand's markers sit {:.1} mm (RMS, median over \
             the frames) from where the body model puts them about its wrist centre, {:.1} mm mirrored. A {other} arm? \
             Say so in a marker map, side = \"{other}\" (ikid map-template --side {other} FILE prints one; pass \
             it with --map), or calibrate the {other} arm (ikid calibrate --side {other})",
            side.name(),
            as_is * 1e3,
            mirrored * 1e3
        )));
    }
    Ok(())
}

/// How far (RMS, m) the hand's markers of one complete right-arm frame sit from the body
/// model's hand placed about its wrist centre: the forearm's markers place the wrist centre
/// (a rigid fit of the model's forearm markers), the model's hand markers and that centre are
/// fitted to the frame's hand markers and it. Both segments are first scaled to the frame's
/// marker spreads (a subject of another size fits as well). A rotation about the wrist centre
/// fits any posture of a right arm; a left arm's hand is the mirror image of that
/// tetrahedron (its markers ~26 mm out of their plane from the centre), which no rotation fits.
pub fn hand_about_wrist_residual(frame: &[f64], body: &body::BodyModel) -> f64 {
    let point = |f: &[f64], m: usize| Vector3::new(f[3 * m], f[3 * m + 1], f[3 * m + 2]);
    let model = |m: usize| Vector3::from(body.marker_offsets[m]);
    let spread = |points: &[Vector3<f64>]| {
        let c = points.iter().sum::<Vector3<f64>>() / points.len() as f64;
        (points.iter().map(|p| (p - c).norm_squared()).sum::<f64>() / points.len() as f64).sqrt()
    };
    let forearm: Vec<Vector3<f64>> = (0..3).map(|m| point(frame, m)).collect();
    let hand: Vec<Vector3<f64>> = (3..6).map(|m| point(frame, m)).collect();
    let forearm_model: Vec<Vector3<f64>> = (0..3).map(model).collect();
    let hand_model: Vec<Vector3<f64>> = (3..6).map(model).collect();
    let scale = 0.5 * (spread(&forearm) / spread(&forearm_model) + spread(&hand) / spread(&hand_model));
    let scaled = |points: &[Vector3<f64>]| points.iter().map(|p| p * scale).collect::<Vec<_>>();
    // The wrist centre is the forearm frame's origin: the fit's translation.
    let (_, wrist) = crate::cluster::kabsch(&scaled(&forearm_model), &forearm, &[1.0; 3]);
    let mut local = vec![Vector3::zeros()];
    local.extend(scaled(&hand_model));
    let mut lab = vec![wrist];
    lab.extend(hand);
    let (rot, shift) = crate::cluster::kabsch(&local, &lab, &[1.0; 4]);
    (local.iter().zip(&lab).map(|(l, g)| (rot * l + shift - g).norm_squared()).sum::<f64>() / 4.0).sqrt()
}
