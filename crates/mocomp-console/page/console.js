// The mocomp console's page: status over the WebSocket, the plot, the 3-D view, the operator's
// buttons and the tuning form. Plain JavaScript, nothing fetched from elsewhere.
"use strict";

const $ = (id) => document.getElementById(id);
const HISTORY_S = 30;
const state = {
  status: null,
  scene: null,
  config: null,
  history: [], // [t, deviation_mm, head_speed_mm_s]
  latencies: [], // loop → page, ms (the newest 2000)
  statuses: 0, // how many the page has shown: the latencies are capped, this is not
  view: { az: -0.9, el: 0.45, dist: 0.7 }, // framed on the head (about 45 % of the view); the wheel zooms out to the arm
};
// For tests and the latency benchmark.
window.mocomp = state;

function fmt(v, digits) {
  return v === null || v === undefined || !Number.isFinite(v) ? "—" : v.toFixed(digits);
}

async function api(method, path, body) {
  const init = { method, credentials: "same-origin", headers: {} };
  if (body !== undefined) {
    init.headers["Content-Type"] = "application/json";
    init.body = JSON.stringify(body);
  }
  const r = await fetch(path, init);
  let data = null;
  try { data = await r.json(); } catch (_) { /* an empty body */ }
  return { ok: r.ok, status: r.status, data };
}

// ---- status ---------------------------------------------------------------------------------

async function refreshScene() {
  const sc = await api("GET", "/api/scene");
  if (sc.ok) { state.scene = sc.data; drawScene(); }
}

function showStatus(s) {
  state.status = s;
  state.statuses += 1;
  // An experiment's run places its own scene: fetch it again when it changes.
  if (state.scene && s.scene_version !== state.scene.version && !state.sceneLoading) {
    state.sceneLoading = true;
    refreshScene().finally(() => { state.sceneLoading = false; });
  }
  $("controller").textContent = s.controller ? "controller: " + s.controller : "";
  const badge = $("mode-badge");
  badge.className = "badge " + s.mode;
  $("mode").textContent = s.mode;
  $("reason").textContent = s.reason_text || s.reason || "";
  $("deviation_mm").textContent = fmt(s.deviation_mm, 2);
  $("deviation_deg").textContent = fmt(s.deviation_deg, 2);
  $("head_speed_mm_s").textContent = fmt(s.head_speed_mm_s, 1);
  $("head_speed_deg_s").textContent = fmt(s.head_speed_deg_s, 1);
  $("clearance_mm").textContent = fmt(s.clearance_mm, 1);
  $("standoff_mm").textContent = fmt(s.standoff_mm, 1);
  $("rate_hz").textContent = fmt(s.rate_hz, 0);
  $("horizon_ms").textContent = fmt(s.horizon_ms, 1);
  $("sample_age_ms").textContent = fmt(s.sample_age_ms, 1);
  $("force_n").textContent = fmt(s.force_n, 1);
  // The dose tile once a coil model gives one; it then stays, showing — while there is none.
  if (s.dose_pct != null) $("dose-tile").hidden = false;
  $("dose_pct").textContent = fmt(s.dose_pct, 1);
  $("dose_v_per_m").textContent = fmt(s.dose_v_per_m, 1);
  $("t").textContent = fmt(s.t, 2);
  $("hold").disabled = !s.running || s.operator_hold;
  // Resume ends the operator's hold and re-arms a latched fault: offered for either.
  $("resume").disabled = !s.running || !(s.operator_hold || s.mode === "faulted");
  $("stop").disabled = !s.running;
  $("teach").disabled = !s.running || !s.operator_hold;
  $("freedrive").disabled = !s.running || !s.operator_hold || s.freedrive;
  $("handback").disabled = !s.running || !s.freedrive;
  $("go-target").disabled = !s.running || $("target-select").options.length === 0;
  if (Number.isFinite(s.cycle_unix_ms)) {
    const lat = Date.now() - s.cycle_unix_ms;
    state.latencies.push(lat);
    if (state.latencies.length > 2000) state.latencies.shift();
    $("latency").textContent = fmt(Math.max(0, lat), 0);
  }
  if (s.running && s.mode !== "starting") {
    state.history.push([s.t, s.deviation_mm, s.head_speed_mm_s]);
    while (state.history.length && s.t - state.history[0][0] > HISTORY_S) state.history.shift();
  }
  showCamera(s.camera);
  showCalibration(s.calibration);
  showNavigation(s.navigation);
  showMri(s);
  showSession(s.session);
  drawPlot();
  drawScene();
}

