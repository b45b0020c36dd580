//! The tokio UDP driver of the swarm: the coordinator's sockets (one per vehicle in PX4
//! SITL's layout, one per MAVLink network otherwise), a receive task per socket feeding
//! one channel, and a single task that owns the swarm machine and sleeps until its next
//! deadline. Which vehicle a datagram is for, and where a vehicle's datagrams go, is the
//! [`Router`]'s business.
//!
//! Real PX4 or `ringswarm sitl` vehicle `i` listens on `14580+i` and answers whoever
//! talks to it; on a network it sends to the network's socket from a port of its own.

use std::io;
use std::net::SocketAddr;
use std::ops::Range;
use std::sync::Arc;

use ringswarm_wire::time::SimTime;
use tokio::net::UdpSocket;
use tokio::sync::{mpsc, watch};
use tokio::task::JoinSet;
use tokio::time::Instant;

use super::listening::{Listening, STALL};
use super::serial::{SerialLine, SerialWriter};
use super::{Intake, Observer};
use crate::link::router::{Router, SERIAL_PEER};
use crate::swarm::Swarm;

/// One coordinator socket: UDP, or a serial port to one vehicle.
pub enum Port {
    /// A bound UDP socket.
    Udp(UdpSocket),
    /// An open serial port.
    Serial(SerialLine),
}

impl From<UdpSocket> for Port {
    fn from(socket: UdpSocket) -> Self {
        Port::Udp(socket)
    }
}

/// A running coordinator socket.
enum Running {
    Udp(Arc<UdpSocket>),
    Serial(SerialWriter),
}

/// What carries a shard's messages to the other shards (Zenoh, `zenoh_bus`).
pub trait ShardTransport {
    /// The payloads from other shards.
    fn inbound(&mut self) -> &mut mpsc::Receiver<Vec<u8>>;
    /// Sends one message to the shards that read it (never waits).
    fn publish(&mut self, message: &crate::distributed::ShardMessage);
    /// Sends what this tick's [`Self::publish`] calls left gathered (a batch), if any.
    fn flush(&mut self) {}
    /// Reads the tiles the swarm's horizon holds (`watch = "horizon"`), from now on.
    fn follow(&mut self, tiles: &crate::distributed::TileInterest);
    /// Sends what is queued and closes.
    fn close(self: Box<Self>);
}

/// What the owner of a running swarm asks of it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DriverCommand {
    /// Keep flying.
    #[default]
    Fly,
    /// Land every vehicle (Ctrl-C); the driver returns once they are all disarmed.
    Land,
    /// Return at once (a second Ctrl-C, or a test that is done).
    Stop,
}

/// Largest datagram read.
const MAX_DATAGRAM: usize = 2048;

/// Batches received and not yet handled by the swarm, over all sockets.
const RECEIVE_QUEUE: usize = 1024;

/// At most this many datagrams per batch.
const BATCH: usize = 64;

/// At most this many datagrams sent per turn of the loop (about a millisecond of sends).
const SEND_BUDGET: usize = 500;

/// Datagrams read from one socket in one go: one allocation and one hand-over for up to
/// [`BATCH`] of them, instead of one each.
struct Batch {
    socket: usize,
    /// The read stopped at [`BATCH`]: more was waiting.
    full: bool,
    datagrams: Vec<(SocketAddr, Range<usize>)>,
    bytes: Vec<u8>,
}

/// Waits for a datagram on `socket`, then takes whatever else is already there.
///
/// # Errors
/// A receive error other than an ICMP "port unreachable" for an earlier send (a vehicle
/// not listening yet), which is not ours.
async fn receive_batch(socket_index: usize, socket: &UdpSocket) -> io::Result<Batch> {
    let mut buf = [0u8; MAX_DATAGRAM];
    let mut batch = Batch {
        socket: socket_index,
        full: false,
        datagrams: Vec::new(),
        bytes: Vec::new(),
    };
    let keep = |batch: &mut Batch, n: usize, from: SocketAddr, buf: &[u8]| {
        let start = batch.bytes.len();
        batch.bytes.extend_from_slice(&buf[..n]);
        batch.datagrams.push((from, start..start + n));
    };
    loop {
        match socket.recv_from(&mut buf).await {
            Ok((n, from)) => {
                keep(&mut batch, n, from, &buf);
                break;
            }
            Err(e) if e.kind() == io::ErrorKind::ConnectionRefused => continue,
            Err(e) => return Err(e),
        }
    }
    while batch.datagrams.len() < BATCH {
        match socket.try_recv_from(&mut buf) {
            Ok((n, from)) => keep(&mut batch, n, from, &buf),
            Err(e) if e.kind() == io::ErrorKind::ConnectionRefused => continue,
            Err(_) => break, // WouldBlock: nothing more for now
        }
    }
    batch.full = batch.datagrams.len() == BATCH;
    Ok(batch)
}

