//! Frame-by-frame inference over a fixed ring window, without heap allocation per frame.

use crate::body::{MARKER_FRAME_LEN, N_COORDINATES};
use crate::calibration::{Calibration, MarkerShapes};
use crate::error::{Error, Result};
use crate::features::FeatureSet;
use crate::gaps::{GapFiller, MissingMarkers};
use crate::model::{Model, SdState};
use crate::net::Scratch;
use crate::status;

/// A stamp more than this many periods after the last one means frames were lost: the filter
/// restarts ([`Tracker::push_at`](crate::Tracker::push_at)), a stream's window too ([`Stream::push_at`]).
/// Python's `ikid.io.resample.GAP_STEPS` is this constant.
pub const GAP_PERIODS: f64 = 1.5;
/// A stamp less than this many periods after the last one is refused: the source runs faster
/// than the tracker's or the model's rate, and every velocity and torque would be wrong by the ratio.
pub const FOLLOWS_PERIODS: f64 = 0.5;
/// Stamps in a row, each more than [`GAP_PERIODS`] after the stamp before it, that mean the
/// source is slower than the rate, not losing frames now and then: the last of them and each
/// such stamp after it is refused, saying so. Accepted, every one would restart the window (a
/// stream that never gives an output, and says nothing) or the filter (estimates that never
/// settle). A stamp one period after the one before ends the run.
pub const SLOW_SOURCE_FRAMES: u32 = 3;

/// Steps between consecutive frames' stamps (0.5–1.5 periods apart) averaged before their
/// mean is judged against the rate ([`RATE_TOLERANCE`]); then followed with a gain of its
/// inverse.
pub const RATE_CHECK_STEPS: u32 = 128;
/// How far the mean step between consecutive frames' stamps may be from one period (a
/// fraction of it) before the source is said to run at another rate. A source at 80 or 120 Hz
/// read at 100 Hz has every step 1.25 or 0.83 periods, within the 0.5–1.5 a jittered frame may
/// take, and was read as if at 100 Hz: torques about twice as far off, every line "ok". Real
/// sources keep their nominal rate to well under 1 %. Stamps jittering by ±0.35 periods (the
/// most [`FrameGrid`] takes) have 8 % of their steps outside 0.5–1.5, left out of the mean,
/// which moves it: at most 3.9 % over 2·10⁶ frames, 5.5 % with 30 % of the frames lost at
/// random, 8.7 % with every third lost (simulated; at 32 steps instead of 128: 5 % within
/// 3000 frames of the first case).
pub const RATE_TOLERANCE: f64 = 0.10;

/// How the stamps a stream or a tracker is given follow each other, accepted or not: a run of
/// [`SLOW_SOURCE_FRAMES`] late ones is a source slower than the rate, and consecutive frames'
/// steps that average more than [`RATE_TOLERANCE`] off one period a source at another rate.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct SourcePace {
    last_seen: Option<f64>,
    late: u32,
    /// The mean step between consecutive frames, periods (the first [`RATE_CHECK_STEPS`]
    /// averaged, then followed with a gain of 1 / [`RATE_CHECK_STEPS`]), and how many such
    /// steps were seen.
    mean_step: f64,
    steps: u32,
}

impl SourcePace {
    /// An unstamped frame: one `period` after the stamp before it.
    pub(crate) fn advance(&mut self, period: f64) {
        if let Some(t) = self.last_seen.as_mut() {
            *t += period;
        }
        self.late = 0;
    }

    /// Notes the finite stamp `time_s`; the error to give when it ends a run of late stamps at
    /// `rate_hz`, or when consecutive frames come at another rate (`what`: whose rate it is,
    /// `fix`: what to do, made only then: the path of every frame allocates nothing).
    pub(crate) fn note(&mut self, time_s: f64, rate_hz: f64, what: &str, fix: impl FnOnce() -> String) -> Result<()> {
        let periods = self.last_seen.map(|t| (time_s - t) * rate_hz);
        self.last_seen = Some(time_s);
        match periods {
            Some(p) if p > GAP_PERIODS => self.late += 1,
            _ => self.late = 0,
        }
        if let Some(p) = periods.filter(|p| (FOLLOWS_PERIODS..=GAP_PERIODS).contains(p)) {
            self.steps = self.steps.saturating_add(1);
            let gain = 1.0 / f64::from(self.steps.min(RATE_CHECK_STEPS));
            self.mean_step += gain * (p - self.mean_step);
        }
        if self.late >= SLOW_SOURCE_FRAMES {
            let p = periods.unwrap_or(f64::NAN);
            let source_hz = (10.0 * rate_hz / p).round() / 10.0;
            return Err(Error::BadArgument {
                what: "time",
                detail: format!(
                    "{time_s} s is {p:.1} periods after the stamp before it, as were the {} before: the source \
                     runs at about {source_hz} Hz (or loses most frames), {what} at {rate_hz} Hz; {}",
                    SLOW_SOURCE_FRAMES - 1,
                    fix()
                ),
            });
        }
        if self.steps >= RATE_CHECK_STEPS && (self.mean_step - 1.0).abs() > RATE_TOLERANCE {
            let source_hz = (10.0 * rate_hz / self.mean_step).round() / 10.0;
            return Err(Error::BadArgument {
                what: "time",
                detail: format!(
                    "consecutive frames' stamps come {:.3} ms apart on average, not {:.3}: the source runs at about \
                     {source_hz} Hz, {what} at {rate_hz} Hz; {}",
                    1e3 * self.mean_step / rate_hz,
                    1e3 / rate_hz,
                    fix()
                ),
            });
        }
        Ok(())
    }
}

