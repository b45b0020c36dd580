//! The bus between shards over Zenoh: a peer session on a thread of its own (Zenoh runs
//! its own multi-threaded runtime; the coordinator's loop stays on its one thread), fed
//! and read through channels.
//!
//! - Publishes each [`ShardMessage`] the swarm makes: a vehicle's state under
//!   `ringswarm/<swarm>/state/<network>/<sysid>/<tile>` (the tile its position is in),
//!   the shard's report under `ringswarm/<swarm>/shard/<name>`. Under `watch = "all"`
//!   the shard's vehicle states of one tick go together, as one batch
//!   ([`crate::distributed::encode_into_batch`]), under `ringswarm/<swarm>/states/<name>`.
//! - Subscribes to the state keys of the remote vehicles its plan watches (any tile;
//!   under `watch = "all"`, every other shard's batch),
//!   to every shard's report (`ringswarm/<swarm>/shard/*`), and, under
//!   `watch = "horizon"`, to the tiles its swarm reads
//!   (`ringswarm/<swarm>/state/*/*/<tile>`), declared again as they move.
//! - Declares the liveliness token `ringswarm/<swarm>/alive/<name>` while it runs: any
//!   Zenoh peer (`ringswarm view --zenoh`, a monitor) sees which shards are up.
//!
//! Payloads are the versioned bytes of [`crate::distributed::payload`]. A payload that
//! arrives while the coordinator's queue is full is dropped and counted: the next tick's
//! replaces it.
//!
//! Every publication carries a Zenoh timestamp (the session's hybrid logical clock:
//! timestamping is on). On arrival a payload is taken only if its timestamp is newer than
//! the last one taken under its key (a vehicle's key without its tile, or a shard's), so a
//! payload reordered on the way, or the same one delivered through two subscriptions,
//! never reaches the coordinator. The swarm machine still orders by the payload's own
//! swarm-clock time, which lockstep (with no Zenoh) needs too.

use std::collections::{HashMap, HashSet};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::thread::JoinHandle;

use tokio::sync::mpsc;

use crate::config::ShardLayout;
use crate::distributed::{ShardMessage, ShardPlan, TileInterest, Watch, encode};

/// Payloads waiting for the coordinator's loop at most.
const INBOUND_QUEUE: usize = 16_384;

/// Orders waiting for the Zenoh thread at most.
const OUTBOUND_QUEUE: usize = 65_536;

/// The publisher slot of the shard's report (vehicles use their ring index).
const REPORT_SLOT: usize = usize::MAX;

/// The publisher slot of the shard's batch of vehicle states (`watch = "all"`).
const BATCH_SLOT: usize = usize::MAX - 1;

/// What the coordinator asks of the Zenoh thread.
#[derive(Debug)]
enum Order {
    /// Put `bytes` under `key` through slot `slot`'s publisher (declared again when
    /// the key moves: a vehicle entering another tile).
    Publish {
        slot: usize,
        key: String,
        bytes: Vec<u8>,
    },
    /// Hold exactly these subscriptions besides the fixed ones.
    Follow(Vec<String>),
}

/// Counters of a bus.
#[derive(Debug, Default)]
pub struct BusStats {
    /// Payloads published.
    pub published: AtomicU64,
    /// Their bytes.
    pub published_bytes: AtomicU64,
    /// Payloads received.
    pub received: AtomicU64,
    /// Payloads dropped on arrival because their Zenoh timestamp was not newer than the
    /// last one taken under their key: reordered on the way, or the same sample through a
    /// second subscription (a ring neighbour inside a followed tile).
    pub not_newer: AtomicU64,
    /// Payloads received and dropped because the coordinator's queue was full.
    pub dropped_inbound: AtomicU64,
    /// Messages not published because the Zenoh thread's queue was full.
    pub dropped_outbound: AtomicU64,
    /// Subscriptions declared after the start (tiles entering the horizon).
    pub subscribed: AtomicU64,
    /// Batches that ended in a cut payload (what came before the cut was taken).
    pub malformed_batches: AtomicU64,
}

