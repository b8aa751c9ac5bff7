// seqrun operator console: one page over the /api/v1 HTTP API and the live WebSocket.
// STOP is sent on the WebSocket (HTTP when it is down) and never waits for anything else.
import { ArmView, frames } from "/static/view3d.js";

const API = "/api/v1";
const $ = (sel) => document.querySelector(sel);
const el = (tag, props = {}, ...children) => {
  const node = Object.assign(document.createElement(tag), props);
  for (const c of children) node.append(c);
  return node;
};
// ?draw=0 (benchmarks): count the telemetry, draw nothing (what drawing costs, isolated).
const DRAW = new URLSearchParams(location.search).get("draw") !== "0";
const fmt = (v, digits = 2) => (v === null || v === undefined ? "-" : Number(v).toFixed(digits));

const state = {
  arm: null, view: null, ws: null, client: null, msgId: 0, status: null,
  latched: {}, poses: [], hoverPose: null, slidersTouched: false,
  jog: null, question: null, selected: null, checked: null,
  statusCount: 0, eventCount: 0, lastReplies: [], stopTimes: [],
  control: null, lost: true, lastHeardAt: 0, pendingStop: null,
};
window.seqrunConsole = state;  // for the browser tests and the bench
state.frames = frames;

// ---------------------------------------------------------------- messages and HTTP
function say(text, isError = false) {
  const m = $("#message");
  m.textContent = text;
  m.className = isError ? "error" : "";
  m.title = text;
}

async function api(method, path, body) {
  const headers = { Accept: "application/json" };
  if (state.client) headers["X-Seqrun-Client"] = state.client;
  if (body !== undefined) headers["Content-Type"] = "application/json";
  let response;
  try {
    response = await fetch(API + path, { method, headers, body: body === undefined ? undefined : JSON.stringify(body) });
  } catch (err) {
    say(`${method} ${path}: the console does not answer (${err.message})`, true);
    throw err;
  }
  const data = await response.json().catch(() => ({}));
  if (!response.ok) {
    say(data.error || `${method} ${path}: HTTP ${response.status}`, true);
    const error = new Error(data.error || String(response.status));
    error.status = response.status;
    throw error;
  }
  return data;
}

async function command(label, method, path, body) {
  try {
    const result = await api(method, path, body);
    say(result && result.message ? `${label}: ${result.message}` : `${label}: ok`);
    return result;
  } catch (err) {
    return null;  // already on screen
  }
}

// ---------------------------------------------------------------- STOP
// event: the click or key (its timeStamp is when the operator pressed; the bench reads it).
// Sent on the live connection; when that is down, or has not confirmed within
// STOP_CONFIRM_MS, over HTTP as well; when neither answers, the page says so in full.
const STOP_CONFIRM_MS = 1500;
const STOP_FAILED = "STOP FAILED: the console is unreachable and the arm's state is unknown - use the emergency stop";

function stop(event) {
  state.stopTimes.push(performance.timeOrigin + (event ? event.timeStamp : performance.now()));
  $("#stop").classList.add("pressed");
  setTimeout(() => $("#stop").classList.remove("pressed"), 200);
  releaseJog(false);
  if (state.ws && state.ws.readyState === WebSocket.OPEN && !state.lost) {
    const id = ++state.msgId;
    state.pendingStop = id;
    state.ws.send(JSON.stringify({ op: "halt", id, reason: "STOP (console)" }));
    say("STOP sent");
    setTimeout(() => {
      if (state.pendingStop === id) stopOverHttp("the live connection did not confirm it");
    }, STOP_CONFIRM_MS);
  } else {
    say("STOP sent (no live connection)");
    stopOverHttp("no live connection");
  }
}

async function stopOverHttp(why) {
  const abort = new AbortController();
  const timer = setTimeout(() => abort.abort(), STOP_CONFIRM_MS);
  try {
    const response = await fetch(API + "/halt", {
      method: "POST", headers: { "Content-Type": "application/json", Accept: "application/json" },
      body: JSON.stringify({ reason: `STOP (console, ${why})` }), signal: abort.signal });
    const data = await response.json();
    state.pendingStop = null;
    say(data.message || data.error || `STOP: HTTP ${response.status}`, !data.halt_confirmed);
  } catch (err) {
    stopFailed();
  } finally {
    clearTimeout(timer);
  }
}