/// How far a frame's stamp moves the frame grid toward itself (`FrameGrid`): the grid follows
/// the source's clock (its drift, a rate a little off its nominal one) and averages the jitter
/// of its stamps over about 1 / `GRID_GAIN` frames. Measured over 200,000 frames with stamps
/// uniform within ±0.35 periods of the grid: none misjudged (1/8: 18; 1/16 at ±0.4: 247).
pub const GRID_GAIN: f64 = 1.0 / 32.0;

/// Frames a new frame grid takes to know its phase: until then, as two stamps ±0.35 periods
/// off the grid can be 1.7 periods apart, a stamp up to 1.75 periods on is the next frame
/// (the early side stays at [`FOLLOWS_PERIODS`]: a source faster than the rate is refused from
/// its second frame). Measured on sources jittering ±0.35 periods from their first frame: 25
/// of 300 had a stamp misjudged, each within the first few frames (one refused as too soon,
/// and the frame after it a gap); with 0.5–1.5 from the start, 40 of 300.
pub const GRID_SETTLING_FRAMES: u32 = 16;

/// How a stamp follows the last accepted one ([`FrameGrid::step`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum GridStep {
    /// Less than [`FOLLOWS_PERIODS`] after it: refused (a source faster than the rate).
    Soon,
    /// The next frame.
    Follows,
    /// This many frames lost between them (at least one).
    Lost(usize),
}

/// Where a source's stamped frames fall in time, through the jitter of their stamps. A stamp
/// is measured from the last accepted one and from the frame grid (that frame's time smoothed
/// over the ones before it, [`GRID_GAIN`]), and is the next frame if either puts it 0.5–1.5
/// periods on: stamps taken when a frame reaches a computer (an LSL bridge's) scatter by a
/// good part of a period, and measured from the last stamp alone a jitter of ±0.3 periods
/// restarted a tracker a hundred times in 3 s (1 kHz) and left a stream an output on 19 % of
/// its frames. Jitter up to ±0.35 periods is taken. Frames are lost only when both put it more
/// than [`GAP_PERIODS`] on.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct FrameGrid {
    last: Option<f64>,
    grid: f64,
    /// Frames on the grid since it started: the first ones set its phase as their mean.
    frames: u32,
}

impl FrameGrid {
    /// The last accepted frame's stamp (moved on a period by each unstamped frame).
    pub(crate) fn last(&self) -> Option<f64> {
        self.last
    }

    /// How `time_s`, after the last accepted stamp, follows it at `rate_hz`; `None` for the
    /// first frame. Changes nothing.
    pub(crate) fn step(&self, time_s: f64, rate_hz: f64) -> Option<GridStep> {
        let last = self.last?;
        let from_last = (time_s - last) * rate_hz;
        let on_grid = (time_s - self.grid) * rate_hz;
        let gap = if self.frames < GRID_SETTLING_FRAMES { 1.75 } else { GAP_PERIODS };
        let next = |p: f64| (FOLLOWS_PERIODS..=gap).contains(&p);
        Some(if next(from_last) || next(on_grid) {
            GridStep::Follows
        } else if from_last < FOLLOWS_PERIODS && on_grid < FOLLOWS_PERIODS {
            GridStep::Soon
        } else {
            GridStep::Lost((on_grid.max(from_last).round() as usize).max(2) - 1)
        })
    }

    /// Takes the frame stamped `time_s` as accepted, `step` periods on ([`step`](Self::step)'s
    /// verdict), or as a new start (`None`: the first frame, a clock that restarted).
    pub(crate) fn accept(&mut self, time_s: f64, rate_hz: f64, step: Option<GridStep>) {
        let periods = match step {
            Some(GridStep::Follows) => Some(1.0),
            Some(GridStep::Lost(lost)) => Some(lost as f64 + 1.0),
            Some(GridStep::Soon) | None => None,
        };
        let expected = periods.map(|k| self.grid + k / rate_hz);
        (self.grid, self.frames) = match expected {
            // Half a period off the grid is no longer jitter: it starts again from this stamp.
            Some(at) if ((time_s - at) * rate_hz).abs() < 0.5 || self.frames < GRID_SETTLING_FRAMES => {
                let gain = GRID_GAIN.max(1.0 / f64::from(self.frames + 1));
                (at + gain * (time_s - at), self.frames.saturating_add(1))
            }
            _ => (time_s, 1),
        };
        self.last = Some(time_s);
    }

    /// An unstamped frame: one `period` on.
    pub(crate) fn advance(&mut self, period: f64) {
        if let Some(t) = self.last.as_mut() {
            *t += period;
            self.grid += period;
        }
    }
}

