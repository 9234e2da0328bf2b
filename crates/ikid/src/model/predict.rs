//! Whole recordings through a model at once, on several threads, giving exactly what a
//! stream gives frame by frame.

use super::handle::Model;
use crate::error::{Error, Result};
use crate::gaps::{MissingMarkers, fill_gaps};
use crate::net::BATCH;
use std::sync::{Mutex, PoisonError};

impl Model {
    /// Predictions for a recording of `n` frames: one per full window, `n - window + 1` rows
    /// (row `i` is the prediction for frame `i + window - 1`), or 0 if `n < window`.
    pub fn n_predictions(&self, n_frames: usize) -> usize {
        (n_frames + 1).saturating_sub(self.window())
    }

    /// Predicts a whole recording. `frames` holds `n` frames back to back; `out` receives
    /// [`n_predictions(n)`](Self::n_predictions) rows of [`n_outputs`](Self::n_outputs).
    /// Gives exactly the values a fresh [`Stream`](crate::Stream) fed the same frames gives, missing markers
    /// included (filled in one causal pass first when the model's policy is
    /// [`MissingMarkers::Fill`]). A marker frame spread over more than an arm spans
    /// ([`crate::body::check_marker_span`]: wrong units, a ghost marker) is refused, as a stream
    /// refuses it, and so (under [`MissingMarkers::Refuse`]) is a marker that jumped. Runs on up to [`std::thread::available_parallelism`] threads. Returns the
    /// number of rows.
    pub fn predict(&self, frames: &[f32], out: &mut [f32]) -> Result<usize> {
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
        self.predict_with_threads(frames, out, threads)
    }

    /// [`predict`](Self::predict) on at most `threads` threads (1 = the calling thread only).
    /// Every thread count gives bit-identical results.
    pub fn predict_with_threads(&self, frames: &[f32], out: &mut [f32], threads: usize) -> Result<usize> {
        let set = self.feature_set();
        let (fl, nf, w, no) = (set.frame_len(), set.feature_len(), self.window(), self.n_outputs());
        if !frames.len().is_multiple_of(fl) {
            return Err(Error::BadArgument {
                what: "frames",
                detail: format!("{} values is not a whole number of {fl}-value frames", frames.len()),
            });
        }
        let rows = self.n_predictions(frames.len() / fl);
        if out.len() != rows * no {
            return Err(Error::BadArgument {
                what: "output buffer",
                detail: format!("has {} values, expected {rows} rows × {no} = {}", out.len(), rows * no),
            });
        }
        if fl == crate::body::MARKER_FRAME_LEN {
            // As a stream does: markers no arm could hold are refused, not predicted from, and
            // (under the refuse policy, where nothing is filled) so is a marker that jumped.
            let mut continuity = (self.missing_markers() == MissingMarkers::Refuse).then(crate::GapFiller::new);
            for (i, frame) in frames.chunks_exact(fl).enumerate() {
                let wide: [f64; crate::body::MARKER_FRAME_LEN] = std::array::from_fn(|k| f64::from(frame[k]));
                crate::body::check_marker_span(&wide, i)?;
                if let Some(filler) = continuity.as_mut() {
                    filler.check(frame, i)?;
                }
            }
        }
        let filled;
        // Under the fill policy every frame goes through the filler, as in a stream: it fills
        // missing markers and refuses (or replaces) ones that jumped.
        let frames = if self.missing_markers() == MissingMarkers::Fill && fl == crate::body::MARKER_FRAME_LEN {
            filled = fill_gaps(frames, false, self.card().frame_rate_hz)?.0;
            &filled[..]
        } else {
            frames
        };
        // Below a few hundred rows a thread costs more than it saves.
        const MIN_ROWS_PER_THREAD: usize = 256;
        let threads = threads.clamp(1, rows.div_ceil(MIN_ROWS_PER_THREAD).max(1));
        // Features, then windows, in blocks that threads claim in turn: a thread slowed by
        // another process takes fewer blocks instead of holding the others up.
        const FRAMES_PER_BLOCK: usize = 512;
        const ROWS_PER_BLOCK: usize = 8 * BATCH;
        let mut features = vec![0f32; frames.len() / fl * nf];
        let blocks = frames.chunks(FRAMES_PER_BLOCK * fl).zip(features.chunks_mut(FRAMES_PER_BLOCK * nf));
        for_each_claimed(
            blocks,
            threads,
            || (),
            |(), b, (frames, features)| {
                for (i, (frame, row)) in frames.chunks_exact(fl).zip(features.chunks_exact_mut(nf)).enumerate() {
                    set.compute(frame, row, b * FRAMES_PER_BLOCK + i)?;
                }
                Ok(())
            },
        )?;
        let net = self.net();
        // Windows of consecutive frames are contiguous slices of the feature rows; row r is the
        // prediction for frame r + w - 1, the number its errors carry.
        let window = |r: usize| &features[r * nf..(r + w) * nf];
        let scratch = || (net.scratch(), net.batch_scratch());
        for_each_claimed(
            out.chunks_mut(ROWS_PER_BLOCK * no),
            threads,
            scratch,
            |(scratch, batch_scratch), b, chunk| {
                let mut row = b * ROWS_PER_BLOCK;
                let mut groups = chunk.chunks_exact_mut(BATCH * no);
                for group in &mut groups {
                    net.run_batch(std::array::from_fn(|s| window(row + s)), batch_scratch, group, row + w - 1)?;
                    row += BATCH;
                }
                for out in groups.into_remainder().chunks_exact_mut(no) {
                    net.run(window(row), scratch, out, row + w - 1)?;
                    row += 1;
                }
                Ok(())
            },
        )?;
        Ok(rows)
    }
}

/// Runs `work` on every item on up to `threads` threads (the calling one included), each
/// thread claiming the next item in order and keeping its own `state`. Returns the error of the
/// earliest failing item: every item before it was claimed and run to the end.
fn for_each_claimed<T: Send, S>(
    items: impl Iterator<Item = T> + Send,
    threads: usize,
    state: impl Fn() -> S + Sync,
    work: impl Fn(&mut S, usize, T) -> Result<()> + Sync,
) -> Result<()> {
    let queue = Mutex::new(items.enumerate());
    let worker = || -> Option<(usize, Error)> {
        let mut state = state();
        loop {
            // Only `next` runs under the lock, and it does not panic: no poisoning to handle.
            let (i, item) = queue.lock().unwrap_or_else(PoisonError::into_inner).next()?;
            if let Err(e) = work(&mut state, i, item) {
                return Some((i, e));
            }
        }
    };
    let failed = if threads <= 1 {
        worker()
    } else {
        std::thread::scope(|scope| {
            let others: Vec<_> = (1..threads).map(|_| scope.spawn(worker)).collect();
            let mine = worker();
            let others = others.into_iter().map(|h| h.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic)));
            others.chain([mine]).flatten().min_by_key(|&(i, _)| i)
        })
    };
    failed.map_or(Ok(()), |(_, e)| Err(e))
}
