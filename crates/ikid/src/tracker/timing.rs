//! Frames stamped with their time ([`Tracker::push_at`]): the filter restarts after frames
//! were lost instead of bridging the gap as if none were.

use super::Tracker;
use super::forearm::Roll;
use crate::body::MARKER_FRAME_LEN;
use crate::error::{Error, Result};
use crate::status;
use crate::stream::GridStep;

impl Tracker {
    /// [`push`](Self::push) for a frame stamped with its acquisition time (seconds, any
    /// origin). Frames are expected one period of [`rate_hz`](super::TrackerSettings::rate_hz)
    /// apart, give or take the jitter of their stamps: a stamp is the next frame if it is
    /// 0.5–1.5 periods after the last one or after the frame grid the stamps before it keep
    /// (smoothed with [`GRID_GAIN`](crate::stream::GRID_GAIN): jitter of up to ±0.35 periods taken).
    ///
    /// Frames lost (a stamp more than [`GAP_PERIODS`] on by both), or a stamp before the last
    /// one (the source's clock restarted), restart the filter: bridged as one step, 0.1 s of
    /// lost frames gave torques 3.8 N·m off with every status 0. What was learned of the
    /// subject (the markers' noise and shapes, the placement, the wrist centre) is kept; the
    /// state starts again from the next frame with every marker, and its first frames are
    /// flagged [`status::RESTARTED`] while the velocities settle.
    /// [`gap_restarts`](Self::gap_restarts) counts these restarts. Frames are numbered as the
    /// source's clock counts them, lost ones included: an error names a frame by its place in
    /// the recording.
    ///
    /// A stamp less than [`FOLLOWS_PERIODS`] on by both, equal to the last one (a frame sent
    /// twice), or not finite, is an error and changes nothing; so is a frame
    /// [`push`](Self::push) refuses. A source slower than the rate
    /// ([`SLOW_SOURCE_FRAMES`](crate::stream::SLOW_SOURCE_FRAMES) stamps in a row more than
    /// [`GAP_PERIODS`] apart: every frame would restart the filter, whose estimates would never
    /// settle) is refused from the last of them on, saying so, until a stamp comes one period
    /// after the one before.
    ///
    /// [`GAP_PERIODS`]: crate::stream::GAP_PERIODS
    /// [`FOLLOWS_PERIODS`]: crate::stream::FOLLOWS_PERIODS
    pub fn push_at<V: Copy + Into<f64>>(&mut self, time_s: f64, frame: &[V]) -> Result<Option<super::TrackerOutput>> {
        if !time_s.is_finite() {
            return Err(Error::BadArgument {
                what: "time",
                detail: format!("is {time_s}, expected a finite number of seconds"),
            });
        }
        let rate = self.settings.rate_hz;
        self.pace.note(time_s, rate, "the tracker runs", || "give the tracker the source's rate".to_owned())?;
        let step = match self.clock.last() {
            None => None,
            Some(last) if time_s == last => {
                // A frame sent twice (a stamp going back is a clock that restarted).
                return Err(Error::BadArgument {
                    what: "time",
                    detail: format!("{time_s} s is the previous frame's stamp: a frame sent twice"),
                });
            }
            // The source's clock restarted: no frames lost, the filter starts again.
            Some(last) if time_s < last => Some(GridStep::Lost(0)),
            Some(last) => match self.clock.step(time_s, rate) {
                Some(GridStep::Soon) => {
                    return Err(Error::BadArgument {
                        what: "time",
                        detail: format!(
                            "{time_s} s is {:.3} ms after the previous frame, but the tracker's rate is {rate} Hz \
                             ({:.3} ms apart): give the tracker the source's rate",
                            (time_s - last) * 1e3,
                            1e3 / rate
                        ),
                    });
                }
                step => step,
            },
        };
        if let Some(GridStep::Lost(lost)) = step {
            // A refused frame changes nothing, so it must not restart the filter: `push`
            // refuses it (and says why) before it changes anything.
            if !frame_acceptable(frame) {
                return self.push_frame(frame);
            }
            if lost > 0 && lost < self.lost_frames() && self.state.is_some() {
                // Fewer frames lost than LOST_S: carried through as frames with every marker
                // missing (the state goes on at its last velocity, as through an occlusion) and
                // corrected by this one. Restarted instead, a stream losing a frame in forty had
                // three rows in four flagged restarted, their rates guessed from rest (review 7).
                let missing = [f64::NAN; MARKER_FRAME_LEN];
                for _ in 0..lost {
                    self.push_frame(&missing)?;
                }
                self.bridged += lost;
            } else {
                self.restart_after_gap(lost);
            }
        }
        let out = self.push_frame(frame)?;
        // A restarted clock starts the grid again from this stamp.
        self.clock.accept(time_s, rate, step.filter(|&s| s != GridStep::Lost(0)));
        Ok(out)
    }