function connect() {
  const ws = new WebSocket((location.protocol === "https:" ? "wss://" : "ws://") + location.host + "/ws");
  ws.onopen = () => { $("link").textContent = "live"; $("link").className = "link up"; };
  ws.onmessage = (m) => { try { showStatus(JSON.parse(m.data)); } catch (_) { /* a bad message */ } };
  ws.onclose = () => {
    $("link").textContent = "disconnected"; $("link").className = "link down";
    setTimeout(connect, 1000);
  };
}

// The session's gate (open, or shut and why) and its pulses (how many, the last one's error).
function showSession(ses) {
  $("gate-tile").hidden = !ses;
  $("pulses-tile").hidden = !ses;
  if (!ses) return;
  $("gate").textContent = ses.gate_open ? "open" : "shut";
  $("gate-why").textContent = ses.gate_open ? "" : ses.gate_why;
  $("gate-tile").className = "tile " + (ses.gate_open ? "open" : "shut");
  $("pulses").textContent = ses.pulses;
  const last = ses.last_pulse;
  $("pulse-last").textContent = (ses.pulses_off_target ? ses.pulses_off_target + " off target · " : "") +
    (last ? "last " + fmt(last[0], 2) + " mm, " + fmt(last[1], 2) + "°" + (last[2] ? "" : " (gate shut)") : "");
}

// ---- plot -----------------------------------------------------------------------------------

function niceMax(v) {
  if (!(v > 0)) return 1;
  const p = Math.pow(10, Math.floor(Math.log10(v)));
  for (const m of [1, 2, 5, 10]) if (m * p >= v) return m * p;
  return 10 * p;
}

function drawPlot() {
  const c = $("plot"), g = c.getContext("2d");
  const W = c.width, H = c.height, L = 46, R = 52, T = 12, B = 26;
  g.clearRect(0, 0, W, H);
  const h = state.history;
  const tEnd = h.length ? h[h.length - 1][0] : HISTORY_S;
  const t0 = tEnd - HISTORY_S;
  // The deviation on a logarithmic axis, from 0.01 mm to the largest shown (at least 1 mm): the
  // approach's hundreds of millimetres and tracking's tenths are both read off it.
  const devs = h.map((p) => p[1]).filter(Number.isFinite);
  const devMax = niceMax(Math.max(1, ...devs));
  const DEV_MIN = 0.01, decades = Math.log10(devMax / DEV_MIN);
  const spdMax = niceMax(Math.max(10, ...h.map((p) => (Number.isFinite(p[2]) ? p[2] : 0))));
  const x = (t) => L + ((t - t0) / HISTORY_S) * (W - L - R);
  const yDev = (v) => H - B - (Math.log10(Math.max(v, DEV_MIN) / DEV_MIN) / decades) * (H - T - B);
  const ySpd = (v) => H - B - (v / spdMax) * (H - T - B);
  g.strokeStyle = "#e3e6ea"; g.fillStyle = "#66707a"; g.font = "11px system-ui, sans-serif";
  // Grid and deviation labels at the decades; the head speed's at quarters on the right.
  for (let d = DEV_MIN; d <= devMax * 1.0001; d *= 10) {
    const y = yDev(d);
    g.beginPath(); g.moveTo(L, y); g.lineTo(W - R, y); g.stroke();
    g.textAlign = "right"; g.fillText(d < 0.1 ? d.toFixed(2) : d < 1 ? d.toFixed(1) : d.toFixed(0), L - 6, y + 4);
  }
  for (let k = 0; k <= 4; k++) {
    const y = T + (k / 4) * (H - T - B);
    g.textAlign = "left"; g.fillText(fmt(spdMax * (1 - k / 4), 0), W - R + 6, y + 4);
  }
  g.textAlign = "center";
  for (let s = 0; s <= HISTORY_S; s += 5) g.fillText("-" + (HISTORY_S - s) + " s", x(t0 + s), H - 8);
  const line = (idx, y, color, width) => {
    g.strokeStyle = color; g.lineWidth = width; g.beginPath();
    let pen = false;
    for (const p of h) {
      if (!Number.isFinite(p[idx])) { pen = false; continue; }
      if (pen) g.lineTo(x(p[0]), y(p[idx])); else g.moveTo(x(p[0]), y(p[idx]));
      pen = true;
    }
    g.stroke(); g.lineWidth = 1;
  };
  g.save(); g.beginPath(); g.rect(L, T, W - L - R, H - T - B); g.clip();
  line(2, ySpd, "#e08a3c", 1.2);
  line(1, yDev, "#1f6fd1", 2);
  g.restore();
  // Where the newest deviation was drawn, for tests: its height above the axis, of the plot's.
  const lastDev = devs.length ? devs[devs.length - 1] : NaN;
  state.plot = { dev_max: devMax, last_dev: lastDev, last_dev_height: (H - B - yDev(lastDev)) / (H - T - B) };
  g.textAlign = "left"; g.fillStyle = "#1f6fd1"; g.fillText("deviation mm", L + 6, T + 12);
  g.fillStyle = "#e08a3c"; g.fillText("head speed mm/s", L + 96, T + 12);
}

