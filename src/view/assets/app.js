// The live view and the replay of ringswarm: reads /api/info, then the swarm's state from
// the WebSocket /api/ws (live) or from /api/state?t_s= (replay), and draws it. Read-only.
"use strict";

const TRAIL_S = 5;          // trail length (s of flight)
const ROWS_PER_PAGE = 50;   // the table shows one page of vehicles at a time
const EVENTS_KEPT = 200;
const ARROW_S = 2;          // the velocity arrow shows 2 s of travel

const $ = (id) => document.getElementById(id);
const view = {
  mode: null, setup: null, state: null, trails: [], lastT: -Infinity,
  page: 0, eventsSeen: 0, drawn: [], frames: 0,
  renderMs: 0,               // how long the last state took to show (ms)
};
window.ringswarmView = view; // what was drawn, for whoever inspects the page

const fmt = (x, digits = 2) => (x === null || x === undefined || !Number.isFinite(x)) ? "–" : x.toFixed(digits);
const fmtVec = (v) => v ? `(${fmt(v[0])}, ${fmt(v[1])}) m/s` : "–";

async function start() {
  const info = await (await fetch("/api/info")).json();
  view.mode = info.mode;
  view.setup = info.setup;
  view.trails = info.setup.vehicles.map(() => []);
  $("mode").textContent = info.mode === "live" ? "live" : "replay";
  setupPager();
  if (info.mode === "live") {
    live();
  } else {
    replay(info.duration_s);
  }
}

function live() {
  const socket = new WebSocket(`ws://${location.host}/api/ws`);
  socket.onmessage = (m) => show(JSON.parse(m.data));
  // The server closes the stream when the flight is over; 1006 is a connection lost.
  socket.onclose = (e) => {
    $("mode").textContent = e.code === 1006
      ? "live: connection lost (the last state stays)"
      : "live: flight over (the last state stays)";
  };
}

function replay(duration) {
  $("replay").hidden = false;
  const slider = $("slider");
  slider.max = String(duration);
  let playing = false, t = 0, wall = null, pending = false, wanted = null;
  const fetchAt = async (at) => {
    wanted = at;
    if (pending) return;
    pending = true;
    try {
      while (wanted !== null) {
        const ask = wanted;
        wanted = null;
        const r = await fetch(`/api/state?t_s=${ask}`);
        if (r.ok) show(await r.json());
      }
    } catch (e) {
      $("mode").textContent = `replay: the server is gone (${e})`;
    } finally {
      pending = false;
    }
  };
  const setTime = (at) => {
    t = Math.min(Math.max(at, 0), duration);
    slider.value = String(t);
    $("slider-time").textContent = `${t.toFixed(1)} s of ${duration.toFixed(1)} s`;
    fetchAt(t);
  };
  const tick = (now) => {
    if (!playing) return;
    if (wall !== null) setTime(t + (now - wall) / 1000 * Number($("speed").value));
    wall = now;
    if (t >= duration) { playing = false; $("play").textContent = "play"; return; }
    requestAnimationFrame(tick);
  };
  $("play").onclick = () => {
    playing = !playing;
    $("play").textContent = playing ? "pause" : "play";
    if (playing) {
      if (t >= duration) setTime(0);
      wall = null;
      requestAnimationFrame(tick);
    }
  };
  slider.oninput = () => setTime(Number(slider.value));
  setTime(0);
}

function show(state) {
  if (state.t_s < view.lastT) {
    // A seek backwards: the trails and the events start again.
    view.trails = view.trails.map(() => []);
    view.eventsSeen = 0;
    $("events").replaceChildren();
  }
  view.lastT = state.t_s;
  view.state = state;
  view.frames += 1;
  state.vehicles.forEach((v, i) => {
    const trail = view.trails[i] ?? (view.trails[i] = []);
    if (v.position_enu_m) trail.push([state.t_s, v.position_enu_m[0], v.position_enu_m[1]]);
    while (trail.length && trail[0][0] < state.t_s - TRAIL_S) trail.shift();
  });
  const began = performance.now();
  figures(state);
  draw(state);
  table(state);
  events(state);
  view.renderMs = performance.now() - began;
}

