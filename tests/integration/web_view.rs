//! The live view's API and WebSocket, and the replay of a run directory, against a
//! lockstep flight of paper-sim1 (virtual time; the server on loopback, port chosen by the
//! kernel). Expected values come from the swarm itself and from the ring's left null
//! vector written out by hand, not from the view's own code.

use std::collections::BTreeMap;
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::sync::Arc;
use std::time::Duration;

use futures_util::StreamExt;
use ringswarm::config::Config;
use ringswarm::driver::Observer;
use ringswarm::driver::lockstep::Lockstep;
use ringswarm::record::{Recorder, RowText, RunSetup};
use ringswarm::swarm::Swarm;
use ringswarm::swarm::VehicleIndex;
use ringswarm::view::replay::Replay;
use ringswarm::view::state::VehicleView;
use ringswarm::view::{Content, LiveFeed, ViewState, WebServer};
use ringswarm_wire::time::SimTime;
use serde_json::Value;
use tokio_tungstenite::tungstenite::Message;

const SIM1: &str = include_str!("../../config/paper-sim1.toml");

fn sim1() -> Lockstep {
    Lockstep::from_config(&Config::from_toml(SIM1).expect("parses")).expect("scenario")
}

/// `GET path` over HTTP/1.1: status and body.
fn get(addr: SocketAddr, path: &str) -> (u16, String) {
    let mut stream = TcpStream::connect(addr).expect("connect");
    stream
        .set_read_timeout(Some(Duration::from_secs(30)))
        .expect("timeout");
    write!(
        stream,
        "GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
    )
    .expect("request");
    let mut response = String::new();
    stream.read_to_string(&mut response).expect("response");
    let (head, body) = response.split_once("\r\n\r\n").expect("a head and a body");
    let status = head
        .split_whitespace()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .expect("a status");
    (status, body.to_owned())
}

fn json(body: &str) -> Value {
    serde_json::from_str(body).expect("JSON")
}

/// Feeds the live view at every driver step, as `fly` does.
struct Feeding<'a>(&'a mut LiveFeed);

impl Observer for Feeding<'_> {
    fn swarm(&mut self, swarm: &Swarm, now: SimTime) {
        self.0.offer(swarm, now, None);
    }
}

