//! What the UDP driver tells the flight runner at each tick: the run directory's rows,
//! the live view's feed, the mirrors, the signing clock and the status line once a second.

use std::time::Duration;

use ringswarm_wire::time::SimTime;

use crate::driver::Observer;
use crate::driver::mirror::Mirrors;
use crate::record::Recorder;
use crate::security::FlightSigning;
use crate::swarm::{StopReason, Swarm, SwarmPhase, VehicleIndex};
use crate::vehicle::Phase;
use crate::view::LiveFeed;

pub(super) struct FlyObserver {
    pub(super) recorder: Recorder,
    pub(super) next_status: SimTime,
    pub(super) last: SimTime,
    pub(super) signing: Option<FlightSigning>,
    /// The live view's feed, with `--web`.
    pub(super) feed: Option<LiveFeed>,
    pub(super) mirrors: Mirrors,
}

impl FlyObserver {
    /// Keeps the stored signing clock ahead of the newest stamp any link used.
    pub(super) fn keep_signing_clock(&mut self, swarm: &Swarm) {
        let Some(signing) = self.signing.as_mut() else {
            return;
        };
        let newest = swarm
            .links()
            .filter_map(crate::vehicle::VehicleLink::signing_timestamp)
            .max()
            .unwrap_or(signing.start);
        if let Err(e) = signing.store.keep_ahead(newest) {
            eprintln!("signing clock not stored: {e}");
        }
    }
}

impl Observer for FlyObserver {
    fn datagram(&mut self, now: SimTime, _vehicle: VehicleIndex, _to_vehicle: bool, bytes: &[u8]) {
        self.recorder.datagram(now, bytes);
        self.mirrors.forward(bytes);
    }

    fn swarm(&mut self, swarm: &Swarm, now: SimTime) {
        self.last = now;
        self.recorder.sample(swarm, now);
        if let Some(feed) = &mut self.feed {
            feed.offer(swarm, now, self.recorder.tracker().latest());
        }
        self.mirrors.drain_due(now);
        if now >= self.next_status {
            self.next_status = now + Duration::from_secs(1);
            self.keep_signing_clock(swarm);
            eprintln!("{}", status_line(swarm, &self.recorder, now));
        }
    }
}

/// One line: time, phase, each link's phase, and the figures.
fn status_line(swarm: &Swarm, recorder: &Recorder, now: SimTime) -> String {
    let phase = match swarm.phase() {
        SwarmPhase::Holding(_) => "HOLDING (a vehicle is lost)",
        SwarmPhase::Ended(_) => "ended (hovering)",
        SwarmPhase::Stopped(_) => match swarm.stop_reason() {
            Some(StopReason::Fence) => "STOPPED at the fence (hovering)",
            Some(StopReason::Separation) => "STOPPED: two vehicles too close (hovering)",
            _ => "STOPPED by the divergence guard (hovering)",
        },
        other => other.name(),
    };
    // One mark per vehicle (another shard's: as its shard reports it).
    let links: String = swarm
        .indices()
        .map(|i| match swarm.vehicle_phase(i) {
            Phase::Discovering => '?',
            Phase::Streaming(_) => 's',
            Phase::Arming => 'a',
            Phase::Offboarding => 'o',
            Phase::Flying => 'F',
            Phase::Lost => 'X',
            Phase::Failed => '!',
            Phase::Landing => 'L',
            Phase::Disarming => 'd',
            Phase::Done => '.',
            Phase::Overridden => 'P',
            Phase::VehicleHold => 'H',
        })
        .collect();
    let mut line = format!("[{:7.1} s] {phase:<10} links {links}", now.as_secs_f64());
    if let Some(s) = recorder.tracker().latest() {
        line += &format!(
            " | v ({:6.2}, {:6.2}) m/s | formation {:7.2} m | altitude ±{:5.2} m",
            s.mean_velocity_mps[0], s.mean_velocity_mps[1], s.formation_error_m, s.altitude_error_m
        );
    }
    if let Some(p) = swarm.predicted_final_velocity() {
        line += &format!(" | predicted ({:.2}, {:.2})", p.x, p.y);
    }
    if let Some((i, j, d)) = swarm.closest_pair() {
        let id = |k: usize| swarm.setup().links[k].system_id;
        line += &format!(" | closest {}-{} {d:.1} m", id(i), id(j));
    }
    if matches!(swarm.phase(), SwarmPhase::Handshake) {
        // What the handshake waits for (ArduPilot's EKF, a fence upload, …): the first
        // vehicle waiting, and how many more.
        let mut waiting = swarm.indices().filter_map(|i| {
            let what = swarm.link(i)?.waiting_for()?;
            Some((swarm.setup().links[i].system_id, what))
        });
        if let Some((id, what)) = waiting.next() {
            line += &format!(" | vehicle {id} {what}");
            let more = waiting.count();
            if more > 0 {
                line += &format!(" (+{more} more waiting)");
            }
        }
    }
    line
}
