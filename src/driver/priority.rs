//! The control loop's thread put ahead of ordinary work: Linux's first-in first-out
//! real-time scheduling (`SCHED_FIFO`), as flight software on Linux runs its control
//! loops, so that a busy machine (an emulator of a thousand vehicles beside it, a
//! compile) delays a tick by no more than the kernel's own latency.
//!
//! It needs the right to (root, `CAP_SYS_NICE`, or an `RLIMIT_RTPRIO` of at least the
//! priority, e.g. `rtprio` in `/etc/security/limits.conf`); without it the request fails
//! with the reason, and nothing is changed.

/// The highest priority `SCHED_FIFO` takes on Linux.
pub const MAX_PRIORITY: u8 = 99;

/// Puts the calling thread under `SCHED_FIFO` at `priority` (1..=99).
///
/// # Errors
/// A priority outside 1..=99, no right to it (with what grants it), or a system without
/// `SCHED_FIFO`.
pub fn run_ahead(priority: u8) -> Result<(), String> {
    if !(1..=MAX_PRIORITY).contains(&priority) {
        return Err(format!(
            "a real-time priority must be in 1..={MAX_PRIORITY}, got {priority}"
        ));
    }
    set_fifo(priority)
}

#[cfg(target_os = "linux")]
fn set_fifo(priority: u8) -> Result<(), String> {
    use thread_priority::{
        Error, RealtimeThreadSchedulePolicy, ThreadPriority, ThreadPriorityValue,
        ThreadSchedulePolicy, set_thread_priority_and_policy, thread_native_id,
    };
    let refused = |why: String| {
        format!("cannot run the control loop at real-time priority {priority}: {why}")
    };
    let value = ThreadPriorityValue::try_from(priority).map_err(|e| refused(e.to_string()))?;
    set_thread_priority_and_policy(
        thread_native_id(),
        ThreadPriority::Crossplatform(value),
        ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo),
    )
    .map_err(|e| match e {
        Error::OS(code) if code == EPERM => refused(
            "not permitted (it needs root, CAP_SYS_NICE, or an RLIMIT_RTPRIO of at least the \
             priority: `rtprio` in /etc/security/limits.conf)"
                .to_string(),
        ),
        Error::OS(code) => refused(std::io::Error::from_raw_os_error(code).to_string()),
        other => refused(other.to_string()),
    })
}

/// `EPERM` on Linux: the caller may not.
#[cfg(target_os = "linux")]
const EPERM: i32 = 1;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_priority_outside_its_range_is_refused_by_name() {
        assert_eq!(
            run_ahead(0),
            Err("a real-time priority must be in 1..=99, got 0".to_string())
        );
        assert_eq!(
            run_ahead(100),
            Err("a real-time priority must be in 1..=99, got 100".to_string())
        );
    }

    #[test]
    fn a_thread_is_put_ahead_or_told_why_not() {
        // On a thread of its own, so that the test runner's threads are not changed.
        let result = std::thread::spawn(|| run_ahead(5))
            .join()
            .expect("the thread runs");
        match result {
            Ok(()) => {}
            Err(why) => assert!(
                why.starts_with("cannot run the control loop at real-time priority 5: "),
                "{why}"
            ),
        }
    }
}