#[test]
fn the_state_api_shows_every_vehicle_where_the_swarm_has_it() {
    let mut run = sim1();
    let (mut feed, states) = LiveFeed::new();
    let content = Content::Live {
        setup: RunSetup::of(run.swarm()),
        states,
    };
    let server = WebServer::start("127.0.0.1:0".parse().expect("addr"), content).expect("serve");
    let (status, body) = get(server.addr(), "/api/state");
    assert_eq!(status, 503, "no state before the flight: {body}");
    assert!(json(&body)["error"].as_str().is_some());

    // 20 s: consensus has run for about 18 s.
    run.run_observed(SimTime::from_micros(20_000_000), &mut Feeding(&mut feed));
    let swarm = run.swarm();
    let now = run.now();
    // The latest published state was taken within the last 50 ms; publish the present.
    feed.publish(ViewState::of_swarm(swarm, now, None));
    let state = loop {
        let (status, body) = get(server.addr(), "/api/state");
        assert_eq!(status, 200, "{body}");
        let state = json(&body);
        if state["t_s"].as_f64() == Some(now.as_secs_f64()) {
            break state;
        }
    };
    assert_eq!(state["phase"], "consensus");
    let predicted = swarm.predicted_final_velocity().expect("predicted");
    assert_eq!(
        state["predicted_final_velocity"][0].as_f64(),
        Some(predicted.x)
    );
    assert_eq!(
        state["predicted_final_velocity"][1].as_f64(),
        Some(predicted.y)
    );
    let vehicles = state["vehicles"].as_array().expect("vehicles");
    assert_eq!(vehicles.len(), 6);
    // paper-sim1: k = 5, so the ring's left null vector is (1, 6, 1, 6, 1, 6).
    let w = [1.0, 6.0, 1.0, 6.0, 1.0, 6.0];
    let offsets = &swarm.setup().offsets_m;
    let mut centre = nalgebra::Vector2::zeros();
    for (i, v) in vehicles.iter().enumerate() {
        let v: VehicleView = serde_json::from_value(v.clone()).expect("a vehicle");
        assert_eq!(v.sysid, i as u8 + 1);
        assert_eq!(v.network, None);
        assert_eq!(v.link_phase, "flying");
        assert_eq!(v.mode.as_deref(), Some("OFFBOARD"));
        assert_eq!(v.armed, Some(true));
        let s = swarm.common_state(VehicleIndex(i)).expect("known");
        let p = v.position_enu_m.expect("position");
        let vel = v.velocity_enu_mps.expect("velocity");
        for axis in 0..3 {
            assert_eq!(p[axis], s.pos_enu_m[axis]);
            assert_eq!(vel[axis], s.vel_enu_mps[axis]);
        }
        assert!((v.speed_mps.expect("speed") - s.vel_enu_mps.xy().norm()).abs() < 1e-12);
        let age = v.telemetry_age_ms.expect("heard");
        assert!((0.0..50.0).contains(&age), "telemetry age {age} ms");
        centre += (s.pos_enu_m.xy() - offsets[i]) * w[i] / 21.0;
    }
    // The closest pair, against every pair by the 3 m × 9 m ellipsoid (vertical offsets
    // count a third), and no constraint bound in the hexagon's 20 m sides.
    let mut closest = (0, 0, f64::INFINITY);
    for i in 0..6 {
        for j in i + 1..6 {
            let d = swarm
                .common_state(VehicleIndex(i))
                .expect("known")
                .pos_enu_m
                - swarm
                    .common_state(VehicleIndex(j))
                    .expect("known")
                    .pos_enu_m;
            let d = nalgebra::Vector3::new(d.x, d.y, d.z / 3.0).norm();
            if d < closest.2 {
                closest = (i, j, d);
            }
        }
    }
    let pair = &state["closest_pair"];
    assert_eq!(
        pair["vehicles"],
        serde_json::json!([closest.0, closest.1]),
        "{pair}"
    );
    assert_eq!(
        pair["sysids"],
        serde_json::json!([closest.0 + 1, closest.1 + 1])
    );
    assert!((pair["distance_m"].as_f64().expect("distance") - closest.2).abs() < 1e-9);
    assert!(closest.2 > 15.0, "{closest:?}");
    assert_eq!(state["active_pairs"], serde_json::json!([]));
    assert!(vehicles.iter().all(|v| v["constrained"] == false));
    let c = &state["formation_centre_enu_m"];
    assert!((c[0].as_f64().expect("x") - centre.x).abs() < 1e-9);
    assert!((c[1].as_f64().expect("y") - centre.y).abs() < 1e-9);
    for (i, v) in vehicles.iter().enumerate() {
        let t = &v["target_enu_m"];
        assert!((t[0].as_f64().expect("x") - (centre.x + offsets[i].x)).abs() < 1e-9);
        assert!((t[1].as_f64().expect("y") - (centre.y + offsets[i].y)).abs() < 1e-9);
    }

    let (status, info) = get(server.addr(), "/api/info");
    assert_eq!(status, 200);
    let info = json(&info);
    assert_eq!(info["mode"], "live");
    assert_eq!(info["setup"]["vehicles"].as_array().map(Vec::len), Some(6));
    assert_eq!(info["setup"]["k"].as_f64(), Some(5.0));
    assert_eq!(
        info["setup"]["separation"],
        serde_json::json!({"horizontal_m": 3.0, "vertical_m": 9.0})
    );
    assert_eq!(info["setup"]["fence"], serde_json::Value::Null);
    let (status, page) = get(server.addr(), "/");
    assert_eq!(status, 200);
    assert!(page.contains("<canvas id=\"map\""), "the page");
    assert_eq!(get(server.addr(), "/app.js").0, 200);
    assert_eq!(get(server.addr(), "/no-such-file.js").0, 404);
}