// ---- 3-D view -------------------------------------------------------------------------------

const mul = (r, v) => [
  r[0][0] * v[0] + r[0][1] * v[1] + r[0][2] * v[2],
  r[1][0] * v[0] + r[1][1] * v[1] + r[1][2] * v[2],
  r[2][0] * v[0] + r[2][1] * v[1] + r[2][2] * v[2],
];
const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const apply = (pose, v) => add(mul(pose.r, v), pose.p_mm);

function projector(c) {
  const v = state.view, s = state.status;
  // Look at the head (or the coil, or the base's front) from an orbit around it.
  const target = s && s.scene.head ? s.scene.head.p_mm : (s && s.scene.coil ? s.scene.coil.p_mm : [300, 0, 0]);
  const ca = Math.cos(v.az), sa = Math.sin(v.az), ce = Math.cos(v.el), se = Math.sin(v.el);
  const f = c.height * 1.4, dist = v.dist * 1000;
  return (p) => {
    const d = [p[0] - target[0], p[1] - target[1], p[2] - target[2]];
    const x1 = ca * d[0] + sa * d[1], y1 = -sa * d[0] + ca * d[1];
    const depth = dist - (ce * y1 + se * d[2]) ;
    const up = -se * y1 + ce * d[2];
    return [c.width / 2 + (f * x1) / depth, c.height / 2 - (f * up) / depth];
  };
}

function polyline(g, P, pts, color, width, dash) {
  g.strokeStyle = color; g.lineWidth = width || 1; g.setLineDash(dash || []);
  g.beginPath();
  pts.forEach((p, i) => { const q = P(p); if (i) g.lineTo(q[0], q[1]); else g.moveTo(q[0], q[1]); });
  g.stroke(); g.setLineDash([]); g.lineWidth = 1;
}

function drawCoil(g, P, pose, color, dash) {
  // The casing's outline where one is given, else the cylinder's rim.
  const r = state.scene.coil_radius_mm, outline = state.scene.coil_outline_mm, ring = [];
  if (outline && outline.length) {
    for (const p of outline.concat([outline[0]])) ring.push(apply(pose, p));
  } else {
    for (let k = 0; k <= 32; k++) {
      const a = (2 * Math.PI * k) / 32;
      ring.push(apply(pose, [r * Math.cos(a), r * Math.sin(a), 0]));
    }
  }
  polyline(g, P, ring, color, 2, dash);
  polyline(g, P, [apply(pose, [0, 0, 0]), apply(pose, [0, 0, 40])], color, 1, [3, 3]);
}

