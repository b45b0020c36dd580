//! Real time over UDP: `ringswarm sitl --config F` and `ringswarm fly --config F` as two
//! processes on loopback, a ring of N ideal quadrotors on MAVLink networks of 250, 50 Hz
//! control with LOCAL_POSITION_NED and ATTITUDE_QUATERNION at 50 Hz.
//!
//! `cargo bench --bench realtime -- shards S N` flies the ring of N split into S shards
//! (`fly --shard`, each reading its ring neighbours from the others over Zenoh on
//! loopback) against one emulator, and prints one row per shard: CPU, late ticks, the
//! age of its own vehicles' states and of the other shards' ones it flies on.
//!
//! `cargo bench --bench realtime [-- [dense] [equal] N ...]` (default 64 250 500 1000;
//! `dense`: the ring packed so that the safety filter's constraints bind; `equal`: the
//! emulator at the coordinator's priority rather than nice 10; `quarter`: the filter's
//! braking share 0.25 rather than 0.5; `rt`: the coordinator's
//! control loop at real-time priority 10, `fly --realtime-priority 10`, which needs the
//! right to) prints, per N: CPU
//! per vehicle-tick of each process over a steady window, control ticks started over half
//! a period late, the age of the flown positions (p50/p99; `summary.json`), the setpoint
//! rate the emulator took (its fleet line), the kernel's UDP drops, and what the safety
//! filter did (`summary.json`: the share of ticks with a bound constraint, the closest
//! two vehicles came); beside them the
//! machine's floor, one datagram sent and received on loopback, measured first.

use std::io::{BufRead, BufReader};
use std::net::UdpSocket;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

mod common;
use common::{dense_ring, ring};

/// Seconds before the steady window: handshake and the first transients.
const WARM_UP: Duration = Duration::from_secs(10);
/// The steady window.
const WINDOW: Duration = Duration::from_secs(20);
/// Control rate (Hz).
const RATE_HZ: f64 = 50.0;
/// How one case is run (the words `dense`, `equal`, `rt`).
struct Case {
    /// The ring packed so that the filter binds.
    dense: bool,
    /// The emulator's niceness.
    niceness: i32,
    /// The coordinator's real-time priority (`fly --realtime-priority`), if any.
    priority: Option<u8>,
    /// The filter's braking share (`[safety] braking_share`; the word `quarter`: 0.25),
    /// when not the default.
    braking_share: Option<f64>,
}

/// The coordinator's real-time priority with the word `rt`.
const COORDINATOR_PRIORITY: u8 = 10;
/// The emulator's niceness (the word `equal`: 0, the coordinator's).
const EMULATOR_NICENESS: i32 = 10;
/// Datagrams per vehicle-tick at this rate: one setpoint, two telemetry messages.
const DATAGRAMS_PER_TICK: f64 = 3.0;

fn main() {
    if let Some(at) = std::env::args().position(|a| a == "shards") {
        let numbers: Vec<usize> = std::env::args()
            .skip(at + 1)
            .filter_map(|a| a.parse().ok())
            .collect();
        let (shards, n) = match numbers.as_slice() {
            [s, n, ..] => (*s, *n),
            [s] => (*s, 1000),
            [] => (4, 1000),
        };
        sharded(n, shards);
        return;
    }
    let cases: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let case = Case {
        dense: std::env::args().any(|a| a == "dense"),
        niceness: if std::env::args().any(|a| a == "equal") {
            0
        } else {
            EMULATOR_NICENESS
        },
        priority: std::env::args()
            .any(|a| a == "rt")
            .then_some(COORDINATOR_PRIORITY),
        braking_share: std::env::args().any(|a| a == "quarter").then_some(0.25),
    };
    let cases = if cases.is_empty() {
        vec![64, 250, 500, 1000]
    } else {
        cases
    };
    let floor_us = udp_floor_us();
    println!(
        "UDP loopback floor on this machine: {floor_us:.2} µs per datagram sent and received \
         ({:.2} µs per vehicle-tick of {DATAGRAMS_PER_TICK} datagrams)\n",
        floor_us * DATAGRAMS_PER_TICK
    );
    println!(
        "| vehicles | emulator µs/vehicle-tick | coordinator µs/vehicle-tick | both / floor | \
         late ticks (> T/2) | tick lateness p99 / max (ms) | state age p50 / p99 (ms) | setpoints taken, lowest / mean (Hz) | \
         UDP drops | filter active / closest (m) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for n in cases {
        match run_case(n, &case) {
            Ok(r) => {
                let per_tick = |cpu_s: f64| cpu_s * 1e6 / (n as f64 * RATE_HZ * r.window_s);
                let (e, c) = (per_tick(r.emulator_cpu_s), per_tick(r.coordinator_cpu_s));
                println!(
                    "| {n} | {e:.2} | {c:.2} | {:.1} | {} of {} ({:.3} %) | {} / {} | {} / {} | {} | {} | {} |",
                    (e + c) / (floor_us * DATAGRAMS_PER_TICK),
                    r.late_ticks,
                    r.ticks,
                    100.0 * r.late_ticks as f64 / r.ticks.max(1) as f64,
                    show(r.late_p99_ms),
                    show(r.late_max_ms),
                    show(r.age_p50_ms),
                    show(r.age_p99_ms),
                    r.setpoint_rates
                        .map_or("—".to_owned(), |(lo, mean)| format!(
                            "{lo:.1} / {mean:.1}"
                        )),
                    r.udp_drops,
                    r.safety,
                );
            }
            Err(e) => println!("| {n} | failed: {e} |||||||||"),
        }
    }
}

