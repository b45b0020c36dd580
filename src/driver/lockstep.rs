//! The lockstep driver: the swarm machine and the emulator's vehicle machines exchange
//! encoded MAVLink frames in virtual time, 1 ms at a time, with a seeded latency and loss
//! on every link. Same seed, same inputs: the same trajectory, bit for bit.
//!
//! By default link `i` talks to vehicle `i`. With a transport plan
//! ([`Lockstep::with_transport`]) datagrams go through the same [`Router`] as over UDP:
//! each vehicle has a virtual address (its configured one, or a unique one in
//! 10.0.0.0/8), a network's vehicles are told apart by system id and found from their
//! frames, and what the router cannot deliver is dropped.

use std::time::{Duration, Instant};

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use ringswarm_sitl::autopilot::{LinkId, PHYSICS_STEP, Vehicle};
use ringswarm_sitl::delay_line::DelayLine;
pub use ringswarm_sitl::link_faults::LinkConditions;
use ringswarm_wire::time::SimTime;

use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::ops::Range;

use super::{Intake, Observer};
use crate::link::router::{Router, TransportPlan};
use crate::swarm::Swarm;

/// Datagrams in flight at once, both ways, over all links: a full line drops (and
/// counts) what comes next rather than growing without limit.
const IN_FLIGHT_CAPACITY: usize = 1 << 20;

/// A datagram in flight.
#[derive(Debug, Clone)]
struct InFlight {
    to_vehicle: bool,
    index: usize,
    bytes: Vec<u8>,
}

/// Datagrams through a [`Router`], between virtual addresses.
#[derive(Debug)]
struct Routing {
    router: Router,
    /// Vehicle `j`'s address.
    addresses: Vec<SocketAddr>,
    /// And back.
    vehicle_at: HashMap<SocketAddr, usize>,
    /// The coordinator socket vehicle `j` sends to.
    socket_of: Vec<usize>,
    pieces: Vec<(usize, Range<usize>)>,
}

/// Wall time the lockstep loop spent in each of its phases, kept once asked for
/// ([`Lockstep::keep_phase_times`]): where a benchmark's time goes.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PhaseTimes {
    /// The vehicles' steps: physics, inner loops, autopilot, telemetry built and encoded.
    pub vehicles: Duration,
    /// The coordinator's timers and control ticks: the law, the saturation, setpoints
    /// built and encoded.
    pub coordinator: Duration,
    /// Datagrams carried both ways: the link conditions, decoding, each side's handling
    /// of what it received. An observer's work counts in the phase that calls it.
    pub delivery: Duration,
}

/// The clock behind [`PhaseTimes`].
#[derive(Debug, Clone, Copy)]
struct PhaseClock {
    times: PhaseTimes,
    lap_start: Instant,
}

/// The coordinator and its vehicles in one virtual world.
#[derive(Debug)]
pub struct Lockstep {
    swarm: Swarm,
    vehicles: Vec<Vehicle>,
    now: SimTime,
    in_flight: DelayLine<InFlight>,
    conditions: LinkConditions,
    rng: ChaCha8Rng,
    silenced: Vec<Vec<(SimTime, SimTime)>>,
    /// The coordinator's own stall ([`Lockstep::stall_coordinator`]), and what arrived
    /// for it meanwhile, unread.
    stall: Option<(SimTime, SimTime)>,
    unread: Vec<(usize, Vec<u8>)>,
    routing: Option<Routing>,
    /// Datagrams from the swarm the router had no address for.
    unsent: u64,
    /// Step the vehicles on every core (see [`Lockstep::set_parallel`]).
    parallel: bool,
    clock: Option<PhaseClock>,
}

/// From this many vehicles on, they are stepped on every core: below, handing work to
/// other threads every millisecond costs more than it saves.
const PARALLEL_FROM: usize = 128;