function drawScene() {
  const c = $("view3d"), g = c.getContext("2d");
  g.clearRect(0, 0, c.width, c.height);
  const s = state.status, sc = state.scene;
  if (!s || !sc) return;
  const P = projector(c);
  // The floor grid at the base, and the base's axes.
  for (let k = -4; k <= 8; k++) {
    polyline(g, P, [[k * 100, -400, 0], [k * 100, 400, 0]], "#eceff2");
  }
  for (let k = -4; k <= 4; k++) polyline(g, P, [[-400, k * 100, 0], [800, k * 100, 0]], "#eceff2");
  polyline(g, P, [[0, 0, 0], [100, 0, 0]], "#d33", 2);
  polyline(g, P, [[0, 0, 0], [0, 100, 0]], "#3a3", 2);
  polyline(g, P, [[0, 0, 0], [0, 0, 100]], "#33d", 2);
  // The tracker: a box, and its line of sight to the head.
  const tr = sc.tracker, box = [];
  for (const [x, y] of [[-60, -20], [60, -20], [60, 20], [-60, 20], [-60, -20]]) box.push(apply(tr, [x, y, 0]));
  polyline(g, P, box, "#444", 2);
  if (s.scene.head) polyline(g, P, [tr.p_mm, s.scene.head.p_mm], "#bbb", 1, [2, 4]);
  // The head model: the patient's scalp as a wireframe of its (decimated) triangles, each edge
  // once; or the ellipsoid's meridians and parallels.
  if (s.scene.head && sc.head_mesh) {
    const v = sc.head_mesh.vertices_mm.map((p) => P(apply(s.scene.head, p))), seen = new Set();
    g.strokeStyle = "#c7a98f"; g.lineWidth = 1; g.beginPath();
    for (const t of sc.head_mesh.triangles) {
      for (let k = 0; k < 3; k++) {
        const a = t[k], b = t[(k + 1) % 3], key = a < b ? a * 1e6 + b : b * 1e6 + a;
        if (seen.has(key)) continue;
        seen.add(key);
        g.moveTo(v[a][0], v[a][1]); g.lineTo(v[b][0], v[b][1]);
      }
    }
    g.stroke();
  } else if (s.scene.head) {
    const e = sc.head_from_ellipsoid, [a, b, cc] = sc.head_radii_mm;
    const at = (u, v) => apply(s.scene.head, apply(e, [a * Math.cos(v) * Math.cos(u), b * Math.cos(v) * Math.sin(u), cc * Math.sin(v)]));
    for (let m = 0; m < 12; m++) {
      const u = (2 * Math.PI * m) / 12, pts = [];
      for (let k = 0; k <= 24; k++) pts.push(at(u, -Math.PI / 2 + (Math.PI * k) / 24));
      polyline(g, P, pts, "#c7a98f");
    }
    for (let k = 1; k < 8; k++) {
      const v = -Math.PI / 2 + (Math.PI * k) / 8, pts = [];
      for (let m = 0; m <= 32; m++) pts.push(at((2 * Math.PI * m) / 32, v));
      polyline(g, P, pts, "#c7a98f");
    }
  }
  // The arm: its joint frames' origins joined.
  const links = s.scene.links_mm;
  if (links.length) {
    polyline(g, P, [[0, 0, 0], ...links], "#5b6770", 7);
    g.fillStyle = "#20262d";
    for (const p of links) { const q = P(p); g.beginPath(); g.arc(q[0], q[1], 4, 0, 2 * Math.PI); g.fill(); }
  }
  if (s.scene.goal) drawCoil(g, P, s.scene.goal, "#1b8a3a", [5, 4]);
  if (s.scene.coil) drawCoil(g, P, s.scene.coil, "#d25f00");
  g.fillStyle = "#66707a"; g.font = "11px system-ui, sans-serif"; g.textAlign = "left";
  g.fillText(sc.robot + " · coil (orange) · goal (green, dashed) · head model · tracker", 8, c.height - 8);
}

function orbit() {
  const c = $("view3d");
  let drag = null;
  c.addEventListener("mousedown", (e) => { drag = [e.clientX, e.clientY]; });
  window.addEventListener("mouseup", () => { drag = null; });
  window.addEventListener("mousemove", (e) => {
    if (!drag) return;
    state.view.az -= (e.clientX - drag[0]) * 0.01;
    state.view.el = Math.max(-1.4, Math.min(1.4, state.view.el + (e.clientY - drag[1]) * 0.01));
    drag = [e.clientX, e.clientY];
    drawScene();
  });
  c.addEventListener("wheel", (e) => {
    e.preventDefault();
    state.view.dist = Math.max(0.3, Math.min(5, state.view.dist * (e.deltaY > 0 ? 1.1 : 0.9)));
    drawScene();
  }, { passive: false });
}

// ---- events ---------------------------------------------------------------------------------

function addEvent(e) {
  const body = document.querySelector("#events tbody");
  const tr = document.createElement("tr");
  tr.className = e.kind;
  for (const text of [fmt(e.t, 3), e.kind, e.text]) {
    const td = document.createElement("td"); td.textContent = text; tr.appendChild(td);
  }
  body.insertBefore(tr, body.firstChild);
  while (body.children.length > 500) body.removeChild(body.lastChild);
}

let eventsSeen = 0;
async function pollEvents() {
  const r = await api("GET", "/api/events");
  if (r.ok && Array.isArray(r.data)) {
    // The server keeps the newest 500; it only appends.
    const fresh = r.data.length >= eventsSeen ? r.data.slice(eventsSeen) : r.data;
    fresh.forEach(addEvent);
    eventsSeen = r.data.length;
  }
}

// ---- controls -------------------------------------------------------------------------------

async function command(path) {
  $("control-error").textContent = "";
  const r = await api("POST", path);
  if (!r.ok) $("control-error").textContent = (r.data && r.data.error) || ("refused: " + r.status);
}