fn show(v: Option<f64>) -> String {
    v.map_or("—".to_owned(), |v| format!("{v:.1}"))
}

struct CaseResult {
    window_s: f64,
    emulator_cpu_s: f64,
    coordinator_cpu_s: f64,
    ticks: u64,
    late_ticks: u64,
    late_p99_ms: Option<f64>,
    late_max_ms: Option<f64>,
    age_p50_ms: Option<f64>,
    age_p99_ms: Option<f64>,
    setpoint_rates: Option<(f64, f64)>,
    udp_drops: u64,
    /// The safety filter: active share of ticks and closest pair, or "off".
    safety: String,
}

/// Kills a child when dropped (a failed case leaves nothing running).
struct Running(Child);

impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn run_case(n: usize, case: &Case) -> Result<CaseResult, String> {
    let bin = env!("CARGO_BIN_EXE_ringswarm");
    let dir = std::env::temp_dir().join(format!("ringswarm-realtime-{}-{n}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let config = dir.join("ring.toml");
    let mut text = if case.dense {
        dense_ring(n, RATE_HZ)
    } else {
        ring(n, RATE_HZ)
    };
    if let Some(share) = case.braking_share {
        text.push_str(&format!("[safety]\nbraking_share = {share}\n"));
    }
    std::fs::write(&config, text).map_err(|e| e.to_string())?;

    let (sitl, lines) = start_sitl(bin, &config, &dir, case.niceness)?;
    let out = dir.join("run");
    let mut command = Command::new(bin);
    command
        .args(["fly", "--config"])
        .arg(&config)
        .arg("--out")
        .arg(&out);
    if let Some(priority) = case.priority {
        command.args(["--realtime-priority", &priority.to_string()]);
    }
    let fly = Running(
        command
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .map_err(|e| format!("start fly: {e}"))?,
    );
    std::thread::sleep(WARM_UP);
    let udp_before = udp_counters();
    let cpu_before = (cpu_s(sitl.0.id())?, cpu_s(fly.0.id())?);
    let start = Instant::now();
    std::thread::sleep(WINDOW);
    let cpu_after = (cpu_s(sitl.0.id())?, cpu_s(fly.0.id())?);
    let window_s = start.elapsed().as_secs_f64();
    let udp_after = udp_counters();
    // Ctrl-C twice: land, then return at once (the summary is written either way).
    let mut fly = fly;
    for _ in 0..2 {
        interrupt(fly.0.id());
        std::thread::sleep(Duration::from_millis(500));
    }
    let waited = Instant::now();
    loop {
        if fly.0.try_wait().map_err(|e| e.to_string())?.is_some() {
            break;
        }
        if waited.elapsed() > Duration::from_secs(120) {
            return Err("fly did not stop".into());
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    interrupt(sitl.0.id());
    let summary = std::fs::read_to_string(out.join("summary.json"))
        .map_err(|e| format!("summary.json: {e}"))?;
    let summary: serde_json::Value = serde_json::from_str(&summary).map_err(|e| e.to_string())?;
    let timing = &summary["timing"];
    let setpoint_rates = lines.lock().ok().and_then(|l| {
        // Fleet lines printed within the window (every 5 s): the lowest rate, the mean.
        let rates: Vec<(f64, f64)> = l
            .iter()
            .filter(|(at, _)| *at > start + Duration::from_secs(5) && *at <= start + WINDOW)
            .filter_map(|(_, line)| setpoint_rate(line))
            .collect();
        (!rates.is_empty()).then(|| {
            let lowest = rates.iter().map(|r| r.0).fold(f64::INFINITY, f64::min);
            let mean = rates.iter().map(|r| r.1).sum::<f64>() / rates.len() as f64;
            (lowest, mean)
        })
    });
    if let Some(at) = timing["latest_tick_due_s"].as_f64() {
        eprintln!("{n} vehicles: the latest tick was due at {at:.2} s");
    }
    let safety = &summary["safety"];
    let safety = match (
        safety["active_fraction"].as_f64(),
        safety["min_separation_seen_m"].as_f64(),
    ) {
        (Some(active), Some(closest)) => format!("{:.1} % / {closest:.2}", 100.0 * active),
        _ => "off".to_owned(),
    };
    if std::env::var_os("RINGSWARM_BENCH_KEEP").is_some() {
        eprintln!("{n} vehicles: run directory kept in {}", dir.display());
    } else {
        let _ = std::fs::remove_dir_all(&dir);
    }
    Ok(CaseResult {
        safety,
        window_s,
        emulator_cpu_s: cpu_after.0 - cpu_before.0,
        coordinator_cpu_s: cpu_after.1 - cpu_before.1,
        ticks: timing["lateness"]["samples"].as_u64().unwrap_or(0),
        late_ticks: timing["late_ticks"].as_u64().unwrap_or(0),
        late_p99_ms: timing["lateness"]["p99_ms"].as_f64(),
        late_max_ms: timing["lateness"]["max_ms"].as_f64(),
        age_p50_ms: timing["state_age"]["p50_ms"].as_f64(),
        age_p99_ms: timing["state_age"]["p99_ms"].as_f64(),
        setpoint_rates,
        udp_drops: udp_after.saturating_sub(udp_before),
    })
}

/// The emulator's stdout lines, each with when it came.
type Lines = Arc<Mutex<Vec<(Instant, String)>>>;

/// Starts `ringswarm sitl --config config` and waits until it serves; its stdout lines,
/// each with when it came, are collected as it runs. The emulator stands for the
/// vehicles' own computers: on this shared machine it runs at a lower priority
/// (`niceness`, [`EMULATOR_NICENESS`] unless the word `equal` is given), so that the
/// coordinators' schedule is what is measured, not the scheduler's choice.
fn start_sitl(
    bin: &str,
    config: &std::path::Path,
    dir: &std::path::Path,
    niceness: i32,
) -> Result<(Running, Lines), String> {
    let niceness = niceness.to_string();
    let mut sitl = Running(
        Command::new("nice")
            .args(["-n", &niceness, bin, "sitl", "--config"])
            .arg(config)
            .arg("--state-dir")
            .arg(dir.join("state"))
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .map_err(|e| format!("start sitl: {e}"))?,
    );
    let lines: Lines = Arc::new(Mutex::new(Vec::new()));
    let stdout = sitl.0.stdout.take().ok_or("no sitl stdout")?;
    let (ready_tx, ready_rx) = std::sync::mpsc::channel();
    {
        let lines = Arc::clone(&lines);
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if line.starts_with("Ctrl-C stops") {
                    let _ = ready_tx.send(());
                }
                if let Ok(mut l) = lines.lock() {
                    l.push((Instant::now(), line));
                }
            }
        });
    }
    ready_rx
        .recv_timeout(Duration::from_secs(60))
        .map_err(|_| "sitl did not start")?;
    Ok((sitl, lines))
}

/// `(lowest, mean)` from a fleet line's "setpoints L Hz lowest, M Hz mean".
fn setpoint_rate(line: &str) -> Option<(f64, f64)> {
    let rest = line.split("setpoints ").nth(1)?;
    let mut words = rest.split_whitespace();
    let lowest = words.next()?.parse().ok()?;
    let mean = words.nth(2)?.parse().ok()?;
    Some((lowest, mean))
}

fn interrupt(pid: u32) {
    let _ = Command::new("kill")
        .args(["-INT", &pid.to_string()])
        .status();
}

/// CPU seconds (user + system, every thread) a process has used, from /proc.
fn cpu_s(pid: u32) -> Result<f64, String> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .map_err(|e| format!("/proc/{pid}/stat: {e} (Linux only)"))?;
    let after = stat.rsplit_once(") ").ok_or("odd /proc stat")?.1;
    let fields: Vec<&str> = after.split_whitespace().collect();
    let ticks = |i: usize| fields.get(i).and_then(|f| f.parse::<f64>().ok());
    let (utime, stime) = ticks(11).zip(ticks(12)).ok_or("odd /proc stat")?;
    Ok((utime + stime) / clock_ticks_per_s())
}