/// The coordinator's side of the bus.
pub struct ZenohBus {
    /// Payloads from other shards.
    pub inbound: mpsc::Receiver<Vec<u8>>,
    outbound: mpsc::Sender<Order>,
    layout: ShardLayout,
    state_prefixes: Vec<String>,
    shard_key: String,
    /// The tiles' generation last declared.
    following: Option<u64>,
    /// Under `watch = "all"`: the batch's key and the states of this tick so far.
    batch: Option<(String, Vec<u8>)>,
    stats: Arc<BusStats>,
    thread: Option<JoinHandle<()>>,
}

impl std::fmt::Debug for ZenohBus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ZenohBus")
            .field("shard_key", &self.shard_key)
            .finish_non_exhaustive()
    }
}

impl crate::driver::udp::ShardTransport for ZenohBus {
    fn inbound(&mut self) -> &mut mpsc::Receiver<Vec<u8>> {
        &mut self.inbound
    }

    fn publish(&mut self, message: &ShardMessage) {
        ZenohBus::publish(self, message);
    }

    fn flush(&mut self) {
        ZenohBus::flush(self);
    }

    fn follow(&mut self, tiles: &TileInterest) {
        ZenohBus::follow(self, tiles);
    }

    fn close(self: Box<Self>) {
        ZenohBus::close(*self);
    }
}

impl ZenohBus {
    /// Opens shard `plan.this()`'s session (its listen and connect endpoints from
    /// `layout`) and declares its subscriptions; `vehicles` names each vehicle of the
    /// ring (network, system id) for its key. Returns once the session is open.
    ///
    /// # Errors
    /// The session cannot be opened (an endpoint that cannot be bound), or a key or a
    /// subscription is refused; each named.
    pub fn open(
        layout: &ShardLayout,
        plan: &ShardPlan,
        vehicles: &[(Option<String>, u8)],
    ) -> Result<Self, String> {
        let this = plan.this();
        let state_prefixes: Vec<String> = vehicles
            .iter()
            .map(|(network, id)| layout.state_prefix(network.as_deref(), *id))
            .collect();
        let watched = state_prefixes
            .iter()
            .enumerate()
            .filter(|(i, _)| plan.is_watched(*i));
        // Zenoh routes each sample on its own (matching its key against the session's
        // subscriptions and publishers, then queueing it): with a sample per vehicle per
        // tick, 1000 vehicles in 4 shards spent most of each shard's core in Zenoh's
        // routing. Where every shard reads every vehicle, a shard publishes its vehicles
        // of one tick as one batch and reads every other shard's batch: a sample per
        // shard per tick. A shard that reads a few keeps a subscription each, so Zenoh
        // sends it only those.
        let all = plan.watch() == Watch::All;
        let mut subscriptions: Vec<Subscription> = if all {
            let others: HashSet<String> = (0..layout.names.len())
                .filter(|&s| s != this)
                .map(|s| layout.batch_key(s))
                .collect();
            vec![Subscription {
                key: format!("ringswarm/{}/states/*", layout.swarm),
                keep: Some(Arc::new(others)),
                batches: true,
            }]
        } else {
            watched
                .map(|(_, k)| Subscription::all(layout.watched_key(k)))
                .collect()
        };
        subscriptions.push(Subscription::all(format!(
            "ringswarm/{}/shard/*",
            layout.swarm
        )));
        let alive = format!(
            "ringswarm/{}/alive/{}",
            layout.swarm,
            layout.names.get(this).map_or("", String::as_str)
        );
        let listen = layout.listen.get(this).cloned().unwrap_or_default();
        let connect = layout.connect.get(this).cloned().unwrap_or_default();
        let config = peer_config(&listen, &connect)?;
        let (thread, inbound, outbound, stats) = start_session(config, subscriptions, Some(alive))?;
        Ok(Self {
            inbound,
            outbound,
            layout: layout.clone(),
            state_prefixes,
            shard_key: layout.shard_key(this),
            following: None,
            batch: all.then(|| (layout.batch_key(this), Vec::with_capacity(64 * 256))),
            stats,
            thread: Some(thread),
        })
    }