impl Lockstep {
    /// Pairs the swarm's links with `vehicles` (link `i` talks to vehicle `i`'s offboard link).
    pub fn new(swarm: Swarm, mut vehicles: Vec<Vehicle>, conditions: LinkConditions) -> Self {
        let n = vehicles.len();
        // Only the offboard links are carried: nothing is built for the ground station's.
        for v in &mut vehicles {
            v.set_link_wired(LinkId::Gcs, false);
        }
        Self {
            swarm,
            vehicles,
            now: SimTime::ZERO,
            in_flight: DelayLine::new(IN_FLIGHT_CAPACITY),
            rng: ChaCha8Rng::seed_from_u64(conditions.seed),
            conditions,
            silenced: vec![Vec::new(); n],
            stall: None,
            unread: Vec::new(),
            routing: None,
            unsent: 0,
            parallel: n >= PARALLEL_FROM,
            clock: None,
        }
    }

    /// From now on, adds up the wall time of each phase of the loop ([`PhaseTimes`]); a
    /// few clock reads per step, and the flight is the same.
    pub fn keep_phase_times(&mut self) {
        self.clock = Some(PhaseClock {
            times: PhaseTimes::default(),
            lap_start: Instant::now(),
        });
    }

    /// The phase times kept so far (none unless [`Lockstep::keep_phase_times`] was called).
    pub fn phase_times(&self) -> Option<PhaseTimes> {
        self.clock.map(|c| c.times)
    }

    /// Adds the time since the last lap to one phase.
    fn lap(&mut self, phase: fn(&mut PhaseTimes) -> &mut Duration) {
        if let Some(clock) = &mut self.clock {
            let now = Instant::now();
            *phase(&mut clock.times) += now - clock.lap_start;
            clock.lap_start = now;
        }
    }

    /// Whether the vehicles' physics steps run on every core (by default from
    /// 128 vehicles on). Either way the flight is the same bit for bit: each vehicle steps
    /// on its own, and what they send is collected in vehicle order afterwards.
    pub fn set_parallel(&mut self, parallel: bool) {
        self.parallel = parallel;
    }

    /// Routes every datagram as `plan` says (vehicle `j` sits at its route's address, or
    /// at a unique virtual one, and sends to its route's socket).
    pub fn with_transport(mut self, plan: &TransportPlan) -> Self {
        let addresses: Vec<SocketAddr> = plan
            .routes
            .iter()
            .enumerate()
            .map(|(j, r)| {
                r.address.unwrap_or_else(|| {
                    let [_, a, b, c] = (j as u32).to_be_bytes();
                    SocketAddr::new(IpAddr::from([10, a, b, c]), 14580)
                })
            })
            .collect();
        self.routing = Some(Routing {
            router: Router::new(plan),
            vehicle_at: addresses.iter().enumerate().map(|(j, a)| (*a, j)).collect(),
            addresses,
            socket_of: plan.routes.iter().map(|r| r.socket).collect(),
            pieces: Vec::new(),
        });
        self
    }

    /// Datagrams from the swarm that had nowhere to go (a network vehicle not heard
    /// from yet).
    pub fn unsent(&self) -> u64 {
        self.unsent
    }

    /// The swarm and the emulated vehicles of a coordinator config, with its `[emulator]`
    /// link faults and silences.
    ///
    /// # Errors
    /// The config's problems (all of them), or a vehicle the emulator refuses.
    pub fn from_config(config: &crate::config::Config) -> Result<Self, String> {
        let setup = config.validate()?;
        let (world, vehicle_configs) = config.emulator()?;
        let faults = config.lockstep_faults()?;
        let vehicles = vehicle_configs
            .into_iter()
            .map(|v| Vehicle::new(v, world))
            .collect::<Result<Vec<_>, _>>()?;
        let plan = config.transport_plan()?;
        let mut run =
            Self::new(Swarm::new(setup), vehicles, faults.conditions).with_transport(&plan);
        for (i, from, until) in faults.silences {
            run.silence(i, from, until);
        }
        Ok(run)
    }

    /// Virtual time.
    pub fn now(&self) -> SimTime {
        self.now
    }

    /// The swarm machine.
    pub fn swarm(&self) -> &Swarm {
        &self.swarm
    }