#[test]
fn the_live_feed_takes_the_swarm_every_50_ms_of_swarm_time() {
    let mut run = sim1();
    let (mut feed, mut states) = LiveFeed::new();
    let mut times = Vec::new();
    run.run_observed(
        SimTime::from_micros(9_999_000),
        &mut |swarm: &Swarm, now: SimTime| {
            feed.offer(swarm, now, None);
            if states.has_changed().unwrap_or(false) {
                let t = states.borrow_and_update().as_ref().map(|s| s.t_s);
                times.push(t.expect("a state"));
            }
        },
    );
    // 0.001 (the first step), 0.05, …, 9.95 s: the driver hands over the swarm every
    // simulated millisecond.
    assert_eq!(times.len(), 200, "{times:?}");
    for (i, t) in times.iter().enumerate() {
        assert!((t - i as f64 * 0.05).abs() < 1.5e-3, "state {i} at {t} s");
    }
}

/// A synthetic state of `n` vehicles at `t_s`.
fn state_of(n: usize, t_s: f64) -> ViewState {
    ViewState {
        t_s,
        phase: "consensus".into(),
        predicted_final_velocity: Some([1.0, 2.0]),
        mean_velocity_enu_mps: None,
        velocity_error_mps: None,
        formation_error_m: None,
        altitude_error_m: None,
        altitude_target_m: 10.0,
        formation_centre_enu_m: None,
        vehicles: (0..n)
            .map(|i| VehicleView {
                sysid: (i % 250) as u8 + 1,
                network: Some(format!("net{}", i / 250)),
                position_enu_m: Some([i as f64, t_s, 10.0]),
                velocity_enu_mps: Some([1.0, 2.0, 0.0]),
                target_enu_m: None,
                link_phase: "flying".into(),
                mode: Some("OFFBOARD".into()),
                armed: Some(true),
                telemetry_age_ms: Some(12.0),
                speed_mps: Some(5f64.sqrt()),
                saturated: Some(false),
                constrained: Some(false),
            })
            .collect(),
        closest_pair: None,
        active_pairs: Vec::new(),
        events: Vec::new(),
        events_total: 0,
    }
}

fn live_server() -> (WebServer, LiveFeed) {
    let (feed, states) = LiveFeed::new();
    let setup = RunSetup {
        vehicles: Vec::new(),
        k: 1.0,
        altitude_m: 10.0,
        control_rate_hz: 50.0,
        separation: None,
        fence: None,
    };
    let server = WebServer::start(
        "127.0.0.1:0".parse().expect("addr"),
        Content::Live { setup, states },
    )
    .expect("serve");
    (server, feed)
}

/// A WebSocket client of the live stream.
type Client =
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

/// Runs `body` with a client of `server`'s live stream.
fn with_client<Fut: std::future::Future<Output = ()>>(
    server: &WebServer,
    body: impl FnOnce(Client) -> Fut,
) {
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    runtime.block_on(async {
        let url = format!("ws://{}/api/ws", server.addr());
        let (ws, _) = tokio_tungstenite::connect_async(url)
            .await
            .expect("connect");
        body(ws).await;
    });
}

fn t_of(message: &Message) -> f64 {
    match message {
        Message::Text(text) => json(text)["t_s"].as_f64().expect("t_s"),
        other => panic!("not a text message: {other:?}"),
    }
}

#[test]
fn the_websocket_pushes_every_state_to_a_client_that_keeps_up() {
    let (server, feed) = live_server();
    with_client(&server, |mut ws| async move {
        for i in 0..40 {
            let t = f64::from(i) * 0.05;
            feed.publish(state_of(6, t));
            // Each state arrives, in order, before the next is published.
            let message = tokio::time::timeout(Duration::from_secs(30), ws.next())
                .await
                .expect("a state within 30 s")
                .expect("open")
                .expect("a message");
            assert_eq!(t_of(&message), t);
            let expected = serde_json::to_string(&state_of(6, t)).expect("JSON");
            assert_eq!(message.to_text().expect("text"), expected);
        }
    });
}