function stopFailed() {
  state.pendingStop = null;
  say(STOP_FAILED, true);
  // in full where nothing cuts it short, whether or not contact was lost before
  if (!state.lost) setLost(true, "");
  $("#lost-stop").textContent = STOP_FAILED;
  $("#lost-stop").hidden = false;
}

function isTyping(target) {
  return target && target.tagName === "INPUT" && target.type === "text";
}

window.addEventListener("keydown", (e) => {
  if (e.key === "Escape" || (e.code === "Space" && !isTyping(e.target))) {
    e.preventDefault();
    e.stopPropagation();
    if (!e.repeat) stop(e);
  }
}, true);
// Space would also click a focused button on release: never let it.
window.addEventListener("keyup", (e) => {
  if (e.code === "Space" && !isTyping(e.target)) { e.preventDefault(); e.stopPropagation(); }
}, true);

// ---------------------------------------------------------------- live connection
// The console sends a status at least every 0.5 s: a page that heard nothing for LOST_MS
// (a console killed, frozen or cut off without a TCP close) has lost contact.
const LOST_MS = 2000;

function connect() {
  const ws = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}${API}/live`);
  state.ws = ws;
  // A ping every 0.5 s: the server takes a page silent for 2 s during its motion as gone.
  let ping = null;
  ws.onopen = () => {
    $("#conn").textContent = "live"; $("#conn").className = "badge on";
    ping = setInterval(() => { if (ws.readyState === WebSocket.OPEN) ws.send('{"op":"ping"}'); }, 500);
  };
  ws.onclose = () => {
    clearInterval(ping);
    $("#conn").textContent = "offline"; $("#conn").className = "badge off";
    state.client = null;
    releaseJog(false);
    setLost(true, "The live connection closed.");
    setTimeout(connect, 1000);
  };
  ws.onmessage = (msg) => {
    state.lastHeardAt = performance.now();
    if (state.lost && state.client) setLost(false);  // a console that was frozen, back
    const data = JSON.parse(msg.data);
    if (data.type === "status") showStatus(data.status);
    else if (data.type === "event") showEvent(data.event);
    else if (data.type === "hello") {
      state.client = data.client;
      setLost(false);
      showControl(data.control);
      showStatus(data.status);
    } else if (data.type === "reply") onReply(data);
  };
}

setInterval(() => {
  if (!state.lost && performance.now() - state.lastHeardAt > LOST_MS) {
    setLost(true, `No word from the console for ${LOST_MS / 1000} s.`);
  }
}, 250);

// Lost contact: whatever the page shows is old. Everything greys out under a banner, the
// activity reads "unknown"; STOP stays red and still tries (and says if it fails).
function setLost(lost, why = "") {
  if (lost === state.lost && (!lost || !why)) return;
  state.lost = lost;
  document.body.classList.toggle("lost", lost);
  $("#lost-banner").hidden = !lost;
  $("#lost-why").textContent = why;
  if (!lost) $("#lost-stop").hidden = true;
  if (lost) {
    setText($("#activity"), "unknown");
    $("#activity").className = "badge unknown";
    say("The console is unreachable: the arm's state is unknown - use the emergency stop", true);
  } else {
    if (state.status) drawBadges(state.status);
    if ($("#message").textContent.startsWith("The console is unreachable")) say("");
  }
  applyControl();
}

function onReply(reply) {
  state.lastReplies.push(reply);
  if (state.lastReplies.length > 50) state.lastReplies.shift();
  if (reply.id !== null && reply.id === state.pendingStop) state.pendingStop = null;
  if (reply.note) say(reply.note, true);
  if (!reply.ok) {
    say(reply.error, true);
    if (state.jog) releaseJog(false);
  } else if (reply.result && reply.result.message) {
    say(reply.result.message, !reply.result.confirmed && reply.result.confirmed !== undefined);
  }
}

// ---------------------------------------------------------------- telemetry
// Every status is received, counted and kept as it arrives (up to 100 a second during a
// move); faults are latched from every one. Painting is what costs: every frame the browser
// paints (new numbers or a new 3D picture) is rasterised and composited, in software on a PC
// without a GPU, on the cores the 100 Hz control loop needs. So the page paints in frames of
// its own, only when something changed, numbers and 3D view in the same frame, at most
// frameHz() frames a second (the numbers at most NUMBERS_HZ): none while hidden.
// Flags shown as A|B|C, with a line break allowed after each bar (a narrow panel wraps there).
const FLAG_SEP = "|\u200b";
// The numbers never wait for the 3D view: they are drawn on a timer of their own (at most
// NUMBERS_HZ), the 3D view in animation frames of its own (at most frameHz(): with WebGL in
// software a frame can take a quarter of a second). What must be seen at once - the
// activity (HALTED), lost contact - is drawn the moment it arrives.
const NUMBERS_HZ = 10;
const NUMBERS_HZ_SLOW = 4;   // without the focus
const FRAME_HZ = 20;         // the focused page on a GPU
const FRAME_HZ_SLOW = 4;     // without the focus, or with software-rendered WebGL
state.drawCount = 0;  // redraws of the numbers (tests, bench)

function frameHz() {
  if (document.hidden) return 0;
  if (!document.hasFocus() || (state.view && state.view.software)) return FRAME_HZ_SLOW;
  return FRAME_HZ;
}

function numbersHz() {
  if (document.hidden) return 0;
  return document.hasFocus() ? NUMBERS_HZ : NUMBERS_HZ_SLOW;
}

function showStatus(s) {
  const before = state.status;
  state.status = s;
  state.statusCount += 1;
  if (!DRAW) return;
  for (const j of s.joints) if (j.fault) state.latched[j.name] = j.flags.join(FLAG_SEP);
  if (!before || before.activity !== s.activity || before.stale !== s.stale) drawBadges(s);
  state.statusDirty = true;
  scheduleNumbers();
  if (state.view) { state.view.setMeasured(s.joints.map((j) => j.position_deg)); scheduleView(); }
}

function scheduleNumbers() {
  const hz = numbersHz();
  if (state.numbersPending || hz === 0 || !state.status) return;
  state.numbersPending = true;
  const wait = Math.max(0, (state.drawnAt ?? -Infinity) + 1000 / hz - performance.now());
  setTimeout(() => {
    state.numbersPending = false;
    if (document.hidden) return;  // drawn when shown again (visibilitychange)
    state.drawnAt = performance.now();
    if (state.statusDirty) {
      state.statusDirty = false;
      drawStatus(state.status);
    }
  }, wait);
}

function scheduleView() {
  const hz = frameHz();
  if (state.framePending || hz === 0 || !state.view) return;
  state.framePending = true;
  const wait = Math.max(0, (state.frameAt ?? -Infinity) + 1000 / hz - performance.now());
  setTimeout(() => requestAnimationFrame((now) => {
    state.framePending = false;
    if (document.hidden) return;  // drawn when shown again (visibilitychange)
    state.frameAt = now;
    state.view.renderIfDirty();
  }), wait);
}
for (const [target, kind] of [[document, "visibilitychange"], [window, "focus"]]) {
  target.addEventListener(kind, () => { scheduleNumbers(); scheduleView(); });
}

// textContent only when it changed: an unchanged field costs no layout.
function setText(node, text) {
  if (node.textContent !== text) node.textContent = text;
}

function drawBadges(s) {
  if (state.lost) return;  // "unknown" until contact is back
  const act = $("#activity");
  setText(act, s.stale ? `${s.activity} (stale)` : s.activity);
  act.className = `badge ${s.activity}`;
}

function drawStatus(s) {
  state.drawCount += 1;
  const title = s.simulator ? "seqrun console - SIMULATOR" : `seqrun console - ${s.bus}`;
  if (document.title !== title) {
    document.title = title;
    $("#title").textContent = title;
    $("#title").className = s.simulator ? "sim" : "";
  }
  drawBadges(s);
  setText($("#zero"), s.zero_reference ? `zero: ${s.zero_reference}` : "");
  setText($("#bus"), s.bus);
  setText($("#updated"), s.updated_at === null ? "never" : fmt(s.updated_at, 2));
  const rows = $("#telemetry tbody");
  s.joints.forEach((j, i) => {
    let row = rows.children[i];
    if (!row) {
      row = el("tr", { id: `tlm-${j.name}` }, el("td", { textContent: j.name }), el("td", { className: "pos" }),
        el("td", { className: "vel" }), el("td", { className: "target" }), el("td", { className: "flags" }));
      rows.append(row);
    }
    setText(row.children[1], fmt(j.position_deg));
    setText(row.children[2], fmt(j.velocity_deg_s));
    setText(row.children[3], fmt(j.target_deg));
    if (j.fault) state.latched[j.name] = j.flags.join(FLAG_SEP);
    const latched = state.latched[j.name];
    setText(row.children[4], j.fault ? j.flags.join(FLAG_SEP) : (latched ? `${j.flags.join(FLAG_SEP)} (was ${latched})` : j.flags.join(FLAG_SEP)));
    row.className = [j.fault || latched ? "fault" : "", latched ? "latched" : "", j.locked ? "locked" : ""].join(" ").trim();
  });
  $("#ack-faults").disabled = Object.keys(state.latched).length === 0;
  const ee = s.end_effector;
  setText($("#ee-xyz"), ee ? ee.position_mm.map((v) => fmt(v, 1)).join("  ") : "-");
  setText($("#ee-rpy"), ee ? ee.rpy_deg.map((v) => fmt(v, 2)).join("  ") : "-");
  const q = s.joints.map((j) => j.position_deg);
  if (!state.slidersTouched) setSliders(q);
  updateGhost();
  highlightStep(s.run);
}

$("#ack-faults").addEventListener("click", () => {
  const s = state.status;
  for (const name of Object.keys(state.latched)) {
    const joint = s && s.joints.find((j) => j.name === name);
    if (!joint || !joint.fault) delete state.latched[name];  // a fault still present stays
  }
  if (s) drawStatus(s);
});

// ---------------------------------------------------------------- events
function summary(e) {
  const keys = ["message", "label", "text", "reason", "status", "kind", "error", "cause"];
  const parts = keys.filter((k) => e[k] !== undefined && e[k] !== null && e[k] !== "").map((k) => String(e[k]));
  return [...new Set(parts)].join(" - ");
}

function showEvent(e) {
  state.eventCount += 1;
  const bad = ["fault", "internal_error", "halt_unconfirmed", "halt_failed", "latched_fault", "session_halt", "halt_requested"];
  const warn = ["controlled_stop", "operator_abort", "abort_requested", "paused", "status_poll_failed"];
  const item = el("li", { className: bad.includes(e.type) ? "bad" : warn.includes(e.type) ? "warn" : "",
    textContent: `${fmt(e.t, 2)} ${e.type}${e.step ? ` [${e.step}]` : ""} ${summary(e)}` });
  const log = $("#events");
  log.append(item);
  while (log.children.length > 400) log.firstChild.remove();
  log.scrollTop = log.scrollHeight;
  if (e.type === "activity_finished" && e.exit_code !== 0) say(`${e.kind} ${e.status}: ${e.message}`, true);
  if (e.type === "activity_started" && !ownSliderMove(e)) followArm();
  if (e.type === "activity_finished") followArm();
  if (["control_taken", "control_released", "client_joined", "client_left"].includes(e.type)) {
    const took = e.type === "control_taken" && e.previous && e.previous.id === state.client
      && (!e.holder || e.holder.id !== state.client);
    if (took) say(`Control taken by ${e.holder.name}: this page watches now (STOP still works)`, true);
    showControl(e);
  }
  if (e.type === "confirm_requested") askOperator(e);
  else if (e.type === "confirm_answered" && state.question && state.question.question_id === e.question_id) closeQuestion();
  else if (e.type === "run_finished" || e.type === "activity_finished") { if (e.type === "run_finished") loadRuns(); closeQuestionIfRunEnded(e); }
  else if (e.type === "step_started") markStep(e.step);
  else if (e.type === "run_started") markStep(0);
}

// ---------------------------------------------------------------- control
// One page or API client holds control and commands; the others watch (their commands are
// disabled; STOP, Pause and Abort never are) and may take control explicitly.
function myName() {
  const me = state.control && state.control.clients.find((c) => c.id === state.client);
  return me ? me.name : null;
}

function holdsControl() {
  return Boolean(!state.lost && state.control && state.control.holder && state.client
    && state.control.holder.id === state.client);
}

function showControl(c) {
  if (!c) return;
  state.control = { holder: c.holder ?? null, clients: c.clients ?? [] };
  applyControl();
}

function applyControl() {
  const c = state.control || { holder: null, clients: [] };
  const mine = holdsControl();
  const badge = $("#control-state");
  badge.textContent = state.lost ? "control: unknown" : mine ? "in control" : c.holder ? "watching" : "nobody in control";
  badge.className = `badge ${state.lost ? "unknown" : mine ? "mine" : "watching"}`;
  badge.title = c.holder ? `${c.holder.name} holds control` : "nobody holds control";
  $("#take-control").hidden = mine || state.lost || !state.client;
  const others = c.clients.filter((x) => x.id !== state.client).map((x) => x.name + (c.holder && x.id === c.holder.id ? " (in control)" : ""));
  $("#clients").textContent = state.lost ? "The console is unreachable: who holds control is unknown."
    : mine ? `You hold control.${others.length ? ` Watching: ${others.join(", ")}.` : ""}`
    : `${c.holder ? `${c.holder.name} holds control` : "Nobody holds control"}: this page watches (STOP, Pause and Abort still work).`;
  document.body.classList.toggle("watching", !mine);
  document.querySelectorAll(".needs-control").forEach((b) => {
    b.disabled = !mine || (b.dataset.why !== undefined);
  });
  if (state.question) showQuestionWho(state.question);
}

$("#take-control").addEventListener("click", () => {
  const holder = state.control && state.control.holder;
  if (holder && !window.confirm(`${holder.name} holds control. Take it? (That page is told.)`)) return;
  command("Take control", "POST", "/control/take");
});

// ---------------------------------------------------------------- confirm dialog
function askOperator(e) {
  state.question = e;
  $("#confirm-text").textContent = e.text;
  showQuestionWho(e);
  $("#confirm-dialog").hidden = false;
}

function showQuestionWho(e) {
  $("#confirm-who").textContent = e.local ? "" : `Asked by the run ${e.started_by ? `${e.started_by} started` : "under way"}.`;
  const mine = holdsControl();
  const holder = state.control && state.control.holder;
  $("#confirm-note").hidden = mine;
  $("#confirm-note").textContent = mine ? "" : `Only the page in control answers (${holder ? holder.name : "nobody holds control"}).`;
}
function closeQuestion() { state.question = null; $("#confirm-dialog").hidden = true; }
function closeQuestionIfRunEnded(e) { if (e.type === "run_finished") closeQuestion(); }
async function answer(yes) {
  if (!state.question) return;
  const question = state.question;
  closeQuestion();
  if (question.local === "shutdown") {  // the page's own question, not the session's
    if (yes) await command("Shutdown", "POST", "/shutdown");
    return;
  }
  const id = question.question_id;
  await command(yes ? "Yes" : "No", "POST", "/answer", { question_id: id, yes });
}
$("#confirm-yes").addEventListener("click", () => answer(true));
$("#confirm-no").addEventListener("click", () => answer(false));

// ---------------------------------------------------------------- commands
// pointerdown, not click: STOP acts when pressed, not when released.
$("#stop").addEventListener("pointerdown", (e) => { if (e.button === 0) stop(e); });
$("#stop").addEventListener("keydown", (e) => { if (e.key === "Enter") { e.preventDefault(); stop(e); } });
$("#cmd-arm").addEventListener("click", () => command("Arm", "POST", "/arm-up"));
$("#cmd-home").addEventListener("click", () => command("Home", "POST", "/home"));
$("#cmd-reset").addEventListener("click", () => command("Reset", "POST", "/reset"));
$("#cmd-shutdown").addEventListener("click", () => {
  state.question = { question_id: null, local: "shutdown" };
  $("#confirm-text").textContent = "Shut down: run the shutdown sequence (the arm goes to Totem, then you switch the supply off)?";
  $("#confirm-dialog").hidden = false;
});
$("#cmd-save-pose").addEventListener("click", async () => {
  const name = $("#pose-name").value.trim();
  const result = await command("Save pose", "POST", "/poses", { name, overwrite: $("#pose-overwrite").checked });
  if (result) { say(`pose '${name}' saved to ${result.saved}`); loadPoses(); }
});

// ---- poses
async function loadPoses() {
  state.poses = await api("GET", "/poses").catch(() => []);
  const box = $("#poses");
  box.replaceChildren();
  for (const p of state.poses) {
    const b = el("button", { type: "button", textContent: p.name, title: p.description || p.file, className: "needs-control" });
    b.dataset.pose = p.name;
    if (p.error || p.move_target === false) { b.dataset.why = p.why || p.error; b.title = b.dataset.why; }
    b.addEventListener("click", () => command(`To ${p.name}`, "POST", "/move/pose", { name: p.name }));
    const show = () => { state.hoverPose = p; updateGhost(); };
    const hide = () => { if (state.hoverPose === p) state.hoverPose = null; updateGhost(); };
    b.addEventListener("pointerenter", show); b.addEventListener("focus", show);
    b.addEventListener("pointerleave", hide); b.addEventListener("blur", hide);
    box.append(b);
  }
  applyControl();
}

// ---- MOVE sliders and ALLVEL boxes
function buildJointControls() {
  const body = $("#move-table tbody");
  const vel = $("#vel-boxes");
  const jog = $("#jog");
  for (const j of state.arm.joints) {
    const [lo, hi] = j.limits_deg;
    const slider = el("input", { type: "range", min: lo, max: hi, step: 0.1, value: 0, className: "move-slider", disabled: j.locked !== null });
    const number = el("input", { type: "number", min: lo, max: hi, step: 0.1, value: 0, className: "move-number", disabled: j.locked !== null });
    slider.dataset.joint = j.name; number.dataset.joint = j.name;
    slider.addEventListener("input", () => { number.value = slider.value; state.slidersTouched = true; updateGhost(); });
    number.addEventListener("input", () => { slider.value = number.value; state.slidersTouched = true; updateGhost(); });
    body.append(el("tr", {}, el("td", { textContent: j.name }), el("td", {}, slider), el("td", {}, number)));
    const box = el("input", { type: "number", min: 0.1, max: j.max_velocity_deg_s, step: 0.5, className: "vel-box", title: `${j.name}, at most ${j.max_velocity_deg_s} deg/s`, disabled: j.locked !== null });
    box.dataset.joint = j.name;
    box.placeholder = j.name;
    vel.append(box);
    if (j.locked === null) {
      const minus = el("button", { type: "button", textContent: `${j.name} -`, className: "jog-minus needs-control" });
      const plus = el("button", { type: "button", textContent: `${j.name} +`, className: "jog-plus needs-control" });
      minus.dataset.joint = j.name; plus.dataset.joint = j.name;
      holdToJog(minus, j.name, -1); holdToJog(plus, j.name, +1);
      jog.append(el("span", { className: "jog-pair" }, minus, plus));
    }
  }
}

function setSliders(q) {
  const numbers = document.querySelectorAll(".move-number");
  document.querySelectorAll(".move-slider").forEach((s, i) => {
    const v = q[state.arm.joints.findIndex((j) => j.name === s.dataset.joint)];
    if (v === null || v === undefined) return;
    const text = v.toFixed(1);
    if (numbers[i].value !== text) { s.value = text; numbers[i].value = text; }
  });
}

function sliderTargets() {
  const out = {};
  document.querySelectorAll(".move-number").forEach((n) => { if (!n.disabled) out[n.dataset.joint] = Number(n.value); });
  return out;
}

function updateGhost() {
  if (!state.view || !state.status) return;
  const measured = state.status.joints.map((j) => j.position_deg);
  if (state.hoverPose && state.hoverPose.joints_deg) {
    state.view.setGhost(state.arm.joints.map((j) => state.hoverPose.joints_deg[j.name] ?? 0));
    return;
  }
  if (state.slidersTouched) {
    const targets = sliderTargets();
    const q = state.arm.joints.map((j, i) => (j.name in targets ? targets[j.name] : measured[i]));
    const differs = q.some((v, i) => measured[i] !== null && Math.abs(v - measured[i]) > 0.1);
    state.view.setGhost(differs ? q : null);
    return;
  }
  state.view.setGhost(null);
}

// The sliders and the ghost follow the arm again once something else moves it (a run, a
// pose, a jog, another page) and when any activity ends; only this page's own MOVE keeps
// its targets on show while it runs.
function followArm() {
  state.slidersTouched = false;
  if (state.status) setSliders(state.status.joints.map((j) => j.position_deg));
  updateGhost();
}

function ownSliderMove(e) {
  return e.kind === "move" && e.detail && e.detail.joints && e.detail.by && e.detail.by === myName();
}

$("#move-from-arm").addEventListener("click", followArm);
// MOVE sends the joints whose target differs from where they are: the others stay (and a
// joint that stands just outside its limits, as j4 at Park, is not asked to go there).
function changedTargets() {
  const targets = sliderTargets();
  const now = state.status ? state.status.joints : [];
  const changed = {};
  for (const [name, value] of Object.entries(targets)) {
    const joint = now.find((j) => j.name === name);
    if (!joint || joint.position_deg === null || Math.abs(value - joint.position_deg) > 0.05) changed[name] = value;
  }
  return changed;
}
$("#cmd-move").addEventListener("click", () => {
  const joints = changedTargets();
  if (Object.keys(joints).length === 0) { say("MOVE: every target is where the arm is already"); return; }
  command("MOVE", "POST", "/move/joints", { joints });
});
$("#cmd-allvel").addEventListener("click", () => {
  const joints = {};
  document.querySelectorAll(".vel-box").forEach((b) => { if (b.value !== "") joints[b.dataset.joint] = Number(b.value); });
  command("ALLVEL", "POST", "/velocities", { joints });
});

// ---- gripper: its state (read when the session is idle), Grip and Release (need control)
async function showGripper() {
  let g;
  try { g = await api("GET", "/gripper"); } catch (err) { return; }
  const panel = $("#gripper-panel");
  panel.hidden = g === null;
  if (g === null) return;
  $("#gripper-name").textContent = `(${g.name}, stroke ${g.stroke_mm} mm, at most ${g.max_force_n} N)`;
  $("#gripper-state").textContent = g.error ? `no reading: ${g.error}`
    : `${g.width_mm.toFixed(1)} mm open, ${g.holding ? "holding a part" : "not holding"}${g.faulted ? ", FAULT " + g.state : ""}`;
}
$("#cmd-grip").addEventListener("click", () => {
  command("Grip", "POST", "/gripper/grip", { part_width_mm: Number($("#grip-width").value), force_n: Number($("#grip-force").value) });
});
$("#cmd-release").addEventListener("click", () => {
  command("Release", "POST", "/gripper/release", { width_mm: Number($("#release-width").value) });
});
showGripper();
setInterval(showGripper, 2000);

// ---- jog: hold to move, renewed every 100 ms (the server stops it 200 ms after the last)
$("#jog-scale").addEventListener("input", () => { $("#jog-scale-value").textContent = `${Math.round($("#jog-scale").value * 100)} %`; });

function sendJog() {
  if (!state.jog || !state.ws || state.ws.readyState !== WebSocket.OPEN) return;
  const scale = Number($("#jog-scale").value) * state.jog.direction;
  const mode = $("#jog-velocity-mode").checked ? "velocity" : "position";
  state.ws.send(JSON.stringify({ op: "jog", id: ++state.msgId, joint: state.jog.joint, speed_scale: scale, mode }));
}

function holdToJog(button, joint, direction) {
  button.addEventListener("pointerdown", (e) => {
    e.preventDefault();
    button.setPointerCapture(e.pointerId);
    releaseJog(false);
    state.jog = { joint, direction, button, timer: setInterval(sendJog, 100) };
    button.classList.add("held");
    sendJog();
  });
  for (const ev of ["pointerup", "pointercancel", "lostpointercapture"]) button.addEventListener(ev, () => releaseJog(true));
  button.addEventListener("contextmenu", (e) => e.preventDefault());  // a tablet's long press
}

function releaseJog(sendStop) {
  const jog = state.jog;
  if (!jog) return;
  clearInterval(jog.timer);
  jog.button.classList.remove("held");
  state.jog = null;
  if (sendStop && state.ws && state.ws.readyState === WebSocket.OPEN) {
    state.ws.send(JSON.stringify({ op: "jog_stop", id: ++state.msgId }));
  }
}
window.addEventListener("blur", () => releaseJog(true));
document.addEventListener("visibilitychange", () => { if (document.hidden) releaseJog(true); });

// ---------------------------------------------------------------- sequences
async function loadSequences() {
  const list = await api("GET", "/sequences").catch(() => []);
  const ul = $("#sequences");
  ul.replaceChildren();
  for (const s of list) {
    const b = el("button", { type: "button", textContent: s.name, title: s.file });
    b.dataset.sequence = s.name;
    b.addEventListener("click", () => openSequence(s.name));
    const li = el("li", {}, b);
    li.dataset.sequence = s.name;
    ul.append(li);
  }
}

async function openSequence(name) {
  state.selected = name;
  document.querySelectorAll("#sequences li").forEach((li) => li.classList.toggle("selected", li.dataset.sequence === name));
  $("#seq-detail").hidden = false;
  $("#seq-name").textContent = name;
  $("#seq-findings").replaceChildren(el("p", { className: "dim", textContent: "validating and dry-running..." }));
  $("#seq-dryrun").replaceChildren();
  $("#seq-steps").replaceChildren();
  let check;
  try { check = await api("POST", `/sequences/${encodeURI(name)}/check`); } catch (err) { $("#seq-findings").replaceChildren(); return; }
  if (state.selected !== name) return;
  state.checked = check;
  const findings = [el("p", { className: check.valid ? "passed" : "failed", id: "seq-verdict", textContent: check.valid ? "valid" : `invalid: ${check.errors.length} error(s)` })];
  for (const e of check.errors) findings.push(el("div", { className: "finding error", textContent: e.text }));
  for (const n of check.notes) findings.push(el("div", { className: "finding note", textContent: n.text }));
  $("#seq-findings").replaceChildren(...findings);
  if (check.dry_run) {
    const d = check.dry_run;
    const rows = d.steps.map((s) => el("tr", {}, el("td", { textContent: s.number }), el("td", { textContent: s.label }),
      el("td", { className: s.status === "passed" ? "passed" : "failed", textContent: s.status }),
      el("td", { textContent: s.planned_duration_s === null || s.planned_duration_s === undefined ? "" : `${fmt(s.planned_duration_s)} s` }),
      el("td", { textContent: s.duration_s === null || s.duration_s === undefined ? "" : `${fmt(s.duration_s)} s` })));
    $("#seq-dryrun").replaceChildren(
      el("p", { className: d.passed ? "passed" : "failed", textContent: `dry run ${d.passed ? "passed" : "FAILED"}: ${fmt(d.simulated_s)} s simulated${d.message ? ` - ${d.message}` : ""}` }),
      el("table", { className: "joints", id: "dry-run-steps" }, el("thead", {}, el("tr", {}, ...["#", "step", "result", "planned", "simulated"].map((h) => el("th", { textContent: h })))), el("tbody", {}, ...rows)));
  }
  $("#seq-steps").replaceChildren(...check.steps.map((s) => {
    const li = el("li", { textContent: s.label });
    li.dataset.step = s.number;
    return li;
  }));
  if (state.status) highlightStep(state.status.run);
}

function markStep(step) {
  document.querySelectorAll("#seq-steps li").forEach((li) => {
    const n = Number(li.dataset.step);
    li.classList.toggle("current", n === step);
    li.classList.toggle("done", n < step);
  });
}

// The step under way stays marked after the run ends (where it ended); a new run clears it.
function highlightStep(run) {
  if (!run || !state.checked || !run.file) return;
  if (!run.file.endsWith(state.checked.sequence)) return;
  if (run.step) markStep(run.step);
}

$("#run").addEventListener("click", () => {
  if (!state.selected) return;
  command(`Run ${state.selected}`, "POST", "/run", { sequence: state.selected, speed: Number($("#run-speed").value), step_mode: $("#run-step-mode").checked });
});
for (const verb of ["pause", "resume", "step", "abort"]) {
  $(`#${verb}`).addEventListener("click", () => command(verb, "POST", `/run/${verb}`));
}

