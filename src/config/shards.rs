//! `[distributed]` and `[[shard]]`: the swarm split into shards, each a `fly --shard NAME`
//! process flying its own vehicles, all reading the same file (docs/distributed.md).
//! The file is checked whole whichever shard reads it: every vehicle in exactly one
//! shard, names unique and fit for a Zenoh key, endpoints that parse.

use std::collections::HashMap;
use std::time::Duration;

use serde::Deserialize;

use super::Config;
use crate::consensus::RingDigraph;
use crate::distributed::{ShardPlan, Watch};

/// `[distributed]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DistributedSection {
    /// The swarm's name: every key is under `ringswarm/<swarm>/`.
    pub swarm: String,
    /// Which other shards' vehicles a shard reads: `all` (default); `horizon` (the ring
    /// in-neighbours of its own vehicles and every vehicle within its safety filter's
    /// horizon, by tile); or `neighbours` (the ring in-neighbours only; needs
    /// `[safety] enabled = false`, since the safety filter would not see the other
    /// shards' vehicles).
    #[serde(default)]
    pub watch: WatchName,
    /// The side of the tiles states are published in (m, default 100; 1 to 100 000).
    #[serde(default = "default_tile_m")]
    pub tile_m: f64,
    /// How long after a shard sees every vehicle flying it proposes to start consensus
    /// (ms, default 200): more than the longest hop between shards.
    #[serde(default = "default_start_lead_ms")]
    pub start_lead_ms: f64,
    /// The one-way delay between shards the flight must stand (ms, default 20): the
    /// bandwidth gate limits the law's speed by it and recommends a time scale.
    #[serde(default = "default_hop_ms")]
    pub hop_ms: f64,
}

fn default_start_lead_ms() -> f64 {
    200.0
}

fn default_hop_ms() -> f64 {
    20.0
}

fn default_tile_m() -> f64 {
    crate::distributed::DEFAULT_TILE_M
}

/// `all`, `horizon` or `neighbours`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum WatchName {
    /// Every vehicle.
    #[default]
    All,
    /// The ring in-neighbours and every vehicle within the safety filter's horizon.
    Horizon,
    /// The ring in-neighbours of the shard's own vehicles.
    Neighbours,
}

/// `[[shard]]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShardSection {
    /// Its name (`fly --shard NAME`), unique; letters, digits, `-`, `_` and `.`.
    pub name: String,
    /// The vehicles it flies, each as its `[[vehicle]]` table names it.
    pub vehicles: Vec<ShardVehicle>,
    /// Zenoh endpoints it listens on (`tcp/0.0.0.0:7447`); none: Zenoh's own choice.
    #[serde(default)]
    pub listen: Vec<String>,
    /// Zenoh endpoints of other shards it connects to; none: found by Zenoh's
    /// scouting (multicast on the local network).
    #[serde(default)]
    pub connect: Vec<String>,
}

/// A vehicle of a shard: its system id, and its network when it has one.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShardVehicle {
    /// Its `[[vehicle]] system_id`.
    pub system_id: u8,
    /// Its `[[vehicle]] network`, if it has one.
    pub network: Option<String>,
}

/// The split, checked.
#[derive(Debug, Clone, PartialEq)]
pub struct ShardLayout {
    /// The swarm's name.
    pub swarm: String,
    /// The shards' names, in file order.
    pub names: Vec<String>,
    /// Each vehicle's shard (index into `names`), in ring order.
    pub owner: Vec<usize>,
    /// Each shard's listen endpoints.
    pub listen: Vec<Vec<String>>,
    /// Each shard's connect endpoints.
    pub connect: Vec<Vec<String>>,
    /// What a shard reads.
    pub watch: Watch,
    /// The side of the tiles states are published in (m).
    pub tile_m: f64,
    /// The start proposal's lead.
    pub start_lead: Duration,
}

impl ShardLayout {
    /// The key prefix of a vehicle's state: `ringswarm/<swarm>/state/<network>/<sysid>`,
    /// `-` for a vehicle without a network. The state is published under this prefix
    /// and the tile of its position ([`Self::state_key`]).
    pub fn state_prefix(&self, network: Option<&str>, system_id: u8) -> String {
        format!(
            "ringswarm/{}/state/{}/{system_id}",
            self.swarm,
            network.unwrap_or("-")
        )
    }

