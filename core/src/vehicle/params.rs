//! Reading and writing a vehicle's parameters by name, the way a ground station does
//! (PARAM_REQUEST_READ, PARAM_SET, the PARAM_VALUE echo), with every value the handshake
//! changed remembered so that the end of the flight puts it back.
//!
//! ```text
//!  step (one parameter, in order):
//!   Reading: PARAM_REQUEST_READ for each of its spellings; again every `retry`
//!     ──PARAM_VALUE of one spelling──► read: that spelling is the vehicle's
//!        Read ──► next step;  Set/SetBits already at the value ──► next step
//!        otherwise ──► Writing: PARAM_SET (the value), again every `retry`
//!   Writing ──PARAM_VALUE of that name, at the value──► next step (the old value kept
//!            for the restore) ; at another value ──► Failed (the write refused, named);
//!            at the old value: a late answer to a resent read, or a refusal: waited
//!            out (the PARAM_SET is resent), and named as a refusal if it stays so
//!   Reading/Writing ──no answer after `max_attempts` sends──► Failed (named)
//!  every step done ──► Done
//! ```
//!
//! Values travel as floats, as ArduPilot reads and writes them (an integer parameter is
//! its value cast to a float): exact for the small integers and flags set here.
//!
//! Pure: the MAVLink messages are built and read in `crate::link`.

use std::time::Duration;

use ringswarm_wire::ardupilot::ParamName;
use ringswarm_wire::time::SimTime;

pub use crate::link::{ParamAction, ParamStep};

/// A message the machine wants sent.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ParamSend {
    /// PARAM_REQUEST_READ by name.
    Read(&'static str),
    /// PARAM_SET.
    Set {
        /// The name.
        name: &'static str,
        /// The value.
        value: f32,
    },
}

/// Where the machine is.
#[derive(Debug, Clone, PartialEq)]
enum State {
    Reading,
    Writing {
        name: &'static str,
        old: f32,
        value: f32,
        /// It answered with the old value since the write.
        still_old: bool,
    },
    Done,
    Failed(String),
}

