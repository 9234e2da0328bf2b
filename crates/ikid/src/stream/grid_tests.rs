//! The frame grid on its own (`FrameGrid`): which stamp follows, which is too soon, how many
//! frames a late one lost, and when the grid starts again. The streams' and the tracker's
//! jitter tests reach it only through whole trials; here each verdict is set by hand from the
//! documented rules (0.5-1.5 periods on from the last stamp or from the grid: the next frame;
//! 1.75 while the grid settles; half a period off the grid: a new grid).

use super::*;

const RATE: f64 = 1000.0;
const MS: f64 = 1e-3;

/// A grid that has taken `n` frames stamped exactly 1 ms apart from 0 (settled once `n` is
/// at least `GRID_SETTLING_FRAMES`).
fn on_time(n: usize) -> FrameGrid {
    let mut grid = FrameGrid::default();
    for k in 0..n {
        let t = k as f64 * MS;
        let step = grid.step(t, RATE);
        assert_eq!(step, if k == 0 { None } else { Some(GridStep::Follows) }, "frame {k}");
        grid.accept(t, RATE, step);
    }
    grid
}

#[test]
fn the_first_stamp_has_no_step_and_the_last_stamp_is_kept() {
    let mut grid = FrameGrid::default();
    assert_eq!(grid.last(), None);
    assert_eq!(grid.step(5.0, RATE), None);
    grid.accept(5.0, RATE, None);
    assert_eq!(grid.last(), Some(5.0));
    assert_eq!(grid.step(5.0 + MS, RATE), Some(GridStep::Follows));
}

#[test]
fn a_stamp_under_half_a_period_on_is_too_soon_and_one_over_is_the_next_frame() {
    let grid = on_time(20);
    let last = 19.0 * MS;
    assert_eq!(grid.step(last + 0.3 * MS, RATE), Some(GridStep::Soon));
    assert_eq!(grid.step(last + 0.6 * MS, RATE), Some(GridStep::Follows));
    assert_eq!(grid.step(last + 1.4 * MS, RATE), Some(GridStep::Follows));
}

#[test]
fn a_settled_grid_counts_the_frames_a_late_stamp_lost() {
    let grid = on_time(20);
    let last = 19.0 * MS;
    // 1.7 periods: past GAP_PERIODS once settled, so one frame lost (2 periods rounded, less the frame itself).
    assert_eq!(grid.step(last + 1.7 * MS, RATE), Some(GridStep::Lost(1)));
    assert_eq!(grid.step(last + 2.0 * MS, RATE), Some(GridStep::Lost(1)));
    assert_eq!(grid.step(last + 3.0 * MS, RATE), Some(GridStep::Lost(2)));
    assert_eq!(grid.step(last + 10.2 * MS, RATE), Some(GridStep::Lost(9)));
}

#[test]
fn a_settling_grid_takes_a_stamp_up_to_one_and_three_quarter_periods_on_as_the_next_frame() {
    let grid = on_time(3);
    let last = 2.0 * MS;
    assert_eq!(grid.step(last + 1.7 * MS, RATE), Some(GridStep::Follows));
    assert_eq!(grid.step(last + 1.8 * MS, RATE), Some(GridStep::Lost(1)));
    // The early side does not widen: a faster source is refused from its second frame.
    assert_eq!(grid.step(last + 0.45 * MS, RATE), Some(GridStep::Soon));
}

#[test]
fn a_late_stamp_after_an_early_one_follows_through_the_grid() {
    // Early by 0.35 periods, then late by 0.35: 1.7 periods apart, more than GAP_PERIODS
    // measured from the last stamp, but the grid, moved only a small part of the way to the
    // early stamp (1/21: its 21st frame), puts the late one about 1.37 periods on.
    let mut grid = on_time(20);
    let early = 20.0 * MS - 0.35 * MS;
    let step = grid.step(early, RATE);
    assert_eq!(step, Some(GridStep::Follows));
    grid.accept(early, RATE, step);
    let late = 21.0 * MS + 0.35 * MS;
    assert!((late - early) * RATE > GAP_PERIODS);
    assert_eq!(grid.step(late, RATE), Some(GridStep::Follows));
}

#[test]
fn frames_lost_move_the_grid_on_by_their_periods() {
    let mut grid = on_time(20);
    let late = 19.0 * MS + 3.0 * MS;
    let step = grid.step(late, RATE);
    assert_eq!(step, Some(GridStep::Lost(2)));
    grid.accept(late, RATE, step);
    assert_eq!(grid.last(), Some(late));
    // The grid moved on three periods and stayed settled and in phase: 1 ms on follows, 1.6 ms
    // on lost a frame (a grid that took the late stamp as a new start would still be settling
    // and take it as the next frame).
    assert_eq!(grid.step(late + MS, RATE), Some(GridStep::Follows));
    assert_eq!(grid.step(late + 1.6 * MS, RATE), Some(GridStep::Lost(1)));
}