    /// The key a vehicle's state is published under: its [`Self::state_prefix`] and the
    /// tile its position is in (`e<east>n<north>`, `tile_m` squares of the common frame;
    /// `far` for a position outside the tiles' range).
    pub fn state_key(&self, prefix: &str, pos_enu_m: [f32; 3]) -> String {
        let pos = nalgebra::Vector2::new(f64::from(pos_enu_m[0]), f64::from(pos_enu_m[1]));
        let tile = crate::distributed::Tile::of(pos, self.tile_m)
            .map_or_else(|| "far".to_owned(), |t| t.chunk());
        format!("{prefix}/{tile}")
    }

    /// What a shard subscribes to for a watched vehicle: its state in any tile.
    pub fn watched_key(&self, prefix: &str) -> String {
        format!("{prefix}/*")
    }

    /// What a shard subscribes to for a tile it reads: every vehicle's state in it.
    pub fn tile_key(&self, tile: crate::distributed::Tile) -> String {
        format!("ringswarm/{}/state/*/*/{}", self.swarm, tile.chunk())
    }

    /// The key a shard's vehicle states of one tick are published under together, as a
    /// batch, when every shard reads them all (`watch = "all"`):
    /// `ringswarm/<swarm>/states/<name>`.
    pub fn batch_key(&self, shard: usize) -> String {
        format!(
            "ringswarm/{}/states/{}",
            self.swarm,
            self.names.get(shard).map_or("", String::as_str)
        )
    }

    /// The key a shard's report is published under: `ringswarm/<swarm>/shard/<name>`.
    pub fn shard_key(&self, shard: usize) -> String {
        format!(
            "ringswarm/{}/shard/{}",
            self.swarm,
            self.names.get(shard).map_or("", String::as_str)
        )
    }
}

/// Whether `name` is fit for one chunk of a Zenoh key (no `/`, no wildcard or special
/// character).
fn key_safe(name: &str) -> bool {
    !name.is_empty()
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
}

/// The problems of one Zenoh endpoint (`<protocol>/<address>`), if any.
pub fn endpoint_problem(endpoint: &str) -> Option<String> {
    const PROTOCOLS: [&str; 2] = ["tcp", "udp"];
    let Some((protocol, address)) = endpoint.split_once('/') else {
        return Some(format!(
            "\"{endpoint}\" is not <protocol>/<address> (tcp/192.168.1.2:7447)"
        ));
    };
    if !PROTOCOLS.contains(&protocol) {
        return Some(format!(
            "\"{endpoint}\": protocol \"{protocol}\" is not one of tcp, udp"
        ));
    }
    let address = address.split(['?', '#']).next().unwrap_or(address);
    let Some((host, port)) = address.rsplit_once(':') else {
        return Some(format!("\"{endpoint}\": the address has no :port"));
    };
    if host.is_empty() || port.parse::<u16>().map_or(true, |p| p == 0) {
        return Some(format!(
            "\"{endpoint}\": \"{address}\" is not host:port with a port in 1..=65535"
        ));
    }
    None
}

impl Config {
    /// The split into shards, when the file has one.
    ///
    /// # Errors
    /// Every problem, one per line: `[distributed]` without `[[shard]]` or the other way
    /// round, a name unfit for a key or used twice, a vehicle in no shard or in two, a
    /// shard naming a vehicle the file does not have, a shard with none, an endpoint that
    /// does not parse, `watch = "neighbours"`
    /// with the safety filter on.
    pub fn shard_layout(&self) -> Result<Option<ShardLayout>, String> {
        let (d, shards) = match (&self.distributed, self.shard.is_empty()) {
            (None, true) => return Ok(None),
            (None, false) => {
                return Err(
                    "[[shard]] tables need a [distributed] table (its swarm name)".to_owned(),
                );
            }
            (Some(_), true) => {
                return Err("[distributed] needs at least one [[shard]] table".to_owned());
            }
            (Some(d), false) => (d, &self.shard),
        };
        let mut problems = distributed_problems(d, self.safety.enabled);
        let owner = self.shard_owners(shards, &mut problems);
        if problems.is_empty() {
            // Judged on a split that is otherwise sound: names unique, endpoints parsed.
            problems.extend(mesh_problems(shards));
        }
        for (i, o) in owner.iter().enumerate() {
            if o.is_none() {
                let v = &self.vehicle[i];
                let named = vehicle_named(v.system_id, v.network.as_deref());
                problems.push(format!("vehicle[{i}] ({named}) is in no [[shard]]"));
            }
        }
        if !problems.is_empty() {
            return Err(problems.join("\n"));
        }
        Ok(Some(ShardLayout {
            swarm: d.swarm.clone(),
            names: shards.iter().map(|s| s.name.clone()).collect(),
            owner: owner.into_iter().flatten().collect(),
            listen: shards.iter().map(|s| s.listen.clone()).collect(),
            connect: shards.iter().map(|s| s.connect.clone()).collect(),
            watch: match d.watch {
                WatchName::All => Watch::All,
                WatchName::Horizon => Watch::Horizon,
                WatchName::Neighbours => Watch::Neighbours,
            },
            tile_m: d.tile_m,
            start_lead: Duration::from_secs_f64(d.start_lead_ms / 1000.0),
        }))
    }

