//! The swarm's event log: every link event and every decision of the swarm, with its
//! time, in words an operator reads. Warnings (lost, refused, timeouts, failsafes, origin
//! changes, isolation) are also logged at `warn`, the rest at `info`; the run directory
//! writes the log as `events.csv`.
//!
//! A vehicle's warnings of one kind (the same words, whatever their numbers) are logged
//! at most once per [`REPEAT_WINDOW`]: the next one says how many were left out. A
//! vehicle refusing its telemetry on every report would otherwise write thousands of
//! lines a second, and a thousand such vehicles would drown the operator and slow the
//! coordinator that prints them.

use std::collections::HashMap;
use std::time::Duration;

use ringswarm_wire::time::SimTime;

use crate::vehicle::LinkConfig;

/// Events kept in memory; later ones are counted, logged, and not kept.
pub const MAX_KEPT_EVENTS: usize = 100_000;

/// The shortest time between two logged warnings of one kind from one vehicle.
pub const REPEAT_WINDOW: Duration = Duration::from_secs(1);

/// One event.
#[derive(Debug, Clone, PartialEq)]
pub struct SwarmEvent {
    /// When (the swarm's time).
    pub t: SimTime,
    /// The vehicle's system id, or `None` for the swarm as a whole.
    pub system_id: Option<u8>,
    /// The vehicle's MAVLink network (`None` for a vehicle on its own socket, and for the
    /// swarm): system ids repeat from one network to the next.
    pub network: Option<String>,
    /// Whether an operator must see it.
    pub warning: bool,
    /// What happened.
    pub text: String,
}

/// The log.
#[derive(Debug, Clone, Default)]
pub(super) struct EventLog {
    kept: Vec<SwarmEvent>,
    dropped: u64,
    /// Per vehicle and kind of warning: when one was last logged, and how many were left
    /// out since.
    repeats: HashMap<(u8, Option<String>, String), (SimTime, u64)>,
    /// Warnings left out as repeats, in all.
    repeated: u64,
}

impl EventLog {
    /// Logs and keeps an event of the swarm as a whole.
    pub(super) fn push(&mut self, t: SimTime, warning: bool, text: String) {
        self.keep(t, None, None, warning, text);
    }

    /// Logs and keeps an event of the vehicle on `link`.
    pub(super) fn push_vehicle(
        &mut self,
        t: SimTime,
        link: &LinkConfig,
        warning: bool,
        text: String,
    ) {
        let mut text = text;
        if warning {
            let key = (link.system_id, link.network.clone(), kind(&text));
            match self.repeats.get_mut(&key) {
                Some((last, left_out)) if t.saturating_since(*last) < REPEAT_WINDOW => {
                    *left_out += 1;
                    self.repeated += 1;
                    return;
                }
                Some((last, left_out)) => {
                    if *left_out > 0 {
                        text = format!(
                            "{text} ({left_out} more like it in the {:.1} s before, not logged)",
                            t.saturating_since(*last).as_secs_f64()
                        );
                    }
                    *last = t;
                    *left_out = 0;
                }
                None => {
                    self.repeats.insert(key, (t, 0));
                }
            }
        }
        self.keep(t, Some(link.system_id), link.network.clone(), warning, text);
    }

    fn keep(
        &mut self,
        t: SimTime,
        system_id: Option<u8>,
        network: Option<String>,
        warning: bool,
        text: String,
    ) {
        let secs = t.as_secs_f64();
        let who = match (system_id, &network) {
            (Some(id), Some(net)) => format!("vehicle {id} on {net}"),
            (Some(id), None) => format!("vehicle {id}"),
            (None, _) => "swarm".to_owned(),
        };
        if warning {
            tracing::warn!("[{secs:.3} s] {who}: {text}");
        } else {
            tracing::info!("[{secs:.3} s] {who}: {text}");
        }
        if self.kept.len() < MAX_KEPT_EVENTS {
            self.kept.push(SwarmEvent {
                t,
                system_id,
                network,
                warning,
                text,
            });
        } else {
            self.dropped += 1;
        }
    }

    pub(super) fn events(&self) -> &[SwarmEvent] {
        &self.kept
    }

    pub(super) fn dropped(&self) -> u64 {
        self.dropped
    }

    /// Vehicle warnings left out as repeats of one logged within [`REPEAT_WINDOW`].
    pub(super) fn repeated(&self) -> u64 {
        self.repeated
    }
}

/// A warning's kind: its words, with every number made `#` ("jumped 9.0 m" and "jumped
/// 10.5 m" are one kind).
fn kind(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut in_number = false;
    for c in text.chars() {
        if c.is_ascii_digit() || (in_number && c == '.') {
            if !in_number {
                out.push('#');
                in_number = true;
            }
        } else {
            in_number = false;
            out.push(c);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(ms: u64) -> SimTime {
        SimTime::from_millis(ms)
    }

    #[test]
    fn a_vehicle_s_repeated_warnings_are_logged_once_a_second_with_a_count() {
        let mut log = EventLog::default();
        let v3 = LinkConfig::new(3);
        let v4 = LinkConfig::new(4);
        let jump = |m: f64| format!("telemetry refused: LOCAL_POSITION_NED jumped {m:.1} m");
        // Vehicle 3 refuses a report every 20 ms for 2.5 s; vehicle 4 once.
        for k in 0..125u64 {
            log.push_vehicle(ms(20 * k), &v3, true, jump(5.0 + k as f64 * 0.1));
        }
        log.push_vehicle(ms(30), &v4, true, jump(7.0));
        // Another kind from vehicle 3, and information, are never held back.
        log.push_vehicle(ms(40), &v3, true, "lost (link timeout)".to_owned());
        log.push_vehicle(ms(60), &v3, false, "landing".to_owned());
        log.push_vehicle(ms(80), &v3, false, "landing".to_owned());
        let mut texts: Vec<(u64, Option<u8>, &str)> = log
            .events()
            .iter()
            .map(|e| (e.t.as_micros() / 1000, e.system_id, e.text.as_str()))
            .collect();
        texts.sort_by_key(|(t, _, _)| *t);
        assert_eq!(
            texts,
            [
                (
                    0,
                    Some(3),
                    "telemetry refused: LOCAL_POSITION_NED jumped 5.0 m"
                ),
                (
                    30,
                    Some(4),
                    "telemetry refused: LOCAL_POSITION_NED jumped 7.0 m"
                ),
                (40, Some(3), "lost (link timeout)"),
                (60, Some(3), "landing"),
                (80, Some(3), "landing"),
                (
                    1000,
                    Some(3),
                    "telemetry refused: LOCAL_POSITION_NED jumped 10.0 m (49 more like it in the 1.0 s before, not logged)"
                ),
                (
                    2000,
                    Some(3),
                    "telemetry refused: LOCAL_POSITION_NED jumped 15.0 m (49 more like it in the 1.0 s before, not logged)"
                ),
            ]
        );
        assert_eq!(log.repeated(), 125 - 3);
    }

    #[test]
    fn numbers_do_not_make_a_new_kind() {
        assert_eq!(kind("jumped 9.0 m in 12 ms"), "jumped # m in # ms");
        assert_eq!(
            kind("MAV_CMD_DO_SET_MODE not acknowledged: attempt 3"),
            "MAV_CMD_DO_SET_MODE not acknowledged: attempt #"
        );
    }
}