#[test]
fn a_stamp_half_a_period_off_the_grid_starts_a_new_grid_there() {
    // The last stamp early by 0.35 periods, then one 2.3 periods after the grid's frame:
    // 2.65 periods from the last stamp, rounded to three, so two lost and the grid expected it
    // 0.7 periods later than it came: a new grid from this stamp, settling again.
    let mut grid = on_time(20);
    let early = 20.0 * MS - 0.35 * MS;
    let step = grid.step(early, RATE);
    grid.accept(early, RATE, step);
    let grid_frame = 20.0 * MS - 0.35 * MS / 21.0;
    let stamp = grid_frame + 2.3 * MS;
    let step = grid.step(stamp, RATE);
    assert_eq!(step, Some(GridStep::Lost(2)));
    grid.accept(stamp, RATE, step);
    // Settling again (1.75 periods for the next frame), in phase with the new stamp: 1.8 ms on
    // is a lost frame, where the old grid, 0.7 periods behind, would take it as the next one.
    assert_eq!(grid.step(stamp + 1.7 * MS, RATE), Some(GridStep::Follows));
    assert_eq!(grid.step(stamp + 1.8 * MS, RATE), Some(GridStep::Lost(1)));
    assert_eq!(grid.step(stamp + 0.45 * MS, RATE), Some(GridStep::Soon));
}

#[test]
fn a_stamp_off_the_grid_by_less_than_half_a_period_keeps_the_grid_settled() {
    // A stamp 2.3 periods on without an early one before it: one frame lost (2.3 rounds to two
    // periods), so expected 0.3 periods before it came, which is jitter: the grid stays
    // settled, so 1.7 periods on is a lost frame, not the next one.
    let mut grid = on_time(20);
    let stamp = 19.0 * MS + 2.3 * MS;
    let step = grid.step(stamp, RATE);
    assert_eq!(step, Some(GridStep::Lost(1)));
    grid.accept(stamp, RATE, step);
    assert_eq!(grid.step(stamp + 1.7 * MS, RATE), Some(GridStep::Lost(1)));
}

#[test]
fn the_first_frames_set_the_grid_at_their_mean() {
    // Stamps alternately on time and 0.3 periods late: the first 16 set the grid at their mean
    // (0.15 periods late), the 17th (on time) moves it 1/17 of the way back (0.14 late). A stamp
    // 1.6 periods after that on-time frame is 1.46 from the grid: the next frame, where a grid
    // that had moved 1/32 of the way from the first stamp on (about 0.06 late) would count a
    // frame lost.
    let mut grid = FrameGrid::default();
    let stamp = |k: usize| k as f64 * MS + if k % 2 == 1 { 0.3 * MS } else { 0.0 };
    for k in 0..17 {
        let step = grid.step(stamp(k), RATE);
        assert_ne!(step, Some(GridStep::Soon));
        grid.accept(stamp(k), RATE, step);
    }
    let last = stamp(16);
    let next = 17.0 * MS + 0.6 * MS;
    assert!((next - last) * RATE > GAP_PERIODS);
    assert_eq!(grid.step(next, RATE), Some(GridStep::Follows));
}

#[test]
fn an_unstamped_frame_moves_the_last_stamp_and_the_grid_a_period_on() {
    let mut grid = on_time(20);
    grid.advance(MS);
    assert_eq!(grid.last(), Some(20.0 * MS));
    assert_eq!(grid.step(21.0 * MS, RATE), Some(GridStep::Follows));
    assert_eq!(grid.step(20.3 * MS, RATE), Some(GridStep::Soon));
    let mut empty = FrameGrid::default();
    empty.advance(MS);
    assert_eq!(empty.last(), None);
}

#[test]
fn the_grid_is_settled_from_its_grid_settling_frames_th_frame_on() {
    // GRID_SETTLING_FRAMES frames on the grid settle it: up to the one before, 1.7 periods on
    // is the next frame (1.75 while settling); from it, a frame lost (GAP_PERIODS).
    let n = GRID_SETTLING_FRAMES as usize;
    let before = on_time(n - 1);
    assert_eq!(before.step((n - 2) as f64 * MS + 1.7 * MS, RATE), Some(GridStep::Follows));
    let settled = on_time(n);
    assert_eq!(settled.step((n - 1) as f64 * MS + 1.7 * MS, RATE), Some(GridStep::Lost(1)));
}

#[test]
fn a_settled_grid_half_a_period_off_its_expectation_starts_again_and_settles_anew() {
    // Fifteen frames on time, the sixteenth 0.2 periods late (still settling: taken into the
    // phase at 1/16): the grid at 15.0125 ms. The next stamp 1.45 periods on is the next frame,
    // but 0.6375 periods off where the settled grid expects it (16.0125 ms): a new grid starts
    // from it, settling again, so a stamp 1.7 periods after it is the next frame (1.75 while
    // settling; a grid that had kept on, settled, would count one lost).
    let mut grid = on_time(15);
    let t = 15.2 * MS;
    assert_eq!(grid.step(t, RATE), Some(GridStep::Follows));
    grid.accept(t, RATE, Some(GridStep::Follows));
    let t = t + 1.45 * MS;
    assert_eq!(grid.step(t, RATE), Some(GridStep::Follows));
    grid.accept(t, RATE, Some(GridStep::Follows));
    assert_eq!(grid.step(t + 1.7 * MS, RATE), Some(GridStep::Follows));
}

#[test]
fn the_first_stamps_set_the_grids_phase_as_their_mean() {
    // Stamps 0.4 periods early, then on time: the phase is their mean, 0.2 periods early, so
    // the grid stands at 0.8 ms. A stamp at 3.4 ms is 2.6 periods on the grid (2.4 from the
    // last stamp): 3 periods rounded, 2 frames lost.
    let mut grid = FrameGrid::default();
    grid.accept(-0.4 * MS, RATE, None);
    assert_eq!(grid.step(1.0 * MS, RATE), Some(GridStep::Follows));
    grid.accept(1.0 * MS, RATE, Some(GridStep::Follows));
    assert_eq!(grid.step(3.4 * MS, RATE), Some(GridStep::Lost(2)));
}
