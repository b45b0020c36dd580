//! The text `sitl` prints: where each vehicle listens, and the refreshing status lines.

use ringswarm_sitl::autopilot::{LinkId, VehicleStatus};
use ringswarm_sitl::fleet::FleetVehicle;
use ringswarm_sitl::udp::{LinkPort, LinkSocket};
use tokio::sync::watch;

/// Each link's socket and where it sends.
pub(super) fn describe_links(links: &[LinkSocket]) -> String {
    links
        .iter()
        .map(|l| {
            let at = l.port.describe();
            match (l.id, &l.port) {
                (_, LinkPort::Pty(_)) => format!("offboard/API link {at}"),
                (LinkId::Offboard, LinkPort::Udp(_)) => format!(
                    "offboard/API link {at} -> {} (MAVSDK: udpin://0.0.0.0:{})",
                    l.default_peer,
                    l.default_peer.port()
                ),
                (LinkId::Gcs, LinkPort::Udp(_)) => format!("GCS link {at} -> {}", l.default_peer),
            }
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// How many vehicles there are and where they send.
pub(super) fn placements_summary(fleet: &[FleetVehicle]) -> String {
    let mut peers: Vec<std::net::SocketAddr> = fleet
        .iter()
        .filter_map(|v| v.links.first().map(|l| l.default_peer))
        .collect();
    peers.sort();
    peers.dedup();
    let shown: Vec<String> = peers.iter().take(8).map(ToString::to_string).collect();
    format!(
        "{} vehicles on {} core(s), sending to {} address(es): {}{}",
        fleet.len(),
        crate::driver::cores(),
        peers.len(),
        shown.join(", "),
        if peers.len() > shown.len() {
            ", ..."
        } else {
            ""
        }
    )
}

/// Offboard setpoints each vehicle had taken at the previous fleet line, with the
/// vehicle's time of that count.
#[derive(Default)]
pub(super) struct SetpointTally {
    taken: Vec<(f64, u64)>,
}

/// One line for a large fleet: how many are armed, in each mode, heard from, and the rate
/// of offboard setpoints each vehicle took since the previous line (lowest and mean).
pub(super) fn fleet_line(
    statuses: &[watch::Receiver<VehicleStatus>],
    now_s: f64,
    tally: &mut SetpointTally,
) -> String {
    let mut armed = 0;
    let mut heard = 0;
    let mut modes: std::collections::BTreeMap<&'static str, usize> = Default::default();
    let mut lowest = f64::INFINITY;
    let mut highest = f64::NEG_INFINITY;
    let mut taken = Vec::with_capacity(statuses.len());
    for s in statuses {
        let s = s.borrow();
        armed += usize::from(s.armed);
        heard += usize::from(s.last_heard[0].is_some_and(|t| now_s - t.as_secs_f64() < 2.0));
        *modes.entry(s.mode.name()).or_default() += 1;
        lowest = lowest.min(s.height_m);
        highest = highest.max(s.height_m);
        taken.push((s.at.as_secs_f64(), s.counters.setpoints));
    }
    let modes: Vec<String> = modes.iter().map(|(m, n)| format!("{m} {n}")).collect();
    // Each vehicle's count over its own clock between its two snapshots (none on the
    // first line).
    let per: Vec<f64> = if tally.taken.len() == taken.len() {
        taken
            .iter()
            .zip(&tally.taken)
            .filter(|((t1, _), (t0, _))| t1 > t0)
            .map(|((t1, n1), (t0, n0))| n1.saturating_sub(*n0) as f64 / (t1 - t0))
            .collect()
    } else {
        Vec::new()
    };
    let rates = if per.is_empty() {
        String::new()
    } else {
        let low = per.iter().copied().fold(f64::INFINITY, f64::min);
        let mean = per.iter().sum::<f64>() / per.len() as f64;
        format!("  setpoints {low:.1} Hz lowest, {mean:.1} Hz mean")
    };
    *tally = SetpointTally { taken };
    format!(
        "  t {now_s:7.1} s  {} vehicles: {armed} armed, offboard link up {heard}, {}  height {lowest:.1}..{highest:.1} m{rates}",
        statuses.len(),
        modes.join(", ")
    )
}

pub(super) fn status_line(s: &VehicleStatus, now_s: f64) -> String {
    let link = |heard: Option<ringswarm_wire::time::SimTime>| match heard {
        Some(t) if now_s - t.as_secs_f64() < 2.0 => "up".to_owned(),
        Some(t) => format!("silent {:.0}s", now_s - t.as_secs_f64()),
        None => "none".to_owned(),
    };
    format!(
        "  sys {:>3}  {:<8} {:<8}{}  alt {:>7.2} m  battery {:>5.1} %  offboard link {:<10} gcs link {}",
        s.system_id,
        s.mode.name(),
        if s.armed { "ARMED" } else { "disarmed" },
        if s.failsafe { " FAILSAFE" } else { "" },
        s.height_m,
        s.battery_pct,
        link(s.last_heard[0]),
        link(s.last_heard[1]),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use ringswarm_sitl::autopilot::{Vehicle, VehicleConfig};
    use ringswarm_sitl::profile::Profile;
    use ringswarm_sitl::world::World;
    use ringswarm_wire::time::SimTime;

    #[test]
    fn the_fleet_line_shows_each_vehicle_s_setpoint_rate_over_its_own_clock() {
        let vehicle = Vehicle::new(VehicleConfig::new(1, Profile::ideal()), World::default())
            .expect("vehicle");
        let status = |at_ms: u64, setpoints: u64| {
            let mut s = vehicle.status();
            s.at = SimTime::from_millis(at_ms);
            s.counters.setpoints = setpoints;
            s
        };
        let (a_tx, a) = watch::channel(status(1_000, 0));
        let (b_tx, b) = watch::channel(status(1_300, 10));
        let fleet = [a, b];
        let mut tally = SetpointTally::default();
        // The first line has nothing to compare with.
        assert!(!fleet_line(&fleet, 1.0, &mut tally).contains("setpoints"));
        // Vehicle a: 250 setpoints in 5 s, 50 Hz; b: 240 in 4.8 s (its snapshot came
        // 200 ms before the line), also 50 Hz, then 100 in 5 s: 20 Hz.
        a_tx.send_replace(status(6_000, 250));
        b_tx.send_replace(status(6_100, 250));
        let line = fleet_line(&fleet, 6.0, &mut tally);
        assert!(
            line.ends_with("setpoints 50.0 Hz lowest, 50.0 Hz mean"),
            "{line}"
        );
        a_tx.send_replace(status(11_000, 500));
        b_tx.send_replace(status(11_100, 350));
        let line = fleet_line(&fleet, 11.0, &mut tally);
        assert!(
            line.ends_with("setpoints 20.0 Hz lowest, 35.0 Hz mean"),
            "{line}"
        );
    }
}