/// Whether a datagram waits on `socket`, asked of the kernel (tokio's own readiness may not
/// know yet after a stall of the runtime).
fn has_waiting(socket: &UdpSocket) -> bool {
    let mut byte = [std::mem::MaybeUninit::<u8>::uninit(); 1];
    // Non-blocking (tokio's sockets are): an empty socket answers WouldBlock; a longer
    // datagram answers its truncated peek, which is enough.
    socket2::SockRef::from(socket).peek(&mut byte).is_ok()
}

/// Starts serial port `socket`'s threads: its frames reach the swarm as datagrams from
/// [`SERIAL_PEER`], one batch per read, until the swarm's loop has ended.
///
/// # Errors
/// The port's threads could not be started.
fn serial_reader(
    socket: usize,
    line: SerialLine,
    tx: mpsc::Sender<Batch>,
) -> io::Result<SerialWriter> {
    line.spawn(move |frames| {
        if frames.is_empty() {
            return !tx.is_closed();
        }
        let mut batch = Batch {
            socket,
            full: false,
            datagrams: Vec::with_capacity(frames.len()),
            bytes: Vec::new(),
        };
        for frame in frames.drain(..) {
            let start = batch.bytes.len();
            batch.bytes.extend_from_slice(&frame);
            batch
                .datagrams
                .push((SERIAL_PEER, start..start + frame.len()));
        }
        tx.blocking_send(batch).is_ok()
    })
}