/// Largest gap in time stamps taken as frames lost, s: a stamp further ahead of the last
/// accepted frame (or behind it) is a clock glitch until [`TIME_REANCHOR_FRAMES`] stamps in a
/// row continue from it; one bad stamp is refused alone and the stream goes on.
pub const MAX_TIME_GAP_S: f64 = 1.0;

/// Consecutive stamps, each one period (0.5–1.5) after the one before, that must all jump
/// from the last accepted frame's time before the stream takes them as the source's new clock
/// (a source restarted, its clock reset): the last of them is accepted and the window restarts.
pub const TIME_REANCHOR_FRAMES: u32 = 3;

/// How a frame's time stamp follows the last accepted one's.
#[derive(Debug, Clone, Copy, PartialEq)]
enum TimeStep {
    /// One period later (0.5–1.5), or the first frame.
    Follows,
    /// Frames lost: more than 1.5 periods, at most [`MAX_TIME_GAP_S`], later.
    Gap,
    /// The [`TIME_REANCHOR_FRAMES`]-th stamp in a row continuing a jump: the new clock.
    Reanchor,
    /// A jump not (yet) confirmed: refused.
    Jump,
}

/// A causal stream over a [`Model`]: push one frame at a time, get the prediction for the
/// newest frame once the window is full.
///
/// All buffers are allocated in [`Model::stream`]; [`push`](Stream::push) never allocates
/// (proved by `tests/allocations.rs`). A frame that is refused (wrong length, NaN,
/// degenerate markers) leaves the window exactly as it was, and what follows gives what it
/// would have without it, with one designed exception: frames refused only for having moved
/// too far are remembered, and [`REANCHOR_FRAMES`](crate::gaps::REANCHOR_FRAMES) of them in a
/// row that agree are a new place (a stall without time stamps), so the last is taken. A
/// non-finite prediction (input far outside the training range) is an error too, never an
/// output; that frame stays in the window.
///
/// A missing marker (non-finite value) is handled by the stream's [`MissingMarkers`] policy,
/// the model card's unless [`set_missing_markers`](Stream::set_missing_markers) says
/// otherwise: refused, or filled by the stream's [`GapFiller`] and flagged in
/// [`filled_markers`](Stream::filled_markers).
#[derive(Debug, Clone)]
pub struct Stream {
    model: Model,
    /// `window` feature rows; row `head` is the next to overwrite (the oldest once full).
    ring: Vec<f32>,
    head: usize,
    filled: usize,
    /// Features of the frame being pushed, before it is accepted into the ring.
    incoming: Vec<f32>,
    /// The window flattened oldest → newest: the network input.
    input: Vec<f32>,
    scratch: Scratch,
    output: Vec<f32>,
    policy: MissingMarkers,
    filler: GapFiller,
    /// The pushed frame with its missing marker filled (Fill policy only).
    frame_buf: [f32; MARKER_FRAME_LEN],
    filled_mask: u8,
    /// The filler's [`status`] bits for the last accepted frame (filled, rejected, swapped).
    marker_status: u16,
    /// Where the frames accepted by [`push_at`](Stream::push_at) fall in time.
    clock: FrameGrid,
    gap_restarts: u64,
    /// How the stamps follow each other (a source slower than the model's rate).
    pace: SourcePace,
    /// The turn from the markers' lab into the body model's ([`set_lab_up`](Stream::set_lab_up)).
    lab: Option<nalgebra::Rotation3<f64>>,
    /// The last time stamp refused for jumping ([`MAX_TIME_GAP_S`] ahead, or behind), and how
    /// many refused stamps in a row continue from each other at the model's rate.
    time_candidate: Option<f64>,
    time_candidate_frames: u32,
    /// The stamp of the last frame refused for its markers (a gap) whose stamp came in order:
    /// frames after a long gap continue from it, not from the last frame accepted.
    refused_in_order: Option<f64>,
    time_reanchors: u64,
    /// Rows the last [`push_many`](Stream::push_many) wrote before the frame it refused.
    rows_before_refusal: usize,
    /// A new clock was taken and no output has been given since ([`status::RESYNCED`]).
    resynced: bool,
    /// The subject's marker placement, applied to each (filled) frame before its features.
    calibration: Option<Calibration>,
    /// The subject's marker shapes, learned from the first frames the calibration is applied
    /// to: each segment's orientation is fitted to them by least squares.
    shapes: MarkerShapes,
    /// Frames pushed since the stream was made (accepted or refused): the next frame's
    /// number, which its errors carry.
    pushed: usize,
    /// [`status`] bits of the last output.
    status: u16,
    /// Give the per-frame solution while the window fills (correcting models only).
    early_outputs: bool,
    /// The outputs' standard deviations, for a model whose card says how ([`SdState`]).
    sd: Option<SdState>,
    /// Whether the hand, read from each accepted frame's markers, is turned over on the
    /// forearm (labels or calibration the wrong way round), and the bits it gave the last one.
    turned_over: status::TurnedOverWatch,
    posture_status: u16,
}

impl Model {
    /// A new stream over this model (allocates its buffers once, here).
    pub fn stream(&self) -> Stream {
        Stream::new(self.clone())
    }
}

