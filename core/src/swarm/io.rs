//! The swarm machine's sans-IO interface: datagrams in ([`Swarm::handle_datagram`]),
//! timers ([`Swarm::poll_timeout`], [`Swarm::handle_timeout`]), datagrams out
//! ([`Swarm::poll_transmit`]), the coordinator's own stall ([`Swarm::set_listen_lag`]),
//! and after each link ran, its output, its next deadline and its events.

use std::time::Duration;

use ringswarm_wire::time::SimTime;

use super::VehicleIndex;
use super::slot::VehicleSlot;
use super::{Swarm, model};
use crate::vehicle::{LinkEvent, VehicleLink};

/// A listen lag shorter than this is none: the link and state timeouts are hundreds of
/// milliseconds, and a lag that comes and goes every loop would reschedule every link.
pub const LISTEN_LAG_FLOOR: Duration = Duration::from_millis(20);

/// The longest a control tick waits for the unread datagrams of the coordinator's own
/// stall ([`Swarm::set_listen_lag`]).
pub const MAX_TICK_DEFER: Duration = Duration::from_millis(100);

/// The finest a link timer is looked at again when it stays due: the emulator's and the
/// lockstep driver's step.
const TIMER_GRANULARITY: Duration = Duration::from_millis(1);

impl Swarm {
    /// Hands a datagram from vehicle `i` to its link; `true` when the link took a frame
    /// of it as the vehicle's (see [`VehicleLink::handle_datagram`]).
    ///
    /// Costs the link's work only: nothing here visits the other links.
    pub fn handle_datagram(&mut self, now: SimTime, i: VehicleIndex, bytes: &[u8]) -> bool {
        let Some(link) = self.slots.get_mut(i.get()).and_then(VehicleSlot::link_mut) else {
            return false;
        };
        let taken = link.handle_datagram(now, bytes);
        self.after_link(now, i);
        taken
    }

    /// When [`Swarm::handle_timeout`] must next be called (never later than needed; a
    /// deadline that moved later may cause one early call).
    pub fn poll_timeout(&self) -> SimTime {
        self.scheduler
            .next_deadline()
            .map_or(self.next_control, |t| self.next_control.min(t))
    }

    /// Whether some link may have a datagram queued ([`Swarm::poll_transmit`] may still
    /// find none).
    pub fn has_output(&self) -> bool {
        self.scheduler.any_output()
    }

    /// Gives a sent datagram's buffer back to link `i` (any link will do: the buffer is
    /// only memory) so that the next frame reuses it.
    pub fn recycle(&mut self, i: VehicleIndex, bytes: Vec<u8>) {
        if let Some(link) = self.slots.get_mut(i.get()).and_then(VehicleSlot::link_mut) {
            link.recycle(bytes);
        }
    }

    /// The next datagram and the vehicle it is for (round robin over the links).
    pub fn poll_transmit(&mut self) -> Option<(VehicleIndex, Vec<u8>)> {
        loop {
            let i = self.scheduler.next_output()?;
            let Some(link) = self.slots[i].link_mut() else {
                continue;
            };
            let Some(bytes) = link.poll_transmit() else {
                continue;
            };
            if link.has_output() {
                self.scheduler.has_output(i);
            }
            return Some((i, bytes));
        }
    }

    /// Tells every link that the coordinator had read everything received only up to
    /// `now − lag` (the UDP driver measures it: `ringswarm::driver::listening`): a stall of its own is not taken for
    /// its vehicles going silent. Lags under [`LISTEN_LAG_FLOOR`] count as none.
    pub fn set_listen_lag(&mut self, now: SimTime, lag: Duration) {
        let lag = if lag < LISTEN_LAG_FLOOR {
            Duration::ZERO
        } else {
            lag
        };
        if lag == self.listen_lag {
            return;
        }
        let shrank = lag < self.listen_lag;
        self.listen_lag = lag;
        for link in self.slots.iter_mut().filter_map(VehicleSlot::link_mut) {
            link.set_listen_lag(lag);
        }
        if shrank {
            // Deadlines moved earlier: the timers must know.
            self.after_all_links(now);
        }
    }

    /// Whether a tick due now waits for the unread datagrams of a stall: while there is a
    /// listen lag, for at most [`MAX_TICK_DEFER`]; an overload that lasts longer is flown
    /// through (its old states then hold the swarm as one).
    fn defer_tick(&mut self, now: SimTime) -> bool {
        if self.listen_lag.is_zero() {
            return false;
        }
        let since = *self.tick_due_since.get_or_insert(now);
        now.saturating_since(since) < MAX_TICK_DEFER
    }