function figures(s) {
  $("t").textContent = `${fmt(s.t_s, 1)} s`;
  $("phase").textContent = s.phase;
  $("formation").textContent = s.formation_error_m === null ? "–" : `${fmt(s.formation_error_m)} m`;
  $("velocity").textContent = fmtVec(s.mean_velocity_enu_mps);
  $("predicted").textContent = fmtVec(s.predicted_final_velocity);
  $("velocity-error").textContent = s.velocity_error_mps === null ? "–" : `${fmt(s.velocity_error_mps, 3)} m/s`;
  $("altitude").textContent = s.altitude_error_m === null ? "–" : `±${fmt(s.altitude_error_m)} m of ${fmt(s.altitude_target_m, 1)} m`;
  const c = s.closest_pair, sep = view.setup.separation;
  const bound = sep ? ` (separation ${fmt(sep.horizontal_m, 1)} m)` : "";
  $("closest").textContent = c ? `${c.sysids[0]}–${c.sysids[1]}: ${fmt(c.distance_m)} m${bound}` : "–";
  $("closest").classList.toggle("bad", Boolean(c && sep && c.distance_m < sep.horizontal_m));
}

// The fence (red; a circle's margin dashed inside it), in map pixels.
function drawFence(ctx, px, scale) {
  const f = view.setup.fence;
  if (!f) return null;
  ctx.strokeStyle = "#b22"; ctx.lineWidth = 2; ctx.beginPath();
  if (f.kind === "circle") {
    const [x, y] = px(f.centre_enu_m[0], f.centre_enu_m[1]);
    ctx.arc(x, y, f.radius_m * scale, 0, 2 * Math.PI); ctx.stroke();
    if (f.margin_m > 0 && f.radius_m > f.margin_m) {
      ctx.setLineDash([6, 4]); ctx.lineWidth = 1; ctx.beginPath();
      ctx.arc(x, y, (f.radius_m - f.margin_m) * scale, 0, 2 * Math.PI); ctx.stroke(); ctx.setLineDash([]);
    }
  } else {
    f.vertices_enu_m.forEach((v, i) => { const [x, y] = px(v[0], v[1]); i ? ctx.lineTo(x, y) : ctx.moveTo(x, y); });
    ctx.closePath(); ctx.stroke();
  }
  ctx.lineWidth = 1;
  return f.kind;
}

// Each vehicle's separation circle (radius half the separation: two vehicles at the
// separation touch), red where a constraint bound its command; the bound pairs joined in
// red and the closest pair dashed.
function drawSeparation(ctx, s, px, scale) {
  const sep = view.setup.separation;
  const drawn = { circles: 0, constrained: [], activePairs: 0, closest: null };
  const pos = (i) => s.vehicles[i] && s.vehicles[i].position_enu_m;
  if (sep && s.vehicles.length <= 200) {
    s.vehicles.forEach((v) => {
      if (!v.position_enu_m) return;
      const [x, y] = px(v.position_enu_m[0], v.position_enu_m[1]);
      ctx.strokeStyle = v.constrained ? "rgba(200, 30, 30, 0.9)" : "rgba(90, 90, 110, 0.35)";
      ctx.lineWidth = v.constrained ? 2 : 1;
      ctx.beginPath(); ctx.arc(x, y, sep.horizontal_m / 2 * scale, 0, 2 * Math.PI); ctx.stroke();
      drawn.circles += 1;
      if (v.constrained) drawn.constrained.push(v.sysid);
    });
    ctx.lineWidth = 1;
  }
  ctx.strokeStyle = "rgba(200, 30, 30, 0.9)"; ctx.lineWidth = 2;
  for (const [i, j] of s.active_pairs ?? []) {
    const a = pos(i), b = pos(j);
    if (!a || !b) continue;
    const [x0, y0] = px(a[0], a[1]), [x1, y1] = px(b[0], b[1]);
    ctx.beginPath(); ctx.moveTo(x0, y0); ctx.lineTo(x1, y1); ctx.stroke();
    drawn.activePairs += 1;
  }
  ctx.lineWidth = 1;
  const c = s.closest_pair;
  if (c && pos(c.vehicles[0]) && pos(c.vehicles[1])) {
    const a = pos(c.vehicles[0]), b = pos(c.vehicles[1]);
    const [x0, y0] = px(a[0], a[1]), [x1, y1] = px(b[0], b[1]);
    ctx.strokeStyle = "#c60"; ctx.setLineDash([3, 3]);
    ctx.beginPath(); ctx.moveTo(x0, y0); ctx.lineTo(x1, y1); ctx.stroke(); ctx.setLineDash([]);
    drawn.closest = [c.sysids[0], c.sysids[1], c.distance_m];
  }
  return drawn;
}