// ---------------------------------------------------------------- past runs
async function loadRuns() {
  const runs = await api("GET", "/runs").catch(() => []);
  $("#runs").replaceChildren(...runs.slice(0, 50).map((r) => {
    const text = `${r.when || "?"} ${r.sequence || "?"} ${r.result || "?"}${r.exit_code !== null && r.exit_code !== undefined ? ` (exit ${r.exit_code})` : ""}`;
    const link = r.report
      ? el("a", { href: `${API}/runs/${encodeURIComponent(r.id)}/report.html`, target: "_blank", textContent: text })
      : el("a", { href: `${API}/runs/${encodeURIComponent(r.id)}/report.json`, target: "_blank", textContent: text });
    const li = el("li", { className: r.result === "passed" ? "" : "failed" }, link);
    li.dataset.run = r.id;
    return li;
  }));
}
$("#runs-refresh").addEventListener("click", loadRuns);

// ---------------------------------------------------------------- start
async function start() {
  state.arm = await api("GET", "/arm");
  buildJointControls();
  applyControl();
  if (DRAW) try { state.view = new ArmView($("#view3d"), state.arm); } catch (err) { say(`3D view unavailable: ${err.message}`, true); }
  connect();
  await Promise.all([loadPoses(), loadSequences(), loadRuns()]);
  state.ready = true;
}
start();
