//! Where each marker sits on its segment: a calibration's template, taken from the subject's
//! own first frames, and each marker's recent place (skin markers slide); the rigid fit of a
//! segment to three points.

use nalgebra::{Isometry3, Vector3};

use super::Tracker;
use super::centre::JointCentre;
use crate::body::{self, MARKER_FRAME_LEN, Segment};
use crate::features::technical_frame;

/// How long a calibrated segment's template is averaged over (see `Tracker::take_template`):
/// the calibration's, as a stream's marker shapes.
pub use crate::calibration::TEMPLATE_S;
/// The rigid fit of a segment to three points (shared with the calibration's streams).
pub(crate) use crate::reference::fit_points;

/// How long a marker's recent placement on its segment looks back, s (see [`Tracker::push`]):
/// skin markers slide with the posture, and the pose from two of a segment's markers is the
/// three's only with the two where they sit now, not where they sat when the shape was taken.
pub const LIVE_PLACEMENT_S: f64 = 0.1;

impl Tracker {
    /// Places `segment`'s markers in the body model as the calibration says: the markers of
    /// `frame` in the segment's technical frame, turned into its anatomical frame; averaged
    /// over the segment's first [`TEMPLATE_S`] of complete, rigid frames (one noisy frame puts
    /// a template millimetres off, and every angle after it by as much as that turns the
    /// segment). Only the first frame resets what was learned in the old placement.
    pub(super) fn take_template(&mut self, segment: Segment, frame: &[f64]) {
        let Some(calibration) = self.calibration.as_ref() else { return };
        let narrow: [f32; MARKER_FRAME_LEN] = std::array::from_fn(|i| frame[i] as f32);
        let Ok((origin, technical)) = technical_frame(&narrow, segment, 0) else { return };
        let t = match segment {
            Segment::Forearm => calibration.forearm,
            Segment::Hand => calibration.hand,
        };
        let s = segment as usize;
        let first_take = !self.templated[s];
        // The calibration's own shape, measured with its rotations, once per start (a shape
        // relearned later, a marker that moved on its segment, is the trial's).
        let calibrated = calibration.shapes.filter(|_| first_take && self.template_frames[s] == 0);
        self.template_frames[s] = if calibrated.is_some() {
            ((TEMPLATE_S * self.settings.rate_hz).ceil() as usize).max(1)
        } else if first_take {
            1
        } else {
            self.template_frames[s] + 1
        };
        let weight = 1.0 / self.template_frames[s] as f64;
        let first = body::first_marker(segment);
        for k in first..first + 3 {
            let p = Vector3::new(frame[3 * k], frame[3 * k + 1], frame[3 * k + 2]);
            let local = t * calibrated.map_or_else(|| technical.transpose() * (p - origin), |c| c[s][k - first]);
            let offset = Vector3::from(self.body.marker_offsets[k]);
            let mean = if first_take { local } else { offset + weight * (local - offset) };
            self.body.marker_offsets[k] = [mean.x, mean.y, mean.z];
            if first_take {
                self.live[k] = local;
            }
        }
        if first_take {
            self.templated[s] = true;
            self.shapes[s].template = self.shapes[s].learned;
            // The centre was learned in the old placement's frames.
            self.centre = JointCentre::new();
            self.motion_anchor = Vector3::zeros();
        }
    }

    /// Whether `segment`'s template is still to be taken or averaged (see
    /// [`take_template`](Self::take_template)).
    pub(super) fn templating(&self, segment: Segment) -> bool {
        let s = segment as usize;
        let frames = ((TEMPLATE_S * self.settings.rate_hz).ceil() as usize).max(1);
        !self.templated[s] || (self.calibration.is_some() && self.template_frames[s] < frames)
    }

    /// Moves each of `segment`'s markers' recent placement ([`Tracker::live`]) towards where
    /// `frame` has it in the segment's pose `pose`.
    pub(super) fn follow_placement(&mut self, segment: Segment, pose: &Isometry3<f64>, frame: &[f64]) {
        let w = (1.0 / (LIVE_PLACEMENT_S * self.settings.rate_hz)).min(1.0);
        let first = body::first_marker(segment);
        for k in first..first + 3 {
            let p = nalgebra::Point3::new(frame[3 * k], frame[3 * k + 1], frame[3 * k + 2]);
            let local = pose.inverse_transform_point(&p).coords;
            self.live[k] += w * (local - self.live[k]);
        }
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // the checks index truth and estimate side by side
mod tests {
    use super::super::testkit::*;

    use super::*;
    use crate::body::BodyModel;

    #[test]
    fn a_segment_from_two_markers_takes_them_where_they_sit_now() {
        // Skin markers slide: USP drifts 5 mm on the forearm, and MC2 on the hand, over 4 s (the
        // gap-free run reads 8° off the bones by then: the markers define the segments). Gaps
        // of each other marker are bridged with those two where they sit lately, not where the
        // shape was taken: 0.3–2° off the gap-free run (1.4–5.3° before).
        let rate = 100.0;
        let body = BodyModel::default();
        let q = trajectory(500, rate);
        let pose = body.forearm_pose(0.2);
        let clean: Vec<f64> = q
            .iter()
            .enumerate()
            .flat_map(|(i, qi)| {
                let mut slid = body.clone();
                let s = 0.005 * i as f64 / 400.0;
                slid.marker_offsets[1][0] += s;
                slid.marker_offsets[3][2] -= s;
                slid.marker_frame(qi, &pose)
            })
            .collect();
        let (good, _, _) = track_calibrated(&clean, rate);
        for (marker, bound) in [(0, 1.2), (2, 2.5), (4, 1.0), (5, 0.6)] {
            let mut f = clean.clone();
            for i in 400..420 {
                f[i * MARKER_FRAME_LEN + 3 * marker..i * MARKER_FRAME_LEN + 3 * marker + 3].fill(f64::NAN);
            }
            let (est, _, _) = track_calibrated(&f, rate);
            let off = worst_turn_deg(&good[400..], &est[400..]);
            assert!(off < bound, "marker {marker}: {off}° off the gap-free run");
        }
    }

    #[test]
    fn a_template_is_averaged_over_the_first_template_s_of_frames() {
        // TEMPLATE_S = 0.5 s: ceil(0.5 × 10 Hz) = 5 frames, ceil(0.5 × 100 Hz) = 50; every
        // frame here is complete and rigid, so each segment's template takes the first ones.
        for (rate, n) in [(10.0, 5usize), (100.0, 50)] {
            let f = frames(&BodyModel::default(), &trajectory(n + 10, rate), 0.2);
            let settings = super::super::TrackerSettings::new(rate);
            let mut tracker = Tracker::new(BodyModel::default(), settings).unwrap();
            tracker.set_calibration(Some(crate::calibration::Calibration::body_model()));
            for (i, frame) in f.chunks_exact(MARKER_FRAME_LEN).enumerate() {
                tracker.push(frame).unwrap();
                let taken = (i + 1).min(n);
                assert_eq!(tracker.template_frames, [taken; 2], "{rate} Hz, frame {i}");
                for segment in [Segment::Forearm, Segment::Hand] {
                    assert_eq!(tracker.templating(segment), i + 1 < n, "{rate} Hz, frame {i}");
                }
            }
        }
    }
}