    /// How many times [`push_at`](Self::push_at) restarted the filter after a time gap.
    pub fn gap_restarts(&self) -> usize {
        self.gap_restarts
    }

    /// How many lost frames [`push_at`](Self::push_at) carried the filter through (losses
    /// shorter than [`LOST_S`](super::LOST_S), each bridged instead of restarting it).
    pub fn bridged_frames(&self) -> usize {
        self.bridged
    }

    /// Forgets the motion, keeps what was learned of the subject: `lost` frames are counted as
    /// gone (every check that measures time in frames sees the gap), histories that need
    /// consecutive frames start again, and the next frame with every marker starts the state.
    fn restart_after_gap(&mut self, lost: usize) {
        self.frames += lost;
        self.state = None;
        self.forearm = None;
        self.motion.reset();
        self.history_len = 0;
        self.gated_streak = 0;
        self.coast_streak = 0;
        self.forearm_jumps = 0;
        self.roll = Roll::idle();
        self.refined = false;
        self.turned_over = status::TurnedOverWatch::new();
        self.settling = self.lost_frames();
        self.gap_restarts += 1;
        if let Some(r) = self.refiner.as_mut() {
            r.reset();
        }
    }
}

/// Whether [`Tracker::push`] takes the frame past its first checks (it refuses a frame of the
/// wrong length or with an infinite value, NaN being a missing marker, before it changes
/// anything).
fn frame_acceptable<V: Copy + Into<f64>>(frame: &[V]) -> bool {
    frame.len() == MARKER_FRAME_LEN && frame.iter().all(|&v| !v.into().is_infinite())
}

#[cfg(test)]
mod tests {
    use super::super::testkit::*;
    use super::super::*;
    use crate::reference::{JointState, inverse_dynamics};

    const RATE: f64 = 1000.0;
    const SHOULDER: f64 = 0.2;

    /// The trajectory's true torques at frame `i`: its angles, and their derivatives by central
    /// differences of the (smooth) trajectory, through the reference inverse dynamics.
    fn true_torques(body: &BodyModel, q: &[[f64; 3]], i: usize) -> [f64; 3] {
        let h = 1.0 / RATE;
        let state = JointState {
            q: q[i],
            qd: std::array::from_fn(|c| (q[i + 1][c] - q[i - 1][c]) / (2.0 * h)),
            qdd: std::array::from_fn(|c| (q[i + 1][c] - 2.0 * q[i][c] + q[i - 1][c]) / (h * h)),
        };
        inverse_dynamics(body, SHOULDER, &state).unwrap()
    }

    /// Runs frames `0..gap.0` and `gap.1..n` of a trial (the frames between lost), stamped or
    /// not; per frame pushed after the gap, the largest torque error (N·m) and the status.
    fn across_gap(stamped: bool, gap: (usize, usize)) -> (Vec<f64>, Vec<u16>, Tracker) {
        let body = BodyModel::default();
        let q = trajectory(2000, RATE);
        let f = frames(&body, &q, SHOULDER);
        let mut tracker = Tracker::new(body.clone(), TrackerSettings::new(RATE)).unwrap();
        let (mut errors, mut flags) = (vec![], vec![]);
        for i in (0..gap.0).chain(gap.1..q.len() - 1) {
            let frame = &f[i * MARKER_FRAME_LEN..(i + 1) * MARKER_FRAME_LEN];
            let out = if stamped { tracker.push_at(i as f64 / RATE, frame) } else { tracker.push(frame) };
            let out = out.unwrap();
            if i >= gap.1 {
                let truth = true_torques(&body, &q, i);
                let o = out.expect("the filter runs again on the first whole frame after the gap");
                errors.push((0..3).map(|c| (o.tau[c] - truth[c]).abs()).fold(0.0, f64::max));
                flags.push(o.status);
            }
        }
        (errors, flags, tracker)
    }

