//! The VecEnv's hot path allocates nothing: a counting global allocator watches
//! 50 batch steps (episodes ending and resetting included).
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use dreampolicy::env::VecEnv;
use dreampolicy::robot::NUM_JOINTS;

struct Counting;
static COUNTING: AtomicBool = AtomicBool::new(false);
static ALLOCS: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards to the system allocator; only counts.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if COUNTING.load(Ordering::Relaxed) {
            ALLOCS.fetch_add(1, Ordering::Relaxed);
        }
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if COUNTING.load(Ordering::Relaxed) {
            ALLOCS.fetch_add(1, Ordering::Relaxed);
        }
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn vec_env_step_does_not_allocate() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/terrain_small.yaml");
    // short episodes so that resets happen inside the window
    let sets = ["env.n_envs=8", "env.threads=2", "env.episode_length_s=0.2"].map(String::from);
    let cfg = dreampolicy::rl::config::load(&path, &sets).unwrap();
    let mut v = VecEnv::new(&cfg.env).unwrap();
    let actions = vec![0.1f32; 8 * NUM_JOINTS];
    for _ in 0..5 {
        v.step(&actions); // warm up the thread pool
    }
    let (mut resets, mut warnings) = (0, 0);
    COUNTING.store(true, Ordering::SeqCst);
    for _ in 0..50 {
        let info = v.step(&actions);
        resets += info.episodes_done;
        warnings += info.warnings;
    }
    COUNTING.store(false, Ordering::SeqCst);
    assert!(resets > 0, "the window includes resets");
    assert_eq!(
        warnings, 0,
        "no MuJoCo warning (e.g. a full contact buffer)"
    );
    assert_eq!(
        ALLOCS.load(Ordering::SeqCst),
        0,
        "allocations during VecEnv::step"
    );
}