fn clock_ticks_per_s() -> f64 {
    Command::new("getconf")
        .arg("CLK_TCK")
        .output()
        .ok()
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .and_then(|s| s.trim().parse().ok())
        .unwrap_or(100.0)
}

/// Datagrams the kernel dropped for a full receive or send buffer (all of this network
/// namespace), from /proc/net/snmp.
fn udp_counters() -> u64 {
    let Ok(snmp) = std::fs::read_to_string("/proc/net/snmp") else {
        return 0;
    };
    let udp: Vec<Vec<&str>> = snmp
        .lines()
        .filter(|l| l.starts_with("Udp:"))
        .map(|l| l.split_whitespace().collect())
        .collect();
    let [names, values] = udp.as_slice() else {
        return 0;
    };
    names
        .iter()
        .zip(values)
        .filter(|(name, _)| matches!(**name, "RcvbufErrors" | "SndbufErrors"))
        .filter_map(|(_, v)| v.parse::<u64>().ok())
        .sum()
}

/// The machine's floor: µs of CPU to send one 52-byte datagram on loopback and receive
/// it (one thread, both ends, 64 in flight), the cost no UDP design avoids.
fn udp_floor_us() -> f64 {
    let a = UdpSocket::bind("127.0.0.1:0").expect("bind");
    let b = UdpSocket::bind("127.0.0.1:0").expect("bind");
    let to = b.local_addr().expect("addr");
    let payload = [0u8; 52];
    let mut buf = [0u8; 2048];
    let rounds = 4000;
    let start = Instant::now();
    for _ in 0..rounds {
        for _ in 0..64 {
            a.send_to(&payload, to).expect("send");
        }
        for _ in 0..64 {
            b.recv_from(&mut buf).expect("recv");
        }
    }
    start.elapsed().as_secs_f64() * 1e6 / f64::from(rounds * 64)
}

