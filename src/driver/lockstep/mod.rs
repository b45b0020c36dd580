//! The lockstep driver: one or several swarm machines (one process, or the shards of one
//! swarm) and the emulator's vehicle machines exchange encoded MAVLink frames in virtual
//! time, 1 ms at a time, with a seeded latency and loss on every link. Same seed, same
//! inputs: the same trajectory, bit for bit.
//!
//! By default link `i` talks to vehicle `i`. With a transport layout
//! ([`Lockstep::with_transport`]) datagrams go through the same router as over UDP
//! (`routing`). Shards ([`Lockstep::sharded`]) each fly their own vehicles and tell each
//! other the rest over a simulated bus (`bus`).
//!
//! ```text
//!  step: vehicles (physics, autopilot) ─► their datagrams into the MAVLink line
//!        ─► deliver what is due ─► each coordinator: timers, control tick, datagrams
//!        into the line, shard messages onto the bus ─► deliver what is due
//! ```

mod bus;
mod phase_times;
mod routing;

use std::time::Duration;

use ringswarm_sitl::autopilot::{LinkId, PHYSICS_STEP, Vehicle};
use ringswarm_sitl::faulty_line::FaultyLine;
pub use ringswarm_sitl::link_faults::LinkConditions;
use ringswarm_wire::time::SimTime;

use super::{Intake, Observer};
use crate::distributed::ShardPlan;
use crate::link::router::TransportLayout;
use crate::swarm::{Swarm, VehicleIndex};
pub use bus::BusCounts;
use bus::ShardBus;
use phase_times::PhaseClock;
pub use phase_times::PhaseTimes;
use routing::Routing;

/// Datagrams in flight at once, both ways, over all links (and payloads on the shards'
/// bus): a full line drops (and counts) what comes next rather than growing without
/// limit.
const IN_FLIGHT_CAPACITY: usize = 1 << 20;

/// A datagram in flight between vehicle `index` and its coordinator.
#[derive(Debug, Clone)]
struct InFlight {
    to_vehicle: bool,
    index: usize,
    bytes: Vec<u8>,
}

/// The coordinators and their vehicles in one virtual world.
#[derive(Debug)]
pub struct Lockstep {
    /// One swarm machine, or one per shard.
    coordinators: Vec<Swarm>,
    vehicles: Vec<Vehicle>,
    /// The coordinator of each vehicle (all 0 in one process).
    owner: Vec<usize>,
    now: SimTime,
    in_flight: FaultyLine<InFlight>,
    conditions: LinkConditions,
    silenced: Vec<Vec<(SimTime, SimTime)>>,
    /// The coordinators' stall ([`Lockstep::stall_coordinator`]), and what arrived for
    /// them meanwhile, unread.
    stall: Option<(SimTime, SimTime)>,
    unread: Vec<(usize, Vec<u8>)>,
    routing: Option<Routing>,
    /// The bus between shards.
    bus: Option<ShardBus>,
    /// Datagrams from a swarm the router had no address for.
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
    pub fn new(swarm: Swarm, vehicles: Vec<Vehicle>, conditions: LinkConditions) -> Self {
        let owner = vec![0; vehicles.len()];
        Self::with_coordinators(vec![swarm], vehicles, owner, conditions)
    }

    /// Shards (each built with [`Swarm::new_shard`] over the same ring) and every
    /// vehicle of the ring; `mavlink` on each vehicle's link, `bus` between shards.
    ///
    /// # Errors
    /// When the shards' plans do not agree on who flies whom, or a vehicle is missing.
    pub fn sharded(
        shards: Vec<Swarm>,
        vehicles: Vec<Vehicle>,
        mavlink: LinkConditions,
        bus: LinkConditions,
    ) -> Result<Self, String> {
        let owner = agreed_owners(&shards, vehicles.len())?;
        let count = shards.len();
        let mut run = Self::with_coordinators(shards, vehicles, owner, mavlink);
        run.bus = Some(ShardBus::new(count, bus, IN_FLIGHT_CAPACITY));
        Ok(run)
    }

    fn with_coordinators(
        coordinators: Vec<Swarm>,
        mut vehicles: Vec<Vehicle>,
        owner: Vec<usize>,
        conditions: LinkConditions,
    ) -> Self {
        let n = vehicles.len();
        // Only the offboard links are carried: nothing is built for the ground station's.
        for v in &mut vehicles {
            v.set_link_wired(LinkId::Gcs, false);
        }
        Self {
            coordinators,
            vehicles,
            owner,
            now: SimTime::ZERO,
            in_flight: FaultyLine::new(IN_FLIGHT_CAPACITY, conditions.seed),
            conditions,
            silenced: vec![Vec::new(); n],
            stall: None,
            unread: Vec::new(),
            routing: None,
            bus: None,
            unsent: 0,
            parallel: n >= PARALLEL_FROM,
            clock: None,
        }
    }

    /// From now on, adds up the wall time of each phase of the loop ([`PhaseTimes`]); a
    /// few clock reads per step, and the flight is the same.
    pub fn keep_phase_times(&mut self) {
        self.clock = Some(PhaseClock::start());
    }

