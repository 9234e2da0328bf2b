//! `Stream::push` must not touch the heap once the stream exists: a counting global
//! allocator proves it for every thesis network shape and every feature set.

use ikid::FeatureSet;
use ikid::testing::{random_frames, random_model};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards to the system allocator unchanged; only counts calls.
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn push_never_allocates() {
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
        let before = ALLOCATIONS.load(Ordering::SeqCst);
        let mut produced = 0;
        for (i, frame) in frames.chunks_exact(set.frame_len()).enumerate() {
            if i == 100 {
                stream.reset();
            }
            if let Some(out) = stream.push(frame).expect("valid frame") {
                produced += usize::from(out[0].is_finite());
            }
        }
        let after = ALLOCATIONS.load(Ordering::SeqCst);
        assert_eq!(after - before, 0, "{set:?} {hidden:?}: {} allocations in 200 pushes", after - before);
        assert_eq!(produced, 200 - 2 * 4, "{set:?}: predictions once each window (re)filled");
    }
}