/// A run of parameter steps.
#[derive(Debug, Clone)]
pub struct ParamSession {
    steps: Vec<ParamStep>,
    step: usize,
    state: State,
    retry: Duration,
    max_attempts: u8,
    attempts: u8,
    deadline: Option<SimTime>,
    /// Every value read, by the vehicle's spelling.
    read: Vec<(&'static str, f32)>,
    /// What was changed: the vehicle's spelling and the value before.
    changed: Vec<(&'static str, f32)>,
}

impl ParamSession {
    /// A session running `steps` in order, each message sent again after `retry` without
    /// an answer, up to `max_attempts` sends.
    pub fn new(steps: Vec<ParamStep>, retry: Duration, max_attempts: u8) -> Self {
        Self {
            state: if steps.is_empty() {
                State::Done
            } else {
                State::Reading
            },
            steps,
            step: 0,
            retry,
            max_attempts: max_attempts.max(1),
            attempts: 0,
            deadline: None,
            read: Vec::new(),
            changed: Vec::new(),
        }
    }

    /// A session putting back what `changed` lists (a spelling and its old value).
    pub fn restore(changed: &[(&'static str, f32)], retry: Duration, max_attempts: u8) -> Self {
        let steps = changed
            .iter()
            .map(|&(name, old)| ParamStep {
                param: ParamName::unrenamed(name),
                action: ParamAction::Set(old),
            })
            .collect();
        Self::new(steps, retry, max_attempts)
    }

    /// The messages to send now: the first step's reads (nothing once done).
    pub fn start(&mut self, now: SimTime) -> Vec<ParamSend> {
        if self.state != State::Reading || self.deadline.is_some() {
            return Vec::new();
        }
        self.attempts = 0;
        self.send(now)
    }

    /// Whether every step is done.
    pub fn done(&self) -> bool {
        self.state == State::Done
    }

    /// Why it failed, if it did.
    pub fn failure(&self) -> Option<&str> {
        match &self.state {
            State::Failed(why) => Some(why),
            _ => None,
        }
    }

    /// The value read of `param` (under either spelling), if any.
    pub fn value(&self, param: &ParamName) -> Option<f32> {
        self.read
            .iter()
            .find(|(name, _)| param.is(name))
            .map(|(_, v)| *v)
    }

    /// What the session changed: the vehicle's spelling and the value before.
    pub fn changed(&self) -> &[(&'static str, f32)] {
        &self.changed
    }

    /// What to put back: what it changed, and a write in flight (it may have been taken).
    pub fn to_restore(&self) -> Vec<(&'static str, f32)> {
        let mut all = self.changed.clone();
        if let State::Writing { name, old, .. } = self.state {
            all.push((name, old));
        }
        all
    }

    /// When [`ParamSession::handle_timeout`] must be called.
    pub fn poll_timeout(&self) -> SimTime {
        match self.state {
            State::Reading | State::Writing { .. } => self.deadline.unwrap_or(SimTime::MAX),
            _ => SimTime::MAX,
        }
    }

    /// Resends what went unanswered, or fails after the last attempt.
    pub fn handle_timeout(&mut self, now: SimTime) -> Vec<ParamSend> {
        let Some(deadline) = self.deadline else {
            return Vec::new();
        };
        if now < deadline || matches!(self.state, State::Done | State::Failed(_)) {
            return Vec::new();
        }
        if self.attempts >= self.max_attempts {
            let Some(step) = self.steps.get(self.step) else {
                return Vec::new();
            };
            let names: Vec<&str> = step.param.spellings().collect();
            let why = match &self.state {
                State::Writing {
                    name,
                    value,
                    old,
                    still_old: true,
                } => format!(
                    "parameter {name} = {value} refused: the vehicle reads back {old} after {} attempts",
                    self.attempts
                ),
                State::Writing { name, value, .. } => format!(
                    "parameter {name} = {value} not confirmed after {} attempts",
                    self.attempts
                ),
                _ => format!(
                    "parameter {} never answered after {} attempts (is it a vehicle of this autopilot and version?)",
                    names.join(" / "),
                    self.attempts
                ),
            };
            self.state = State::Failed(why);
            self.deadline = None;
            return Vec::new();
        }
        self.send(now)
    }

    /// A PARAM_VALUE from the vehicle: what to send next.
    pub fn on_value(&mut self, now: SimTime, name: &str, value: f32) -> Vec<ParamSend> {
        let Some(step) = self.steps.get(self.step).copied() else {
            return Vec::new();
        };
        match self.state.clone() {
            State::Reading => {
                let Some(spelling) = step.param.spellings().find(|s| *s == name) else {
                    return Vec::new();
                };
                self.read.retain(|(n, _)| *n != spelling);
                self.read.push((spelling, value));
                let target = match step.action {
                    ParamAction::Read => None,
                    ParamAction::Set(v) | ParamAction::SetIfOn { value: v, .. } => Some(v),
                    ParamAction::SetBits(bits) => {
                        // An integer mask read as a float: its bits or'ed in.
                        Some(((value.max(0.0) as u32) | bits) as f32)
                    }
                };
                match target {
                    Some(target) if target != value => {
                        self.state = State::Writing {
                            name: spelling,
                            old: value,
                            value: target,
                            still_old: false,
                        };
                        self.attempts = 0;
                        self.send(now)
                    }
                    _ => self.next(now),
                }
            }
            State::Writing {
                name: writing,
                old,
                value: target,
                ..
            } if writing == name => {
                if value == old {
                    // A late answer to a read sent twice, or the write not taken: the
                    // PARAM_SET is resent at the deadline.
                    self.state = State::Writing {
                        name: writing,
                        old,
                        value: target,
                        still_old: true,
                    };
                    Vec::new()
                } else if value == target {
                    self.changed.push((writing, old));
                    self.read.retain(|(n, _)| *n != writing);
                    self.read.push((writing, value));
                    self.next(now)
                } else {
                    self.state = State::Failed(format!(
                        "parameter {writing} = {target} refused: the vehicle reads back {value}"
                    ));
                    self.deadline = None;
                    Vec::new()
                }
            }
            _ => Vec::new(),
        }
    }

    fn next(&mut self, now: SimTime) -> Vec<ParamSend> {
        self.step += 1;
        self.attempts = 0;
        // A step set only when a flag read before is on is skipped while it is off (or
        // was never read).
        while let Some(ParamAction::SetIfOn { flag, .. }) =
            self.steps.get(self.step).map(|s| s.action)
            && self.value(&flag).is_none_or(|v| v == 0.0)
        {
            self.step += 1;
        }
        if self.step >= self.steps.len() {
            self.state = State::Done;
            self.deadline = None;
            return Vec::new();
        }
        self.state = State::Reading;
        self.send(now)
    }

    fn send(&mut self, now: SimTime) -> Vec<ParamSend> {
        self.attempts += 1;
        self.deadline = Some(now + self.retry);
        match &self.state {
            State::Reading => self
                .steps
                .get(self.step)
                .map(|s| s.param.spellings().map(ParamSend::Read).collect())
                .unwrap_or_default(),
            State::Writing { name, value, .. } => vec![ParamSend::Set {
                name,
                value: *value,
            }],
            _ => Vec::new(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ringswarm_wire::ardupilot::{FS_GCS_ENABLE, GUID_OPTIONS, MAV_GCS_SYSID, MOT_THST_HOVER};

    fn t(s: f64) -> SimTime {
        SimTime::from_secs_f64(s)
    }

    fn session() -> ParamSession {
        ParamSession::new(
            vec![
                ParamStep {
                    param: MOT_THST_HOVER,
                    action: ParamAction::Read,
                },
                ParamStep {
                    param: GUID_OPTIONS,
                    action: ParamAction::SetBits(8),
                },
                ParamStep {
                    param: MAV_GCS_SYSID,
                    action: ParamAction::Set(253.0),
                },
            ],
            Duration::from_millis(500),
            3,
        )
    }

    #[test]
    fn reads_sets_and_remembers_what_it_changed() {
        let mut s = session();
        assert_eq!(s.start(t(0.0)), vec![ParamSend::Read("MOT_THST_HOVER")]);
        // Another parameter's value is not an answer.
        assert!(s.on_value(t(0.1), "GUID_TIMEOUT", 3.0).is_empty());
        assert_eq!(
            s.on_value(t(0.1), "MOT_THST_HOVER", 0.39),
            vec![ParamSend::Read("GUID_OPTIONS")]
        );
        // Bit 3 or'ed into what was there (bit 2 kept).
        assert_eq!(
            s.on_value(t(0.2), "GUID_OPTIONS", 4.0),
            vec![ParamSend::Set {
                name: "GUID_OPTIONS",
                value: 12.0
            }]
        );
        // Both spellings of a renamed parameter are asked for; a 4.6 vehicle answers
        // the old one, which is then the one written.
        assert_eq!(
            s.on_value(t(0.3), "GUID_OPTIONS", 12.0),
            vec![
                ParamSend::Read("MAV_GCS_SYSID"),
                ParamSend::Read("SYSID_MYGCS")
            ]
        );
        assert_eq!(
            s.on_value(t(0.4), "SYSID_MYGCS", 255.0),
            vec![ParamSend::Set {
                name: "SYSID_MYGCS",
                value: 253.0
            }]
        );
        assert!(s.on_value(t(0.5), "SYSID_MYGCS", 253.0).is_empty());
        assert!(s.done());
        assert_eq!(s.value(&MOT_THST_HOVER), Some(0.39));
        assert_eq!(s.value(&MAV_GCS_SYSID), Some(253.0));
        assert_eq!(
            s.changed(),
            &[("GUID_OPTIONS", 4.0), ("SYSID_MYGCS", 255.0)]
        );
        // The restore writes the old values back under the vehicle's spellings.
        let mut r = ParamSession::restore(s.changed(), Duration::from_millis(500), 3);
        assert_eq!(r.start(t(1.0)), vec![ParamSend::Read("GUID_OPTIONS")]);
        assert_eq!(
            r.on_value(t(1.1), "GUID_OPTIONS", 12.0),
            vec![ParamSend::Set {
                name: "GUID_OPTIONS",
                value: 4.0
            }]
        );
        assert_eq!(
            r.on_value(t(1.2), "GUID_OPTIONS", 4.0),
            vec![ParamSend::Read("SYSID_MYGCS")]
        );
        assert_eq!(
            r.on_value(t(1.3), "SYSID_MYGCS", 253.0),
            vec![ParamSend::Set {
                name: "SYSID_MYGCS",
                value: 255.0
            }]
        );
        r.on_value(t(1.4), "SYSID_MYGCS", 255.0);
        assert!(r.done());
    }

    #[test]
    fn a_step_whose_flag_is_off_is_skipped() {
        let steps = |_| {
            vec![
                ParamStep {
                    param: FS_GCS_ENABLE,
                    action: ParamAction::Read,
                },
                ParamStep {
                    param: MAV_GCS_SYSID,
                    action: ParamAction::SetIfOn {
                        value: 253.0,
                        flag: FS_GCS_ENABLE,
                    },
                },
            ]
        };
        let mut off = ParamSession::new(steps(()), Duration::from_millis(500), 3);
        off.start(t(0.0));
        assert!(off.on_value(t(0.1), "FS_GCS_ENABLE", 0.0).is_empty());
        assert!(off.done() && off.changed().is_empty());
        let mut on = ParamSession::new(steps(()), Duration::from_millis(500), 3);
        on.start(t(0.0));
        assert_eq!(
            on.on_value(t(0.1), "FS_GCS_ENABLE", 5.0),
            vec![
                ParamSend::Read("MAV_GCS_SYSID"),
                ParamSend::Read("SYSID_MYGCS")
            ]
        );
    }

    #[test]
    fn a_value_already_right_is_not_written() {
        let mut s = session();
        s.start(t(0.0));
        s.on_value(t(0.1), "MOT_THST_HOVER", 0.4);
        s.on_value(t(0.2), "GUID_OPTIONS", 8.0);
        s.on_value(t(0.3), "MAV_GCS_SYSID", 253.0);
        assert!(s.done());
        assert!(s.changed().is_empty());
    }

    #[test]
    fn a_write_read_back_at_another_value_fails_by_name() {
        let mut s = session();
        s.start(t(0.0));
        s.on_value(t(0.1), "MOT_THST_HOVER", 0.4);
        s.on_value(t(0.2), "GUID_OPTIONS", 0.0);
        s.on_value(t(0.3), "GUID_OPTIONS", 4.0);
        assert_eq!(
            s.failure(),
            Some("parameter GUID_OPTIONS = 8 refused: the vehicle reads back 4")
        );
        assert!(s.changed().is_empty());
    }

    #[test]
    fn a_late_answer_at_the_old_value_is_waited_out_and_a_write_that_stays_old_is_named() {
        let mut s = session();
        s.start(t(0.0));
        s.on_value(t(0.1), "MOT_THST_HOVER", 0.4);
        // The read of GUID_OPTIONS went unanswered and was sent again.
        s.handle_timeout(t(0.7));
        assert_eq!(
            s.on_value(t(0.8), "GUID_OPTIONS", 0.0),
            vec![ParamSend::Set {
                name: "GUID_OPTIONS",
                value: 8.0
            }]
        );
        // The second read's answer comes after the write: not a refusal.
        assert!(s.on_value(t(0.85), "GUID_OPTIONS", 0.0).is_empty());
        assert_eq!(s.failure(), None);
        assert!(s.on_value(t(0.9), "GUID_OPTIONS", 8.0).len() == 2);
        assert_eq!(s.changed(), &[("GUID_OPTIONS", 0.0)]);
        // A vehicle that keeps answering the old value: resent, then named a refusal.
        let mut s = session();
        s.start(t(0.0));
        s.on_value(t(0.1), "MOT_THST_HOVER", 0.4);
        s.on_value(t(0.2), "GUID_OPTIONS", 0.0);
        for k in 1..=3 {
            s.on_value(t(0.2 + 0.5 * f64::from(k) - 0.1), "GUID_OPTIONS", 0.0);
            s.handle_timeout(t(0.2 + 0.5 * f64::from(k)));
        }
        assert_eq!(
            s.failure(),
            Some("parameter GUID_OPTIONS = 8 refused: the vehicle reads back 0 after 3 attempts")
        );
    }

    #[test]
    fn silence_is_retried_then_fails_naming_the_parameter() {
        let mut s = session();
        s.start(t(0.0));
        assert_eq!(s.poll_timeout(), t(0.5));
        assert!(s.handle_timeout(t(0.4)).is_empty());
        assert_eq!(
            s.handle_timeout(t(0.5)),
            vec![ParamSend::Read("MOT_THST_HOVER")]
        );
        assert_eq!(s.handle_timeout(t(1.0)).len(), 1);
        assert!(s.handle_timeout(t(1.5)).is_empty());
        let why = s.failure().unwrap_or_default();
        assert!(
            why.starts_with("parameter MOT_THST_HOVER never answered after 3 attempts"),
            "{why}"
        );
        assert_eq!(s.poll_timeout(), SimTime::MAX);
    }
}
