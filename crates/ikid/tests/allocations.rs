//! `Stream::push` and `Tracker::push` must not touch the heap once they exist: a counting
//! global allocator proves it for every thesis network shape and every feature set.

use ikid::FeatureSet;
use ikid::testing::{random_frames, random_model};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    /// Only the test thread that measures counts: the harness starting another test's thread
    /// (which allocates) must not show up in this one's count.
    static COUNTING: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

fn count() {
    if COUNTING.with(|c| c.get()) {
        ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
    }
}

/// Allocations made by this thread while `f` runs.
fn allocations_in(f: impl FnOnce()) -> usize {
    let before = ALLOCATIONS.load(Ordering::SeqCst);
    COUNTING.with(|c| c.set(true));
    f();
    COUNTING.with(|c| c.set(false));
    ALLOCATIONS.load(Ordering::SeqCst) - before
}

// SAFETY: forwards to the system allocator unchanged; only counts calls.
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// The counter is global: tests that read it take turns.
static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());

#[test]
fn push_never_allocates() {
    let _turn = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let cases: [(FeatureSet, &[usize]); 5] = [
        (FeatureSet::Markers, &[300, 300]),
        (FeatureSet::Basis, &[240, 240]),
        (FeatureSet::JointState, &[330, 60, 165]),
        (FeatureSet::Relative, &[64]),
        (FeatureSet::Markers, &[7]),
    ];
    for (set, hidden) in cases {
        let model = random_model(set, 5, hidden, 3, 3);
        let frames = random_frames(set, 200, 4);
        let mut stream = model.stream();
        let mut produced = 0;
        let n = allocations_in(|| {
            for (i, frame) in frames.chunks_exact(set.frame_len()).enumerate() {
                if i == 100 {
                    stream.reset();
                }
                if let Some(out) = stream.push(frame).expect("valid frame") {
                    produced += usize::from(out[0].is_finite());
                }
            }
        });
        assert_eq!(n, 0, "{set:?} {hidden:?}: {n} allocations in 200 pushes");
        assert_eq!(produced, 200 - 2 * 4, "{set:?}: predictions once each window (re)filled");
    }
}

#[test]
fn a_stamped_stream_never_allocates() {
    // push_at's clock, its pace (the rate check) and a gap's restart run on the stack too.
    let _turn = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let model = random_model(FeatureSet::Angles, 5, &[64], 3, 3);
    let frames = random_frames(FeatureSet::Angles, 300, 4);
    let mut stream = model.stream();
    let mut produced = 0;
    let n = allocations_in(|| {
        for (i, frame) in frames.chunks_exact(18).enumerate() {
            let lost = if i >= 150 { 10 } else { 0 }; // ten frames lost at 150
            let time = (i + lost) as f64 * 1e-3;
            if stream.push_at(time, frame).expect("valid frame").is_some() {
                produced += 1;
            }
        }
    });
    assert_eq!(n, 0, "{n} allocations in 300 stamped pushes");
    assert_eq!(produced, 300 - 2 * 4, "predictions once each window (re)filled");
}

#[test]
fn filling_a_missing_marker_never_allocates() {
    let _turn = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let model = random_model(FeatureSet::Angles, 5, &[64, 64], 3, 5);
    let mut frames = random_frames(FeatureSet::Angles, 300, 6);
    let mut stream = model.stream();
    stream.set_missing_markers(ikid::MissingMarkers::Fill).expect("marker model");
    // Every third frame after the filler has calibrated loses one marker, in turn.
    for (i, frame) in frames.chunks_exact_mut(18).enumerate().skip(100).step_by(3) {
        let gone = i % 6;
        frame[3 * gone..3 * gone + 3].fill(f32::NAN);
    }
    let mut filled = 0;
    let n = allocations_in(|| {
        for frame in frames.chunks_exact(18) {
            stream.push(frame).expect("one missing marker is filled");
            filled += usize::from(stream.filled_markers() != 0);
        }
    });
    assert_eq!(n, 0, "{n} allocations in 300 pushes with fills");
    assert_eq!(filled, 200 / 3 + 1);
}