function buttons() {
  $("hold").addEventListener("click", () => command("/api/hold"));
  $("resume").addEventListener("click", () => command("/api/resume"));
  $("stop").addEventListener("click", () => $("stop-dialog").showModal());
  $("cancel-stop").addEventListener("click", () => $("stop-dialog").close());
  $("confirm-stop").addEventListener("click", () => { $("stop-dialog").close(); command("/api/stop"); });
  $("teach").addEventListener("click", () => $("teach-dialog").showModal());
  $("cancel-teach").addEventListener("click", () => $("teach-dialog").close());
  $("confirm-teach").addEventListener("click", teach);
  $("freedrive").addEventListener("click", () => command("/api/freedrive"));
  $("handback").addEventListener("click", () => command("/api/handback"));
  $("go-target").addEventListener("click", async () => {
    $("control-error").textContent = "";
    const r = await api("POST", "/api/target", { name: $("target-select").value });
    if (!r.ok) $("control-error").textContent = (r.data && r.data.error) || ("refused: " + r.status);
  });
}

async function loadTargets() {
  const r = await api("GET", "/api/targets");
  if (!r.ok) return;
  const sel = $("target-select");
  const names = r.data.targets.map((t) => t.name);
  if (names.join("\n") === Array.from(sel.options).map((o) => o.value).join("\n")) return;
  sel.replaceChildren(...names.map((n) => { const o = document.createElement("option"); o.value = n; o.textContent = n; return o; }));
  sel.hidden = names.length === 0;
  $("go-target").hidden = names.length === 0;
}

async function teach() {
  $("teach-dialog").close();
  const out = $("teach-result");
  out.className = ""; out.textContent = "teaching…";
  const r = await api("POST", "/api/teach");
  if (r.ok) {
    out.className = "ok";
    out.textContent = "goal taught: " + fmt(r.data.distance_mm, 1) + " mm off the head" +
      (r.data.written ? ", written to " + r.data.written : "");
    await loadConfig();
  } else {
    out.className = "error";
    out.textContent = (r.data && r.data.error) || ("refused: " + r.status);
  }
}

// ---- tuning ---------------------------------------------------------------------------------

// The two forms: the loop's parameters, and the camera pipeline's (the simulated camera's
// [tracker.camera.params], or an Azure Kinect's [tracker.k4a.params]: whichever the session's
// tracker is). Each field's id is its prefix and key; its error is shown beside it.
const FORMS = {
  loop: { form: "params", input: "param-", error: "error-", result: "params-result", key: "loop." },
  camera: { form: "cam-params", input: "cam-", error: "cam-error-", result: "camera-result", key: "tracker.camera.params." },
};

// The camera section of the configuration in use: "k4a" for an Azure Kinect, else "camera".
function cameraSection() {
  return state.config && state.config.tracker.source === "k4a" ? "k4a" : "camera";
}

function show(value) {
  if (value === null || value === undefined) return "";
  return Array.isArray(value) ? value.join(", ") : String(value);
}

function buildForm(which, values) {
  const f = FORMS[which], form = $(f.form);
  form.textContent = "";
  for (const [key, value] of Object.entries(values)) {
    const label = document.createElement("label");
    label.htmlFor = f.input + key; label.textContent = key;
    const input = document.createElement("input");
    input.id = f.input + key; input.name = key; input.value = show(value);
    input.dataset.current = show(value);
    const err = document.createElement("span");
    err.id = f.error + key; err.className = "error";
    form.append(label, input, err);
  }
}

function parseValue(text) {
  const t = text.trim();
  if (t === "") return null;
  if (t === "true") return true;
  if (t === "false") return false;
  if (t.includes(",")) return t.split(",").map((x) => Number(x.trim()));
  const n = Number(t);
  // A value that is not a number goes as text: the server names the key and the type it wants.
  return Number.isFinite(n) ? n : t;
}

async function applyForm(which) {
  const f = FORMS[which], changed = {};
  document.querySelectorAll("#" + f.form + " input").forEach((input) => {
    $(f.error + input.name).textContent = "";
    input.classList.remove("invalid");
    if (input.value.trim() !== input.dataset.current) changed[input.name] = parseValue(input.value);
  });
  const result = $(f.result);
  result.className = ""; result.textContent = "";
  if (!Object.keys(changed).length) { result.textContent = "nothing changed"; return; }
  const body = which === "loop" ? { loop: changed } : { tracker: { [cameraSection()]: { params: changed } } };
  const r = await api("POST", "/api/params", body);
  if (r.ok) {
    result.className = "ok";
    result.textContent = "applied: " + (r.data.changed.join(", ") || "nothing changed");
    await loadConfig();
    return;
  }
  const key = r.data && r.data.key ? r.data.key : "";
  const name = key.startsWith(f.key) ? key.slice(f.key.length) : key;
  const msg = (r.data && r.data.error) || ("refused: " + r.status);
  if ($(f.error + name)) {
    $(f.error + name).textContent = msg;
    $(f.input + name).classList.add("invalid");
  }
  result.className = "error";
  result.textContent = key && !msg.startsWith(key) ? key + ": " + msg : msg;
}