    /// The phase times kept so far (none unless [`Lockstep::keep_phase_times`] was called).
    pub fn phase_times(&self) -> Option<PhaseTimes> {
        self.clock.map(|c| c.times())
    }

    fn lap(&mut self, phase: fn(&mut PhaseTimes) -> &mut Duration) {
        if let Some(clock) = &mut self.clock {
            clock.lap(phase);
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
    pub fn with_transport(mut self, plan: &TransportLayout) -> Self {
        self.routing = Some(Routing::new(plan));
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
        Self::from_config_with(config, crate::config::Stability::Required)
    }

    /// [`Self::from_config`], unstable gains refused or flown as `stability` says
    /// (`ringswarm sweep` maps where the swarm stops converging).
    ///
    /// # Errors
    /// As [`Self::from_config`].
    pub fn from_config_with(
        config: &crate::config::Config,
        stability: crate::config::Stability,
    ) -> Result<Self, String> {
        let setup = config.validate_with(stability)?;
        let (world, vehicle_configs) = config.emulator()?;
        let faults = config.lockstep_faults()?;
        let vehicles = vehicle_configs
            .into_iter()
            .map(|v| Vehicle::new(v, world))
            .collect::<Result<Vec<_>, _>>()?;
        let plan = config.transport_layout()?;
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

    /// The swarm machine (the first shard's, when sharded).
    pub fn swarm(&self) -> &Swarm {
        &self.coordinators[0]
    }

    /// The swarm machine, to hand it what a driver would (the first shard's, when
    /// sharded).
    pub fn swarm_mut(&mut self) -> &mut Swarm {
        &mut self.coordinators[0]
    }

    /// Every swarm machine: the one of one process, or each shard's.
    pub fn shards(&self) -> &[Swarm] {
        &self.coordinators
    }

    /// The emulated vehicles.
    pub fn vehicles(&self) -> &[Vehicle] {
        &self.vehicles
    }

    /// What crossed the bus between shards (nothing in one process).
    pub fn bus_counts(&self) -> BusCounts {
        self.bus
            .as_ref()
            .map_or_else(BusCounts::default, ShardBus::counts)
    }

    /// Takes shard `s` down over `[from, until)`: it runs nothing, sends nothing, and
    /// what is sent to it (MAVLink or bus) is lost, as when its process is killed. (It
    /// comes back with its state as it was, as a process paused rather than restarted.)
    /// Nothing in one process.
    pub fn take_down(&mut self, s: usize, from: SimTime, until: SimTime) {
        if let Some(bus) = &mut self.bus {
            bus.take_down(s, from, until);
        }
    }

    /// Cuts the bus between shards `a` and `b` (both ways) over `[from, until)`: each
    /// still hears the others, as a mesh with one broken link.
    pub fn cut(&mut self, a: usize, b: usize, from: SimTime, until: SimTime) {
        if let Some(bus) = &mut self.bus {
            bus.cut(a, b, from, until);
        }
    }

    fn is_down(&self, s: usize) -> bool {
        self.bus.as_ref().is_some_and(|b| b.is_down(s, self.now))
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
        for swarm in &mut self.coordinators {
            swarm.set_listen_lag(now, now.saturating_since(from));
            swarm.handle_timeout(now);
        }
        for (j, bytes) in std::mem::take(&mut self.unread) {
            self.deliver_to_swarm(now, j, &bytes, observer);
            self.recycle(false, j, bytes);
        }
        for swarm in &mut self.coordinators {
            swarm.set_listen_lag(now, Duration::ZERO);
        }
        self.stall = None;
    }

    /// Advances by one physics step.
    pub fn step(&mut self) {
        self.step_observed(&mut ());
    }

    /// Runs until virtual time `end`; `observer` sees every datagram the swarm sends or
    /// receives (when it is sent, and when it is delivered) and the swarm (the first
    /// shard's, when sharded) after each step.
    pub fn run_observed(&mut self, end: SimTime, observer: &mut impl Observer) {
        while self.now < end {
            self.step_observed(observer);
            observer.swarm(&self.coordinators[0], self.now);
        }
    }

    fn step_observed(&mut self, observer: &mut impl Observer) {
        self.now = self.now + PHYSICS_STEP;
        let now = self.now;
        self.lap(|t| &mut t.delivery); // the caller's observer, between steps
        self.step_vehicles(now);
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
        for s in 0..self.coordinators.len() {
            if !self.is_down(s) {
                self.step_coordinator(s, now, observer);
            }
        }
        self.lap(|t| &mut t.coordinator);
        self.deliver(now, observer);
        self.lap(|t| &mut t.delivery);
    }

    fn step_vehicles(&mut self, now: SimTime) {
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
    }

    /// Coordinator `s`'s timers and tick, its datagrams into the line and its messages
    /// onto the bus.
    fn step_coordinator(&mut self, s: usize, now: SimTime, observer: &mut impl Observer) {
        if now >= self.coordinators[s].poll_timeout() {
            self.coordinators[s].handle_timeout(now);
        }
        while let Some((i, bytes)) = self.coordinators[s].poll_transmit() {
            observer.datagram(now, i, true, &bytes);
            match self.vehicle_reached_by(i) {
                Some(j) => self.send(true, j, bytes),
                None => {
                    self.unsent += 1;
                    self.coordinators[s].recycle(i, bytes);
                }
            }
        }
        if let Some(bus) = &mut self.bus {
            while let Some(message) = self.coordinators[s].poll_shard_message() {
                bus.publish(now, s, &message, &self.coordinators);
            }
        }
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

    /// The emulated vehicle a datagram for link `i` reaches.
    fn vehicle_reached_by(&self, i: VehicleIndex) -> Option<usize> {
        match &self.routing {
            Some(r) => r.vehicle_reached_by(i),
            None => Some(i.get()),
        }
    }

    /// Hands a datagram from vehicle `j` to its coordinator (through the router, if any).
    fn deliver_to_swarm(
        &mut self,
        now: SimTime,
        j: usize,
        bytes: &[u8],
        observer: &mut impl Observer,
    ) {
        let swarm = &mut self.coordinators[self.owner[j]];
        let Some(r) = self.routing.as_mut() else {
            // Without a router, emulated vehicle j is link j.
            observer.datagram(now, VehicleIndex(j), false, bytes);
            swarm.handle_datagram(now, VehicleIndex(j), bytes);
            return;
        };
        let (socket, from) = (r.socket_of[j], r.addresses[j]);
        let mut intake = Intake {
            swarm,
            router: &mut r.router,
            pieces: &mut r.pieces,
        };
        intake.deliver(socket, from, bytes, now, observer);
    }

    /// Whether vehicle `i`'s link carries nothing now: silenced, or its shard down.
    fn is_cut_off(&self, i: usize) -> bool {
        self.silenced[i]
            .iter()
            .any(|&(from, until)| self.now >= from && self.now < until)
            || self.is_down(self.owner[i])
    }

    fn send(&mut self, to_vehicle: bool, index: usize, bytes: Vec<u8>) {
        if self.is_cut_off(index) {
            self.recycle(to_vehicle, index, bytes);
            return;
        }
        let held = InFlight {
            to_vehicle,
            index,
            bytes,
        };
        let mut lost = None;
        self.in_flight.send(
            self.now,
            &self.conditions.faults,
            held,
            InFlight::clone,
            |d| lost = Some(d),
        );
        // Lost on the way (or the line full): back to where it came from.
        if let Some(d) = lost {
            self.recycle(d.to_vehicle, d.index, d.bytes);
        }
    }

    /// Gives a delivered (or lost) datagram's buffer back to its sender.
    fn recycle(&mut self, to_vehicle: bool, index: usize, bytes: Vec<u8>) {
        if to_vehicle {
            // Any link of its coordinator takes the buffer back (it is only memory).
            self.coordinators[self.owner[index]].recycle(VehicleIndex(index), bytes);
        } else if let Some(v) = self.vehicles.get_mut(index) {
            v.recycle(bytes);
        }
    }

    fn deliver(&mut self, now: SimTime, observer: &mut impl Observer) {
        while let Some(d) = self.in_flight.pop_due(now) {
            if d.to_vehicle {
                self.vehicles[d.index].handle_datagram(now, LinkId::Offboard, &d.bytes);
            } else if self.is_down(self.owner[d.index]) {
                // Its shard's process is gone: lost.
            } else if self.coordinator_stalled() {
                self.unread.push((d.index, d.bytes));
                continue;
            } else {
                self.deliver_to_swarm(now, d.index, &d.bytes, observer);
            }
            self.recycle(d.to_vehicle, d.index, d.bytes);
        }
        if let Some(bus) = &mut self.bus {
            bus.deliver(now, &mut self.coordinators);
        }
    }
}

/// Each vehicle's shard, as every shard's plan gives it.
///
/// # Errors
/// A swarm of one process among the shards, plans that do not cover every vehicle, or
/// plans that disagree.
fn agreed_owners(shards: &[Swarm], n: usize) -> Result<Vec<usize>, String> {
    let plans: Vec<&ShardPlan> = shards
        .iter()
        .map(|s| {
            s.shard_plan()
                .ok_or("a swarm of one process among the shards")
        })
        .collect::<Result<_, _>>()?;
    let owner: Vec<usize> = (0..n)
        .map(|i| plans.first().and_then(|p| p.owner(i)))
        .collect::<Option<_>>()
        .ok_or(format!("the shards' plans do not cover the {n} vehicles"))?;
    for (s, p) in plans.iter().enumerate() {
        if p.this() != s || p.shards() != shards.len() {
            return Err(format!(
                "shard {s}'s plan is shard {} of {}",
                p.this(),
                p.shards()
            ));
        }
        if (0..n).any(|i| p.owner(i) != Some(owner[i])) {
            return Err(format!("shard {s}'s plan gives the vehicles other owners"));
        }
    }
    Ok(owner)
}