#[test]
fn tracker_push_never_allocates_even_refined() {
    let _turn = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let body = ikid::body::BodyModel::default();
    let q: Vec<f64> = (0..400)
        .flat_map(|i| {
            let t = i as f64 / 1000.0;
            [0.5 * (3.0 * t).sin(), -0.4 * (2.0 * t).sin(), 0.2 * (5.0 * t).cos()]
        })
        .collect();
    let mut frames = body.marker_frames(&q, 0.2).expect("valid angles");
    ikid::noise::uniform_range(&mut frames, 0.02, 3).expect("valid noise");
    // A marker missing now and then, a forearm marker once: the paths that skip corrections.
    for i in (150..400).step_by(7) {
        frames[i * 18 + 3 * (3 + i % 3)..i * 18 + 3 * (3 + i % 3) + 3].fill(f64::NAN);
    }
    frames[300 * 18] = f64::NAN;
    let mut tracker = ikid::Tracker::new(body, ikid::TrackerSettings::new(1000.0)).expect("default settings");
    tracker.set_refiner(Some(ikid::testing::random_refiner(16, &[32, 32], 9))).expect("a refiner");
    let mut torques = 0;
    let n = allocations_in(|| {
        for (i, frame) in frames.chunks_exact(18).enumerate() {
            if i == 200 {
                tracker.reset();
            }
            let out = tracker.push(frame).expect("valid frame");
            torques += usize::from(out.is_some_and(|o| o.tau[1].is_finite()));
        }
    });
    assert_eq!(n, 0, "{n} allocations in 400 tracker pushes");
    assert!(torques >= 390, "estimates on all but the frames waiting for a complete one: {torques}");
    assert!(tracker.refiner().is_some());
}

#[test]
fn a_stamped_tracker_in_a_turned_lab_never_allocates() {
    // push_at's gap restarts and the lab's turn (a Z-up lab) run on the stack too.
    let _turn = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let body = ikid::body::BodyModel::default();
    let q: Vec<f64> = (0..300)
        .flat_map(|i| {
            let t = i as f64 / 1000.0;
            [0.5 * (3.0 * t).sin(), -0.4 * (2.0 * t).sin(), 0.2 * (5.0 * t).cos()]
        })
        .collect();
    let frames = body.marker_frames(&q, 0.2).expect("valid angles");
    let settings = ikid::TrackerSettings { up: [0.0, 0.0, 1.0], ..ikid::TrackerSettings::new(1000.0) };
    let mut tracker = ikid::Tracker::new(body, settings).expect("valid settings");
    let mut estimates = 0;
    let n = allocations_in(|| {
        for (i, frame) in frames.chunks_exact(18).enumerate() {
            // 50 ms lost after frame 150, and the clock restarted at frame 250.
            let time = match i {
                0..150 => i as f64 / 1000.0,
                150..250 => 0.05 + i as f64 / 1000.0,
                _ => (i - 250) as f64 / 1000.0,
            };
            let out = tracker.push_at(time, frame).expect("valid frame");
            estimates += usize::from(out.is_some_and(|o| o.tau[1].is_finite()));
        }
    });
    assert_eq!(n, 0, "{n} allocations in 300 stamped pushes");
    assert_eq!(tracker.gap_restarts(), 2);
    assert_eq!(estimates, 300, "every frame complete: each restart starts on its frame");
}

#[test]
fn the_counter_sees_this_threads_allocations() {
    let _turn = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let n = allocations_in(|| {
        std::hint::black_box(vec![1u8; 16]);
    });
    assert_eq!(n, 1, "the counting allocator must see a Vec's allocation");
}

#[test]
fn a_stream_giving_standard_deviations_never_allocates() {
    let _turn = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let card = ikid::model::SdCard {
        method: ikid::model::uncertainty::SD_METHOD.into(),
        memory_frames: 5.0,
        power: 0.8,
        constant: vec![1e-6; 3],
        angle_noise: vec![vec![0.5; 3]; 3],
        correction: vec![0.0; 3],
        provenance: Default::default(),
    };
    let model = random_model(FeatureSet::Angles, 5, &[64], 3, 7).with_uncertainty(Some(card)).expect("a valid card");
    let frames = random_frames(FeatureSet::Angles, 200, 8);
    let mut stream = model.stream();
    let mut with_sd = 0;
    let n = allocations_in(|| {
        for frame in frames.chunks_exact(18) {
            if stream.push(frame).expect("valid frame").is_some() {
                with_sd += usize::from(stream.output_sd().is_some_and(|sd| sd.iter().all(|&v| v > 0.0)));
            }
        }
    });
    assert_eq!(n, 0, "{n} allocations in 200 pushes with σ");
    // σ from the frame whose third difference is the MIN_NOISE_FRAMES-th.
    assert_eq!(with_sd, 200 - (3 + ikid::model::uncertainty::MIN_NOISE_FRAMES - 1));
}