/// Runs `swarm` over `sockets` (bound or opened as `router`'s plan says) until the swarm has
/// landed every vehicle, or `commands` says [`DriverCommand::Stop`]; returns the swarm
/// and the observer. The observer sees every datagram (a network datagram once per
/// vehicle frame in it) and the swarm after every change, with the time since start.
/// A swarm that is one shard of several gets `shards`: their payloads go to the swarm,
/// its messages to them, and its clock is set to the Unix time at start.
///
/// # Errors
/// A receive task's error (send errors are logged: a vehicle may be unreachable for a
/// while).
pub async fn run_swarm<O: Observer>(
    mut swarm: Swarm,
    sockets: Vec<Port>,
    mut router: Router,
    mut commands: watch::Receiver<DriverCommand>,
    mut observer: O,
    mut shards: Option<&mut (dyn ShardTransport + Send + 'static)>,
) -> io::Result<(Swarm, O)> {
    let start = Instant::now();
    swarm.set_swarm_epoch_us(
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_micros()).unwrap_or(u64::MAX)),
    );
    let now = || SimTime::from_micros(start.elapsed().as_micros() as u64);
    let (tx, mut rx) = mpsc::channel::<Batch>(RECEIVE_QUEUE);
    let mut receivers = JoinSet::new();
    let mut running = start_receivers(sockets, &tx, &mut receivers)?;
    let mut pieces = Vec::new();
    let mut unsent = vec![0u64; swarm.vehicle_count()];
    let mut listening = Listening::new(running.len());
    // Place assignments solved off the control loop (a thousand vehicles take ~0.2 s).
    let mut assignments = JoinSet::new();
    drop(tx);
    loop {
        let deadline = next_wake(&swarm, start);
        let mut late = std::time::Duration::ZERO;
        tokio::select! {
            // The control schedule first: a burst of datagrams (a thousand vehicles'
            // default streams at start) must not hold a tick back.
            biased;
            changed = commands.changed() => {
                let command = if changed.is_err() { DriverCommand::Stop } else { *commands.borrow() };
                match command {
                    DriverCommand::Fly => {}
                    DriverCommand::Land => swarm.land(now()),
                    DriverCommand::Stop => break,
                }
            }
            _ = tokio::time::sleep_until(deadline) => {
                late = Instant::now().saturating_duration_since(deadline);
                // Judged with the lag as it stands: after a stall, the frames that came
                // meanwhile are still unread.
                let t = now();
                swarm.set_listen_lag(t, listening.lag(t));
                swarm.handle_timeout(t);
            }
            Some(solved) = assignments.join_next(), if !assignments.is_empty() => {
                match solved {
                    Ok((id, result)) => swarm.finish_assignment(now(), id, result),
                    Err(e) => tracing::warn!(error = %e, "the place assignment's thread failed"),
                }
            }
            payload = async {
                match shards.as_mut() {
                    Some(s) => s.inbound().recv().await,
                    None => std::future::pending().await,
                }
            } => match payload {
                Some(bytes) => match crate::distributed::decode(&bytes) {
                    Ok(message) => swarm.handle_shard_message(now(), &message),
                    Err(e) => tracing::warn!(error = %e, "payload from another shard refused"),
                },
                None => shards = None,
            },
            received = rx.recv() => match received {
                Some(first) => {
                    let mut intake = Intake { swarm: &mut swarm, router: &mut router, pieces: &mut pieces };
                    take_batches(first, &mut rx, &mut intake, &mut listening, deadline, now(), &mut observer);
                }
                None => break,
            },
        }
        // How far behind its sockets the loop is: silence is judged up to there.
        let t = now();
        settle_listening(&mut listening, t, rx.is_empty(), late, &running);
        swarm.set_listen_lag(t, listening.lag(t));
        send_round(
            &mut swarm,
            &router,
            &mut running,
            &mut observer,
            &mut unsent,
            now,
        )
        .await;
        if let Some(s) = shards.as_mut() {
            publish_to_shards(&mut swarm, &mut **s);
        }
        if let Some(job) = swarm.take_assignment_job() {
            assignments.spawn_blocking(move || (job.id, job.solve()));
        }
        observer.swarm(&swarm, now());
        if swarm.is_finished() {
            break;
        }
    }
    report_left_over(&unsent, &running);
    receivers.abort_all();
    while let Some(joined) = receivers.join_next().await {
        if let Ok(Err(err)) = joined {
            return Err(err);
        }
    }
    Ok((swarm, observer))
}

/// A receive task for every UDP socket (batches into `tx`), a reader thread for every
/// serial line; what the loop sends through, in socket order.
///
/// # Errors
/// A serial line whose reader cannot be started.
fn start_receivers(
    sockets: Vec<Port>,
    tx: &mpsc::Sender<Batch>,
    receivers: &mut JoinSet<io::Result<()>>,
) -> io::Result<Vec<Running>> {
    let mut running = Vec::with_capacity(sockets.len());
    for (s, port) in sockets.into_iter().enumerate() {
        let socket = match port {
            Port::Udp(socket) => Arc::new(socket),
            Port::Serial(line) => {
                running.push(Running::Serial(serial_reader(s, line, tx.clone())?));
                continue;
            }
        };
        running.push(Running::Udp(Arc::clone(&socket)));
        let tx = tx.clone();
        receivers.spawn(async move {
            loop {
                let batch = receive_batch(s, &socket).await?;
                let full = batch.full;
                if tx.send(batch).await.is_err() {
                    return Ok::<(), io::Error>(());
                }
                if full {
                    // More is likely waiting. Without a yield, this task would go on
                    // reading until tokio's budget (128 awaits: some four thousand
                    // datagrams, milliseconds) runs out while the swarm waits.
                    tokio::task::yield_now().await;
                }
            }
        });
    }
    Ok(running)
}
/// When the loop must next wake: at once while output is left over from the last round
/// (after a tick that fell due meanwhile), else at the swarm's timers rounded up to the
/// next whole millisecond (as the lockstep driver steps): a thousand links with deadlines
/// scattered over a control period wake the swarm at most once per millisecond, not once
/// per link.
fn next_wake(swarm: &Swarm, start: Instant) -> Instant {
    if swarm.has_output() {
        return Instant::now();
    }
    let due_us = swarm.poll_timeout().as_micros().div_ceil(1000) * 1000;
    start + std::time::Duration::from_micros(due_us)
}