function draw(s) {
  const canvas = $("map");
  const ctx = canvas.getContext("2d");
  const W = canvas.width, H = canvas.height, pad = 30;
  ctx.clearRect(0, 0, W, H);
  // The view: every vehicle, trail, target and the arrow, at least 10 m across, one scale
  // for both axes (a running min/max: a thousand trails are too many points to spread).
  let x0 = Infinity, x1 = -Infinity, y0 = Infinity, y1 = -Infinity;
  const take = (x, y) => { x0 = Math.min(x0, x); x1 = Math.max(x1, x); y0 = Math.min(y0, y); y1 = Math.max(y1, y); };
  s.vehicles.forEach((v, i) => {
    if (v.position_enu_m) take(v.position_enu_m[0], v.position_enu_m[1]);
    if (v.target_enu_m) take(v.target_enu_m[0], v.target_enu_m[1]);
    for (const p of view.trails[i] ?? []) take(p[1], p[2]);
  });
  const v = s.predicted_final_velocity, c = s.formation_centre_enu_m;
  if (v && c) take(c[0] + v[0] * ARROW_S, c[1] + v[1] * ARROW_S);
  if (!Number.isFinite(x0)) { view.drawn = []; return; }
  const cx = (x0 + x1) / 2, cy = (y0 + y1) / 2;
  const span = Math.max(10, x1 - x0, (y1 - y0) * (W - 2 * pad) / (H - 2 * pad));
  const scale = (W - 2 * pad) / span;
  const px = (x, y) => [W / 2 + (x - cx) * scale, H / 2 - (y - cy) * scale];
  grid(ctx, W, H, cx, cy, scale, px);
  const fence = drawFence(ctx, px, scale);
  view.drawnSafety = { fence, ...drawSeparation(ctx, s, px, scale) };
  // The target formation, in ring order.
  const targets = s.vehicles.map((v) => v.target_enu_m).filter(Boolean);
  if (targets.length > 1) {
    ctx.strokeStyle = "#8aa"; ctx.setLineDash([4, 4]); ctx.beginPath();
    targets.forEach((t, i) => { const [x, y] = px(t[0], t[1]); i ? ctx.lineTo(x, y) : ctx.moveTo(x, y); });
    ctx.closePath(); ctx.stroke(); ctx.setLineDash([]);
  }
  for (const t of targets) {
    const [x, y] = px(t[0], t[1]);
    ctx.strokeStyle = "#4a8"; ctx.beginPath(); ctx.arc(x, y, 7, 0, 2 * Math.PI); ctx.stroke();
  }
  // Trails.
  ctx.strokeStyle = "rgba(40, 70, 140, 0.35)";
  for (const trail of view.trails) {
    if (trail.length < 2) continue;
    ctx.beginPath();
    trail.forEach((p, i) => { const [x, y] = px(p[1], p[2]); i ? ctx.lineTo(x, y) : ctx.moveTo(x, y); });
    ctx.stroke();
  }
  // Vehicles, coloured by altitude error (blue low, green on target, red high).
  const drawn = [];
  const r = s.vehicles.length > 200 ? 2.5 : 5;
  s.vehicles.forEach((v) => {
    if (!v.position_enu_m) return;
    const [x, y] = px(v.position_enu_m[0], v.position_enu_m[1]);
    const dz = Math.max(-1, Math.min(1, (v.position_enu_m[2] - s.altitude_target_m) / Math.max(1, s.altitude_target_m)));
    ctx.fillStyle = `hsl(${120 - 120 * dz}, 70%, 40%)`;
    ctx.beginPath(); ctx.arc(x, y, r, 0, 2 * Math.PI); ctx.fill();
    if (s.vehicles.length <= 50) { ctx.fillStyle = "#223"; ctx.fillText(String(v.sysid), x + 7, y - 7); }
    drawn.push({ sysid: v.sysid, network: v.network, x_m: v.position_enu_m[0], y_m: v.position_enu_m[1], x_px: x, y_px: y });
  });
  view.drawn = drawn;
  // The predicted final velocity, from the formation's reference point.
  if (v && c) arrow(ctx, px(c[0], c[1]), px(c[0] + v[0] * ARROW_S, c[1] + v[1] * ARROW_S), "#c50");
}