async function loadConfig() {
  const r = await api("GET", "/api/config");
  if (!r.ok) return;
  state.config = r.data.config;
  $("auth").hidden = r.data.authorized;
  buildForm("loop", r.data.config.loop);
  FORMS.camera.key = "tracker." + cameraSection() + ".params.";
  buildForm("camera", r.data.config.tracker[cameraSection()].params);
}

// ---- the calibration collection -------------------------------------------------------------

function showCalibration(c) {
  $("calibration-panel").hidden = !c;
  if (!c) return;
  // No loop runs: its buttons have nothing to act on.
  for (const id of ["hold", "resume", "teach"]) $(id).disabled = true;
  $("start-calibration").disabled = c.state !== "waiting";
  $("cal-progress").max = Math.max(1, c.planned);
  $("cal-progress").value = c.done;
  let text = c.done + " of " + c.planned + " poses";
  if (c.missed.length) text += "; marker not seen at " + c.missed.join(", ");
  // The outcome says it all.
  if (c.message) text = c.message;
  $("cal-text").textContent = text;
}

function calibrationControls() {
  $("start-calibration").addEventListener("click", () => $("calibrate-dialog").showModal());
  $("cancel-calibrate").addEventListener("click", () => $("calibrate-dialog").close());
  $("confirm-calibrate").addEventListener("click", () => { $("calibrate-dialog").close(); command("/api/calibrate"); });
}

// ---- navigation: registration, pivot calibration ----------------------------------------------

function showNavigation(n) {
  $("navigation-panel").hidden = !n;
  if (!n) return;
  for (const id of ["hold", "resume", "teach"]) $(id).disabled = true;
  $("nav-task").textContent = "(" + n.task + ": " + n.state + ")";
  $("start-navigation").disabled = n.state !== "waiting";
  $("nav-step").textContent = n.state === "running" ? n.step : (n.state === "waiting" ? "press Start when the patient is ready" : "");
  $("nav-progress").max = Math.max(1, n.samples[1]);
  $("nav-progress").value = n.samples[0];
  $("nav-count").textContent = n.samples[0] + " of " + n.samples[1];
  const body = $("nav-landmarks").tBodies[0];
  if (body.rows.length !== n.landmarks.length) {
    body.replaceChildren(...n.landmarks.map(([name, spread]) => {
      const tr = document.createElement("tr");
      for (const v of [name, fmt(spread, 2)]) {
        const td = document.createElement("td");
        td.textContent = v;
        tr.appendChild(td);
      }
      return tr;
    }));
  }
  const list = $("nav-result");
  if (list.children.length !== n.result.length) {
    list.replaceChildren(...n.result.map((line) => {
      const li = document.createElement("li");
      li.textContent = line;
      return li;
    }));
  }
}

function navigationControls() {
  $("start-navigation").addEventListener("click", () => command("/api/navigate"));
}

// ---- the camera -----------------------------------------------------------------------------

const camera = { loading: false, drag: null, bitmap: null };

function imagePoint(e) {
  const c = $("ir-canvas"), box = c.getBoundingClientRect();
  const x = Math.round(((e.clientX - box.left) / box.width) * c.width);
  const y = Math.round(((e.clientY - box.top) / box.height) * c.height);
  return [Math.max(0, Math.min(c.width, x)), Math.max(0, Math.min(c.height, y))];
}

function drawCamera() {
  const c = $("ir-canvas"), g = c.getContext("2d");
  if (camera.bitmap) g.drawImage(camera.bitmap, 0, 0, c.width, c.height);
  if (camera.drag) {
    const [a, b] = camera.drag;
    g.strokeStyle = "#ff0"; g.setLineDash([4, 3]); g.lineWidth = 1;
    g.strokeRect(Math.min(a[0], b[0]) + 0.5, Math.min(a[1], b[1]) + 0.5, Math.abs(b[0] - a[0]), Math.abs(b[1] - a[1]));
    g.setLineDash([]);
  }
}

async function refreshFrame() {
  if ($("camera-panel").hidden || camera.loading) return;
  camera.loading = true;
  try {
    const r = await fetch("/api/frame.png", { credentials: "same-origin", cache: "no-store" });
    if (r.ok) {
      camera.bitmap = await createImageBitmap(await r.blob());
      drawCamera();
    }
  } catch (_) { /* the next refresh tries again */ }
  camera.loading = false;
}