impl Stream {
    pub(crate) fn new(model: Model) -> Self {
        let nf = model.feature_set().feature_len();
        let w = model.window();
        Stream {
            ring: vec![0.0; w * nf],
            head: 0,
            filled: 0,
            incoming: vec![0.0; nf],
            input: vec![0.0; w * nf],
            scratch: model.net().scratch(),
            output: vec![0.0; model.n_outputs()],
            policy: model.missing_markers(),
            filler: GapFiller::at_rate(model.card().frame_rate_hz),
            frame_buf: [0.0; MARKER_FRAME_LEN],
            filled_mask: 0,
            marker_status: 0,
            clock: FrameGrid::default(),
            gap_restarts: 0,
            pace: SourcePace::default(),
            lab: None,
            time_candidate: None,
            time_candidate_frames: 0,
            refused_in_order: None,
            time_reanchors: 0,
            rows_before_refusal: 0,
            resynced: false,
            calibration: None,
            shapes: MarkerShapes::new(model.card().frame_rate_hz),
            pushed: 0,
            status: 0,
            early_outputs: false,
            // Models that read per-frame angles keep the σ's running means even without the
            // card's coefficients (a study fits them from these), remembering a window.
            sd: model
                .feature_set()
                .leads_with_angles()
                .then(|| SdState::new(model.card().uncertainty.clone(), model.n_outputs(), model.window() as f64)),
            turned_over: status::TurnedOverWatch::new(),
            posture_status: 0,
            model,
        }
    }

    /// The model this stream runs.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// Frames currently held (saturates at the window length).
    pub fn filled(&self) -> usize {
        self.filled
    }

    /// The policy for missing markers this stream applies.
    pub fn missing_markers(&self) -> MissingMarkers {
        self.policy
    }

    /// Overrides the model card's missing-marker policy (e.g. to refuse frames a `"fill"`
    /// model would fill). [`MissingMarkers::Fill`] needs a model that takes marker frames.
    /// What the gap filler has learned is kept.
    pub fn set_missing_markers(&mut self, policy: MissingMarkers) -> Result<()> {
        if policy == MissingMarkers::Fill && self.model.frame_len() != MARKER_FRAME_LEN {
            return Err(Error::BadArgument {
                what: "missing-marker policy",
                detail: format!(
                    "\"fill\" needs marker frames; feature set {:?} takes joint states",
                    self.model.feature_set().name()
                ),
            });
        }
        self.policy = policy;
        Ok(())
    }

    /// Calibrates the stream to the subject's marker placement (see [`Calibration`]): each
    /// frame, once filled, has its markers moved to the body model's placement before its
    /// features are computed, and the gap filler starts from the joint centre the calibration
    /// implies ([`GapFiller::set_calibration`]). `None` uses the markers as they come. Needs
    /// marker frames.
    pub fn set_calibration(&mut self, calibration: Option<Calibration>) -> Result<()> {
        if calibration.is_some() && self.model.frame_len() != MARKER_FRAME_LEN {
            return Err(Error::BadArgument {
                what: "calibration",
                detail: format!(
                    "needs marker frames; feature set {:?} takes joint states",
                    self.model.feature_set().name()
                ),
            });
        }
        // The filler starts from where the calibration puts the wrist's centre: it fills from
        // the first complete frame instead of waiting for the wrist to move about every axis.
        self.filler.set_calibration(calibration.as_ref());
        self.calibration = calibration;
        self.turned_over = status::TurnedOverWatch::new(); // the hand is read anew
        self.shapes = MarkerShapes::for_calibration(self.calibration.as_ref(), self.model.card().frame_rate_hz);
        Ok(())
    }

    /// The calibration this stream applies, if any.
    pub fn calibration(&self) -> Option<&Calibration> {
        self.calibration.as_ref()
    }

    /// With `true`, a correcting model's stream (card `output_offset = "newest_features"`)
    /// gives an output for every accepted frame while its window fills (from the first frame,
    /// and again after a restart): the frame's per-frame solution, its own features (e.g. the
    /// angles its markers give), flagged [`status::PER_FRAME`]. Offline runs use it so that
    /// every frame has an output; a live stream may prefer to wait for the network. Refused
    /// for a model without that offset (it has no per-frame solution).
    pub fn set_early_outputs(&mut self, early: bool) -> Result<()> {
        if early && self.model.net().offset().is_none() {
            return Err(Error::BadArgument {
                what: "early outputs",
                detail: format!(
                    "model {:?} does not correct its newest frame's features, so it has no per-frame solution to give",
                    self.model.card().name
                ),
            });
        }
        self.early_outputs = early;
        Ok(())
    }

    /// Whether this stream gives early outputs ([`set_early_outputs`](Self::set_early_outputs)).
    pub fn early_outputs(&self) -> bool {
        self.early_outputs
    }

    /// Markers filled in the last accepted frame (bit `i` = [`crate::body::MARKERS`]`[i]`; 0
    /// when it was complete). The output for that frame rests on the filled positions.
    pub fn filled_markers(&self) -> u8 {
        self.filled_mask
    }

    /// The gap filler (what it has learned of this subject's markers and joint centre).
    pub fn gap_filler(&self) -> &GapFiller {
        &self.filler
    }

