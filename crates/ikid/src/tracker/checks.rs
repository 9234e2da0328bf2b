//! What a marker must pass before it is used: its segment's rigid shape as learned, a forearm
//! that did not jump faster than a forearm moves, three hand markers that agree with their
//! shape; and the bits that say which markers are missing or rejected.

use nalgebra::{Isometry3, Vector3};

use super::{HAND_START, N_HAND, Step, Tracker};
use crate::body::{self, Segment};
use crate::status;

/// How far a distance between two markers of one segment may stray from what the tracker
/// learned it to be, m, plus [`RIGID_TOLERANCE_REL`] of it: more and a marker is not where
/// that segment could put it (a glitch, a swapped label, another object's marker).
pub const RIGID_TOLERANCE_M: f64 = 0.015;
/// Relative part of the rigid tolerance ([`RIGID_TOLERANCE_M`]): skin markers stretch.
pub const RIGID_TOLERANCE_REL: f64 = 0.15;
/// Fastest a forearm moves, m/s, plus [`JUMP_TOLERANCE_M`]: a faster jump is a glitch.
pub const MAX_SEGMENT_SPEED: f64 = 20.0;
/// Slack on the forearm's jump check, m.
pub const JUMP_TOLERANCE_M: f64 = 0.05;
/// Largest jump of the forearm taken as real once it persists (the subject relabelled, a
/// camera re-calibrated, the first frames the odd ones), m: the size of a capture volume. A
/// farther jump (a frame 1 km off, coordinates in the wrong units) stays rejected however long
/// it lasts.
pub const MAX_RELOCATION_M: f64 = 20.0;
/// How far a hand marker may sit from the rigid fit of the hand's shape to its three markers,
/// m, for the three to count as agreeing with one another.
pub const FIT_TOLERANCE_M: f64 = 0.005;

impl Tracker {
    /// Step 2, the hand's markers: NaN where missing or breaking the hand's rigid shape (a
    /// calibration's template taken or averaged from a whole, rigid hand).
    pub(super) fn check_hand(&mut self, step: &mut Step) {
        let frame = &step.frame[..];
        step.hand = std::array::from_fn(|i| frame[HAND_START + i]);
        let (rejected, relearned) = self.check_rigid(Segment::Hand, frame, step.lost);
        if relearned {
            step.flags |= status::RESTARTED;
            self.templated[Segment::Hand as usize] = false;
        }
        if rejected == 0 && step.missing >> 3 == 0 && self.templating(Segment::Hand) {
            self.take_template(Segment::Hand, frame);
        }
        reject_hand_markers(&mut step.hand, rejected >> 3);
        if rejected != 0 {
            step.flags |= status::REJECTED_MARKER;
        }
        step.hand_complete = step.hand.iter().all(|v| !v.is_nan());
    }

    /// Whether the three markers of `hand` sit where the hand's shape puts them, each within
    /// [`FIT_TOLERANCE_M`] of the rigid fit of the shape to them (none of them an outlier),
    /// beyond what this hand's markers miss its shape by at any frame (their noise and the
    /// template's learned misfit). Skin markers slide off the
    /// shape with the posture: held to the rigid tolerance alone, a hand whose markers
    /// usually miss it by 3 mm never agreed with itself again after a gap the filter drifted
    /// through, and spun without a restart to the end of the trial (issue #28's exam, skin
    /// markers on the MoBL-ARMS wrist with a 0.5-s gap in a flexion: 1382 rows not written).
    pub(super) fn hand_fits(&self, hand: &[f64; N_HAND], index: usize) -> bool {
        let noise = self.noise_variance.iter().sum::<f64>() / N_HAND as f64;
        // A marker's distance from its place over its three coordinates stays within 4 σ in
        // 99.9 % of frames (χ² with 3 degrees of freedom: 16.3 ≈ 4²).
        let usual = 4.0 * (noise + self.template_misfit_variance(noise)).sqrt();
        let tolerance = FIT_TOLERANCE_M + usual;
        self.fit_residual(hand, index)
            .is_some_and(|r| r.chunks_exact(3).all(|m| m.iter().map(|v| v * v).sum::<f64>() <= tolerance * tolerance))
    }