function cameraControls() {
  const c = $("ir-canvas");
  c.addEventListener("mousedown", (e) => { const p = imagePoint(e); camera.drag = [p, p]; drawCamera(); });
  c.addEventListener("mousemove", (e) => { if (camera.drag) { camera.drag[1] = imagePoint(e); drawCamera(); } });
  window.addEventListener("mouseup", () => {
    if (!camera.drag) return;
    const [a, b] = camera.drag;
    camera.drag = null;
    if (Math.abs(b[0] - a[0]) < 4 || Math.abs(b[1] - a[1]) < 4) return;
    $("cam-scan_area").value = [Math.min(a[0], b[0]), Math.min(a[1], b[1]), Math.max(a[0], b[0]), Math.max(a[1], b[1])].join(", ");
    applyForm("camera");
  });
  $("apply-camera").addEventListener("click", () => applyForm("camera"));
  $("clear-scan-area").addEventListener("click", () => { $("cam-scan_area").value = ""; applyForm("camera"); });
  setInterval(refreshFrame, 200);
}

function showCamera(cam) {
  $("camera-panel").hidden = !cam;
  if (!cam) return;
  const rate = cam.frames ? (100 * cam.found) / cam.frames : 0;
  $("camera-meta").textContent = "frames " + cam.frames + " · found " + fmt(rate, 1) + " % · " +
    (cam.found_now ? "FRE " + fmt(cam.fre_mm, 2) + " mm" : "not found: " + (cam.not_found || "?")) +
    " · blobs " + cam.blobs;
}

// ---- MRI ------------------------------------------------------------------------------------
// Three slices of the patient's T1 through the target, from the server (GET /api/mri/slice.png:
// the image's voxels on its RAS axes, 1 px = step_mm); the target, the coil, the landmarks and
// the 10-20 positions drawn over them. A slice's pixel (u, v) has its centre at RAS
// bounds[right][0] + u·step along its right axis and bounds[up][1] − v·step along its up axis
// (crates/mocomp-mri/src/slice.rs).

const MRI_PLANES = { axial: [0, 1, 2], coronal: [0, 2, 1], sagittal: [1, 2, 0] }; // right, up, fixed
const MRI_NEAR_MM = 4;
const mri = { meta: null, at: null, window: null, bitmaps: {}, loading: false, pending: null, drawn: {} };
state.mri = mri;

// RAS (mm) to the slice's pixel (u, v) in `plane`, and the point's distance from the plane.
function mriPixel(plane, p) {
  const [r, u, f] = MRI_PLANES[plane], b = mri.meta.bounds_mm, s = mri.meta.step_mm;
  return [(p[r] - b[r][0]) / s, (b[u][1] - p[u]) / s, Math.abs(p[f] - mri.at[f])];
}

async function loadMri() {
  const m = await api("GET", "/api/mri");
  if (!m.ok || !m.data.available) { $("mri-panel").hidden = true; return; }
  mri.meta = m.data;
  mri.window = m.data.window.slice();
  $("mri-lo").value = mri.window[0];
  $("mri-hi").value = mri.window[1];
  $("mri-panel").hidden = false;
  $("mri-window").addEventListener("click", () => {
    const lo = parseFloat($("mri-lo").value), hi = parseFloat($("mri-hi").value);
    if (Number.isFinite(lo) && Number.isFinite(hi) && hi > lo) { mri.window = [lo, hi]; refreshSlices(mri.at); }
  });
}

async function refreshSlices(at) {
  if (!mri.meta || !at) return;
  // One request at a time; the newest asked for while one runs follows it.
  if (mri.loading) { mri.pending = at; return; }
  mri.loading = true;
  try {
    const got = {};
    for (const plane of Object.keys(MRI_PLANES)) {
      const q = "plane=" + plane + "&x=" + at[0] + "&y=" + at[1] + "&z=" + at[2] +
        "&lo=" + mri.window[0] + "&hi=" + mri.window[1];
      const r = await fetch("/api/mri/slice.png?" + q, { credentials: "same-origin", cache: "no-store" });
      if (!r.ok) return;
      got[plane] = await createImageBitmap(await r.blob());
    }
    mri.bitmaps = got;
    mri.at = at.slice();
    $("mri-at").textContent = "through " + at.map((v) => fmt(v, 1)).join(", ") + " mm (RAS)";
    drawMri();
  } catch (_) { /* the next status tries again */ } finally {
    mri.loading = false;
    if (mri.pending) { const p = mri.pending; mri.pending = null; refreshSlices(p); }
  }
}

