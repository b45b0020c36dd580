//! The lockstep flight allocates nothing per frame or per tick once it is flying: frames
//! are encoded into recycled buffers, decoded without collecting, routed through kept
//! buffers, and the law and the saturation work in place. Counted with a global allocator
//! that counts only on the thread that asks it to.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use ringswarm::config::Config;
use ringswarm::driver::lockstep::Lockstep;
use ringswarm::swarm::SwarmPhase;
use ringswarm_wire::time::SimTime;

struct Counting;

thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    static COUNT: Cell<u64> = const { Cell::new(0) };
}

fn note() {
    // `try_with`: a thread being torn down has no locals left, and counts nothing.
    let _ = COUNTING.try_with(|on| {
        if on.get() {
            let _ = COUNT.try_with(|c| c.set(c.get() + 1));
        }
    });
}

// SAFETY: every call is forwarded unchanged to the system allocator; the counting touches
// only const-initialised thread locals, which never allocate.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note();
        // SAFETY: forwarded with the caller's guarantees.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note();
        // SAFETY: forwarded with the caller's guarantees.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded with the caller's guarantees.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note();
        // SAFETY: forwarded with the caller's guarantees.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Allocations (and reallocations) made by this thread while `f` runs.
fn allocations_during(f: impl FnOnce()) -> u64 {
    COUNT.with(|c| c.set(0));
    COUNTING.with(|on| on.set(true));
    f();
    COUNTING.with(|on| on.set(false));
    COUNT.with(Cell::get)
}

fn lockstep(name: &str) -> Lockstep {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("config")
        .join(name);
    let text = std::fs::read_to_string(path).expect("config");
    Lockstep::from_config(&Config::from_toml(&text).expect("parses")).expect("valid")
}

#[test]
fn the_counter_sees_an_allocation() {
    // The check can fail: a Vec of one element is one allocation.
    let n = allocations_during(|| {
        let v = std::hint::black_box(vec![1u8]);
        drop(v);
    });
    assert_eq!(n, 1);
}

#[test]
fn paper_sim1_allocates_nothing_per_frame_or_tick_in_consensus() {
    // Six vehicles, 250 Hz control, LOCAL_POSITION_NED and ATTITUDE_QUATERNION at 250 Hz:
    // 5 s is 1 250 ticks and about 23 000 datagrams.
    let mut run = lockstep("paper-sim1.toml");
    run.run_until(SimTime::from_millis(5_000), |_| {});
    assert!(matches!(run.swarm().phase(), SwarmPhase::Consensus(_)));
    let n = allocations_during(|| run.run_until(SimTime::from_millis(10_000), |_| {}));
    assert_eq!(n, 0, "allocations in 5 s of flight");
    assert!(matches!(run.swarm().phase(), SwarmPhase::Consensus(_)));
}

#[test]
fn a_ring_on_a_mavlink_network_allocates_nothing_per_frame_or_tick() {
    // 64 vehicles behind one network socket: every datagram goes through the router.
    let mut run = lockstep("big-ring.toml");
    run.run_until(SimTime::from_millis(6_000), |_| {});
    assert!(
        matches!(run.swarm().phase(), SwarmPhase::Consensus(_)),
        "{:?}",
        run.swarm().phase()
    );
    let n = allocations_during(|| run.run_until(SimTime::from_millis(8_000), |_| {}));
    assert_eq!(n, 0, "allocations in 2 s of flight");
}