    /// Checks a segment's present markers against the distances between them learned so far
    /// (learning them on the first complete frame, then following them slowly). Returns the
    /// frame-marker bits of the markers rejected, and whether a new shape was learned (its
    /// template must be taken again; see [`RigidShape`]). One broken distance rejects the
    /// marker of its pair that moved against the third marker since the shape was last kept
    /// (both when that does not tell), two the marker they share, three all.
    pub(super) fn check_rigid(&mut self, segment: Segment, frame: &[f64], lost: usize) -> (u8, bool) {
        let s = segment as usize;
        let first = body::first_marker(segment);
        let points: [Vector3<f64>; 3] = std::array::from_fn(|k| {
            Vector3::new(frame[3 * (first + k)], frame[3 * (first + k) + 1], frame[3 * (first + k) + 2])
        });
        let distances: [f64; 3] = SHAPE_PAIRS.map(|(a, b)| (points[a] - points[b]).norm());
        let complete = distances.iter().all(|&d| d > 0.0);
        let shape = &mut self.shapes[s];
        let Some(learned) = shape.learned else {
            if complete {
                *shape = RigidShape { learned: Some(distances), support: 1.0, last: points, ..RigidShape::new() };
            }
            return (0, false);
        };
        let broken: [bool; 3] = std::array::from_fn(|i| !d_agrees(distances[i], learned[i]));
        let n_broken = broken.iter().filter(|&&b| b).count();
        if n_broken == 0 {
            shape.candidate = None;
            shape.candidate_frames = 0;
            let forget = 1.0 / self.settings.rate_hz; // a one-second memory
            let w = (1.0 / (shape.support + 1.0)).max(forget);
            let mut kept = learned;
            for (l, d) in kept.iter_mut().zip(distances) {
                if !d.is_nan() {
                    *l += w * (d - *l);
                }
            }
            shape.learned = Some(kept);
            shape.support += 1.0;
            if complete {
                shape.last = points;
            }
            return (0, false);
        }
        if complete {
            // Another shape: taken once as many consecutive complete frames agree on it as
            // agreed with the one learned (at least `lost`), at once if it is the shape the
            // template was taken from (a marker coming back). A marker off its place for less
            // long than it was in place stays rejected however long it lasts.
            match shape.candidate {
                Some(c) if shapes_agree(&distances, &c) => shape.candidate_frames += 1,
                _ => {
                    shape.candidate = Some(distances);
                    shape.candidate_frames = 1;
                }
            }
            let back = shape.template.is_some_and(|t| shapes_agree(&distances, &t));
            let needed = if back { 1 } else { lost.max(shape.support as usize) };
            if shape.candidate_frames >= needed {
                let frames = shape.candidate_frames;
                *shape = RigidShape {
                    learned: Some(distances),
                    support: frames as f64,
                    template: shape.template,
                    last: points,
                    ..RigidShape::new()
                };
                return (0, !back);
            }
        }
        let mut bad = 0u8;
        for (i, &(a, b)) in SHAPE_PAIRS.iter().enumerate() {
            if broken[i] {
                bad |= 1 << a | 1 << b;
            }
        }
        // Which marker of one broken distance moved is told by how each moved against the third
        // in the lab since the shape was last kept: right on the new shape's first frame, not
        // once the segment has turned since (a marker stuck back 40 mm off its place, its
        // neighbour rejected instead after a second, read the hand 45° off). While frames keep
        // the candidate shape, the markers found then stay the ones rejected.
        let continued = complete && shape.candidate_frames > 1;
        match n_broken {
            1 => {
                let i = broken.iter().position(|&b| b).unwrap_or(0);
                let (a, b) = SHAPE_PAIRS[i];
                let c = 3 - a - b;
                let found = shape.candidate_rejected;
                if continued && (found == 1 << a || found == 1 << b) {
                    bad = found;
                } else {
                    // How far each moved against the third since the shape was last kept.
                    let moved = |k: usize| ((points[k] - points[c]) - (shape.last[k] - shape.last[c])).norm();
                    let (ma, mb) = (moved(a), moved(b));
                    if ma > 2.0 * mb {
                        bad = 1 << a;
                    } else if mb > 2.0 * ma {
                        bad = 1 << b;
                    }
                }
            }
            2 => {
                let shared =
                    (0..3).find(|&k| SHAPE_PAIRS.iter().zip(broken).all(|(&(a, b), br)| !br || a == k || b == k));
                if let Some(k) = shared {
                    bad = 1 << k;
                }
            }
            _ => {}
        }
        if complete {
            shape.candidate_rejected = bad;
        }
        (bad << first, false)
    }

    /// Whether the forearm's newly fitted pose is one it could have reached since its last
    /// measured one (accepting it anyway once the jump has persisted `lost` frames).
    pub(super) fn forearm_plausible(&mut self, pose: &Isometry3<f64>, index: usize, lost: usize) -> bool {
        let Some(last) = self.forearm else { return true };
        let elapsed = (index - self.forearm_frame) as f64 / self.settings.rate_hz;
        let jump = (pose.translation.vector - last.translation.vector).norm();
        if jump <= MAX_SEGMENT_SPEED * elapsed + JUMP_TOLERANCE_M {
            self.forearm_jumps = 0;
            return true;
        }
        self.forearm_jumps += 1;
        if self.forearm_jumps >= lost && jump <= MAX_RELOCATION_M {
            self.forearm_jumps = 0;
            // Its position re-learned: the step to it is no motion (a whole lab shifted 20 cm
            // read as kN·m of carried torque).
            self.motion.reset();
            return true;
        }
        false
    }
}

/// Marker pairs of a segment whose distances make its shape (indices within the segment).
const SHAPE_PAIRS: [(usize, usize); 3] = [(0, 1), (0, 2), (1, 2)];