function grid(ctx, W, H, cx, cy, scale, px) {
  const step = [1, 2, 5, 10, 20, 50, 100, 200, 500, 1000, 2000, 5000].find((g) => g * scale >= 60) ?? 10000;
  ctx.strokeStyle = "#eef"; ctx.fillStyle = "#99a"; ctx.lineWidth = 1;
  const x0 = Math.floor((cx - W / 2 / scale) / step) * step, y0 = Math.floor((cy - H / 2 / scale) / step) * step;
  for (let x = x0; x <= cx + W / 2 / scale; x += step) {
    const [sx] = px(x, 0); ctx.beginPath(); ctx.moveTo(sx, 0); ctx.lineTo(sx, H); ctx.stroke();
  }
  for (let y = y0; y <= cy + H / 2 / scale; y += step) {
    const [, sy] = px(0, y); ctx.beginPath(); ctx.moveTo(0, sy); ctx.lineTo(W, sy); ctx.stroke();
  }
  ctx.fillText(`grid ${step} m`, 6, H - 6);
}

function arrow(ctx, [x0, y0], [x1, y1], colour) {
  const a = Math.atan2(y1 - y0, x1 - x0);
  ctx.strokeStyle = ctx.fillStyle = colour; ctx.lineWidth = 2;
  ctx.beginPath(); ctx.moveTo(x0, y0); ctx.lineTo(x1, y1); ctx.stroke();
  ctx.beginPath(); ctx.moveTo(x1, y1);
  ctx.lineTo(x1 - 10 * Math.cos(a - 0.4), y1 - 10 * Math.sin(a - 0.4));
  ctx.lineTo(x1 - 10 * Math.cos(a + 0.4), y1 - 10 * Math.sin(a + 0.4));
  ctx.closePath(); ctx.fill(); ctx.lineWidth = 1;
}

function setupPager() {
  const pages = () => Math.max(1, Math.ceil(view.setup.vehicles.length / ROWS_PER_PAGE));
  $("prev").onclick = () => { view.page = Math.max(0, view.page - 1); rebuildRows(); };
  $("next").onclick = () => { view.page = Math.min(pages() - 1, view.page + 1); rebuildRows(); };
  $("pager").hidden = pages() === 1;
  rebuildRows();
}

function rebuildRows() {
  const vs = view.setup.vehicles;
  const first = view.page * ROWS_PER_PAGE, last = Math.min(vs.length, first + ROWS_PER_PAGE);
  $("page").textContent = `vehicles ${first + 1}–${last} of ${vs.length}`;
  const rows = [];
  for (let i = first; i < last; i++) {
    const tr = document.createElement("tr");
    tr.dataset.sysid = String(vs[i].sysid);
    if (vs[i].network !== null) tr.dataset.network = vs[i].network;
    tr.dataset.index = String(i);
    for (let c = 0; c < 8; c++) tr.appendChild(document.createElement("td"));
    rows.push(tr);
  }
  document.querySelector("#vehicles tbody").replaceChildren(...rows);
  if (view.state) table(view.state);
}

function table(s) {
  const bad = new Set(["lost", "failed", "vehicle_hold", "overridden"]);
  for (const tr of document.querySelectorAll("#vehicles tbody tr")) {
    const v = s.vehicles[Number(tr.dataset.index)];
    if (!v) continue;
    const cells = [
      v.sysid, v.network ?? "", v.link_phase, v.mode ?? "–",
      v.position_enu_m ? fmt(v.position_enu_m[2], 1) : "–",
      fmt(v.telemetry_age_ms, 0), fmt(v.speed_mps),
      v.saturated === null ? "–" : (v.saturated ? "yes" : "no"),
    ];
    cells.forEach((text, c) => { const td = tr.children[c]; if (td.textContent !== String(text)) td.textContent = String(text); });
    tr.classList.toggle("bad", bad.has(v.link_phase));
    tr.classList.toggle("sat", v.saturated === true);
  }
}

function events(s) {
  const fresh = s.events_total - view.eventsSeen;
  if (fresh <= 0) return;
  const list = $("events");
  for (const e of s.events.slice(Math.max(0, s.events.length - fresh))) {
    const li = document.createElement("li");
    const who = e.sysid === null ? "swarm" : `vehicle ${e.sysid}${e.network ? ` on ${e.network}` : ""}`;
    li.textContent = `${e.t_s.toFixed(1)} s ${who}: ${e.text}`;
    if (e.warning) li.className = "warning";
    list.prepend(li);
  }
  while (list.children.length > EVENTS_KEPT) list.lastChild.remove();
  view.eventsSeen = s.events_total;
}

start().catch((e) => { $("mode").textContent = `error: ${e}`; });