    /// Pushes one frame ([`Model::frame_len`] values). Returns `None` until the window is
    /// full, then the prediction for this frame ([`Model::n_outputs`] values).
    /// Errors name the frame by its number in this stream (0 for the first frame pushed).
    pub fn push(&mut self, frame: &[f32]) -> Result<Option<&[f32]>> {
        let index = self.pushed;
        self.pushed += 1;
        self.prepare(frame, index)?;
        self.advance(index)
    }

    /// Checks, fills and calibrates `frame` and computes its features into `incoming`; an
    /// error leaves the window and the filler as they were.
    fn prepare(&mut self, frame: &[f32], index: usize) -> Result<()> {
        let set = self.model.feature_set();
        let reanchors = self.filler.reanchors();
        // Into the body model's lab first ([`set_lab_up`](Self::set_lab_up)), on the stack.
        let mut turned = [0f32; MARKER_FRAME_LEN];
        let frame = match self.lab {
            Some(turn) if set.frame_len() == MARKER_FRAME_LEN && frame.len() == MARKER_FRAME_LEN => {
                for (dst, m) in turned.chunks_exact_mut(3).zip(frame.chunks_exact(3)) {
                    let v = turn * nalgebra::Vector3::new(f64::from(m[0]), f64::from(m[1]), f64::from(m[2]));
                    dst.copy_from_slice(&[v.x as f32, v.y as f32, v.z as f32]);
                }
                &turned[..]
            }
            _ => frame,
        };
        if set.frame_len() == MARKER_FRAME_LEN && frame.len() == MARKER_FRAME_LEN {
            // Markers no arm could hold (wrong units, a ghost far away) are refused, not fed
            // to a network that would answer them with a confident number.
            let wide: [f64; MARKER_FRAME_LEN] = std::array::from_fn(|i| f64::from(frame[i]));
            crate::body::check_marker_span(&wide, index)?;
        }
        if self.policy == MissingMarkers::Fill {
            if frame.len() != MARKER_FRAME_LEN {
                return Err(Error::FrameLength {
                    feature_set: set.name(),
                    found: frame.len(),
                    expected: MARKER_FRAME_LEN,
                });
            }
            // The filler learns only from frames it accepts, and refuses before changing
            // anything, so a refused frame leaves it and the window as they were.
            self.frame_buf.copy_from_slice(frame);
            let mask = self.filler.fill(&mut self.frame_buf, index)?;
            let marker_status = self.filler.status();
            if let Some(calibration) = &self.calibration {
                // The shapes are learned from markers as measured, never from filled ones.
                calibration.apply_fitted(&mut self.frame_buf, index, &mut self.shapes, mask == 0)?;
            }
            set.compute(&self.frame_buf, &mut self.incoming, index)?;
            self.filled_mask = mask;
            self.marker_status = marker_status;
        } else {
            if set.frame_len() == MARKER_FRAME_LEN {
                // Refuse a marker that jumped (the filler watches complete frames either way).
                self.filler.check(frame, index)?;
            }
            match &self.calibration {
                Some(calibration) => {
                    set.check_frame(frame, index)?;
                    self.frame_buf.copy_from_slice(frame);
                    calibration.apply_fitted(&mut self.frame_buf, index, &mut self.shapes, true)?;
                    set.compute(&self.frame_buf, &mut self.incoming, index)?;
                }
                None => set.compute(frame, &mut self.incoming, index)?,
            }
            self.filled_mask = 0;
            self.marker_status = 0;
        }
        if self.filler.reanchors() != reanchors {
            // The markers moved further than continuity allows and the filler took this frame
            // as the new truth: frames were lost. A window spanning the loss would mix frames
            // the network never saw together, so it restarts here (as after a time gap).
            self.head = 0;
            self.filled = 0;
        }
        self.posture_status = self.watch_hand(frame);
        Ok(())
    }

    /// The [`status::TurnedOverWatch`]'s bits for the frame just prepared (`frame` as pushed):
    /// the hand's posture is the angles a model's features lead with (per-frame angles, a joint
    /// state's q), else the per-frame angles of the markers as filled and calibrated. 0 for a
    /// model that has neither: it has no hand to read. (The model's
    /// [`frame_status`](Model::frame_status) leaves these angles to this watch.)
    fn watch_hand(&mut self, frame: &[f32]) -> u16 {
        let set = self.model.feature_set();
        let mut q = [0f32; N_COORDINATES];
        if set.leads_with_angles() {
            q.copy_from_slice(&self.incoming[..N_COORDINATES]);
        } else if set.frame_len() == MARKER_FRAME_LEN {
            let prepared = self.policy == MissingMarkers::Fill || self.calibration.is_some();
            let markers = if prepared { &self.frame_buf[..] } else { frame };
            if FeatureSet::Angles.compute(markers, &mut q, 0).is_err() {
                return self.turned_over.bits();
            }
        } else {
            return 0;
        }
        self.turned_over.update(&q.map(f64::from))
    }

