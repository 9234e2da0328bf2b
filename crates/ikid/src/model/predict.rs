//! Whole recordings through a model at once, on several threads, giving exactly what a
//! stream gives frame by frame.

use super::handle::Model;
use crate::error::{Error, Result};
use crate::gaps::{MissingMarkers, fill_gaps};
use crate::net::BATCH;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

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
        // another process takes fewer blocks instead of holding the others up. The workers own
        // what they read (the model is shared by reference count, the frames and features are
        // moved into an `Arc`) and hand back each block's values, which the caller copies.
        const FRAMES_PER_BLOCK: usize = 512;
        const ROWS_PER_BLOCK: usize = 8 * BATCH;
        let n_frames = frames.len() / fl;
        let frames: Arc<[f32]> = Arc::from(frames);
        let blocks = for_each_claimed(n_frames.div_ceil(FRAMES_PER_BLOCK), threads, || (), {
            let frames = Arc::clone(&frames);
            move |(), b| {
                let first = b * FRAMES_PER_BLOCK;
                let block = &frames[first * fl..(first + FRAMES_PER_BLOCK).min(n_frames) * fl];
                let mut features = vec![0f32; block.len() / fl * nf];
                for (i, (frame, row)) in block.chunks_exact(fl).zip(features.chunks_exact_mut(nf)).enumerate() {
                    set.compute(frame, row, first + i)?;
                }
                Ok(features)
            }
        })?;
        let features: Arc<[f32]> = blocks.concat().into();
        let model = self.clone();
        let scratch = move || (model.net().scratch(), model.net().batch_scratch());
        let model = self.clone();
        let blocks =
            for_each_claimed(rows.div_ceil(ROWS_PER_BLOCK), threads, scratch, move |(scratch, batch_scratch), b| {
                let net = model.net();
                // Windows of consecutive frames are contiguous slices of the feature rows; row r
                // is the prediction for frame r + w - 1, the number its errors carry.
                let window = |r: usize| &features[r * nf..(r + w) * nf];
                let first = b * ROWS_PER_BLOCK;
                let mut chunk = vec![0f32; ((first + ROWS_PER_BLOCK).min(rows) - first) * no];
                let mut row = first;
                let mut groups = chunk.chunks_exact_mut(BATCH * no);
                for group in &mut groups {
                    net.run_batch(std::array::from_fn(|s| window(row + s)), batch_scratch, group, row + w - 1)?;
                    row += BATCH;
                }
                for out in groups.into_remainder().chunks_exact_mut(no) {
                    net.run(window(row), scratch, out, row + w - 1)?;
                    row += 1;
                }
                Ok(chunk)
            })?;
        for (chunk, values) in out.chunks_mut(ROWS_PER_BLOCK * no).zip(blocks) {
            chunk.copy_from_slice(&values);
        }
        Ok(rows)
    }
}

/// What one thread of [`for_each_claimed`] did: its items' results, and the item it stopped
/// at with its error, if one failed.
type Claimed<R> = (Vec<(usize, R)>, Option<(usize, Error)>);

/// Runs `work` on items `0..n_items` on up to `threads` threads (the calling one included),
/// each thread claiming the next item in order and keeping its own `state`; returns the
/// items' results in item order, or the error of the earliest failing item (every item before
/// it was claimed and run to the end).
///
/// The threads are spawned here and joined before returning, and are not scoped: a scope
/// keeps a handle to the calling thread (`std::thread::current`), which a C host's main
/// thread never frees, and valgrind reports it as possibly lost in every host that predicts.
/// So `work` and `state` own what they use (`'static`).
fn for_each_claimed<S, R: Send + 'static>(
    n_items: usize,
    threads: usize,
    state: impl Fn() -> S + Send + Sync + 'static,
    work: impl Fn(&mut S, usize) -> Result<R> + Send + Sync + 'static,
) -> Result<Vec<R>> {
    let next = Arc::new(AtomicUsize::new(0));
    let shared = Arc::new((state, work));
    let worker = {
        let (next, shared) = (Arc::clone(&next), Arc::clone(&shared));
        move || -> Claimed<R> {
            let (state, work) = &*shared;
            let mut state = state();
            let mut done = Vec::new();
            loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                if i >= n_items {
                    return (done, None);
                }
                match work(&mut state, i) {
                    Ok(r) => done.push((i, r)),
                    Err(e) => return (done, Some((i, e))),
                }
            }
        }
    };
    let others: Vec<_> = (1..threads.min(n_items)).map(|_| std::thread::spawn(worker.clone())).collect();
    let mine = worker();
    let mut results: Vec<Option<R>> = std::iter::repeat_with(|| None).take(n_items).collect();
    let mut failed: Option<(usize, Error)> = None;
    let outcomes = others.into_iter().map(|h| h.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic)));
    for (done, error) in outcomes.chain([mine]) {
        for (i, r) in done {
            results[i] = Some(r);
        }
        if let Some((i, e)) = error
            && failed.as_ref().is_none_or(|(j, _)| i < *j)
        {
            failed = Some((i, e));
        }
    }
    match failed {
        Some((_, e)) => Err(e),
        // Without a failure every item was claimed and run.
        None => Ok(results.into_iter().flatten().collect()),
    }
}