    #[test]
    fn frames_lost_one_in_forty_are_bridged_and_cost_the_torques_little() {
        // Review 7: each lost frame restarted the filter, so a source losing one in forty had
        // three rows in four flagged restarted (here 49 restarts, 1419 rows), rates guessed from
        // rest. Fewer than LOST_S in a row are bridged: no restart, no flag, and the torques
        // within 2 % of their size of the truth (the oracle: the reference inverse dynamics of
        // the trajectory).
        let body = BodyModel::default();
        let q = trajectory(2000, RATE);
        let f = frames(&body, &q, SHOULDER);
        let frame = |i: usize| &f[i * MARKER_FRAME_LEN..(i + 1) * MARKER_FRAME_LEN];
        let mut lossy = Tracker::new(body.clone(), TrackerSettings::new(RATE)).unwrap();
        let (mut size, mut err_lossy, mut flagged) = (0.0, 0.0, 0);
        for i in 0..q.len() - 1 {
            if i % 40 == 39 {
                continue; // lost
            }
            let l = lossy.push_at(i as f64 / RATE, frame(i)).unwrap();
            if i > 100 {
                let truth = true_torques(&body, &q, i);
                let sq = |o: TrackerOutput| (0..3).map(|c| (o.tau[c] - truth[c]).powi(2)).sum::<f64>();
                size += truth.iter().map(|t| t * t).sum::<f64>();
                let l = l.unwrap();
                flagged += usize::from(l.status & status::RESTARTED != 0);
                err_lossy += sq(l);
            }
        }
        assert_eq!((lossy.gap_restarts(), lossy.bridged_frames(), flagged), (0, 49, 0));
        assert!(err_lossy < 0.02f64.powi(2) * size, "{err_lossy} against {size} (sums of squares)");
    }

    #[test]
    fn lost_frames_restart_the_filter_instead_of_being_bridged() {
        // 0.1 s of frames lost. Pushed unstamped, the filter takes the gap for one step; stamped,
        // it restarts on the frame after it, its first frames flagged while velocities settle.
        let gap = (1000, 1100);
        let (bridged, _, _) = across_gap(false, gap);
        let (restarted, flags, tracker) = across_gap(true, gap);
        assert_eq!(tracker.gap_restarts(), 1);
        assert!(flags[0] & status::RESTARTED != 0, "the first frame after the gap is flagged");
        let settled = tracker.lost_frames();
        assert!(flags[settled..].iter().all(|f| f & status::RESTARTED == 0), "flagged only while settling");
        // After settling, within what the filter reaches on the same trial without a gap.
        let worst = |e: &[f64]| e[settled..settled + 50].iter().copied().fold(0.0, f64::max);
        let (whole, _, _) = across_gap(true, (gap.1, gap.1));
        // Measured: 4e-5 N·m restarted, 4e-5 without the gap, 0.035 bridged.
        assert!(worst(&restarted) < 2.0 * worst(&whole) + 1e-4, "{} vs {}", worst(&restarted), worst(&whole));
        assert!(
            worst(&bridged) > 100.0 * worst(&restarted),
            "bridged {} restarted {}",
            worst(&bridged),
            worst(&restarted)
        );
    }