    /// Accepts the prepared frame into the window and runs the network once it is full.
    fn advance(&mut self, index: usize) -> Result<Option<&[f32]>> {
        let nf = self.incoming.len();
        let w = self.model.window();
        self.ring[self.head * nf..(self.head + 1) * nf].copy_from_slice(&self.incoming);
        self.head = (self.head + 1) % w;
        self.filled = (self.filled + 1).min(w);
        if let Some(sd) = &mut self.sd {
            if self.filled == 1 {
                sd.restart(); // a new window: the frames before it say nothing of this one's noise
            }
            sd.accept(&self.incoming);
        }
        // RESYNCED goes with the first output after a new clock (the window refilled).
        let resynced = (self.filled >= w || self.early_outputs) && std::mem::take(&mut self.resynced);
        let filled = self.marker_status | if resynced { status::RESYNCED } else { 0 };
        if self.filled < w {
            if !self.early_outputs {
                return Ok(None);
            }
            // The per-frame solution: the offset's features, as a withheld correction gives.
            let n = self.output.len();
            self.output.copy_from_slice(&self.incoming[..n]);
            self.status = filled
                | status::PER_FRAME
                | self.posture_status
                | self.model.frame_status_of(&self.incoming, &self.output, false);
            if let Some(sd) = &mut self.sd {
                sd.set_output(&self.output, &self.incoming, true, true);
            }
            return Ok(Some(&self.output));
        }
        // Unroll the ring oldest-first: rows head.. then ..head.
        let split = self.head * nf;
        let tail = self.ring.len() - split;
        self.input[..tail].copy_from_slice(&self.ring[split..]);
        self.input[tail..].copy_from_slice(&self.ring[..split]);
        let corrected = self.model.net().run(&self.input, &mut self.scratch, &mut self.output, index)?;
        let per_frame = if corrected { 0 } else { status::PER_FRAME };
        self.status =
            filled | per_frame | self.posture_status | self.model.frame_status_of(&self.incoming, &self.output, false);
        if let Some(sd) = &mut self.sd {
            sd.set_output(&self.output, &self.incoming, !corrected, self.model.adds_newest_features());
        }
        Ok(Some(&self.output))
    }

    /// [`push`](Self::push) for a frame stamped with its acquisition time (seconds, any
    /// origin). Frames are expected one period of the model's rate apart, give or take the
    /// jitter of their stamps (the frame grid, [`GRID_GAIN`]: up to ±0.35 periods); after a gap
    /// of more than 1.5 periods (dropped frames), up to [`MAX_TIME_GAP_S`], the window restarts,
    /// as after [`reset`](Self::reset), so no output mixes frames further apart than the
    /// network was trained on: outputs resume once the window has refilled. A frame less than
    /// half a period after the previous one is refused (a source at a faster rate than the
    /// model's would be silently mis-timed; resample it).
    ///
    /// A frame refused for its markers (a gap the filler cannot fill) is a frame lost to the
    /// window, not to the clock: the window restarts after it, and the stamps after a long
    /// gap follow its stamp, not the last accepted frame's (a hand hidden for two seconds is
    /// not a glitch of the source's clock).
    ///
    /// A source slower than the model's rate ([`SLOW_SOURCE_FRAMES`] stamps in a row more than
    /// [`GAP_PERIODS`] apart) is refused from the last of them on, saying so, until a stamp
    /// comes one period after the one before.
    ///
    /// A stamp that jumps (more than [`MAX_TIME_GAP_S`] ahead, or not after the last accepted
    /// frame's) is refused alone and changes nothing the next good frame sees: one glitch of
    /// the source's clock never ends the stream. Only [`TIME_REANCHOR_FRAMES`] jumped stamps in
    /// a row, each a period after the one before, are taken as the source's new clock (it was
    /// restarted): the last of them is accepted, the window restarts and
    /// [`time_reanchors`](Self::time_reanchors) counts it.
    pub fn push_at(&mut self, time_s: f64, frame: &[f32]) -> Result<Option<&[f32]>> {
        let index = self.pushed;
        self.pushed += 1;
        let step = self.check_time(time_s)?;
        let rate = self.model.card().frame_rate_hz;
        self.pace.note(time_s, rate, "the model was trained", || format!("resample it to {rate} Hz"))?;
        if step == TimeStep::Jump {
            return Err(self.refuse_jump(time_s));
        }
        let restart = step != TimeStep::Follows;
        if restart {
            // The frame before the gap is no guide to this one (nor to the next, should this
            // one be refused: it comes after the same gap).
            self.filler.forget_last_frame();
        }
        if let Err(e) = self.prepare(frame, index) {
            // Its stamp came in order all the same: a marker hidden for over MAX_TIME_GAP_S
            // must not make the frames after it read as a jump of the source's clock.
            // Only a stamp one period on from the last one that came in order: a refused frame
            // with a stamp of its own (a glitch) leaves the clock as it was.
            if self.last_in_order().is_some_and(|t| (FOLLOWS_PERIODS..=GAP_PERIODS).contains(&((time_s - t) * rate))) {
                self.refused_in_order = Some(time_s);
            }
            return Err(e);
        }
        self.refused_in_order = None;
        if restart {
            // Restart the window only for a frame that is accepted: a refused one leaves the
            // stream as it was (the next frame accepted after it comes after a gap).
            self.head = 0;
            self.filled = 0;
            if step == TimeStep::Gap {
                self.gap_restarts += 1;
            } else {
                self.time_reanchors += 1;
                self.resynced = true;
            }
        }
        let grid_step = match step {
            // Across frames lost the grid keeps its phase; a new clock starts it again.
            TimeStep::Follows | TimeStep::Gap => self.clock.step(time_s, rate),
            TimeStep::Reanchor | TimeStep::Jump => None,
        };
        self.clock.accept(time_s, rate, grid_step);
        self.time_candidate = None;
        self.time_candidate_frames = 0;
        let produced = self.advance(index)?.is_some();
        Ok(produced.then_some(&self.output[..]))
    }

