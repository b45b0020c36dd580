//! The link's timers: the heartbeat (with TIMESYNC and the origin request), the warning
//! for a vehicle never heard, link loss, the state timeout, the handshake's parameter and
//! fence sessions, command deadlines and retries, and the setpoint stream. Run in this
//! order by [`VehicleLink::handle_timeout`].

use ringswarm_wire::time::SimTime;

use super::super::{LinkEvent, Phase};
use super::VehicleLink;
use crate::link::{Outgoing, command_name};

impl VehicleLink {
    /// Runs the timers due at `now`: the setpoint stream, the pre-stream, command
    /// deadlines and link loss.
    pub fn handle_timeout(&mut self, now: SimTime) {
        self.clock(now);
        self.heartbeat_due(now);
        self.warn_never_heard(now);
        // Silence counts only up to the last instant the coordinator had read everything
        // received: its own stall is not the vehicle's.
        let listened = SimTime::from_micros(
            now.as_micros()
                .saturating_sub(self.listen_lag.as_micros() as u64),
        );
        self.watch_silence(listened);
        self.watch_state_age(now, listened);
        self.take_back_if_usable(now);
        self.handshake_timers(now);
        self.command_deadline(now);
        self.setpoint_due(now);
    }

    /// The heartbeat, with a TIMESYNC to the vehicles we command and the origin asked for
    /// while it is missing.
    fn heartbeat_due(&mut self, now: SimTime) {
        if now >= self.next_heartbeat {
            self.queue(Outgoing::Heartbeat);
            // The round trip of the vehicles we command (none to one someone else flies).
            let commanded = !matches!(
                self.phase,
                Phase::Discovering | Phase::Done | Phase::Failed | Phase::Overridden | Phase::Lost
            );
            if commanded {
                // Stamps are the link's clock + 1 ns: never 0, which means "no stamp".
                let stamp = (now.as_micros() * 1000 + 1) as i64;
                self.timesync_sent_ns = Some(stamp);
                self.queue(Outgoing::Timesync { ts1_ns: stamp });
            }
            let streaming = matches!(
                self.phase,
                Phase::Streaming(_)
                    | Phase::Arming
                    | Phase::Offboarding
                    | Phase::Flying
                    | Phase::VehicleHold
            );
            if streaming && self.state.origin.is_none() {
                self.request_origin();
            }
            let next = self.next_heartbeat
                + self.cfg.heartbeat_interval
                + self.heartbeat_phase.take().unwrap_or_default();
            self.next_heartbeat = if next <= now {
                now + self.cfg.heartbeat_interval
            } else {
                next
            };
        }
    }

    /// Says once that the vehicle was never heard within the discovery warning.
    fn warn_never_heard(&mut self, now: SimTime) {
        if self.phase == Phase::Discovering
            && !self.never_heard_reported
            && now >= SimTime::ZERO + self.cfg.discovery_warning
        {
            self.never_heard_reported = true;
            self.events.push_back(LinkEvent::NeverHeard {
                after: self.cfg.discovery_warning,
            });
        }
    }

    /// Link loss: nothing heard for the link timeout (up to `listened`).
    fn watch_silence(&mut self, listened: SimTime) {
        if let Some(last) = self.state.last_heard
            && listened.saturating_since(last) > self.cfg.link_timeout
            && !matches!(
                self.phase,
                Phase::Lost | Phase::Failed | Phase::Discovering | Phase::Done | Phase::Overridden
            )
        {
            if self.phase == Phase::Disarming && self.restore_running() {
                // Disarmed on the ground and gone silent (powered off, out of range):
                // what was not put back is said, and the link is done.
                self.restore_reported = true;
                let text = "parameters not put back: the vehicle went silent".to_owned();
                self.events.push_back(LinkEvent::VehicleSays(text));
                self.pending = None;
                self.phase = Phase::Done;
            } else {
                self.phase = Phase::Lost;
                self.pending = None;
                self.events.push_back(LinkEvent::Lost);
            }
        }
    }

    /// A flying vehicle without a usable position for the state timeout goes to its own
    /// hold.
    fn watch_state_age(&mut self, now: SimTime, listened: SimTime) {
        if self.phase == Phase::Flying && !self.state_fresh(listened) {
            let age = self.state.last_position.map_or("none".to_owned(), |t| {
                format!("{} ms old", now.saturating_since(t).as_millis())
            });
            let reason = format!(
                "no usable position within the {} ms state timeout (last {age})",
                self.cfg.state_timeout.as_millis()
            );
            self.hand_to_hold(now, reason, true);
        }
    }

    /// The handshake's fence and parameter sessions, the restore, and the next step once
    /// the pre-stream is over and the vehicle is ready.
    fn handshake_timers(&mut self, now: SimTime) {
        // Arm and take OFFBOARD only once the origin is known: without it the swarm
        // cannot place the vehicle, and would hand it to its Hold on the first tick.
        if matches!(self.phase, Phase::Streaming(_)) {
            let answer = self.fence.as_mut().map(|f| f.handle_timeout(now));
            self.on_fence_answer(answer);
            self.params_timeout(now, false);
        }
        if self.restore_running() {
            self.params_timeout(now, true);
        }
        if let Phase::Streaming(since) = self.phase
            && now.saturating_since(since) >= self.cfg.pre_stream
            && self.ready_to_arm()
        {
            self.next_handshake_step(now);
        }
    }

    /// A command past its deadline: taken (an ACCEPTED mode change), resent, or the link
    /// failed after the last attempt.
    fn command_deadline(&mut self, now: SimTime) {
        if let Some(p) = self.pending
            && now >= p.deadline
            && p.accepted
            && self.phase == Phase::Offboarding
        {
            // ACCEPTED and nothing else came: the mode it is.
            self.mode_taken(now);
        }
        if let Some(p) = self.pending
            && now >= p.deadline
        {
            if p.attempt >= self.cfg.max_attempts {
                self.pending = None;
                self.phase = Phase::Failed;
                let reason = format!(
                    "vehicle {}: {} not accepted after {} attempts",
                    self.cfg.system_id,
                    command_name(p.command.id()),
                    p.attempt
                );
                self.events.push_back(LinkEvent::Failed(reason));
            } else {
                self.events.push_back(LinkEvent::Retrying {
                    command: p.command.id(),
                    attempt: p.attempt + 1,
                });
                self.send_pending(now, p.command, p.attempt + 1);
            }
        }
    }

    /// The setpoint stream, on a fixed schedule.
    fn setpoint_due(&mut self, now: SimTime) {
        if self.streams() && now >= self.next_setpoint {
            self.send_setpoint(now);
            let next = self.next_setpoint + self.cfg.setpoint_interval;
            self.next_setpoint = if next <= now {
                now + self.cfg.setpoint_interval
            } else {
                next
            };
        }
    }
}
