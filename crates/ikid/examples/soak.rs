//! Soak: millions of pushes through one stream, with a marker missing now and then (filled),
//! checking that nothing allocates, memory stays flat and latency does not drift.
//!
//! ```text
//! cargo run --release -p ikid --example soak -- [--pushes N]
//! ```
//! Prints one JSON line: pushes, allocations during them, resident memory before/after,
//! p50/p99/max latency of the first and the last million pushes.

use ikid::testing::{random_frames, random_model};
use ikid::{FeatureSet, MissingMarkers};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

struct Counting;
static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards to the system allocator unchanged; only counts calls.
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Resident set size in KiB (Linux), 0 elsewhere.
fn rss_kib() -> u64 {
    std::fs::read_to_string("/proc/self/statm")
        .ok()
        .and_then(|s| s.split_whitespace().nth(1).and_then(|v| v.parse::<u64>().ok()))
        .map_or(0, |pages| pages * 4)
}

fn quantiles(ns: &mut [u32]) -> (f64, f64, f64) {
    ns.sort_unstable();
    let q = |p: f64| ns[((ns.len() - 1) as f64 * p) as usize] as f64 / 1000.0;
    (q(0.5), q(0.99), q(1.0))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let pushes: usize = args
        .iter()
        .position(|a| a == "--pushes")
        .and_then(|i| args.get(i + 1))
        .map(|v| v.parse())
        .transpose()?
        .unwrap_or(10_000_000);
    let model = random_model(FeatureSet::Angles, 50, &[128, 128], 3, 1);
    let mut frames = random_frames(FeatureSet::Angles, 4096, 2);
    // Every 7th frame after the first 1000 loses one marker (in turn): the fill path soaks too.
    for (i, frame) in frames.chunks_exact_mut(18).enumerate().skip(1000).step_by(7) {
        frame[3 * (i % 6)..3 * (i % 6) + 3].fill(f32::NAN);
    }
    let mut stream = model.stream();
    stream.set_missing_markers(MissingMarkers::Fill)?;
    for frame in frames.chunks_exact(18) {
        stream.push(frame)?; // warm-up: the filler calibrates, every buffer is touched
    }
    let window = 1_000_000.min(pushes);
    // Touched now, so their pages count in the "before" memory.
    let mut first = vec![1u32; window];
    let mut last = vec![1u32; window];
    let (rss_before, allocs_before) = (rss_kib(), ALLOCATIONS.load(Ordering::Relaxed));
    let mut sink = 0f32;
    let mut filled = 0usize;
    let mut first_alloc_at = None;
    for i in 0..pushes {
        let frame = &frames[(i % 4096) * 18..(i % 4096 + 1) * 18];
        let t = Instant::now();
        let out = stream.push(frame)?;
        let dt = t.elapsed().as_nanos().min(u32::MAX as u128) as u32;
        sink += out.map_or(0.0, |o| o[0]);
        filled += usize::from(stream.filled_markers() != 0);
        if first_alloc_at.is_none() && ALLOCATIONS.load(Ordering::Relaxed) != allocs_before {
            first_alloc_at = Some(i);
        }
        if i < window {
            first[i] = dt;
        }
        if i >= pushes - window {
            last[i - (pushes - window)] = dt;
        }
    }
    // The count first: reading /proc allocates.
    let allocs = ALLOCATIONS.load(Ordering::Relaxed) - allocs_before;
    let rss_after = rss_kib();
    let (f50, f99, fmax) = quantiles(&mut first);
    let (l50, l99, lmax) = quantiles(&mut last);
    println!(
        "{{\"pushes\": {pushes}, \"filled_frames\": {filled}, \"allocations\": {allocs}, \"rss_kib_before\": {rss_before}, \"rss_kib_after\": {rss_after}, \
         \"first_million_us\": [{f50:.2}, {f99:.2}, {fmax:.0}], \"last_million_us\": [{l50:.2}, {l99:.2}, {lmax:.0}], \"checksum\": {sink}}}"
    );
    if allocs != 0 || rss_after > rss_before + 1024 {
        return Err(format!(
            "not flat: {allocs} allocations (first at push {first_alloc_at:?}), RSS {rss_before} → {rss_after} KiB"
        )
        .into());
    }
    Ok(())
}