#[test]
fn a_client_that_does_not_read_is_sent_the_newest_state_not_a_queue() {
    let (server, feed) = live_server();
    with_client(&server, |mut ws| async move {
        // 500 states of a thousand vehicles (~250 kB of JSON each, 125 MB in all) while
        // the client reads nothing.
        let published = 500;
        for i in 0..published {
            feed.publish(state_of(1000, f64::from(i)));
            if i % 50 == 0 {
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
        }
        let last = f64::from(published - 1);
        let mut received = 0;
        loop {
            let message = tokio::time::timeout(Duration::from_secs(60), ws.next())
                .await
                .expect("the newest state within 60 s")
                .expect("open")
                .expect("a message");
            received += 1;
            if t_of(&message) == last {
                break;
            }
        }
        eprintln!("{received} of {published} states reached the client");
        // What the socket buffers held, and the newest: nothing like the 500 published.
        assert!(
            received < 100,
            "{received} states queued for a client that did not read"
        );
    });
}

/// Records a lockstep flight into a run directory, keeping every tick's positions.
struct Recording<'a> {
    recorder: &'a mut Recorder,
    ticks: BTreeMap<u64, Vec<[f64; 3]>>,
}

impl Observer for Recording<'_> {
    fn datagram(&mut self, now: SimTime, _: VehicleIndex, _: bool, bytes: &[u8]) {
        self.recorder.datagram(now, bytes);
    }

    fn swarm(&mut self, swarm: &Swarm, now: SimTime) {
        self.recorder.sample(swarm, now);
        let positions: Option<Vec<[f64; 3]>> = (0..swarm.vehicle_count())
            .map(|i| {
                swarm
                    .common_state(VehicleIndex(i))
                    .map(|s| s.pos_enu_m.into())
            })
            .collect();
        if let Some(p) = positions {
            self.ticks.insert(now.as_micros(), p);
        }
    }
}