/// The ring of `n` split into `shards` contiguous shards, each listening on loopback and
/// connecting to every shard before it; `watch = "neighbours"` (each shard reads only the
/// ring neighbours of its own vehicles), so the safety filter is off.
fn sharded_ring(n: usize, shards: usize) -> String {
    let mut text = ring(n, RATE_HZ);
    text.push_str(
        "[safety]\nenabled = false\n[distributed]\nswarm = \"bench\"\nwatch = \"neighbours\"\n",
    );
    let per = n.div_ceil(shards);
    for s in 0..shards {
        let vehicles: Vec<String> = (s * per..((s + 1) * per).min(n))
            .map(|i| {
                format!(
                    "{{ system_id = {}, network = \"n{}\" }}",
                    i % 250 + 1,
                    i / 250
                )
            })
            .collect();
        let connect: Vec<String> = (0..s)
            .map(|t| format!("\"tcp/127.0.0.1:{}\"", 7500 + t))
            .collect();
        text.push_str(&format!(
            "[[shard]]\nname = \"s{s}\"\nvehicles = [{}]\nlisten = [\"tcp/127.0.0.1:{}\"]\nconnect = [{}]\n",
            vehicles.join(", "),
            7500 + s,
            connect.join(", ")
        ));
    }
    text
}