    /// Each vehicle's shard, as the `[[shard]]` tables list them (`None`: in none), and
    /// the tables' problems: names, vehicles not in the file or listed twice, endpoints.
    fn shard_owners(
        &self,
        shards: &[ShardSection],
        problems: &mut Vec<String>,
    ) -> Vec<Option<usize>> {
        let mut seen_names: HashMap<&str, usize> = HashMap::new();
        let vehicle_index: HashMap<(u8, Option<&str>), usize> = self
            .vehicle
            .iter()
            .enumerate()
            .map(|(i, v)| ((v.system_id, v.network.as_deref()), i))
            .collect();
        let mut owner: Vec<Option<usize>> = vec![None; self.vehicle.len()];
        for (s, shard) in shards.iter().enumerate() {
            let label = format!("shard[{s}] \"{}\"", shard.name);
            if !key_safe(&shard.name) {
                problems.push(format!(
                    "{label}: the name must be letters, digits, '-', '_' or '.'"
                ));
            }
            if let Some(first) = seen_names.insert(&shard.name, s) {
                problems.push(format!("{label}: the name is also shard[{first}]'s"));
            }
            if shard.vehicles.is_empty() {
                problems.push(format!("{label} flies no vehicle"));
            }
            for v in &shard.vehicles {
                let named = vehicle_named(v.system_id, v.network.as_deref());
                let Some(&i) = vehicle_index.get(&(v.system_id, v.network.as_deref())) else {
                    problems.push(format!("{label}: {named} is not a [[vehicle]] of the file"));
                    continue;
                };
                match owner[i] {
                    Some(other) if other == s => {
                        problems.push(format!("{label}: {named} is listed twice"))
                    }
                    Some(other) => problems.push(format!(
                        "{label}: {named} is already shard[{other}] \"{}\"'s",
                        shards[other].name
                    )),
                    None => owner[i] = Some(s),
                }
            }
            for (what, endpoints) in [("listen", &shard.listen), ("connect", &shard.connect)] {
                for e in endpoints {
                    if let Some(problem) = endpoint_problem(e) {
                        problems.push(format!("{label}.{what}: {problem}"));
                    }
                }
            }
        }
        owner
    }