#[test]
fn a_replay_shows_the_recorded_positions_and_serves_them() {
    let dir = std::env::temp_dir().join(format!("ringswarm-replay-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let mut run = sim1();
    let mut recorder =
        Recorder::create(&dir, run.swarm(), 0, RowText::Writer).expect("run directory");
    let mut recording = Recording {
        recorder: &mut recorder,
        ticks: BTreeMap::new(),
    };
    run.run_observed(SimTime::from_micros(20_000_000), &mut recording);
    let ticks = recording.ticks;
    // The events are on the disk while the flight goes on (what a killed run leaves).
    let events = dir.join("events.csv");
    let deadline = std::time::Instant::now() + Duration::from_secs(30);
    while !std::fs::read_to_string(&events)
        .unwrap_or_default()
        .contains("consensus started")
    {
        assert!(
            std::time::Instant::now() < deadline,
            "events.csv has no event 30 s after it happened"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    let started = run
        .swarm()
        .consensus_started()
        .expect("consensus")
        .as_secs_f64();
    let predicted = run.swarm().predicted_final_velocity().expect("predicted");
    recorder
        .finish(run.swarm(), run.now(), 1.0)
        .expect("summary");

    let replay = Replay::load(&dir).expect("loads");
    // The last row kept (rows are kept 50 ms apart at most).
    assert!(
        (replay.duration_s() - 20.0).abs() <= 0.05,
        "{}",
        replay.duration_s()
    );
    for t in [5.0, 12.34, 19.9] {
        let state = replay.state_at(t);
        assert_eq!(state.t_s, t);
        assert_eq!(state.phase, "consensus");
        // The positions are those of one recorded tick, at most 50 ms before t (the CSV
        // keeps 4 decimals).
        let shown: Vec<[f64; 3]> = state
            .vehicles
            .iter()
            .map(|v| v.position_enu_m.expect("position"))
            .collect();
        let t_us = (t * 1e6) as u64;
        let matching = ticks.range(t_us - 50_000..=t_us).find(|(_, p)| {
            p.iter()
                .zip(&shown)
                .all(|(a, b)| (0..3).all(|k| (a[k] - b[k]).abs() <= 0.6e-4))
        });
        assert!(
            matching.is_some(),
            "t = {t}: no tick in the last 50 ms shows {shown:?}"
        );
        let v = state.predicted_final_velocity.expect("consensus started");
        assert!((v[0] - predicted.x).abs() < 1e-9 && (v[1] - predicted.y).abs() < 1e-9);
    }
    let before = replay.state_at(started / 2.0);
    assert_eq!(before.predicted_final_velocity, None);
    assert_eq!(before.phase, "handshake");

    let server = WebServer::start(
        "127.0.0.1:0".parse().expect("addr"),
        Content::Replay(Arc::new(replay.clone())),
    )
    .expect("serve");
    let (status, body) = get(server.addr(), "/api/state?t_s=12.34");
    assert_eq!(status, 200, "{body}");
    let served: ViewState = serde_json::from_str(&body).expect("a state");
    assert_eq!(served, replay.state_at(12.34));
    let (status, body) = get(server.addr(), "/api/state?t_s=soon");
    assert_eq!(status, 400);
    assert_eq!(
        json(&body)["error"],
        "t_s must be a finite number of seconds, not negative: got \"soon\""
    );
    let (status, info) = get(server.addr(), "/api/info");
    assert_eq!(status, 200);
    assert_eq!(json(&info)["mode"], "replay");
    assert_eq!(get(server.addr(), "/api/ws").0, 404);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_directory_that_is_not_a_run_directory_is_named() {
    let dir = std::env::temp_dir().join(format!("ringswarm-not-a-run-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let err = Replay::load(&dir).expect_err("no setup.json");
    assert!(err.contains("setup.json"), "{err}");
    assert!(err.contains("ringswarm fly"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_state_names_the_constraints_the_safety_filter_bound() {
    // crossing.toml: eight x500s through the centre; find ticks where the filter bound
    // pairs and compare the view with the filter's own rows.
    let text = include_str!("../../config/crossing.toml");
    let mut run =
        Lockstep::from_config(&Config::from_toml(text).expect("parses")).expect("scenario");
    let mut checked = 0;
    let mut tick = 0;
    let mut states = Vec::new();
    run.run_until(SimTime::from_millis(30_000), |r| {
        let swarm = r.swarm();
        if swarm.control_ticks() == tick {
            return;
        }
        tick = swarm.control_ticks();
        let rows = swarm.safety_active_rows().to_vec();
        if rows.iter().any(|(i, j)| i != j) && states.len() < 20 {
            states.push((rows, ViewState::of_swarm(swarm, r.now(), None)));
        }
    });
    for (rows, state) in &states {
        let pairs: Vec<[usize; 2]> = rows
            .iter()
            .filter(|(i, j)| i != j)
            .map(|&(i, j)| [i, j])
            .collect();
        assert_eq!(state.active_pairs, pairs);
        for (k, v) in state.vehicles.iter().enumerate() {
            let bound = rows.iter().any(|&(i, j)| i == k || j == k);
            assert_eq!(v.constrained, Some(bound), "vehicle {k}");
        }
        let pair = state.closest_pair.as_ref().expect("a closest pair");
        assert!(pair.distance_m >= 2.85, "{pair:?}");
        checked += 1;
    }
    assert!(checked >= 5, "the filter bound pairs on {checked} ticks");
    let setup = RunSetup::of(run.swarm());
    let sep = setup.separation.expect("on");
    assert_eq!((sep.horizontal_m, sep.vertical_m), (3.0, 9.0));
}