    /// A session that only reads: every vehicle state and every shard report of the
    /// swarm `layout` names, through `connect` (a shard's listen endpoint), with no
    /// liveliness token (a viewer is no shard). For `ringswarm view --zenoh`.
    ///
    /// # Errors
    /// As [`ZenohBus::open`].
    pub fn watch(layout: &ShardLayout, connect: &[String]) -> Result<Self, String> {
        let config = peer_config(&[], connect)?;
        let subscriptions = vec![
            Subscription::all(format!("ringswarm/{}/state/**", layout.swarm)),
            Subscription {
                key: format!("ringswarm/{}/states/*", layout.swarm),
                keep: None,
                batches: true,
            },
            Subscription::all(format!("ringswarm/{}/shard/*", layout.swarm)),
        ];
        let (thread, inbound, outbound, stats) = start_session(config, subscriptions, None)?;
        Ok(Self {
            inbound,
            outbound,
            layout: layout.clone(),
            state_prefixes: Vec::new(),
            shard_key: String::new(),
            following: None,
            batch: None,
            stats,
            thread: Some(thread),
        })
    }

    /// Hands a message to the Zenoh thread (never waits: a full queue drops it). Under
    /// `watch = "all"` a vehicle's state joins the tick's batch, sent by [`Self::flush`].
    pub fn publish(&mut self, message: &ShardMessage) {
        if let (ShardMessage::Vehicle(_), Some((_, batch))) = (message, &mut self.batch) {
            crate::distributed::encode_into_batch(message, batch);
            return;
        }
        let (slot, key) = match message {
            ShardMessage::Vehicle(v) => {
                let slot = usize::from(v.vehicle);
                match self.state_prefixes.get(slot) {
                    Some(prefix) => (slot, self.layout.state_key(prefix, v.pos_enu_m)),
                    None => return,
                }
            }
            ShardMessage::Shard(_) => (REPORT_SLOT, self.shard_key.clone()),
        };
        let mut bytes = Vec::with_capacity(48);
        encode(message, &mut bytes);
        if self
            .outbound
            .try_send(Order::Publish { slot, key, bytes })
            .is_err()
        {
            self.stats.dropped_outbound.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Hands the tick's batch of vehicle states to the Zenoh thread (`watch = "all"`;
    /// nothing otherwise, or when no state was published since the last flush).
    pub fn flush(&mut self) {
        let Some((key, batch)) = &mut self.batch else {
            return;
        };
        if batch.is_empty() {
            return;
        }
        let bytes = std::mem::replace(batch, Vec::with_capacity(batch.capacity()));
        let order = Order::Publish {
            slot: BATCH_SLOT,
            key: key.clone(),
            bytes,
        };
        if self.outbound.try_send(order).is_err() {
            self.stats.dropped_outbound.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Declares the subscriptions to `tiles` when they changed since the last call
    /// (every state of the swarm when the horizon holds too many tiles).
    pub fn follow(&mut self, tiles: &TileInterest) {
        if self.following == Some(tiles.generation()) {
            return;
        }
        let keys = if tiles.everything() {
            vec![format!("ringswarm/{}/state/**", self.layout.swarm)]
        } else {
            tiles.tiles().map(|t| self.layout.tile_key(t)).collect()
        };
        // A full queue: try again on the next tick.
        if self.outbound.try_send(Order::Follow(keys)).is_ok() {
            self.following = Some(tiles.generation());
        }
    }

    /// The counters.
    pub fn stats(&self) -> &BusStats {
        &self.stats
    }

    /// Closes the session (after what was handed to it is published) and waits for
    /// its thread.
    pub fn close(mut self) {
        let (dummy, _) = mpsc::channel(1);
        drop(std::mem::replace(&mut self.outbound, dummy));
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// A peer session's configuration: its listen and connect endpoints; multicast scouting
/// only when neither is given.
///
/// # Errors
/// A setting Zenoh refuses, named.
fn peer_config(listen: &[String], connect: &[String]) -> Result<zenoh::Config, String> {
    let mut config = zenoh::Config::default();
    let json = |v: &[String]| serde_json::to_string(v).unwrap_or_else(|_| "[]".into());
    let mut settings = vec![("mode", "\"peer\"".to_owned())];
    if !listen.is_empty() {
        settings.push(("listen/endpoints", json(listen)));
    }
    if !connect.is_empty() {
        settings.push(("connect/endpoints", json(connect)));
    }
    // Each publication is stamped by the session's hybrid logical clock, for the order
    // on arrival.
    settings.push(("timestamping/enabled", "true".to_owned()));
    if !(listen.is_empty() && connect.is_empty()) {
        // Endpoints given: the shards find each other there, not by multicast.
        settings.push(("scouting/multicast/enabled", "false".to_owned()));
    }
    for (key, value) in settings {
        config
            .insert_json5(key, &value)
            .map_err(|e| format!("zenoh config {key} = {value}: {e}"))?;
    }
    Ok(config)
}

/// What a running session hands back: its thread, the payloads it receives, where to
/// hand it `(key, payload)` to publish, and its counters.
type Session = (
    JoinHandle<()>,
    mpsc::Receiver<Vec<u8>>,
    mpsc::Sender<Order>,
    Arc<BusStats>,
);

/// Opens a session with `config` on a thread of its own, subscribes to `subscriptions`,
/// declares the liveliness token `alive` if any, and publishes what it is handed until
/// the sender is dropped. Returns once the session is open.
///
/// # Errors
/// The session, a subscription or the token refused, named.
fn start_session(
    config: zenoh::Config,
    subscriptions: Vec<Subscription>,
    alive: Option<String>,
) -> Result<Session, String> {
    let (in_tx, inbound) = mpsc::channel::<Vec<u8>>(INBOUND_QUEUE);
    let (outbound, out_rx) = mpsc::channel::<Order>(OUTBOUND_QUEUE);
    let (ready_tx, ready_rx) = std::sync::mpsc::channel::<Result<(), String>>();
    let stats = Arc::new(BusStats::default());
    let thread_stats = Arc::clone(&stats);
    let thread = std::thread::Builder::new()
        .name("zenoh-bus".into())
        .spawn(move || {
            let runtime = match tokio::runtime::Builder::new_multi_thread()
                .worker_threads(1)
                .enable_all()
                .build()
            {
                Ok(r) => r,
                Err(e) => {
                    let _ = ready_tx.send(Err(format!("start the Zenoh thread's runtime: {e}")));
                    return;
                }
            };
            runtime.block_on(serve_session(
                config,
                subscriptions,
                alive,
                in_tx,
                out_rx,
                ready_tx,
                thread_stats,
            ));
        })
        .map_err(|e| format!("start the Zenoh thread: {e}"))?;
    match ready_rx.recv() {
        Ok(Ok(())) => {}
        Ok(Err(e)) => {
            let _ = thread.join();
            return Err(e);
        }
        Err(_) => return Err("the Zenoh thread stopped before its session opened".into()),
    }
    Ok((thread, inbound, outbound, stats))
}
/// The Zenoh thread's work: opens the session, subscribes and declares the liveliness
/// token (`ready` hears whether that worked), then carries out orders until the sender
/// is dropped, and closes everything.
async fn serve_session(
    config: zenoh::Config,
    subscriptions: Vec<Subscription>,
    alive: Option<String>,
    in_tx: mpsc::Sender<Vec<u8>>,
    mut orders: mpsc::Receiver<Order>,
    ready: std::sync::mpsc::Sender<Result<(), String>>,
    stats: Arc<BusStats>,
) {
    let session = match zenoh::open(config).await {
        Ok(s) => s,
        Err(e) => {
            let _ = ready.send(Err(format!("open the Zenoh session: {e}")));
            return;
        }
    };
    let newest: Newest = Arc::default();
    let mut subscribers = Vec::new();
    for sub in &subscriptions {
        match subscribe(&session, sub, &in_tx, &stats, &newest).await {
            Ok(s) => subscribers.push(s),
            Err(e) => {
                let _ = ready.send(Err(e));
                return;
            }
        }
    }
    let token = match &alive {
        Some(alive) => match session.liveliness().declare_token(alive.as_str()).await {
            Ok(t) => Some(t),
            Err(e) => {
                let _ = ready.send(Err(format!("declare {alive}: {e}")));
                return;
            }
        },
        None => None,
    };
    let _ = ready.send(Ok(()));
    let mut served = Served {
        session: &session,
        in_tx: &in_tx,
        stats: &stats,
        newest: &newest,
        publishers: HashMap::new(),
        followed: HashMap::new(),
    };
    while let Some(order) = orders.recv().await {
        match order {
            Order::Publish { slot, key, bytes } => served.publish(slot, key, bytes).await,
            Order::Follow(keys) => served.follow(keys).await,
        }
    }
    let publishers = std::mem::take(&mut served.publishers);
    drop(served);
    drop(token);
    drop(subscribers);
    for (_, (_, p)) in publishers {
        let _ = p.undeclare().await;
    }
    let _ = session.close().await;
}

/// The publishers and the followed subscriptions of an open session.
struct Served<'a> {
    session: &'a zenoh::Session,
    in_tx: &'a mpsc::Sender<Vec<u8>>,
    stats: &'a Arc<BusStats>,
    newest: &'a Newest,
    /// Slot → its key and publisher.
    publishers: HashMap<usize, (String, zenoh::pubsub::Publisher<'static>)>,
    followed: HashMap<String, zenoh::pubsub::Subscriber<()>>,
}

impl Served<'_> {
    /// Puts `bytes` under `key` through slot `slot`'s publisher, declared again when the
    /// slot's key moved.
    async fn publish(&mut self, slot: usize, key: String, bytes: Vec<u8>) {
        if self.publishers.get(&slot).is_none_or(|(k, _)| *k != key) {
            if let Some((_, old)) = self.publishers.remove(&slot) {
                let _ = old.undeclare().await;
            }
            match self.session.declare_publisher(key.clone()).await {
                Ok(p) => {
                    self.publishers.insert(slot, (key.clone(), p));
                }
                Err(e) => {
                    tracing::warn!(key, error = %e, "zenoh publisher refused");
                    return;
                }
            }
        }
        if let Some((_, publisher)) = self.publishers.get(&slot) {
            let n = bytes.len() as u64;
            if publisher.put(bytes).await.is_ok() {
                self.stats.published.fetch_add(1, Ordering::Relaxed);
                self.stats.published_bytes.fetch_add(n, Ordering::Relaxed);
            }
        }
    }

    /// Follows exactly `keys`: subscriptions no longer named are dropped, new ones made.
    async fn follow(&mut self, keys: Vec<String>) {
        self.followed.retain(|k, _| keys.contains(k));
        for key in keys {
            if self.followed.contains_key(&key) {
                continue;
            }
            let sub = Subscription::all(key.clone());
            match subscribe(self.session, &sub, self.in_tx, self.stats, self.newest).await {
                Ok(s) => {
                    self.stats.subscribed.fetch_add(1, Ordering::Relaxed);
                    self.followed.insert(key, s);
                }
                Err(e) => tracing::warn!(error = %e, "zenoh subscription refused"),
            }
        }
    }
}

/// The newest Zenoh timestamp taken under each ordering key ([`ordering_key`]), shared
/// by every subscription of a session.
type Newest = Arc<std::sync::Mutex<HashMap<String, zenoh::time::Timestamp>>>;

/// What payloads are ordered under: a vehicle state's key without its tile (the vehicle
/// moves from tile to tile), any other key whole.
fn ordering_key(key: &str) -> &str {
    if key.contains("/state/") {
        key.rsplit_once('/').map_or(key, |(prefix, _)| prefix)
    } else {
        key
    }
}

/// Whether a sample stamped `stamp` under `key` is newer than the last one taken there
/// (and takes it). A sample without a timestamp (a publisher without timestamping) passes.
fn newer(newest: &Newest, key: &str, stamp: Option<&zenoh::time::Timestamp>) -> bool {
    let Some(stamp) = stamp else {
        return true;
    };
    let Ok(mut map) = newest.lock() else {
        return true;
    };
    let key = ordering_key(key);
    match map.get_mut(key) {
        Some(last) if *last >= *stamp => false,
        Some(last) => {
            *last = *stamp;
            true
        }
        None => {
            map.insert(key.to_owned(), *stamp);
            true
        }
    }
}

/// A key expression to subscribe to, the ordering keys ([`ordering_key`]) of the
/// samples to keep from it (`None`: every one), and whether its samples are batches of
/// payloads ([`crate::distributed::split_batch`]) rather than one payload each.
struct Subscription {
    key: String,
    keep: Option<Arc<HashSet<String>>>,
    batches: bool,
}

impl Subscription {
    /// Every sample under `key`, one payload each.
    fn all(key: String) -> Self {
        Self {
            key,
            keep: None,
            batches: false,
        }
    }
}

/// Whether a sample under `key` is one to keep (`keep`: the ordering keys kept, `None`:
/// every one).
fn keeps(keep: Option<&HashSet<String>>, key: &str) -> bool {
    keep.is_none_or(|keep| keep.contains(ordering_key(key)))
}

/// Declares a subscriber to `sub`'s key whose samples it keeps go to `tx` when newer
/// than the last taken under their key (dropped and counted otherwise, and when `tx` is
/// full). Samples it does not keep (the shard's own vehicles under a wildcard) are
/// dropped uncounted.
///
/// # Errors
/// Zenoh refuses the key or the declaration, named.
async fn subscribe(
    session: &zenoh::Session,
    sub: &Subscription,
    tx: &mpsc::Sender<Vec<u8>>,
    stats: &Arc<BusStats>,
    newest: &Newest,
) -> Result<zenoh::pubsub::Subscriber<()>, String> {
    let tx = tx.clone();
    let stats = Arc::clone(stats);
    let newest = Arc::clone(newest);
    let keep = sub.keep.clone();
    let batches = sub.batches;
    let key = sub.key.as_str();
    session
        .declare_subscriber(key)
        .callback(move |sample| {
            if !keeps(keep.as_deref(), sample.key_expr().as_str()) {
                return;
            }
            stats.received.fetch_add(1, Ordering::Relaxed);
            if !newer(&newest, sample.key_expr().as_str(), sample.timestamp()) {
                stats.not_newer.fetch_add(1, Ordering::Relaxed);
                return;
            }
            let bytes = sample.payload().to_bytes();
            if !batches {
                if tx.try_send(bytes.into_owned()).is_err() {
                    stats.dropped_inbound.fetch_add(1, Ordering::Relaxed);
                }
                return;
            }
            for payload in crate::distributed::split_batch(&bytes) {
                let Ok(payload) = payload else {
                    stats.malformed_batches.fetch_add(1, Ordering::Relaxed);
                    break;
                };
                if tx.try_send(payload.to_vec()).is_err() {
                    stats.dropped_inbound.fetch_add(1, Ordering::Relaxed);
                }
            }
        })
        .await
        .map_err(|e| format!("subscribe to {key}: {e}"))
}

#[cfg(test)]
mod tests {
    use std::time::{Duration, Instant};

    use nalgebra::Vector2;

    use super::*;
    use crate::consensus::RingDigraph;
    use crate::distributed::{MemberPhase, VehicleReport, Watch, decode};

    fn free_port() -> u16 {
        std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .map(|a| a.port())
            .expect("a free port")
    }

    fn report(vehicle: u16, x: f32, y: f32) -> ShardMessage {
        ShardMessage::Vehicle(VehicleReport {
            vehicle,
            sent_us: 1,
            age_us: 0,
            phase: MemberPhase::Flying,
            landed: false,
            pos_enu_m: [x, y, 50.0],
            vel_enu_mps: [0.0; 3],
            unseen_mps: 0.0,
        })
    }

    /// The vehicles whose states reach `bus` while `publish` runs every 20 ms: until
    /// `expected` are all in (at most 20 s), then 0.3 s more for any other.
    fn heard(bus: &mut ZenohBus, expected: &[u16], mut publish: impl FnMut()) -> Vec<u16> {
        let mut seen = Vec::new();
        let deadline = Instant::now() + Duration::from_secs(20);
        let mut end: Option<Instant> = None;
        while end.is_none_or(|e| Instant::now() < e) && Instant::now() < deadline {
            publish();
            std::thread::sleep(Duration::from_millis(20));
            while let Ok(bytes) = bus.inbound.try_recv() {
                if let Ok(ShardMessage::Vehicle(v)) = decode(&bytes) {
                    seen.push(v.vehicle);
                }
            }
            if end.is_none() && expected.iter().all(|e| seen.contains(e)) {
                end = Some(Instant::now() + Duration::from_millis(300));
            }
        }
        seen.sort_unstable();
        seen.dedup();
        seen
    }

    /// Two shards over real Zenoh on loopback: shard b reads its ring neighbour in any
    /// tile, and the other vehicles only in the tiles it follows, as they move.
    #[test]
    fn a_shard_reads_its_neighbour_anywhere_and_the_others_by_tile() {
        let port = free_port();
        let layout = ShardLayout {
            swarm: format!("tiles-{port}"),
            names: ["a", "b", "c"].map(str::to_owned).to_vec(),
            owner: vec![0, 0, 1, 1, 2, 2],
            listen: vec![vec![format!("tcp/127.0.0.1:{port}")], vec![], vec![]],
            connect: vec![vec![], vec![format!("tcp/127.0.0.1:{port}")], vec![]],
            watch: Watch::Horizon,
            tile_m: 100.0,
            start_lead: Duration::from_millis(200),
        };
        let ring = RingDigraph::for_agents(6, 3.0).expect("ring");
        let plan = |s| ShardPlan::new(s, 3, layout.owner.clone(), &ring, Watch::Horizon);
        let vehicles: Vec<(Option<String>, u8)> = (1..=6).map(|id| (None, id)).collect();
        let mut a = ZenohBus::open(&layout, &plan(0).expect("plan a"), &vehicles).expect("a");
        let mut b = ZenohBus::open(&layout, &plan(1).expect("plan b"), &vehicles).expect("b");
        // b follows the tiles about (50, 50) with a 60 m horizon: tiles (−1..=1)².
        let mut tiles = TileInterest::new(100.0);
        tiles.update([Vector2::new(50.0, 50.0)], 60.0);
        b.follow(&tiles);
        // Vehicle 1 (index 1) is b's ring in-neighbour: read at (950, 950). Vehicle 0 is
        // in tile (0, 0): read. Vehicles 4 and 5 (shard c's, published here for it) are
        // in tile (9, 9) and (1, 1).
        let publish = |a: &mut ZenohBus, v4: (f32, f32)| {
            a.publish(&report(0, 10.0, 10.0));
            a.publish(&report(1, 950.0, 950.0));
            a.publish(&report(4, v4.0, v4.1));
            a.publish(&report(5, 150.0, 150.0));
            a.flush();
        };
        let seen = heard(&mut b, &[0, 1, 5], || publish(&mut a, (950.0, 950.0)));
        assert_eq!(seen, vec![0, 1, 5]);
        // Vehicle 4 flies into tile (−1, 0): its publisher moves to that key, and b reads it.
        let seen = heard(&mut b, &[4], || publish(&mut a, (-50.0, 50.0)));
        assert_eq!(seen, vec![0, 1, 4, 5]);
        // Vehicle 1 in a followed tile comes through two subscriptions: each of its
        // samples is taken once, by its Zenoh timestamp.
        let before = b.stats().not_newer.load(Ordering::Relaxed);
        let mut ones = 0;
        for _ in 0..20 {
            a.publish(&report(1, 20.0, 20.0));
            std::thread::sleep(Duration::from_millis(20));
            while let Ok(bytes) = b.inbound.try_recv() {
                ones += usize::from(
                    matches!(decode(&bytes), Ok(ShardMessage::Vehicle(v)) if v.vehicle == 1),
                );
            }
        }
        std::thread::sleep(Duration::from_millis(300));
        while let Ok(bytes) = b.inbound.try_recv() {
            ones += usize::from(
                matches!(decode(&bytes), Ok(ShardMessage::Vehicle(v)) if v.vehicle == 1),
            );
        }
        let doubles = b.stats().not_newer.load(Ordering::Relaxed) - before;
        assert!(
            ones <= 20 && doubles >= 10,
            "{ones} taken, {doubles} dropped"
        );
        // b's vehicles move away: the tiles about (1050, 1050) hold only vehicle 1's.
        tiles.update([Vector2::new(1050.0, 1050.0)], 60.0);
        b.follow(&tiles);
        // (What was in flight when the subscriptions went is let through first.)
        std::thread::sleep(Duration::from_millis(500));
        while b.inbound.try_recv().is_ok() {}
        let seen = heard(&mut b, &[1], || publish(&mut a, (-50.0, 50.0)));
        assert_eq!(seen, vec![1]);
        assert_eq!(
            ordering_key("ringswarm/s/state/-/3/e1n2"),
            "ringswarm/s/state/-/3"
        );
        assert_eq!(ordering_key("ringswarm/s/shard/a"), "ringswarm/s/shard/a");
        a.close();
        b.close();
    }

    /// Under `watch = "all"` each shard publishes its vehicles of a tick as one batch,
    /// and a shard reads every other shard's batch, not its own.
    #[test]
    fn a_shard_watching_all_reads_every_other_shards_batch_and_not_its_own() {
        let port = free_port();
        let layout = ShardLayout {
            swarm: format!("all-{port}"),
            names: ["a", "b", "c"].map(str::to_owned).to_vec(),
            owner: vec![0, 0, 1, 1, 2, 2],
            listen: vec![vec![format!("tcp/127.0.0.1:{port}")], vec![], vec![]],
            connect: vec![
                vec![],
                vec![format!("tcp/127.0.0.1:{port}")],
                vec![format!("tcp/127.0.0.1:{port}")],
            ],
            watch: Watch::All,
            tile_m: 100.0,
            start_lead: Duration::from_millis(200),
        };
        let ring = RingDigraph::for_agents(6, 3.0).expect("ring");
        let plan = |s| ShardPlan::new(s, 3, layout.owner.clone(), &ring, Watch::All);
        let vehicles: Vec<(Option<String>, u8)> = (1..=6).map(|id| (None, id)).collect();
        let mut a = ZenohBus::open(&layout, &plan(0).expect("plan a"), &vehicles).expect("a");
        let mut b = ZenohBus::open(&layout, &plan(1).expect("plan b"), &vehicles).expect("b");
        let mut c = ZenohBus::open(&layout, &plan(2).expect("plan c"), &vehicles).expect("c");
        // Each shard publishes its own two vehicles, far apart, then flushes its batch:
        // b hears a's and c's, and not its own.
        let seen = heard(&mut b, &[0, 1, 4, 5], || {
            a.publish(&report(0, 10.0, 10.0));
            a.publish(&report(1, 950.0, -950.0));
            a.flush();
            c.publish(&report(4, -5000.0, 20.0));
            c.publish(&report(5, 150.0, 150.0));
            c.flush();
        });
        assert_eq!(seen, vec![0, 1, 4, 5]);
        let published = b.stats().published.load(Ordering::Relaxed);
        let mut seen = Vec::new();
        for _ in 0..10 {
            b.publish(&report(2, 10.0, 14.0));
            b.publish(&report(3, 10.0, 18.0));
            b.flush();
            std::thread::sleep(Duration::from_millis(30));
        }
        std::thread::sleep(Duration::from_millis(300));
        while let Ok(bytes) = b.inbound.try_recv() {
            if let Ok(ShardMessage::Vehicle(v)) = decode(&bytes) {
                seen.push(v.vehicle);
            }
        }
        seen.retain(|v| [2, 3].contains(v));
        assert!(seen.is_empty(), "b heard its own {seen:?}");
        // Each flush was one publication, and a flush with nothing gathered sends none.
        b.flush();
        std::thread::sleep(Duration::from_millis(100));
        assert_eq!(b.stats().published.load(Ordering::Relaxed) - published, 10);
        assert_eq!(b.stats().malformed_batches.load(Ordering::Relaxed), 0);
        let keep: HashSet<String> = ["ringswarm/s/states/a".to_owned()].into();
        assert!(keeps(Some(&keep), "ringswarm/s/states/a"));
        assert!(!keeps(Some(&keep), "ringswarm/s/states/b"));
        assert_eq!(ordering_key("ringswarm/s/states/a"), "ringswarm/s/states/a");
        a.close();
        b.close();
        c.close();
    }
}