/// What has arrived, from `first` on, into the swarm at `t`; no further than `deadline`,
/// which the loop then serves before the rest.
fn take_batches<O: Observer>(
    first: Batch,
    rx: &mut mpsc::Receiver<Batch>,
    intake: &mut Intake<'_>,
    listening: &mut Listening,
    deadline: Instant,
    t: SimTime,
    observer: &mut O,
) {
    let mut next = Some(first);
    while let Some(batch) = next.take() {
        for (from, datagram) in &batch.datagrams {
            let bytes = &batch.bytes[datagram.clone()];
            intake.deliver(batch.socket, *from, bytes, t, observer);
        }
        listening.batch(batch.socket, batch.full);
        if Instant::now() >= deadline {
            break;
        }
        next = rx.try_recv().ok();
    }
}

/// Whether the loop has caught up with its sockets at `t` (nothing queued, and after a
/// wake-up more than [`STALL`] late, nothing waiting in a socket); the end of a stall is
/// logged.
fn settle_listening(
    listening: &mut Listening,
    t: SimTime,
    queue_empty: bool,
    late: std::time::Duration,
    running: &[Running],
) {
    let sockets_waiting = late > STALL
        && running
            .iter()
            .any(|s| matches!(s, Running::Udp(s) if has_waiting(s)));
    if let Some(ended) = listening.settle(t, queue_empty, sockets_waiting) {
        tracing::warn!(
            behind_ms = ended.max_lag.as_millis() as u64,
            "the coordinator fell behind its sockets (its host stalled or was overloaded); \
             vehicles' silence during it was not counted against them"
        );
    }
}

/// The swarm's messages for the other shards, and which tiles of them it follows.
fn publish_to_shards(swarm: &mut Swarm, shards: &mut (dyn ShardTransport + Send + 'static)) {
    while let Some(message) = swarm.poll_shard_message() {
        shards.publish(&message);
    }
    shards.flush();
    if let Some(tiles) = swarm.shard_tiles() {
        shards.follow(tiles);
    }
}

/// One round of sends, at most [`SEND_BUDGET`] datagrams: a thousand vehicles discovered
/// together queue some twenty thousand (heartbeats, stream settings), tens of
/// milliseconds of system calls that must not hold the next control tick back.
async fn send_round<O: Observer>(
    swarm: &mut Swarm,
    router: &Router,
    running: &mut [Running],
    observer: &mut O,
    unsent: &mut [u64],
    now: impl Fn() -> SimTime,
) {
    for _ in 0..SEND_BUDGET {
        let Some((i, bytes)) = swarm.poll_transmit() else {
            break;
        };
        observer.datagram(now(), i, true, &bytes);
        match router.destination(i) {
            Some((socket, to)) => match running.get_mut(socket) {
                Some(Running::Udp(socket)) => {
                    if let Err(err) = socket.send_to(&bytes, to).await {
                        tracing::warn!(vehicle = i.get(), error = %err, "send failed");
                    }
                }
                Some(Running::Serial(line)) => line.send(&bytes),
                None => unsent[i.get()] += 1,
            },
            // A network vehicle not heard from yet: nowhere to send.
            None => unsent[i.get()] += 1,
        }
        swarm.recycle(i, bytes);
    }
}

/// Says what could not be sent: datagrams for vehicles whose address never came, frames
/// a serial line dropped or failed to write.
fn report_left_over(unsent: &[u64], running: &[Running]) {
    for (i, n) in unsent.iter().enumerate().filter(|(_, n)| **n > 0) {
        tracing::info!(
            vehicle = i,
            datagrams = n,
            "not sent: the vehicle's address was not known yet"
        );
    }
    for (s, port) in running.iter().enumerate() {
        if let Running::Serial(line) = port
            && line.dropped() + line.failed() > 0
        {
            tracing::info!(
                socket = s,
                dropped = line.dropped(),
                failed = line.failed(),
                "frames not written to the serial port"
            );
        }
    }
}
