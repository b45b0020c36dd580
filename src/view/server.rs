//! The web server of the live view and the replay (an I/O edge): the page and its assets
//! compiled into the binary, `GET /api/info`, `GET /api/state` and, live, the WebSocket
//! `/api/ws`. It runs on a thread and a runtime of its own, so no request ever shares a
//! thread with the control loop, which only replaces the latest state in a watch
//! channel ([`LiveFeed`]) and never waits. Read-only: every route is a GET, and what a
//! WebSocket client sends is ignored.

use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use axum::body::Bytes;
use axum::extract::ws::rejection::WebSocketUpgradeRejection;
use axum::extract::ws::{Message, Utf8Bytes, WebSocket, WebSocketUpgrade};
use axum::extract::{Path, Query, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use ringswarm_wire::time::SimTime;
use serde::Serialize;
use tokio::sync::{oneshot, watch};

use super::replay::Replay;
use super::state::ViewState;
use crate::record::RunSetup;
use crate::record::metrics::Snapshot;
use crate::swarm::Swarm;

/// How often the live view takes the swarm (swarm time): 20 Hz.
pub const LIVE_PERIOD: Duration = Duration::from_millis(50);

/// The page, its script and its style.
#[derive(rust_embed::Embed)]
#[folder = "src/view/assets/"]
struct Assets;

/// What the server shows.
#[derive(Debug, Clone)]
pub enum Content {
    /// A flight as it happens: its setup and the latest state.
    Live {
        /// The flight's setup.
        setup: RunSetup,
        /// The latest state (`None` before the first).
        states: watch::Receiver<Option<Arc<ViewState>>>,
    },
    /// A finished run directory.
    Replay(Arc<Replay>),
}

/// The control loop's side of the live view: takes the swarm every [`LIVE_PERIOD`] of
/// swarm time and replaces the latest state (a watch channel: nothing queues, whoever
/// reads late reads the newest).
#[derive(Debug)]
pub struct LiveFeed {
    tx: watch::Sender<Option<Arc<ViewState>>>,
    next: SimTime,
}

impl LiveFeed {
    /// A feed and what the server reads.
    pub fn new() -> (Self, watch::Receiver<Option<Arc<ViewState>>>) {
        let (tx, rx) = watch::channel(None);
        (
            Self {
                tx,
                next: SimTime::ZERO,
            },
            rx,
        )
    }

    /// Takes the swarm at `now` when a period has passed since the last state.
    pub fn offer(&mut self, swarm: &Swarm, now: SimTime, figures: Option<Snapshot>) {
        if now < self.next {
            return;
        }
        self.next = self.next + LIVE_PERIOD;
        if self.next <= now {
            self.next = now + LIVE_PERIOD;
        }
        self.publish(ViewState::of_swarm(swarm, now, figures));
    }

    /// Replaces the latest state (the flight's last one, for example).
    pub fn publish(&self, state: ViewState) {
        self.tx.send_replace(Some(Arc::new(state)));
    }
}

/// A running server; dropping it stops it (open connections are closed).
#[derive(Debug)]
pub struct WebServer {
    addr: SocketAddr,
    stop: Option<oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl WebServer {
    /// Binds `addr` and serves `content` from a thread of its own.
    ///
    /// # Errors
    /// The address cannot be bound, or the thread cannot start.
    pub fn start(addr: SocketAddr, content: Content) -> Result<Self, String> {
        let listener = std::net::TcpListener::bind(addr)
            .map_err(|e| format!("bind {addr} for the web view: {e}"))?;
        let local = listener
            .local_addr()
            .and_then(|a| listener.set_nonblocking(true).map(|()| a))
            .map_err(|e| format!("web view on {addr}: {e}"))?;
        let (stop, stopped) = oneshot::channel();
        let thread = std::thread::Builder::new()
            .name("web view".into())
            .spawn(move || serve(listener, content, stopped))
            .map_err(|e| format!("start the web view's thread: {e}"))?;
        Ok(Self {
            addr: local,
            stop: Some(stop),
            thread: Some(thread),
        })
    }

    /// The address it listens on (the port chosen when asked for port 0).
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Serves until `signal` resolves (for `ringswarm view`: Ctrl-C).
    pub fn serve_until<F: std::future::Future<Output = ()>>(self, signal: F) {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build();
        match runtime {
            Ok(runtime) => runtime.block_on(signal),
            Err(e) => tracing::error!(error = %e, "web view: no runtime to wait on"),
        }
        drop(self);
    }
}

impl Drop for WebServer {
    fn drop(&mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// The server thread's body: its runtime, the JSON of the latest state, the routes.
fn serve(listener: std::net::TcpListener, content: Content, stopped: oneshot::Receiver<()>) {
    let runtime = match tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
    {
        Ok(runtime) => runtime,
        Err(e) => {
            tracing::error!(error = %e, "web view not started: no runtime");
            return;
        }
    };
    runtime.block_on(async move {
        let listener = match tokio::net::TcpListener::from_std(listener) {
            Ok(listener) => listener,
            Err(e) => {
                tracing::error!(error = %e, "web view not started");
                return;
            }
        };
        let (json_tx, json) = watch::channel(None);
        if let Content::Live { states, .. } = &content {
            tokio::spawn(serialise(states.clone(), json_tx));
        }
        let app = axum::Router::new()
            .route("/", get(index))
            .route("/{file}", get(asset))
            .route("/api/info", get(info))
            .route("/api/state", get(state))
            .route("/api/ws", get(ws))
            .with_state(Shared { content, json });
        tokio::select! {
            served = axum::serve(listener, app) => if let Err(e) = served {
                tracing::error!(error = %e, "web view stopped");
            },
            _ = stopped => {}
        }
    });
}

/// Turns each new state into JSON once, for every client.
async fn serialise(
    mut states: watch::Receiver<Option<Arc<ViewState>>>,
    json: watch::Sender<Option<Utf8Bytes>>,
) {
    loop {
        let state = states.borrow_and_update().clone();
        if let Some(state) = state {
            match serde_json::to_string(&*state) {
                Ok(text) => {
                    json.send_replace(Some(text.into()));
                }
                Err(e) => tracing::warn!(error = %e, "live state not serialised"),
            }
        }
        if states.changed().await.is_err() {
            // The flight is over: the last state stays; streams end.
            return;
        }
    }
}

#[derive(Clone)]
struct Shared {
    content: Content,
    /// The latest live state as JSON.
    json: watch::Receiver<Option<Utf8Bytes>>,
}

/// A JSON error body with its status.
fn error(status: StatusCode, message: impl Into<String>) -> Response {
    #[derive(Serialize)]
    struct Error {
        error: String,
    }
    (
        status,
        axum::Json(Error {
            error: message.into(),
        }),
    )
        .into_response()
}

async fn index() -> Response {
    asset(Path("index.html".to_owned())).await
}

async fn asset(Path(file): Path<String>) -> Response {
    let Some(found) = Assets::get(&file) else {
        return error(StatusCode::NOT_FOUND, format!("no file {file}"));
    };
    let kind = match file.rsplit_once('.').map(|(_, ext)| ext) {
        Some("html") => "text/html; charset=utf-8",
        Some("js") => "text/javascript; charset=utf-8",
        Some("css") => "text/css; charset=utf-8",
        Some("svg") => "image/svg+xml",
        _ => "application/octet-stream",
    };
    (
        [(header::CONTENT_TYPE, kind)],
        Bytes::from(found.data.into_owned()),
    )
        .into_response()
}

/// `GET /api/info`.
#[derive(Debug, Serialize)]
struct Info<'a> {
    /// `live` or `replay`.
    mode: &'static str,
    /// The flight's vehicles, ring gain, altitude and control rate.
    setup: &'a RunSetup,
    /// A replay's length (s); `null` live.
    duration_s: Option<f64>,
}

async fn info(State(shared): State<Shared>) -> Response {
    let info = match &shared.content {
        Content::Live { setup, .. } => Info {
            mode: "live",
            setup,
            duration_s: None,
        },
        Content::Replay(replay) => Info {
            mode: "replay",
            setup: replay.setup(),
            duration_s: Some(replay.duration_s()),
        },
    };
    axum::Json(info).into_response()
}

/// `GET /api/state`: live, the latest state; in a replay, the state at `?t_s=` (default 0).
async fn state(
    State(shared): State<Shared>,
    Query(query): Query<HashMap<String, String>>,
) -> Response {
    match &shared.content {
        Content::Live { .. } => match shared.json.borrow().clone() {
            Some(json) => (
                [(header::CONTENT_TYPE, "application/json")],
                Bytes::from(json),
            )
                .into_response(),
            None => error(
                StatusCode::SERVICE_UNAVAILABLE,
                "no state yet: the flight has not started",
            ),
        },
        Content::Replay(replay) => {
            let t_s = match query.get("t_s").map(|t| t.parse::<f64>()) {
                None => 0.0,
                Some(Ok(t)) if t.is_finite() && t >= 0.0 => t,
                Some(_) => {
                    return error(
                        StatusCode::BAD_REQUEST,
                        format!(
                            "t_s must be a finite number of seconds, not negative: got \"{}\"",
                            query.get("t_s").map_or("", String::as_str)
                        ),
                    );
                }
            };
            axum::Json(replay.state_at(t_s)).into_response()
        }
    }
}

/// `GET /api/ws`: live, every new state as a JSON text message (the newest only when
/// the client reads slower than they come).
async fn ws(
    State(shared): State<Shared>,
    upgrade: Result<WebSocketUpgrade, WebSocketUpgradeRejection>,
) -> Response {
    match shared.content {
        Content::Live { .. } => match upgrade {
            Ok(upgrade) => upgrade.on_upgrade(move |socket| stream(socket, shared.json)),
            Err(rejection) => rejection.into_response(),
        },
        Content::Replay(_) => error(
            StatusCode::NOT_FOUND,
            "a replay has no live stream: ask GET /api/state?t_s=<seconds>",
        ),
    }
}

async fn stream(mut socket: WebSocket, mut json: watch::Receiver<Option<Utf8Bytes>>) {
    loop {
        let latest = json.borrow_and_update().clone();
        if let Some(text) = latest
            && socket.send(Message::Text(text)).await.is_err()
        {
            return;
        }
        loop {
            tokio::select! {
                changed = json.changed() => {
                    if changed.is_err() {
                        // The flight is over.
                        let _ = socket.send(Message::Close(None)).await;
                        return;
                    }
                    break;
                }
                incoming = socket.recv() => match incoming {
                    // The page commands nothing: what it sends is dropped.
                    Some(Ok(Message::Close(_)) | Err(_)) | None => return,
                    Some(Ok(_)) => {}
                },
            }
        }
    }
}