    /// Uniform in ±`half` periods, seeded (a 64-bit LCG: no dependency for a test's scatter).
    fn jitter(seed: &mut u64, half: f64) -> f64 {
        *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((*seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 2.0 * half
    }

    #[test]
    fn jittered_stamps_are_the_next_frames_and_frames_lost_among_them_still_restart() {
        // Stamps scattered ±0.35 periods about the frame grid, as a bridge stamps frames when
        // they reach it: measured from the last stamp alone, two in a row can be 0.3 or 1.7
        // periods apart. Every frame is the next one (the oracle: the same frames unstamped),
        // none refused, no restart (seeded: a source jittering from its very first frame can have
        // one of its first few misjudged, see GRID_SETTLING_FRAMES); 100 frames lost among them restart the filter once, and
        // the frames after it are numbered as the source counts them.
        let body = BodyModel::default();
        let q = trajectory(1200, RATE);
        let f = frames(&body, &q, SHOULDER);
        let frame = |i: usize| &f[i * MARKER_FRAME_LEN..(i + 1) * MARKER_FRAME_LEN];
        let mut seed = 7;
        let mut stamped = Tracker::new(body.clone(), TrackerSettings::new(RATE)).unwrap();
        let mut plain = Tracker::new(body.clone(), TrackerSettings::new(RATE)).unwrap();
        for i in 0..1000 {
            let t = (i as f64 + jitter(&mut seed, 0.35)) / RATE;
            let a = stamped.push_at(t, frame(i)).unwrap_or_else(|e| panic!("frame {i} at {t}: {e}"));
            let b = plain.push(frame(i)).unwrap();
            assert_eq!(a.map(|o| o.values()), b.map(|o| o.values()), "frame {i}");
        }
        assert_eq!(stamped.gap_restarts(), 0);
        for i in 1100..1150 {
            stamped.push_at((i as f64 + jitter(&mut seed, 0.35)) / RATE, frame(i)).unwrap();
        }
        assert_eq!(stamped.gap_restarts(), 1);
        let mut bad = frame(1150).to_vec();
        bad[0] = f64::INFINITY;
        let e = stamped.push_at(1150.0 / RATE, &bad).unwrap_err();
        assert!(matches!(e, Error::NonFiniteInput { frame: 1150, .. }), "{e}");
    }

    #[test]
    fn a_source_at_four_fifths_of_the_rate_is_refused_naming_its_rate() {
        // Review 6: stamps 1.25 periods apart are each the next frame (within 0.5–1.5), so a
        // source at 80 % of the tracker's rate was tracked as if at its rate: velocities and
        // torques off by the ratio, every status 0. Refused from RATE_CHECK_STEPS on.
        let body = BodyModel::default();
        let f = frames(&body, &trajectory(400, RATE), SHOULDER);
        let mut tracker = Tracker::new(body, TrackerSettings::new(RATE)).unwrap();
        let refused: Vec<usize> = (0..400)
            .filter(|&i| {
                tracker.push_at(1.25 * i as f64 / RATE, &f[i * MARKER_FRAME_LEN..][..MARKER_FRAME_LEN]).is_err()
            })
            .collect();
        let first = crate::stream::RATE_CHECK_STEPS as usize;
        assert_eq!(refused, (first..400).collect::<Vec<_>>());
        let e = tracker.push_at(400.0 * 1.25 / RATE, &f[..MARKER_FRAME_LEN]).unwrap_err().to_string();
        assert!(e.contains(&format!("about {} Hz, the tracker runs at {RATE} Hz", RATE / 1.25)), "{e}");
    }

    #[test]
    fn a_gap_keeps_what_was_learned_of_the_subject() {
        // The markers' noise learned before the gap is the noise after it: not the initial guess.
        let (_, _, tracker) = across_gap(true, (1000, 1100));
        let fresh = Tracker::new(BodyModel::default(), TrackerSettings::new(RATE)).unwrap();
        assert!(tracker.noise_variance.iter().zip(&fresh.noise_variance).all(|(a, b)| a < b));
    }

    #[test]
    fn stamps_closer_than_the_rate_are_refused_and_change_nothing() {
        let body = BodyModel::default();
        let f = frames(&body, &trajectory(40, RATE), SHOULDER);
        let frame = |i: usize| &f[i * MARKER_FRAME_LEN..(i + 1) * MARKER_FRAME_LEN];
        let mut a = Tracker::new(body.clone(), TrackerSettings::new(RATE)).unwrap();
        let mut b = Tracker::new(body, TrackerSettings::new(RATE)).unwrap();
        a.push_at(0.0, frame(0)).unwrap();
        b.push_at(0.0, frame(0)).unwrap();
        let e = a.push_at(0.0002, frame(1)).unwrap_err().to_string();
        assert!(e.contains("1000 Hz") && e.contains("0.200 ms"), "{e}");
        let e = a.push_at(0.0, frame(1)).unwrap_err().to_string();
        assert!(e.contains("sent twice"), "{e}");
        let e = a.push_at(f64::NAN, frame(1)).unwrap_err().to_string();
        assert!(e.contains("time") && e.contains("finite"), "{e}");
        // After a gap, a frame push refuses restarts nothing.
        let mut bad = frame(1).to_vec();
        bad[4] = f64::INFINITY;
        assert!(a.push_at(0.5, &bad).is_err());
        assert_eq!(a.gap_restarts(), 0);
        for i in 1..40 {
            let t = i as f64 / RATE;
            let (x, y) = (a.push_at(t, frame(i)).unwrap(), b.push_at(t, frame(i)).unwrap());
            assert_eq!(x.map(|o| o.values()), y.map(|o| o.values()), "frame {i}");
        }
        assert_eq!(a.gap_restarts(), 0);
    }

    #[test]
    fn frames_after_a_gap_are_numbered_as_the_source_counts_them() {
        let body = BodyModel::default();
        let f = frames(&body, &trajectory(20, RATE), SHOULDER);
        let frame = |i: usize| &f[i * MARKER_FRAME_LEN..(i + 1) * MARKER_FRAME_LEN];
        let mut t = Tracker::new(body, TrackerSettings::new(RATE)).unwrap();
        for i in 0..10 {
            t.push_at(i as f64 / RATE, frame(i)).unwrap();
        }
        t.push_at(0.050, frame(10)).unwrap(); // frames 10-49 lost
        let mut bad = frame(11).to_vec();
        bad[0] = f64::INFINITY;
        let e = t.push_at(0.051, &bad).unwrap_err();
        assert!(matches!(e, Error::NonFiniteInput { frame: 51, .. }), "{e}");
    }

    #[test]
    fn unstamped_frames_move_the_clock_on_by_a_period_and_a_reset_forgets_it() {
        let body = BodyModel::default();
        let f = frames(&body, &trajectory(14, RATE), SHOULDER);
        let frame = |i: usize| &f[i * MARKER_FRAME_LEN..(i + 1) * MARKER_FRAME_LEN];
        let mut t = Tracker::new(body, TrackerSettings::new(RATE)).unwrap();
        t.push_at(1.0, frame(0)).unwrap();
        t.push(frame(1)).unwrap();
        t.push(frame(2)).unwrap();
        t.push_at(1.003, frame(3)).unwrap();
        assert_eq!(t.gap_restarts(), 0);
        t.push_at(1.006, frame(4)).unwrap(); // two frames lost: fewer than LOST_S, bridged
        assert_eq!((t.gap_restarts(), t.bridged_frames()), (0, 2));
        t.push_at(1.050, frame(5)).unwrap(); // 43 lost: restarted
        assert_eq!(t.gap_restarts(), 1);
        t.push_at(0.0, frame(5)).unwrap(); // the source's clock restarted
        assert_eq!(t.gap_restarts(), 2);
        t.reset();
        assert_eq!(t.gap_restarts(), 0);
        t.push_at(7.0, frame(6)).unwrap();
        assert_eq!(t.gap_restarts(), 0);
        // Every other frame stamped, at the rate: never a gap, never a slow source.
        let mut t = Tracker::new(BodyModel::default(), TrackerSettings::new(RATE)).unwrap();
        for i in 0..10 {
            if i % 2 == 0 {
                t.push_at(i as f64 / RATE, frame(i)).unwrap();
            } else {
                t.push(frame(i)).unwrap();
            }
        }
        assert_eq!(t.gap_restarts(), 0);
        // The unstamped frame 9 counts as 9 ms: 10 ms follows it; from there, stamps two periods
        // apart are late, and the third of them is refused.
        for (time, i) in [(0.010, 10), (0.012, 11), (0.014, 12)] {
            assert!(t.push_at(time, frame(i)).is_ok(), "{time}");
        }
        assert!(t.push_at(0.016, frame(13)).is_err());
    }

    #[test]
    fn a_source_slower_than_the_rate_is_refused_saying_so_until_it_keeps_the_rate() {
        // 100 Hz stamps into a 1 kHz tracker: each would bridge nine lost frames, the filter
        // running on its prediction nine frames in ten (or, with more lost, restart it: every row
        // flagged restarted, velocities from zero).
        let body = BodyModel::default();
        let f = frames(&body, &trajectory(200, RATE), SHOULDER);
        let frame = |i: usize| &f[i * MARKER_FRAME_LEN..(i + 1) * MARKER_FRAME_LEN];
        let mut t = Tracker::new(body, TrackerSettings::new(RATE)).unwrap();
        let results: Vec<_> = (0..10).map(|i| t.push_at(i as f64 * 0.01, frame(i)).map(|_| ())).collect();
        // The first stamp is not late; the third late one is refused.
        assert!(results[..3].iter().all(Result::is_ok));
        for r in &results[3..] {
            let e = r.as_ref().unwrap_err().to_string();
            assert!(e.contains("about 100 Hz") && e.contains("give the tracker the source's rate"), "{e}");
        }
        // At the tracker's rate again: taken from the first stamp a period after the one before
        // (the first new one is still late), settled after one restart.
        assert!(t.push_at(0.1, frame(10)).is_err());
        for i in 11..200 {
            let out = t.push_at(0.1 + (i - 10) as f64 / RATE, frame(i)).unwrap().unwrap();
            if i > 11 + t.lost_frames() {
                assert_eq!(out.status & status::RESTARTED, 0, "frame {i}");
            }
        }
        // The first two late stamps (9 frames lost each, fewer than LOST_S) were bridged; the
        // stamp after the refusals restarted it.
        assert_eq!((t.gap_restarts(), t.bridged_frames()), (1, 18));
    }

    /// The trial's frames with each marker turned by `turn`.
    fn turned(f: &[f64], turn: &nalgebra::Rotation3<f64>) -> Vec<f64> {
        f.chunks_exact(3).flat_map(|m| (turn * Vector3::new(m[0], m[1], m[2])).as_slice().to_vec()).collect()
    }

    fn torques(f: &[f64], up: [f64; 3]) -> Vec<[f64; 3]> {
        let mut tracker =
            Tracker::new(BodyModel::default(), TrackerSettings { up, ..TrackerSettings::new(RATE) }).unwrap();
        let mut tau = vec![];
        tracker
            .run(f, |_, o, estimated| {
                if estimated {
                    tau.push(o.tau)
                }
            })
            .unwrap();
        tau
    }

    #[test]
    fn the_labs_up_direction_gives_gravity_its_direction() {
        // The same motion recorded in labs turned every way: told which way is up, the torques
        // are the body model's lab's; not told, a Z-up lab's are wrong.
        let body = BodyModel::default();
        let f = frames(&body, &trajectory(1500, RATE), SHOULDER);
        let reference = torques(&f, [0.0, 1.0, 0.0]);
        let worst = |a: &[[f64; 3]], b: &[[f64; 3]]| {
            a.iter().zip(b).flat_map(|(x, y)| (0..3).map(move |c| (x[c] - y[c]).abs())).fold(0.0, f64::max)
        };
        let axis = |v: [f64; 3]| nalgebra::Unit::new_normalize(Vector3::from(v));
        for (name, turn) in [
            ("Z up", nalgebra::Rotation3::from_axis_angle(&axis([1.0, 0.0, 0.0]), std::f64::consts::FRAC_PI_2)),
            ("Y down", nalgebra::Rotation3::from_axis_angle(&axis([0.0, 0.0, 1.0]), std::f64::consts::PI)),
            ("tilted", nalgebra::Rotation3::from_axis_angle(&axis([0.3, -0.5, 0.8]), 2.1)),
        ] {
            let lab = turned(&f, &turn);
            let up = turn * Vector3::y();
            // Any length: normalised.
            let told = torques(&lab, (2.5 * up).into());
            assert!(worst(&told, &reference) < 1e-6, "{name}: {}", worst(&told, &reference));
            let untold = torques(&lab, [0.0, 1.0, 0.0]);
            assert!(worst(&untold, &reference) > 0.05, "{name}: {}", worst(&untold, &reference));
        }
    }

    #[test]
    fn settings_name_what_is_missing_or_wrong() {
        let make = |s: TrackerSettings| Tracker::new(BodyModel::default(), s).unwrap_err().to_string();
        let e = make(TrackerSettings::new(f64::NAN));
        assert!(e.contains("rate_hz") && e.contains("not set"), "{e}");
        for up in [[0.0; 3], [f64::NAN, 1.0, 0.0], [0.0, f64::INFINITY, 0.0]] {
            let e = make(TrackerSettings { up, ..TrackerSettings::new(RATE) });
            assert!(e.contains("up") && e.contains("non-zero"), "{up:?}: {e}");
        }
    }
}