    /// Where `time_s` stands against the last accepted frame's time (and against the jumped
    /// stamps before it); an error for a stamp refused outright. Changes nothing.
    fn check_time(&self, time_s: f64) -> Result<TimeStep> {
        if !time_s.is_finite() {
            return Err(Error::BadArgument {
                what: "time",
                detail: format!("is {time_s}, expected a finite number of seconds"),
            });
        }
        let Some(last) = self.clock.last() else { return Ok(TimeStep::Follows) };
        let rate = self.model.card().frame_rate_hz;
        // After the last accepted frame, and not far on from the last stamp that came in order
        // (that frame, or one refused for its markers since: a refused frame orders nothing,
        // it may be pushed again with its stamp).
        let seen = self.last_in_order().unwrap_or(last);
        if time_s > last && time_s - seen <= MAX_TIME_GAP_S {
            let step = self.clock.step(time_s, rate);
            if step == Some(GridStep::Soon) {
                return Err(Error::BadArgument {
                    what: "time",
                    detail: format!(
                        "{time_s} s is {:.3} ms after the previous frame, but the model was trained at {rate} Hz ({:.3} ms apart); \
                         resample the source to {rate} Hz",
                        (time_s - last) * 1e3,
                        1e3 / rate
                    ),
                });
            }
            return Ok(match step {
                Some(GridStep::Lost(_)) => TimeStep::Gap,
                _ => TimeStep::Follows,
            });
        }
        // A jump: the source's new clock only if it continues the jumped stamps before it.
        let continues =
            self.time_candidate.is_some_and(|c| (FOLLOWS_PERIODS..=GAP_PERIODS).contains(&((time_s - c) * rate)));
        if continues && self.time_candidate_frames + 1 >= TIME_REANCHOR_FRAMES {
            return Ok(TimeStep::Reanchor);
        }
        Ok(TimeStep::Jump)
    }

    /// The last stamp that came in order: the last accepted frame's, or a later one of a frame
    /// refused for its markers since.
    fn last_in_order(&self) -> Option<f64> {
        match (self.clock.last(), self.refused_in_order) {
            (Some(last), Some(refused)) => Some(last.max(refused)),
            (last, refused) => last.or(refused),
        }
    }

    /// Remembers a jumped stamp (to re-anchor on should more continue from it) and says why
    /// it was refused.
    fn refuse_jump(&mut self, time_s: f64) -> Error {
        let rate = self.model.card().frame_rate_hz;
        let continues =
            self.time_candidate.is_some_and(|c| (FOLLOWS_PERIODS..=GAP_PERIODS).contains(&((time_s - c) * rate)));
        self.time_candidate_frames = if continues { self.time_candidate_frames + 1 } else { 1 };
        self.time_candidate = Some(time_s);
        let last = self.clock.last().unwrap_or(f64::NAN);
        let what = if time_s <= last {
            format!("{time_s} s does not follow the previous frame's {last} s")
        } else {
            format!(
                "{time_s} s is {:.6e} s after the previous frame's {last} s (more than {MAX_TIME_GAP_S} s)",
                time_s - last
            )
        };
        Error::BadArgument {
            what: "time",
            detail: format!(
                "{what}: refused as a glitch of the source's clock ({} of {TIME_REANCHOR_FRAMES} stamps in a row that would make it the new clock)",
                self.time_candidate_frames
            ),
        }
    }

    /// Frames pushed since the stream was made, refused ones included (the next frame's
    /// number in errors).
    pub fn frames_pushed(&self) -> usize {
        self.pushed
    }

    /// Times [`push_at`](Self::push_at) restarted the window after a gap.
    pub fn gap_restarts(&self) -> u64 {
        self.gap_restarts
    }

    /// Times [`push_at`](Self::push_at) took a jumped clock as the source's new one
    /// ([`TIME_REANCHOR_FRAMES`] stamps in a row).
    pub fn time_reanchors(&self) -> u64 {
        self.time_reanchors
    }