    /// The emulated vehicles.
    pub fn vehicles(&self) -> &[Vehicle] {
        &self.vehicles
    }

    /// Drops everything vehicle `i` sends and receives between `from` and `until` (in
    /// addition to any earlier silence).
    pub fn silence(&mut self, i: usize, from: SimTime, until: SimTime) {
        if let Some(slot) = self.silenced.get_mut(i) {
            slot.push((from, until));
        }
    }

    /// Stalls the coordinator over `[from, until)`, as a host that stops scheduling it
    /// would: the vehicles fly on and send, nothing is read or sent by the swarm. At
    /// `until` it wakes as the UDP driver does: its timers first, told how far behind its
    /// sockets it is, then what waited for it.
    pub fn stall_coordinator(&mut self, from: SimTime, until: SimTime) {
        self.stall = Some((from, until));
    }

    fn coordinator_stalled(&self) -> bool {
        self.stall
            .is_some_and(|(from, until)| self.now >= from && self.now < until)
    }

    /// The first step after a stall: timers with the lag, then the unread datagrams.
    fn wake_from_stall(&mut self, now: SimTime, observer: &mut impl Observer) {
        let Some((from, until)) = self.stall else {
            return;
        };
        if now < until {
            return;
        }
        self.swarm.set_listen_lag(now, now.saturating_since(from));
        self.swarm.handle_timeout(now);
        for (j, bytes) in std::mem::take(&mut self.unread) {
            self.deliver_to_swarm(now, j, &bytes, observer);
            self.recycle(false, j, bytes);
        }
        self.swarm.set_listen_lag(now, Duration::ZERO);
        self.stall = None;
    }

    /// Advances by one physics step.
    pub fn step(&mut self) {
        self.step_observed(&mut ());
    }

    /// Runs until virtual time `end`; `observer` sees every datagram the swarm sends or
    /// receives (when it is sent, and when it is delivered) and the swarm after each step.
    pub fn run_observed(&mut self, end: SimTime, observer: &mut impl Observer) {
        while self.now < end {
            self.step_observed(observer);
            observer.swarm(&self.swarm, self.now);
        }
    }

    fn step_observed(&mut self, observer: &mut impl Observer) {
        self.now = self.now + PHYSICS_STEP;
        let now = self.now;
        self.lap(|t| &mut t.delivery); // the caller's observer, between steps
        if self.parallel {
            use rayon::iter::{IntoParallelRefMutIterator, ParallelIterator};
            self.vehicles
                .par_iter_mut()
                .for_each(|v| v.handle_timeout(now));
        } else {
            for v in &mut self.vehicles {
                v.handle_timeout(now);
            }
        }
        self.lap(|t| &mut t.vehicles);
        for i in 0..self.vehicles.len() {
            while let Some(tx) = self.vehicles[i].poll_transmit() {
                if tx.link == LinkId::Offboard {
                    self.send(false, i, tx.bytes);
                } else {
                    self.vehicles[i].recycle(tx.bytes);
                }
            }
            // Nothing here stores keys or shows mode changes: drop the events, so that
            // a long run (or a flood of commands) keeps no backlog.
            while self.vehicles[i].poll_event().is_some() {}
        }
        self.deliver(now, observer);
        self.lap(|t| &mut t.delivery);
        if self.coordinator_stalled() {
            return;
        }
        self.wake_from_stall(now, observer);
        if now >= self.swarm.poll_timeout() {
            self.swarm.handle_timeout(now);
        }
        while let Some((i, bytes)) = self.swarm.poll_transmit() {
            observer.datagram(now, i, true, &bytes);
            match self.vehicle_reached_by(i) {
                Some(j) => self.send(true, j, bytes),
                None => {
                    self.unsent += 1;
                    self.swarm.recycle(i, bytes);
                }
            }
        }
        self.lap(|t| &mut t.coordinator);
        self.deliver(now, observer);
        self.lap(|t| &mut t.delivery);
    }