    /// Runs the control tick and the links' timers due at `now`.
    pub fn handle_timeout(&mut self, now: SimTime) {
        if now >= self.next_control && self.defer_tick(now) {
            // The coordinator's own stall: what its vehicles sent meanwhile is still
            // unread. The tick waits for it, a millisecond at a time, rather than fly on
            // states it knows to be old (and hold the swarm for them).
            self.next_control = now + Duration::from_millis(1);
        } else if now >= self.next_control {
            self.tick_due_since = None;
            if let Some((late, count)) = self.timing.tick(self.next_control, now) {
                // The first ten, then one in a hundred: where to look for what held it.
                if count <= 10 || count % 100 == 0 {
                    self.log.push(
                        now,
                        true,
                        format!(
                            "control tick started {:.1} ms late, over half the period ({}; late tick {count})",
                            late.as_secs_f64() * 1e3,
                            self.phase.name()
                        ),
                    );
                }
            }
            self.control(now);
            // A fixed schedule: lateness of one wake-up does not slow the rate down, and
            // a long stall restarts the schedule instead of bursting.
            let next = self.next_control + self.setup.control_interval;
            self.next_control = if next <= now {
                now + self.setup.control_interval
            } else {
                next
            };
            // The law touched every link.
            self.after_all_links(now);
        }
        while let Some(i) = self.scheduler.next_due(now) {
            if let Some(link) = self.slots[i].link_mut()
                && now >= link.poll_timeout()
            {
                link.handle_timeout(now);
            }
            // Scheduled again here.
            self.after_link(now, i);
            self.scheduler.defer_if_still_due(i, now, TIMER_GRANULARITY);
        }
    }

    /// After something that may have touched every link (landing): O(N), rare.
    pub(super) fn after_all_links(&mut self, now: SimTime) {
        for i in self.indices() {
            self.after_link(now, i);
        }
    }

    /// After link `i` ran: its output, its next deadline, its events.
    pub(super) fn after_link(&mut self, now: SimTime, i: VehicleIndex) {
        let Some(slot) = self.slots.get_mut(i.0) else {
            return;
        };
        let Some(link) = slot.link() else {
            return;
        };
        let (origin, output, deadline) =
            (link.state().origin, link.has_output(), link.poll_timeout());
        if let Some(origin) = origin
            && slot.origin_offset.is_none_or(|(known, _)| known != origin)
        {
            slot.origin_offset = Some((origin, self.setup.frame.offset_ned_m(&origin)));
        }
        if output {
            self.scheduler.has_output(i);
        }
        self.scheduler.schedule(i, deadline);
        self.drain_events_of(now, i);
    }

    /// The hover throttle vehicle `i` reports of itself (ArduPilot's learnt
    /// MOT_THST_HOVER): with the hover estimator on, the estimate starts from it (the
    /// estimator corrects it in the air); with it off, the configured one is flown and a
    /// disagreement of more than the estimator's significance is warned of.
    fn take_reported_hover(&mut self, now: SimTime, i: VehicleIndex, hover_throttle: f64) {
        let configured = self.setup.models[i].hover_throttle();
        let differs =
            (hover_throttle - configured).abs() > model::SIGNIFICANT_FRACTION * configured;
        let text = if !self.setup.estimate_hover {
            differs.then(|| {
                format!(
                    "reports a hover throttle of {hover_throttle:.3}, the configured {configured:.3} is flown (swarm.estimate_hover is off)"
                )
            })
        } else if self
            .slots
            .get_mut(i.0)
            .is_some_and(|s| s.flown.seed_hover(hover_throttle))
        {
            differs.then(|| {
                format!(
                    "reports a hover throttle of {hover_throttle:.3}, not the configured {configured:.3}: the estimate starts from it"
                )
            })
        } else {
            Some(format!(
                "reported hover throttle {hover_throttle:.3} is outside the estimator's bounds: the configured one is flown"
            ))
        };
        if let Some(text) = text {
            self.log.push_vehicle(now, &self.setup.links[i], true, text);
        }
    }

    fn drain_events_of(&mut self, now: SimTime, i: VehicleIndex) {
        while let Some(event) = self
            .slots
            .get_mut(i.0)
            .and_then(VehicleSlot::link_mut)
            .and_then(VehicleLink::poll_event)
        {
            self.log.push_vehicle(
                now,
                &self.setup.links[i],
                event.is_warning(),
                event.to_string(),
            );
            if let LinkEvent::HoverReported { hover_throttle } = event {
                self.take_reported_hover(now, i, hover_throttle);
            }
        }
    }
}