    /// Pushes `frames` (whole frames back to back, e.g. a packet from the acquisition
    /// system) and writes one output row into `out` for each frame that completes a window.
    /// Returns the number of rows written. Under [`MissingMarkers::Refuse`] a block holding a
    /// missing (non-finite) value is refused whole, before anything is pushed; under
    /// [`MissingMarkers::Fill`] each frame is filled as by [`push`](Self::push) (flags of
    /// single frames: push them one at a time). A later failure (degenerate markers, a
    /// non-finite prediction) stops at that frame with its error (numbered within `frames`);
    /// the frames before it stay pushed and their rows stay written in `out`
    /// ([`rows_before_refusal`](Self::rows_before_refusal) says how many). Does not allocate
    /// on success.
    pub fn push_many(&mut self, frames: &[f32], out: &mut [f32]) -> Result<usize> {
        self.rows_before_refusal = 0;
        let (fl, no) = (self.model.frame_len(), self.model.n_outputs());
        if !frames.len().is_multiple_of(fl) {
            return Err(Error::BadArgument {
                what: "frames",
                detail: format!("{} values is not a whole number of {fl}-value frames", frames.len()),
            });
        }
        // Refuse a block with a missing value before pushing any of it.
        if let Some(i) = frames.iter().position(|v| !v.is_finite()).filter(|_| self.policy == MissingMarkers::Refuse) {
            return Err(Error::NonFiniteInput {
                frame: i / fl,
                field: self.model.feature_set().frame_names()[i % fl].clone(),
                value: frames[i],
            });
        }
        let n = frames.len() / fl;
        let max_rows = self.rows_for(n);
        if out.len() < max_rows * no {
            return Err(Error::BadArgument {
                what: "output buffer",
                detail: format!("has {} values, {max_rows} rows × {no} = {} needed", out.len(), max_rows * no),
            });
        }
        let mut rows = 0;
        for (i, frame) in frames.chunks_exact(fl).enumerate() {
            match self.push(frame) {
                Ok(Some(o)) => {
                    out[rows * no..(rows + 1) * no].copy_from_slice(o);
                    rows += 1;
                }
                Ok(None) => {}
                Err(e) => {
                    self.rows_before_refusal = rows;
                    return Err(e.renumbered(i));
                }
            }
        }
        Ok(rows)
    }

    /// After [`push_many`](Self::push_many) refused a frame part-way: the rows it wrote into
    /// `out` for the frames before that one (pushed, their outputs valid). 0 after a block
    /// refused whole or pushed whole.
    pub fn rows_before_refusal(&self) -> usize {
        self.rows_before_refusal
    }

    /// Rows [`push_many`](Self::push_many) will write for `n_frames` more frames.
    pub fn rows_for(&self, n_frames: usize) -> usize {
        (n_frames + self.filled + 1).saturating_sub(self.model.window()).min(n_frames)
    }

    /// The last prediction (valid after a `push` that returned `Some`).
    pub fn output(&self) -> &[f32] {
        &self.output
    }

    /// [`status`] bits of the last prediction (valid after a `push` that returned `Some`):
    /// [`status::FILLED`], [`status::OUTSIDE_TRAINING`] (the newest frame's features beyond
    /// the model's training envelope), [`status::IMPLAUSIBLE`] (an output far beyond it),
    /// [`status::PER_FRAME`] (a correcting model's correction withheld, or an early output),
    /// [`status::TURNED_OVER`] (with `IMPLAUSIBLE`: the hand reads turned over on the forearm).
    pub fn status(&self) -> u16 {
        self.status
    }

    /// Forgets every frame held (e.g. after a gap in the recording). The gap filler keeps
    /// what it learned of the subject; a new subject needs a new stream.
    pub fn reset(&mut self) {
        self.filler.forget_last_frame();
        self.clock = FrameGrid::default();
        self.pace = SourcePace::default();
        self.time_candidate = None;
        self.time_candidate_frames = 0;
        self.refused_in_order = None;
        self.head = 0;
        self.filled = 0;
        self.resynced = false;
        if let Some(sd) = &mut self.sd {
            sd.restart();
        }
    }

    /// The lab's up direction (against gravity) in the coordinates of the marker frames pushed
    /// from now on: `[0, 1, 0]` (the body model's lab) until set, `[0, 0, 1]` for a Z-up lab
    /// (Vicon, Qualisys); any non-zero length. Each marker frame is turned into the body
    /// model's lab before anything else. Only a model that reads gravity's direction (the
    /// `angles_gravity` and `relative_gravity` feature sets: the `wrist-chain` torques) depends
    /// on it, and silently; angles do not. An `up` that is not a finite non-zero vector is an
    /// error and changes nothing.
    pub fn set_lab_up(&mut self, up: [f64; 3]) -> Result<()> {
        self.lab = crate::body::lab_turn(up)?;
        Ok(())
    }

    /// The standard deviation of each output of the last frame pushed (output units), or
    /// `None`: the model's card says nothing of its uncertainty (no `uncertainty`), the last
    /// push gave no output, or too few frames have come since the window (re)started to tell
    /// the markers' noise ([`MIN_NOISE_FRAMES`](crate::model::uncertainty::MIN_NOISE_FRAMES)).
    /// How it is computed, and how well it covers: [`crate::model::uncertainty`].
    pub fn output_sd(&self) -> Option<&[f64]> {
        self.sd.as_ref()?.sd()
    }

    /// The running means the last output's σ was computed from (the per-frame angles' noise
    /// variances and the mean squared corrections), for studies that fit a card's
    /// coefficients (kept for every model that reads per-frame angles, with or without the
    /// card's `uncertainty`); `None` for another model or before enough frames.
    pub fn sd_terms(&self) -> Option<([f64; 3], [f64; 3])> {
        self.sd.as_ref()?.terms()
    }
}

#[cfg(test)]
mod grid_tests;