function drawMri() {
  if (!mri.meta || !mri.at) return;
  const image = state.status && state.status.scene && state.status.scene.image;
  for (const plane of Object.keys(MRI_PLANES)) {
    const c = $("mri-" + plane), b = mri.bitmaps[plane];
    if (!b) continue;
    // Each slice pixel a k × k block, sharp: the overlays are drawn at the canvas's resolution.
    const k = Math.max(1, Math.floor(480 / Math.max(b.width, b.height)));
    if (c.width !== b.width * k || c.height !== b.height * k) { c.width = b.width * k; c.height = b.height * k; }
    const g = c.getContext("2d");
    g.imageSmoothingEnabled = false;
    g.drawImage(b, 0, 0, c.width, c.height);
    const at = (p) => { const [u, v, d] = mriPixel(plane, p); return [(u + 0.5) * k, (v + 0.5) * k, d]; };
    g.font = "11px system-ui, sans-serif";
    const label = (x, y, text, color) => { g.fillStyle = color; g.fillText(text, x + 5, y - 4); };
    for (const e of mri.meta.eeg) {
      const [x, y, d] = at(e.p_mm);
      if (d > MRI_NEAR_MM) continue;
      g.fillStyle = "#3cd6e6"; g.beginPath(); g.arc(x, y, 3, 0, 2 * Math.PI); g.fill();
      label(x, y, e.name, "#3cd6e6");
    }
    for (const l of mri.meta.landmarks) {
      const [x, y, d] = at(l.p_mm);
      if (d > MRI_NEAR_MM) continue;
      g.fillStyle = "#ffd400"; g.fillRect(x - 3, y - 3, 6, 6);
      label(x, y, l.name, "#ffd400");
    }
    const axis = (pose, color, width, dash) => {
      const [x, y] = at(pose.p_mm);
      const tip = pose.p_mm.map((v, i) => v + 40 * pose.axis[i]);
      const [tx, ty] = at(tip);
      g.strokeStyle = color; g.lineWidth = width; g.setLineDash(dash);
      g.beginPath(); g.moveTo(x, y); g.lineTo(tx, ty); g.stroke(); g.setLineDash([]);
      return [x, y];
    };
    const drawn = {};
    if (image && image.coil) {
      const [x, y] = axis(image.coil, "#ff8c1a", 2.5, []);
      g.strokeStyle = "#ff8c1a"; g.lineWidth = 2; g.beginPath(); g.arc(x, y, 6, 0, 2 * Math.PI); g.stroke();
      const [u, v] = mriPixel(plane, image.coil.p_mm);
      drawn.coil_px = [u, v];
    }
    // The target last: over the coil that sits on it.
    const goal = image ? image.goal : null;
    if (goal) {
      const [x, y] = axis(goal, "#22c55e", 1.5, [5, 4]);
      g.strokeStyle = "#22c55e"; g.lineWidth = 2; g.beginPath();
      g.moveTo(x - 9, y); g.lineTo(x + 9, y); g.moveTo(x, y - 9); g.lineTo(x, y + 9); g.stroke();
      const [u, v] = mriPixel(plane, goal.p_mm);
      drawn.target_px = [u, v];
    }
    g.lineWidth = 1;
    drawn.scale = k;
    mri.drawn[plane] = drawn;
  }
}

function showMri(s) {
  if (!mri.meta) return;
  const image = s.scene && s.scene.image;
  const goal = image && image.goal && image.goal.p_mm;
  // Through the target: new slices when it moved (another target) by more than a pixel.
  if (goal && (!mri.at || Math.hypot(...goal.map((v, i) => v - mri.at[i])) > mri.meta.step_mm)) {
    refreshSlices(goal);
  }
  drawMri();
}

// ---- start ----------------------------------------------------------------------------------

async function start() {
  buttons();
  orbit();
  cameraControls();
  calibrationControls();
  navigationControls();
  $("apply-params").addEventListener("click", () => applyForm("loop"));
  const sc = await api("GET", "/api/scene");
  if (sc.ok) state.scene = sc.data;
  const h = await api("GET", "/api/history");
  if (h.ok) state.history = h.data;
  await loadConfig();
  await loadMri();
  const s = await api("GET", "/api/status");
  if (s.ok) showStatus(s.data);
  await pollEvents();
  setInterval(pollEvents, 500);
  // The session's targets are known once the loop has started.
  await loadTargets();
  setInterval(loadTargets, 2000);
  connect();
}

start();
