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

/// Whether a recording's markers (frames back to back, metres) can be read with the body
/// model's own placement (`body`'s markers: what an uncalibrated stream or tracker assumes).
/// Refused, with what to do instead, when the median distance between two markers of a
/// segment differs from the model's by more than [`PLACEMENT_DISTANCE_SHARE`] (+ slack), or
/// when the median posture read that way lies beyond a coordinate's range (a cluster turned
/// on its segment keeps its distances but reads as a wrist bent past what wrists do). Frames
/// missing a marker are skipped; a recording without a complete frame passes (nothing to
/// judge). Uncalibrated real recordings read 46–171° off without this check.
pub fn check_default_placement(frames: &[f64], body: &body::BodyModel) -> Result<()> {
    let complete: Vec<&[f64]> =
        frames.chunks_exact(MARKER_FRAME_LEN).filter(|f| f.iter().all(|v| v.is_finite())).collect();
    if complete.is_empty() {
        return Ok(());
    }
    let median = |mut v: Vec<f64>| {
        let mid = v.len() / 2;
        *v.select_nth_unstable_by(mid, f64::total_cmp).1
    };
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