    /// Shard `name`'s plan, over `ring`.
    ///
    /// # Errors
    /// The layout's problems, a file without shards, or no shard of that name (the names
    /// there are listed).
    pub fn shard_plan(&self, name: &str, ring: &RingDigraph) -> Result<ShardPlan, String> {
        let layout = self
            .shard_layout()?
            .ok_or("--shard needs [distributed] and [[shard]] tables in the file")?;
        let this = layout.names.iter().position(|n| n == name).ok_or_else(|| {
            format!(
                "no [[shard]] named \"{name}\"; the file has {}",
                layout
                    .names
                    .iter()
                    .map(|n| format!("\"{n}\""))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        })?;
        ShardPlan::new(
            this,
            layout.names.len(),
            layout.owner.clone(),
            ring,
            layout.watch,
        )
        .map(|p| {
            p.with_start_lead(layout.start_lead)
                .with_tile_m(layout.tile_m)
        })
        .map_err(|e| e.to_string())
    }
}

/// `[distributed]`'s problems: the swarm's key name, the start lead against the hop,
/// the tile size, and a watch that would leave the safety filter blind.
fn distributed_problems(d: &DistributedSection, safety_enabled: bool) -> Vec<String> {
    let mut problems = Vec::new();
    if !key_safe(&d.swarm) {
        problems.push(format!(
            "distributed.swarm \"{}\" must be letters, digits, '-', '_' or '.' (it is a Zenoh key chunk)",
            d.swarm
        ));
    }
    let lead_ok = d.start_lead_ms.is_finite() && (1.0..=10_000.0).contains(&d.start_lead_ms);
    if !lead_ok {
        problems.push(format!(
            "distributed.start_lead_ms must be in [1, 10000] ms, got {}",
            super::show(d.start_lead_ms)
        ));
    }
    if !(d.tile_m.is_finite() && (1.0..=100_000.0).contains(&d.tile_m)) {
        problems.push(format!(
            "distributed.tile_m must be in [1, 100000] m, got {}",
            super::show(d.tile_m)
        ));
    }
    if !(d.hop_ms.is_finite() && (0.0..=5_000.0).contains(&d.hop_ms)) {
        problems.push(format!(
            "distributed.hop_ms must be in [0, 5000] ms, got {}",
            super::show(d.hop_ms)
        ));
    } else if lead_ok && d.start_lead_ms <= 2.0 * d.hop_ms {
        problems.push(format!(
            "distributed.start_lead_ms ({} ms) must exceed two hops (2 × hop_ms = {} ms): \
             a start is proposed and vouched for across them",
            super::show(d.start_lead_ms),
            super::show(2.0 * d.hop_ms)
        ));
    }
    if d.watch == WatchName::Neighbours && safety_enabled {
        problems.push(
            "distributed.watch = \"neighbours\" leaves the safety filter blind to other shards' vehicles that are not ring neighbours: use watch = \"horizon\" or \"all\", or set [safety] enabled = false".to_owned(),
        );
    }
    problems
}

/// `vehicle 3`, or `vehicle 3 on network "a"`.
fn vehicle_named(system_id: u8, network: Option<&str>) -> String {
    match network {
        Some(n) => format!("vehicle {system_id} on network \"{n}\""),
        None => format!("vehicle {system_id}"),
    }
}

/// `(protocol, host, port)` of an endpoint that [`endpoint_problem`] passed.
fn endpoint_parts(endpoint: &str) -> Option<(&str, &str, &str)> {
    let (protocol, address) = endpoint.split_once('/')?;
    let (host, port) = address.rsplit_once(':')?;
    Some((
        protocol,
        host.trim_start_matches('[').trim_end_matches(']'),
        port,
    ))
}

/// Whether a shard connecting to `connect` reaches one listening on `listen`: same
/// protocol and port, and the same host or a listener on every address.
fn reaches(connect: &str, listen: &str) -> bool {
    match (endpoint_parts(connect), endpoint_parts(listen)) {
        (Some((cp, ch, cport)), Some((lp, lh, lport))) => {
            cp == lp && cport == lport && (ch == lh || lh == "0.0.0.0" || lh == "::")
        }
        _ => false,
    }
}

/// Every pair of shards must reach each other: Zenoh peers pass on data one hop only,
/// never for a third peer. A pair is joined when one connects to where the other
/// listens, or when both listen and a third shard joined to both introduces them
/// (Zenoh's gossip). With no endpoint anywhere, multicast scouting finds every shard.
fn mesh_problems(shards: &[ShardSection]) -> Vec<String> {
    if shards
        .iter()
        .all(|s| s.listen.is_empty() && s.connect.is_empty())
    {
        return Vec::new();
    }
    let n = shards.len();
    let direct = |a: usize, b: usize| {
        let one_way = |x: &ShardSection, y: &ShardSection| {
            x.connect
                .iter()
                .any(|c| y.listen.iter().any(|l| reaches(c, l)))
        };
        one_way(&shards[a], &shards[b]) || one_way(&shards[b], &shards[a])
    };
    let mut problems = Vec::new();
    for a in 0..n {
        for b in a + 1..n {
            let introduced = !shards[a].listen.is_empty()
                && !shards[b].listen.is_empty()
                && (0..n).any(|c| c != a && c != b && direct(a, c) && direct(b, c));
            if !direct(a, b) && !introduced {
                problems.push(format!(
                    "shards \"{}\" and \"{}\" cannot reach each other over Zenoh: one must \
                     connect to where the other listens, or both listen and a third shard \
                     joined to both introduces them (Zenoh peers relay nothing for others)",
                    shards[a].name, shards[b].name
                ));
            }
        }
    }
    problems
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file(extra: &str) -> String {
        let mut text = std::fs::read_to_string(
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/paper-sim1.toml"),
        )
        .unwrap();
        text.push_str(extra);
        text
    }

    const THREE: &str = r#"
[distributed]
swarm = "paper"

[[shard]]
name = "a"
vehicles = [{ system_id = 1 }, { system_id = 2 }]
listen = ["tcp/0.0.0.0:7447"]

[[shard]]
name = "b"
vehicles = [{ system_id = 3 }, { system_id = 4 }]
listen = ["tcp/0.0.0.0:7447"]
connect = ["tcp/10.0.0.1:7447"]

[[shard]]
name = "c"
vehicles = [{ system_id = 5 }, { system_id = 6 }]
listen = ["tcp/0.0.0.0:7447"]
connect = ["tcp/10.0.0.1:7447"]
"#;

    #[test]
    fn shards_that_cannot_reach_each_other_are_named() {
        // b and c connect to a and listen nowhere: a relays nothing between them.
        let star = THREE.replace("listen = [\"tcp/0.0.0.0:7447\"]\nconnect", "connect");
        let err = Config::from_toml(&file(&star))
            .unwrap()
            .shard_layout()
            .unwrap_err();
        assert_eq!(
            err,
            "shards \"b\" and \"c\" cannot reach each other over Zenoh: one must connect to \
             where the other listens, or both listen and a third shard joined to both \
             introduces them (Zenoh peers relay nothing for others)"
        );
        // c connecting to b's port as well joins them directly.
        let meshed = star.replace(
            "vehicles = [{ system_id = 3 }, { system_id = 4 }]\n",
            "vehicles = [{ system_id = 3 }, { system_id = 4 }]\nlisten = [\"tcp/0.0.0.0:7448\"]\n",
        );
        let meshed = meshed.replace(
            "vehicles = [{ system_id = 5 }, { system_id = 6 }]\nconnect = [\"tcp/10.0.0.1:7447\"]",
            "vehicles = [{ system_id = 5 }, { system_id = 6 }]\nconnect = [\"tcp/10.0.0.1:7447\", \"tcp/10.0.0.2:7448\"]",
        );
        let layout = Config::from_toml(&file(&meshed)).unwrap().shard_layout();
        assert!(layout.is_ok(), "{layout:?}");
    }

    #[test]
    fn a_file_split_in_three_gives_each_shard_its_plan_and_keys() {
        let config = Config::from_toml(&file(THREE)).unwrap();
        let layout = config.shard_layout().unwrap().unwrap();
        assert_eq!(layout.owner, vec![0, 0, 1, 1, 2, 2]);
        let prefix = layout.state_prefix(None, 3);
        assert_eq!(prefix, "ringswarm/paper/state/-/3");
        // Tiles of 100 m: (−50, 250) is in tile (−1, 2).
        assert_eq!(
            layout.state_key(&prefix, [-50.0, 250.0, 30.0]),
            "ringswarm/paper/state/-/3/e-1n2"
        );
        assert_eq!(
            layout.state_key(&prefix, [f32::NAN, 0.0, 0.0]),
            "ringswarm/paper/state/-/3/far"
        );
        assert_eq!(layout.watched_key(&prefix), "ringswarm/paper/state/-/3/*");
        assert_eq!(
            layout.batch_key(0),
            format!("ringswarm/paper/states/{}", layout.names[0])
        );
        assert_eq!(
            layout.tile_key(crate::distributed::Tile { east: 4, north: -2 }),
            "ringswarm/paper/state/*/*/e4n-2"
        );
        assert_eq!(layout.shard_key(2), "ringswarm/paper/shard/c");
        let setup = config.validate().unwrap();
        let plan = config.shard_plan("b", &setup.ring).unwrap();
        assert_eq!(plan.this(), 1);
        assert!(plan.is_local(2) && plan.is_local(3) && !plan.is_local(4));
        assert_eq!(plan.start_lead(), Duration::from_millis(200));
        assert_eq!(
            config.shard_plan("d", &setup.ring).unwrap_err(),
            "no [[shard]] named \"d\"; the file has \"a\", \"b\", \"c\""
        );
    }

    #[test]
    fn every_problem_of_the_split_is_named_at_once() {
        let bad = r#"
[distributed]
swarm = "pa/per"
start_lead_ms = -1

[[shard]]
name = "a"
vehicles = [{ system_id = 1 }, { system_id = 2 }, { system_id = 9 }]
listen = ["tcp/0.0.0.0"]

[[shard]]
name = "a"
vehicles = [{ system_id = 2 }, { system_id = 3 }, { system_id = 3 }]
connect = ["http/10.0.0.1:7447", "tcp10.0.0.1:7447"]

[[shard]]
name = "c"
vehicles = []
"#;
        let config = Config::from_toml(&file(bad)).unwrap();
        let err = config.shard_layout().unwrap_err();
        let lines: Vec<&str> = err.lines().collect();
        assert_eq!(
            lines,
            vec![
                "distributed.swarm \"pa/per\" must be letters, digits, '-', '_' or '.' (it is a Zenoh key chunk)",
                "distributed.start_lead_ms must be in [1, 10000] ms, got -1",
                "shard[0] \"a\": vehicle 9 is not a [[vehicle]] of the file",
                "shard[0] \"a\".listen: \"tcp/0.0.0.0\": the address has no :port",
                "shard[1] \"a\": the name is also shard[0]'s",
                "shard[1] \"a\": vehicle 2 is already shard[0] \"a\"'s",
                "shard[1] \"a\": vehicle 3 is listed twice",
                "shard[1] \"a\".connect: \"http/10.0.0.1:7447\": protocol \"http\" is not one of tcp, udp",
                "shard[1] \"a\".connect: \"tcp10.0.0.1:7447\" is not <protocol>/<address> (tcp/192.168.1.2:7447)",
                "shard[2] \"c\" flies no vehicle",
                "vehicle[3] (vehicle 4) is in no [[shard]]",
                "vehicle[4] (vehicle 5) is in no [[shard]]",
                "vehicle[5] (vehicle 6) is in no [[shard]]",
            ]
        );
    }

    #[test]
    fn half_a_split_and_unsafe_choices_are_refused() {
        let only_shards = THREE.replace("[distributed]\nswarm = \"paper\"\n", "");
        assert_eq!(
            Config::from_toml(&file(&only_shards))
                .unwrap()
                .shard_layout()
                .unwrap_err(),
            "[[shard]] tables need a [distributed] table (its swarm name)"
        );
        let neighbours = THREE.replace(
            "swarm = \"paper\"",
            "swarm = \"paper\"\nwatch = \"neighbours\"",
        );
        let err = Config::from_toml(&file(&neighbours))
            .unwrap()
            .shard_layout()
            .unwrap_err();
        assert!(err.contains("leaves the safety filter blind"), "{err}");
        let without_filter = format!("{neighbours}\n[safety]\nenabled = false\n");
        let layout = Config::from_toml(&file(&without_filter))
            .unwrap()
            .shard_layout()
            .unwrap()
            .unwrap();
        assert_eq!(layout.watch, Watch::Neighbours);
        let horizon = THREE.replace(
            "swarm = \"paper\"",
            "swarm = \"paper\"\nwatch = \"horizon\"\ntile_m = 50",
        );
        let config = Config::from_toml(&file(&horizon)).unwrap();
        let layout = config.shard_layout().unwrap().unwrap();
        assert_eq!((layout.watch, layout.tile_m), (Watch::Horizon, 50.0));
        let setup = config.validate().unwrap();
        assert_eq!(config.shard_plan("a", &setup.ring).unwrap().tile_m(), 50.0);
        for bad in ["0.5", "nan", "1e6"] {
            let text = THREE.replace(
                "swarm = \"paper\"",
                &format!("swarm = \"paper\"\ntile_m = {bad}"),
            );
            let err = Config::from_toml(&file(&text))
                .unwrap()
                .shard_layout()
                .unwrap_err();
            assert!(
                err.contains("distributed.tile_m must be in [1, 100000] m, got"),
                "{err}"
            );
        }
        // No split: one process, as before.
        assert_eq!(
            Config::from_toml(&file("")).unwrap().shard_layout(),
            Ok(None)
        );
    }
}