/// One emulator for the whole ring, `shards` coordinators: the steady window's CPU and
/// each shard's summary.
fn sharded(n: usize, shards: usize) {
    let run = || -> Result<(), String> {
        // The ring's networks hold 250 vehicles each, and one host's shards cannot bind
        // the same network's socket: each shard takes whole networks.
        if shards == 0 || !n.is_multiple_of(shards) || !(n / shards).is_multiple_of(250) {
            return Err(format!(
                "each shard must take whole networks of 250 vehicles on one host: {n} vehicles in {shards} shards do not split so"
            ));
        }
        let bin = env!("CARGO_BIN_EXE_ringswarm");
        let dir =
            std::env::temp_dir().join(format!("ringswarm-realtime-shards-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        let config = dir.join("ring.toml");
        std::fs::write(&config, sharded_ring(n, shards)).map_err(|e| e.to_string())?;
        let (sitl, _) = start_sitl(bin, &config, &dir, EMULATOR_NICENESS)?;
        let mut flies = Vec::new();
        for s in 0..shards {
            flies.push(Running(
                Command::new(bin)
                    .args(["fly", "--config"])
                    .arg(&config)
                    .args(["--shard", &format!("s{s}"), "--out"])
                    .arg(dir.join(format!("run-s{s}")))
                    .stdin(Stdio::null())
                    .stdout(Stdio::null())
                    .stderr(Stdio::null())
                    .spawn()
                    .map_err(|e| format!("start shard s{s}: {e}"))?,
            ));
        }
        std::thread::sleep(WARM_UP);
        let cpu = |flies: &[Running]| -> Result<Vec<f64>, String> {
            flies.iter().map(|f| cpu_s(f.0.id())).collect()
        };
        let before = (cpu_s(sitl.0.id())?, cpu(&flies)?);
        let start = Instant::now();
        std::thread::sleep(WINDOW);
        let after = (cpu_s(sitl.0.id())?, cpu(&flies)?);
        let window_s = start.elapsed().as_secs_f64();
        for _ in 0..2 {
            for f in &flies {
                interrupt(f.0.id());
            }
            std::thread::sleep(Duration::from_millis(500));
        }
        for f in &mut flies {
            let waited = Instant::now();
            while f.0.try_wait().map_err(|e| e.to_string())?.is_none() {
                if waited.elapsed() > Duration::from_secs(120) {
                    return Err("a shard did not stop".into());
                }
                std::thread::sleep(Duration::from_millis(100));
            }
        }
        interrupt(sitl.0.id());
        let per_tick =
            |cpu_s: f64, vehicles: usize| cpu_s * 1e6 / (vehicles as f64 * RATE_HZ * window_s);
        println!(
            "{n} vehicles in {shards} shards, one emulator: emulator {:.2} µs/vehicle-tick\n",
            per_tick(after.0 - before.0, n)
        );
        println!(
            "| shard | vehicles | coordinator µs/vehicle-tick | late ticks (> T/2) | tick lateness p99 / max (ms) | own state age p50 / p99 (ms) | other shards' state age p50 / p99 (ms) | phase at the end |"
        );
        println!("|---|---|---|---|---|---|---|---|");
        let per = n.div_ceil(shards);
        for s in 0..shards {
            let vehicles = ((s + 1) * per).min(n) - s * per;
            let text = std::fs::read_to_string(dir.join(format!("run-s{s}")).join("summary.json"))
                .map_err(|e| format!("shard s{s}'s summary.json: {e}"))?;
            let summary: serde_json::Value =
                serde_json::from_str(&text).map_err(|e| e.to_string())?;
            let t = &summary["timing"];
            let q = |h: &serde_json::Value| {
                format!(
                    "{} / {}",
                    show(h["p50_ms"].as_f64()),
                    show(h["p99_ms"].as_f64())
                )
            };
            println!(
                "| s{s} | {vehicles} | {:.2} | {} of {} | {} / {} | {} | {} | {} |",
                per_tick(after.1[s] - before.1[s], vehicles),
                t["late_ticks"].as_u64().unwrap_or(0),
                t["lateness"]["samples"].as_u64().unwrap_or(0),
                show(t["lateness"]["p99_ms"].as_f64()),
                show(t["lateness"]["max_ms"].as_f64()),
                q(&t["state_age"]),
                q(&t["remote_state_age"]),
                summary["final_phase"].as_str().unwrap_or("?"),
            );
        }
        if std::env::var_os("RINGSWARM_BENCH_KEEP").is_some() {
            eprintln!("run directories kept in {}", dir.display());
        } else {
            let _ = std::fs::remove_dir_all(&dir);
        }
        Ok(())
    };
    if let Err(e) = run() {
        println!("{n} vehicles in {shards} shards: failed: {e}");
    }
}