    /// Puts a datagram from a third party on vehicle `index`'s link, delivered with the
    /// link's conditions: to the vehicle's offboard link (`to_vehicle`) or to the
    /// coordinator as if from the vehicle's address.
    pub fn inject(&mut self, to_vehicle: bool, index: usize, bytes: Vec<u8>) {
        self.send(to_vehicle, index, bytes);
    }

    /// Datagrams sent and not delivered yet.
    pub fn in_flight(&self) -> usize {
        self.in_flight.len()
    }

    /// Datagrams dropped because [`IN_FLIGHT_CAPACITY`] were already in flight.
    pub fn in_flight_refused(&self) -> u64 {
        self.in_flight.refused()
    }

    /// Runs until virtual time `end`, calling `observe` after every step.
    pub fn run_until(&mut self, end: SimTime, mut observe: impl FnMut(&Self)) {
        while self.now < end {
            self.step();
            observe(self);
        }
    }

    /// The vehicle a datagram for link `i` reaches.
    fn vehicle_reached_by(&self, i: usize) -> Option<usize> {
        let Some(r) = &self.routing else {
            return Some(i);
        };
        let (_, to) = r.router.destination(i)?;
        r.vehicle_at.get(&to).copied()
    }

    /// Hands a datagram from vehicle `j` to the swarm (through the router, if any).
    fn deliver_to_swarm(
        &mut self,
        now: SimTime,
        j: usize,
        bytes: &[u8],
        observer: &mut impl Observer,
    ) {
        let Some(r) = self.routing.as_mut() else {
            observer.datagram(now, j, false, bytes);
            self.swarm.handle_datagram(now, j, bytes);
            return;
        };
        let (socket, from) = (r.socket_of[j], r.addresses[j]);
        let mut intake = Intake {
            swarm: &mut self.swarm,
            router: &mut r.router,
            pieces: &mut r.pieces,
        };
        intake.deliver(socket, from, bytes, now, observer);
    }

    fn is_silenced(&self, i: usize) -> bool {
        self.silenced[i]
            .iter()
            .any(|&(from, until)| self.now >= from && self.now < until)
    }

    fn send(&mut self, to_vehicle: bool, index: usize, bytes: Vec<u8>) {
        if self.is_silenced(index) {
            self.recycle(to_vehicle, index, bytes);
            return;
        }
        let mut copies = self.conditions.faults.copies(&mut self.rng);
        let mut bytes = Some(bytes);
        while let Some(delay) = copies.next() {
            // The last copy takes the buffer itself: a clean link copies nothing.
            let copy = if copies.len() == 0 {
                bytes.take()
            } else {
                bytes.clone()
            };
            if let Some(bytes) = copy {
                let held = InFlight {
                    to_vehicle,
                    index,
                    bytes,
                };
                // A full line drops the datagram, as a router's full queue does.
                if let Err(dropped) = self.in_flight.push(self.now + delay, held) {
                    self.recycle(to_vehicle, index, dropped.bytes);
                }
            }
        }
        // Lost on the way: back to where it came from.
        if let Some(bytes) = bytes {
            self.recycle(to_vehicle, index, bytes);
        }
    }

    /// Gives a delivered (or lost) datagram's buffer back to its sender.
    fn recycle(&mut self, to_vehicle: bool, index: usize, bytes: Vec<u8>) {
        if to_vehicle {
            self.swarm.recycle(index, bytes);
        } else if let Some(v) = self.vehicles.get_mut(index) {
            v.recycle(bytes);
        }
    }

    fn deliver(&mut self, now: SimTime, observer: &mut impl Observer) {
        while let Some(d) = self.in_flight.pop_due(now) {
            if d.to_vehicle {
                self.vehicles[d.index].handle_datagram(now, LinkId::Offboard, &d.bytes);
            } else if self.coordinator_stalled() {
                self.unread.push((d.index, d.bytes));
                continue;
            } else {
                self.deliver_to_swarm(now, d.index, &d.bytes, observer);
            }
            self.recycle(d.to_vehicle, d.index, d.bytes);
        }
    }
}