/// Whether a distance `d` between two markers is the learned `l`, within the rigid tolerance
/// ([`RIGID_TOLERANCE_M`], [`RIGID_TOLERANCE_REL`]); a NaN distance (a marker missing) agrees.
fn d_agrees(d: f64, l: f64) -> bool {
    d.is_nan() || (d - l).abs() <= RIGID_TOLERANCE_M + RIGID_TOLERANCE_REL * l
}

/// Whether two shapes (the three distances of a segment) are one within the rigid tolerance.
fn shapes_agree(a: &[f64; 3], b: &[f64; 3]) -> bool {
    (0..3).all(|i| d_agrees(a[i], b[i]))
}

/// What the tracker knows of one segment's rigid shape (see `Tracker::check_rigid`).
#[derive(Debug, Clone, Copy)]
pub(super) struct RigidShape {
    /// The distances between its markers (01, 02, 12) as learned, and how many frames agreed.
    pub(super) learned: Option<[f64; 3]>,
    support: f64,
    /// Another shape, seen in consecutive complete frames that agree with one another, and how many.
    candidate: Option<[f64; 3]>,
    candidate_frames: usize,
    /// The segment's markers (bits 0–2) found off their place on the candidate's first frame.
    candidate_rejected: u8,
    /// The shape the segment's template was taken from (with a calibration).
    pub(super) template: Option<[f64; 3]>,
    /// The segment's markers in the last complete frame that kept the shape.
    last: [Vector3<f64>; 3],
}

impl RigidShape {
    pub(super) fn new() -> Self {
        RigidShape {
            learned: None,
            support: 0.0,
            candidate: None,
            candidate_frames: 0,
            candidate_rejected: 0,
            template: None,
            last: [Vector3::repeat(f64::NAN); 3],
        }
    }
}

/// Frame-marker bits of the forearm's markers.
pub(super) const FOREARM_MARKERS: u8 = 0b000_111;

/// Sets hand markers `bits` (0–2) of `hand` to NaN: not used.
pub(super) fn reject_hand_markers(hand: &mut [f64; N_HAND], bits: u8) {
    for m in 0..3 {
        if bits & (1 << m) != 0 {
            hand[3 * m..3 * m + 3].fill(f64::NAN);
        }
    }
}

/// Bits 0–2: hand markers with all three coordinates present.
pub(super) fn hand_markers_present(hand: &[f64; N_HAND]) -> u8 {
    (0..3).filter(|&m| hand[3 * m..3 * m + 3].iter().all(|v| !v.is_nan())).fold(0, |b, m| b | 1 << m)
}

/// Bit `i` set: marker `i` of `frame` ([`MARKERS`](crate::body::MARKERS) order) has a NaN coordinate.
pub fn missing_markers(frame: &[f64]) -> u8 {
    frame
        .chunks_exact(3)
        .enumerate()
        .filter(|(_, xyz)| xyz.iter().any(|v| v.is_nan()))
        .fold(0, |bits, (m, _)| bits | 1 << m)
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // the checks index truth and estimate side by side
mod tests {
    use super::super::testkit::*;
    use super::super::*;
    use super::*;
    use crate::body::BodyModel;

    #[test]
    fn markers_in_millimetres_are_refused_before_the_filter_runs_and_ghosts_after_are_flagged() {
        // Frames in mm read as metres: every one refused, saying why, and nothing changed (the
        // same frames in metres then run as on a fresh tracker). Once the filter runs, one
        // frame with a marker 1 km away is rejected and flagged, not an error.
        let body = BodyModel::default();
        let f = frames(&body, &trajectory(60, 1000.0), 0.2);
        let frame = |i: usize| &f[i * MARKER_FRAME_LEN..(i + 1) * MARKER_FRAME_LEN];
        let mut t = Tracker::new(body.clone(), TrackerSettings::new(1000.0)).unwrap();
        for i in 0..5 {
            let mm: Vec<f64> = frame(i).iter().map(|v| v * 1000.0).collect();
            let e = t.push(&mm).unwrap_err().to_string();
            assert!(e.contains("are the units mm"), "{e}");
        }
        let mut fresh = Tracker::new(body, TrackerSettings::new(1000.0)).unwrap();
        for i in 0..50 {
            let (a, b) = (t.push(frame(i)).unwrap(), fresh.push(frame(i)).unwrap());
            assert_eq!(a.map(|o| o.values()), b.map(|o| o.values()), "frame {i}");
        }
        let mut ghost = frame(50).to_vec();
        ghost[0] += 1000.0;
        let out = t.push(&ghost).unwrap().expect("an estimate");
        assert!(out.status & status::REJECTED_MARKER != 0);
    }

    /// The default body's marker frame at rest, with forearm marker `m` moved by `by` (m).
    fn moved(m: usize, by: Vector3<f64>) -> Vec<f64> {
        let body = BodyModel::default();
        let mut f = body.marker_frame(&[0.0; 3], &body.forearm_pose(0.2)).to_vec();
        for k in 0..3 {
            f[3 * m + k] += by[k];
        }
        f
    }

    #[test]
    fn a_new_shape_is_taken_after_as_many_frames_as_held_the_old_one() {
        // Five frames keep the forearm's shape; then FAP sits 10 cm farther from RSP and USP
        // (two distances broken: FAP rejected) for good. The new shape is taken on its fifth
        // frame (max(LOST, 5)), not before.
        let mut tracker = Tracker::new(BodyModel::default(), TrackerSettings::new(1000.0)).unwrap();
        let rest = moved(0, Vector3::zeros());
        for _ in 0..5 {
            assert_eq!(tracker.check_rigid(Segment::Forearm, &rest, 3), (0, false));
        }
        let point = |m: usize| Vector3::new(rest[3 * m], rest[3 * m + 1], rest[3 * m + 2]);
        let off = moved(2, 0.1 * (point(2) - (point(0) + point(1)) / 2.0).normalize());
        for k in 1..5 {
            assert_eq!(tracker.check_rigid(Segment::Forearm, &off, 3), (0b100, false), "displaced frame {k}");
        }
        assert_eq!(tracker.check_rigid(Segment::Forearm, &off, 3), (0, true));
        // The new shape is kept as the old was: right after it was taken, RSP turned 60° about
        // FAP (one distance broken) is RSP's fault alone (it moved since the new shape's frame);
        // then one more frame of the new shape (six in all), and the old shape back needs six
        // frames to be taken again.
        let p = |m: usize| Vector3::new(off[3 * m], off[3 * m + 1], off[3 * m + 2]);
        let axis = nalgebra::Unit::new_normalize((p(1) - p(0)).cross(&(p(2) - p(0))));
        let turned = p(2) + nalgebra::Rotation3::from_axis_angle(&axis, 1.0) * (p(0) - p(2));
        let mut rsp_off = off.clone();
        rsp_off[..3].copy_from_slice(turned.as_slice());
        assert_eq!(tracker.check_rigid(Segment::Forearm, &rsp_off, 3), (0b001, false));
        assert_eq!(tracker.check_rigid(Segment::Forearm, &off, 3), (0, false));
        for k in 1..6 {
            assert_eq!(tracker.check_rigid(Segment::Forearm, &rest, 3), (0b100, false), "old shape, frame {k}");
        }
        assert_eq!(tracker.check_rigid(Segment::Forearm, &rest, 3), (0, true));
    }

    #[test]
    fn the_learned_shape_is_the_mean_of_its_frames_then_follows_over_one_second() {
        // At 10 Hz FAP 1 mm farther out each frame (within the tolerance): the distances learned
        // are the plain mean of the frames so far while there are fewer than ten (weight
        // 1/(n+1)), then follow by a tenth of each new frame's difference (a one-second memory).
        let settings = TrackerSettings::new(10.0);
        let mut tracker = Tracker::new(BodyModel::default(), settings).unwrap();
        let rest = moved(0, Vector3::zeros());
        let point = |m: usize| Vector3::new(rest[3 * m], rest[3 * m + 1], rest[3 * m + 2]);
        let out = (point(2) - (point(0) + point(1)) / 2.0).normalize();
        let distances = |f: &[f64]| {
            let p = |m: usize| Vector3::new(f[3 * m], f[3 * m + 1], f[3 * m + 2]);
            SHAPE_PAIRS.map(|(a, b)| (p(a) - p(b)).norm())
        };
        let mut expected = [0.0; 3];
        for n in 0..15 {
            let f = moved(2, 1e-3 * n as f64 * out);
            assert_eq!(tracker.check_rigid(Segment::Forearm, &f, 3), (0, false), "frame {n}");
            let w = if n < 10 { 1.0 / (n as f64 + 1.0) } else { 0.1 };
            for (e, d) in expected.iter_mut().zip(distances(&f)) {
                *e += w * (d - *e);
            }
            let learned = tracker.shapes[Segment::Forearm as usize].learned.unwrap();
            for i in 0..3 {
                assert!((learned[i] - expected[i]).abs() < 1e-12, "frame {n}: {learned:?} vs {expected:?}");
            }
        }
    }

    #[test]
    fn a_new_shape_must_hold_from_frame_to_frame_to_be_taken() {
        // FAP jumping between two places 10 cm off either way: each frame another candidate
        // shape, so none is ever taken, however long it lasts.
        let mut tracker = Tracker::new(BodyModel::default(), TrackerSettings::new(1000.0)).unwrap();
        let rest = moved(0, Vector3::zeros());
        for _ in 0..5 {
            tracker.check_rigid(Segment::Forearm, &rest, 3);
        }
        let point = |m: usize| Vector3::new(rest[3 * m], rest[3 * m + 1], rest[3 * m + 2]);
        let out = (point(2) - (point(0) + point(1)) / 2.0).normalize();
        let (far, near) = (moved(2, 0.1 * out), moved(2, -0.1 * out));
        for k in 0..20 {
            let f = if k % 2 == 0 { &far } else { &near };
            assert_eq!(tracker.check_rigid(Segment::Forearm, f, 3), (0b100, false), "frame {k}");
        }
    }

    #[test]
    fn the_templates_shape_is_taken_back_at_once_each_time_it_comes_back() {
        // Calibrated at 10 Hz (a one-second memory: the learned shape follows within 9 mm of a
        // marker sliding 1 mm a frame, inside the 15 mm tolerance): the template is taken at
        // rest; FAP slides 10 cm out (two distances now off the template's), then snaps back,
        // twice. Each time the template's shape is taken back on its first frame, the first time
        // as the second: relearning the shape keeps which one the template was taken from.
        let settings = TrackerSettings::new(10.0);
        let mut tracker = Tracker::new(BodyModel::default(), settings).unwrap();
        tracker.set_calibration(Some(crate::calibration::Calibration::body_model()));
        let rest = moved(0, Vector3::zeros());
        assert_eq!(tracker.check_rigid(Segment::Forearm, &rest, 3), (0, false));
        tracker.take_template(Segment::Forearm, &rest);
        assert!(tracker.shapes[Segment::Forearm as usize].template.is_some());
        let point = |m: usize| Vector3::new(rest[3 * m], rest[3 * m + 1], rest[3 * m + 2]);
        let out = (point(2) - (point(0) + point(1)) / 2.0).normalize();
        for time in ["first", "second"] {
            for k in 1..=160 {
                let slid = moved(2, 1e-3 * k.min(100) as f64 * out);
                assert_eq!(tracker.check_rigid(Segment::Forearm, &slid, 3), (0, false), "{time}: slid frame {k}");
            }
            assert_eq!(tracker.check_rigid(Segment::Forearm, &rest, 3), (0, false), "{time} time back");
        }
    }

    #[test]
    fn one_broken_distance_right_after_the_first_frame_rejects_the_marker_that_moved() {
        // RSP turned 60° about FAP right after the shape was learned from one frame: RSP–FAP
        // keeps its length, RSP–USP breaks. RSP moved against FAP, USP did not: RSP alone.
        let body = BodyModel::default();
        let pose = body.forearm_pose(0.2);
        let rest = body.marker_frame(&[0.0; 3], &pose);
        let point = |m: usize| Vector3::new(rest[3 * m], rest[3 * m + 1], rest[3 * m + 2]);
        let axis = nalgebra::Unit::new_normalize((point(1) - point(0)).cross(&(point(2) - point(0))));
        let turned = point(2) + nalgebra::Rotation3::from_axis_angle(&axis, 1.0) * (point(0) - point(2));
        let mut tracker = Tracker::new(body.clone(), TrackerSettings::new(1000.0)).unwrap();
        assert_eq!(tracker.check_rigid(Segment::Forearm, &rest, 3), (0, false));
        let f = moved(0, turned - point(0));
        assert_eq!(tracker.check_rigid(Segment::Forearm, &f, 3), (0b001, false));
    }

    /// The default forearm's three markers at rest (lab), turned `deg` about the lab's y through
    /// its first marker, with marker `m` turned `about_third` degrees about marker `third` in
    /// the markers' plane first (its distance to `third` kept).
    fn turned(m: usize, third: usize, about_third: f64, deg: f64) -> Vec<f64> {
        let body = BodyModel::default();
        let mut f = body.marker_frame(&[0.0; 3], &body.forearm_pose(0.2)).to_vec();
        let point = |f: &[f64], k: usize| Vector3::new(f[3 * k], f[3 * k + 1], f[3 * k + 2]);
        let normal = nalgebra::Unit::new_normalize((point(&f, 1) - point(&f, 0)).cross(&(point(&f, 2) - point(&f, 0))));
        let moved = point(&f, third)
            + nalgebra::Rotation3::from_axis_angle(&normal, about_third.to_radians())
                * (point(&f, m) - point(&f, third));
        f[3 * m..3 * m + 3].copy_from_slice(moved.as_slice());
        let (origin, turn) = (point(&f, 0), nalgebra::Rotation3::from_axis_angle(&Vector3::y_axis(), deg.to_radians()));
        for k in 0..3 {
            let p = origin + turn * (point(&f, k) - origin);
            f[3 * k..3 * k + 3].copy_from_slice(p.as_slice());
        }
        f
    }

    #[test]
    fn the_marker_a_broken_distance_names_is_kept_while_the_segment_turns_with_its_new_shape() {
        // Each marker in turn moved about a neighbour (one distance broken), then the segment
        // turning 120° with the new shape over 60 frames (too few to take it): the marker found
        // on the first frame stays the one rejected. Told again each frame against the pose
        // last kept, the other marker of the pair read as the one that moved once the segment
        // had turned. With the third marker missing, which one moved cannot be told from the
        // frame: both. A new shape's first frame is judged anew.
        let body = BodyModel::default();
        for (m, third) in [(0, 2), (1, 0), (2, 1)] {
            let mut tracker = Tracker::new(body.clone(), TrackerSettings::new(1000.0)).unwrap();
            for _ in 0..100 {
                assert_eq!(tracker.check_rigid(Segment::Forearm, &turned(m, third, 0.0, 0.0), 3), (0, false));
            }
            for k in 0..60 {
                let f = turned(m, third, 50.0, 2.0 * k as f64);
                assert_eq!(tracker.check_rigid(Segment::Forearm, &f, 3), (1 << m, false), "marker {m}, frame {k}");
            }
            let mut gappy = turned(m, third, 50.0, 120.0);
            gappy[3 * third..3 * third + 3].fill(f64::NAN);
            let other = 3 - m - third;
            assert_eq!(tracker.check_rigid(Segment::Forearm, &gappy, 3), (1 << m | 1 << other, false), "marker {m}");
            // A segment that has not turned: the marker moved for a few frames, then back in
            // place and the other marker of the pair moved about the third instead (another
            // shape): that one is rejected.
            let mut tracker = Tracker::new(body.clone(), TrackerSettings::new(1000.0)).unwrap();
            for _ in 0..100 {
                tracker.check_rigid(Segment::Forearm, &turned(m, third, 0.0, 0.0), 3);
            }
            for _ in 0..5 {
                assert_eq!(tracker.check_rigid(Segment::Forearm, &turned(m, third, 50.0, 0.0), 3).0, 1 << m);
            }
            let mut f = turned(m, third, 0.0, 0.0);
            let instead = turned(other, third, 80.0, 0.0);
            f[3 * other..3 * other + 3].copy_from_slice(&instead[3 * other..3 * other + 3]);
            assert_eq!(tracker.check_rigid(Segment::Forearm, &f, 3).0, 1 << other, "marker {m} back, {other} moved");
        }
    }

    #[test]
    fn one_broken_distance_whose_markers_both_moved_rejects_both() {
        // USP turned 70° and FAP 25° about RSP, opposite ways in the plate's plane: their
        // distances to RSP are kept, USP–FAP breaks (172 -> 122 mm), and both moved about as
        // much against RSP (64 and 76 mm), so which one is off cannot be told: both are rejected.
        let body = BodyModel::default();
        let rest = body.marker_frame(&[0.0; 3], &body.forearm_pose(0.2));
        let point = |m: usize| Vector3::new(rest[3 * m], rest[3 * m + 1], rest[3 * m + 2]);
        let axis = nalgebra::Unit::new_normalize((point(1) - point(0)).cross(&(point(2) - point(0))));
        let turn = |m: usize, deg: f64| {
            point(0) + nalgebra::Rotation3::from_axis_angle(&axis, deg.to_radians()) * (point(m) - point(0))
        };
        let mut f = rest;
        for (m, deg) in [(1, 70.0), (2, -25.0)] {
            f[3 * m..3 * m + 3].copy_from_slice(turn(m, deg).as_slice());
        }
        let mut tracker = Tracker::new(body.clone(), TrackerSettings::new(1000.0)).unwrap();
        assert_eq!(tracker.check_rigid(Segment::Forearm, &rest, 3), (0, false));
        assert_eq!(tracker.check_rigid(Segment::Forearm, &f, 3), (0b110, false));
    }

    #[test]
    fn a_burst_a_kilometre_off_stays_rejected_and_a_real_relocation_is_taken() {
        let body = BodyModel::default();
        let q = trajectory(2000, 1000.0);
        let clean = frames(&body, &q, 0.2);
        let (good, _, _) = track(&clean, 1000.0);
        for (shift, taken) in [(1000.0, false), (1.0, true)] {
            // 100 frames (more than LOST_S): the 1 km ones stay rejected and flagged, then the
            // tracker goes on as if they never came; the 1 m ones are a relocation, taken.
            let mut f = clean.clone();
            for v in &mut f[1000 * MARKER_FRAME_LEN..1100 * MARKER_FRAME_LEN] {
                *v += shift;
            }
            let (est, status, _) = track(&f, 1000.0);
            let flagged = status[1000..1100].iter().filter(|s| *s & status::REJECTED_MARKER != 0).count();
            if taken {
                // Taken once the jump has lasted LOST_S (30 frames at 1 kHz): on its 30th frame.
                assert_eq!(flagged, 29, "{shift} m: {flagged} of 100 rejected");
            } else {
                assert_eq!(flagged, 100, "{shift} m");
                let after = worst_deg(&good[1200..], &est[1200..]); // 100 ms after the burst
                assert!(after < 0.01, "{after}° off after the burst");
            }
        }
    }

    #[test]
    fn a_frame_shifted_by_a_kilometre_is_rejected_and_poisons_nothing() {
        // Issue #22 case 1: it used to teach the tracker 18 m of noise and leave it 871° off.
        let body = BodyModel::default();
        let q = trajectory(3000, 1000.0);
        let clean = frames(&body, &q, 0.2);
        let mut glitched = clean.clone();
        for v in &mut glitched[1000 * MARKER_FRAME_LEN..1001 * MARKER_FRAME_LEN] {
            *v += 1000.0;
        }
        let (good, _, clean_tracker) = track(&clean, 1000.0);
        let (bad, status, tracker) = track(&glitched, 1000.0);
        assert!(status[1000] & status::REJECTED_MARKER != 0 && status[1000] & status::HELD != 0, "{}", status[1000]);
        assert_eq!(status[999] & status::REJECTED_MARKER, 0);
        assert!(worst_deg(&good[1001..], &bad[1001..]) < 0.01, "{}", worst_deg(&good[1001..], &bad[1001..]));
        // The noise learned is the clean run's, not the glitch's.
        let (a, b) = (tracker.marker_noise(), clean_tracker.marker_noise());
        assert!(a.iter().zip(b).all(|(x, y)| *x < 2.0 * y + 1e-6), "{a:?} vs {b:?}");
        assert_eq!(tracker.restarts(), 0);
    }

    #[test]
    fn a_marker_off_its_place_for_longer_than_lost_stays_rejected_and_is_taken_back() {
        // MC5 and then USP 10 cm off for 200 ms (20 frames, LOST_S is 3): every frame flagged
        // rejected_marker, the estimate as without them throughout, nothing flagged once they
        // are back. (The shape used to be re-learned after LOST_S from the garbage, its
        // template taken from it: rows unflagged, a restart, and the wrong placement after.)
        let body = BodyModel::default();
        let rate = 100.0;
        let q = trajectory(600, rate);
        let clean = frames(&body, &q, 0.2);
        let (good, _, _) = track_calibrated(&clean, rate);
        for (marker, at) in [(4, 200), (1, 400)] {
            let mut f = clean.clone();
            for i in at..at + 20 {
                f[i * MARKER_FRAME_LEN + 3 * marker] += 0.06;
                f[i * MARKER_FRAME_LEN + 3 * marker + 1] -= 0.08;
            }
            let (est, status, tracker) = track_calibrated(&f, rate);
            assert!(status[at..at + 20].iter().all(|s| s & status::REJECTED_MARKER != 0), "marker {marker}");
            let started = tracker.lost_frames(); // its own start's frames are flagged while settling
            assert!(
                status[started..].iter().all(|s| s & status::RESTARTED == 0),
                "marker {marker}: {:?}",
                &status[at..]
            );
            assert!(status[at + 20..].iter().all(|&s| s == 0), "marker {marker}: {:?}", &status[at + 20..]);
            let off = worst_turn_deg(&good[at..], &est[at..]);
            assert!(off < 0.5, "marker {marker}: {off}° from the clean run");
            assert_eq!(tracker.restarts(), 0);
        }
    }

    /// Skin markers: each hand marker displaced smoothly with the posture, up to `mm` per
    /// coordinate and angle (the hand's shape changes as the wrist turns).
    fn skin(clean: &[f64], q: &[[f64; 3]], mm: f64) -> Vec<f64> {
        let mut f = clean.to_vec();
        for (frame, q) in f.chunks_exact_mut(MARKER_FRAME_LEN).zip(q) {
            for i in HAND_START..MARKER_FRAME_LEN {
                let phase = i as f64;
                frame[i] += mm * 1e-3 * (0..3).map(|j| (q[j] * (1.0 + phase * 0.37 + j as f64)).sin()).sum::<f64>();
            }
        }
        f
    }

    #[test]
    fn skin_markers_agree_with_the_hand_by_their_usual_misfit_and_an_outlier_does_not() {
        // Skin hand markers whose shape changes up to 30 mm with the posture: a frame's three
        // markers, as they are, miss the hand's shape by what they always miss it by, so they
        // agree with one another (what lets the filter restart from them after a gap it drifted
        // through); held to the rigid 5-mm tolerance they did not, and on the exam's skin
        // markers the filter spun with a marker rejected to the end of the trial. One of them
        // 10 cm off its place never agrees.
        let body = BodyModel::default();
        let rate = 100.0;
        let q = trajectory(900, rate);
        let f = skin(&frames(&body, &q, 0.2), &q, 10.0);
        let (_, _, tracker) = track_calibrated(&f, rate);
        let hand = |i: usize| -> [f64; N_HAND] { std::array::from_fn(|k| f[i * MARKER_FRAME_LEN + HAND_START + k]) };
        let late = 600..900;
        let worst = late
            .clone()
            .filter_map(|i| tracker.fit_residual(&hand(i), i))
            .flat_map(|r| r.chunks_exact(3).map(|m| m.iter().map(|v| v * v).sum::<f64>().sqrt()).collect::<Vec<_>>());
        let worst = worst.fold(0.0, f64::max);
        assert!(worst > FIT_TOLERANCE_M, "the skin should move a marker beyond the rigid tolerance: {worst} m");
        let agree = late.clone().filter(|&i| tracker.hand_fits(&hand(i), i)).count();
        assert_eq!(agree, late.len(), "frames whose markers agree with the hand (worst miss {worst} m)");
        let outliers = late
            .filter(|&i| {
                let mut h = hand(i);
                h[3] += 0.06;
                h[4] -= 0.08;
                tracker.hand_fits(&h, i)
            })
            .count();
        assert_eq!(outliers, 0, "a marker 10 cm off agreed with the hand");
    }

    #[test]
    fn noise_unequal_between_the_labs_axes_does_not_bias_skin_markers_angles() {
        // Skin hand markers (the shape changing with the posture) with white noise ten times
        // larger along the lab's x than along y and z: the filter's angles are, on average, where
        // the same markers without noise put them. Weighed by each lab coordinate's noise alone,
        // the fit leaned the skin's misfit onto the quiet axes and biased the angles (the exam's
        // Gonzalez skin markers: 0.0062 → 0.0072 rad² with 1 % noise).
        let body = BodyModel::default();
        let rate = 100.0;
        let q = trajectory(1500, rate);
        let clean = skin(&frames(&body, &q, 0.2), &q, 5.0);
        let mut noisy = clean.clone();
        let mut rng = crate::rng::SplitMix::new(11);
        for frame in noisy.chunks_exact_mut(MARKER_FRAME_LEN) {
            for i in HAND_START..MARKER_FRAME_LEN {
                frame[i] += rng.uniform(-1.0, 1.0) * if i % 3 == 0 { 3e-3 } else { 3e-4 };
            }
        }
        let (without, _, _) = track_calibrated(&clean, rate);
        let (with, _, _) = track_calibrated(&noisy, rate);
        let late = 500..1500;
        for c in 0..3 {
            let shift = late.clone().map(|i| with[i][c] - without[i][c]).sum::<f64>() / late.len() as f64;
            assert!(
                shift.abs().to_degrees() < 0.3,
                "coordinate {c}: the noise moved it by {}° on average",
                shift.to_degrees()
            );
        }
    }

    #[test]
    fn one_broken_distance_rejects_the_marker_that_moved() {
        // USP moved 3 cm away from RSP, keeping its distance to FAP: only RSP–USP breaks. The
        // marker that moved against FAP is USP, so RSP and FAP still fit the forearm (it was
        // held before: both markers of the broken pair were rejected).
        let body = BodyModel::default();
        let q = trajectory(800, 1000.0);
        let mut f = frames(&body, &q, 0.2);
        for i in 400..450 {
            let m = |k: usize| Vector3::new(f[i * 18 + 3 * k], f[i * 18 + 3 * k + 1], f[i * 18 + 3 * k + 2]);
            let (rsp, usp, fap) = (m(0), m(1), m(2));
            let arm = usp - fap;
            let away = -((rsp - usp) - arm * (rsp - usp).dot(&arm) / arm.norm_squared()).normalize();
            // Turned about FAP (its distance to it kept) away from RSP until RSP–USP breaks
            // by a centimetre more than the tolerance.
            let broken = |p: Vector3<f64>| {
                let (d, l) = ((p - rsp).norm(), (usp - rsp).norm());
                d - l > RIGID_TOLERANCE_M + RIGID_TOLERANCE_REL * l + 0.01
            };
            let moved = (1..90)
                .map(|deg| {
                    let a = f64::from(deg).to_radians();
                    fap + (arm * a.cos() + away * arm.norm() * a.sin())
                })
                .find(|&p| broken(p))
                .unwrap();
            assert!(((moved - fap).norm() - arm.norm()).abs() < 1e-9);
            f[i * 18 + 3..i * 18 + 6].copy_from_slice(moved.as_slice());
        }
        let (est, status, _) = track(&f, 1000.0);
        for s in &status[400..450] {
            assert!(s & status::REJECTED_MARKER != 0 && s & status::HELD == 0, "{}", status::describe(*s));
        }
        assert!(worst_deg(&q[400..], &est[400..]) < 0.05, "{}", worst_deg(&q[400..], &est[400..]));
    }

    #[test]
    fn garbage_frames_are_flagged_and_tracking_recovers_within_100_ms() {
        let body = BodyModel::default();
        let q = trajectory(2000, 1000.0);
        let clean = frames(&body, &q, 0.0);
        let mut rng = crate::rng::SplitMix::new(7);
        for scale in [1.0, 0.05] {
            let mut f = clean.clone();
            // 50 ms of random frames: metres apart, or hand-sized (5 cm) noise.
            for v in &mut f[500 * MARKER_FRAME_LEN..550 * MARKER_FRAME_LEN] {
                *v = scale * rng.normal();
            }
            let (est, status, _) = track(&f, 1000.0);
            assert!(status[500..550].iter().all(|s| s & (status::REJECTED_MARKER | status::HELD) != 0), "{scale}");
            let after = worst_deg(&q[650..], &est[650..]);
            assert!(after < 0.1, "scale {scale}: {after}° off 100 ms after the garbage");
            assert!(status[700..].iter().all(|&s| s == 0), "scale {scale}");
        }
    }

    #[test]
    fn one_hand_marker_off_its_segment_is_rejected_alone() {
        let body = BodyModel::default();
        let q = trajectory(1000, 1000.0);
        let mut f = frames(&body, &q, 0.0);
        let mc5_x = 3 * 4;
        for frame in 600..650 {
            f[frame * MARKER_FRAME_LEN + mc5_x] += 0.08; // MC5 8 cm off: a swapped or ghost marker
        }
        let (est, status, tracker) = track(&f, 1000.0);
        assert!(status[600..650].iter().all(|s| s & status::REJECTED_MARKER != 0));
        // MC2 and MCB alone keep the estimate on the wrist.
        assert!(worst_deg(&q[600..], &est[600..]) < 0.05, "{}", worst_deg(&q[600..], &est[600..]));
        assert_eq!(tracker.restarts(), 0);
    }
}
