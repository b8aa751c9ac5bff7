// seqrun operator console of several arms: one page, one live connection, every arm.
// STOP halts every arm (on the WebSocket; HTTP when it is down or slow) and the page shows
// each arm's outcome: "halted" only for an arm whose Halt was read back, a STOP FAILED line
// naming the arm otherwise. Commands address the arm selected (each arm's API lives under
// /api/v1/arms/{id}); one operator holds control of the whole console.
import { frames } from "/static/view3d.js";
import { ArmsView } from "/static/arms3d.js";
import { API, $, el, fmt, say, apiOf, stopKeys, LOST_MS, connectLive, watchContact, markLost, takeControl, Jog, JointControls, GripperPanel } from "/static/controls.js";

// (LOST_MS: the console sends each arm's status at least every 0.5 s: none for that long
// from an arm, contact with it lost.)
const STOP_CONFIRM_MS = 1500;
// Numbers painted at most this often (per second): the browser's painting is what costs the
// CPU the control loop needs (docs/console.md).
const PAINT_HZ = 10, PAINT_HZ_UNFOCUSED = 4;

const state = {
  ready: false, ids: [], arms: {}, selected: null, view: null, ws: null, client: null, token: null,
  msgId: 0, control: null, lost: true, lastHeardAt: 0, pendingStop: null,
  statusCount: 0, eventCount: 0, lastReplies: [], lastStop: null, frames,
};
window.seqrunArms = state;  // for the browser tests and the bench

const api = apiOf(() => state.token);

async function command(label, method, path, body) {
  const arm = state.selected;
  try {
    const result = await api(method, `/arms/${arm}${path}`, body);
    // a reply after contact was lost says nothing of the arm now: the banner's words stay
    if (!state.lost) say(result && result.message ? `arm ${arm}: ${label}: ${result.message}` : `arm ${arm}: ${label}: ok`);
    if (path === "/reset" || path === "/arm-up") state.arms[arm].stop = null;  // cleared
    return result;
  } catch (err) {
    return null;  // already on screen
  }
}

// ---------------------------------------------------------------- STOP (every arm)
function stop(event) {
  $("#stop").classList.add("pressed");
  setTimeout(() => $("#stop").classList.remove("pressed"), 200);
  jog.release(false);
  // Until an arm's Halt is read back, the page does not say it is halted.
  for (const id of state.ids) state.arms[id].stop = { pending: true };
  paint();
  if (state.ws && state.ws.readyState === WebSocket.OPEN && !state.lost) {
    const id = ++state.msgId;
    state.pendingStop = id;
    state.ws.send(JSON.stringify({ op: "halt", id, reason: "STOP (console)" }));
    say("STOP sent to every arm");
    setTimeout(() => { if (state.pendingStop === id) stopOverHttp("the live connection did not confirm it"); }, STOP_CONFIRM_MS);
  } else {
    say("STOP sent (no live connection)");
    stopOverHttp("no live connection");
  }
}

async function stopOverHttp(why) {
  const abort = new AbortController();
  // (a silent arm takes a few seconds to give up its confirmation: wait for the answer)
  const timer = setTimeout(() => abort.abort(), 15000);
  try {
    const response = await fetch(API + "/halt", {
      method: "POST", headers: { "Content-Type": "application/json", Accept: "application/json" },
      body: JSON.stringify({ reason: `STOP (console, ${why})` }), signal: abort.signal });
    stopResult(await response.json());
  } catch (err) {
    state.pendingStop = null;
    for (const id of state.ids) state.arms[id].stop = { failed: "the console is unreachable and the arm's state is unknown - use the emergency stop" };
    const text = "STOP FAILED: the console is unreachable and the arms' state is unknown - use the emergency stop";
    say(text, true);
    if (!state.lost) setLost(true, "");
    $("#lost-stop").textContent = text;
    $("#lost-stop").hidden = false;
    paint();
  } finally {
    clearTimeout(timer);
  }
}

// The STOP's answer: each arm confirmed, or a STOP FAILED line naming it.
function stopResult(result) {
  state.pendingStop = null;
  state.lastStop = result;
  const arms = result.arms || {};
  for (const id of state.ids) {
    const r = arms[id];
    if (!r) continue;
    state.arms[id].stop = r.halt_confirmed ? { confirmed: true } : { failed: r.message };
  }
  const failed = state.ids.filter((id) => arms[id] && !arms[id].halt_confirmed);
  if (failed.length) say(failed.map((id) => `STOP FAILED for arm ${id}: ${arms[id].message}`).join("; ") + " - use the emergency stop", true);
  else say(`STOP: every arm halted (${state.ids.join(", ")})`);
  paint();
}

stopKeys(stop);
$("#stop").addEventListener("pointerdown", (e) => { if (e.button === 0) stop(e); });

// ---------------------------------------------------------------- live connection
function connect() {
  connectLive(state, {
    setLost,
    closed: () => jog.release(false),
    onData: (data) => {
      if (data.type === "status") onStatus(data.arm, data.status);
      else if (data.type === "event") onEvent(data.arm, data.event);
      else if (data.type === "hello") {
        showControl(data.control);
        for (const [id, status] of Object.entries(data.status.arms || {})) onStatus(id, status);
      } else if (data.type === "reply") onReply(data);
    },
  });
}

function onReply(reply) {
  state.lastReplies.push(reply);
  if (state.lastReplies.length > 50) state.lastReplies.shift();
  if (reply.id !== null && reply.id === state.pendingStop) {
    if (reply.ok && reply.result) stopResult(reply.result);
    else state.pendingStop = null;
  }
  if (reply.note) say(reply.note, true);
  else if (!reply.ok && reply.error) say(reply.error, true);
}

function onStatus(id, status) {
  const arm = state.arms[id];
  if (!arm) return;
  state.statusCount += 1;
  arm.status = status;
  arm.heardAt = performance.now();
  if (state.view) state.view.setArmMeasured(id, status.joints.map((j) => j.position_deg));
}

function onEvent(id, event) {
  state.eventCount += 1;
  const type = event.type;
  const controlEvent = type === "client_joined" || type === "client_left" || type === "control_taken" || type === "control_released";
  if (controlEvent) {
    if (type === "control_taken" && event.previous && event.previous.id === state.client) {
      state.token = null;  // taken over: this page's secret is worth nothing now
      say(`Control taken by ${event.holder ? event.holder.name : "another client"}${event.stopped ? ` (${event.stopped})` : ""}: this page watches now (STOP still works)`, true);
    }
    showControl(event.control || event);
    id = null;  // the whole console's, not one arm's
  }
  if (type === "session_halt" && state.arms[id]) {
    // another page's STOP, or this one's arm by arm: what was read back
    state.arms[id].stop = event.halt_confirmed ? { confirmed: true } : { failed: event.message };
  }
  if (type === "confirm_requested" && id) ask(id, event);
  // the MOVE sliders follow the selected arm again once something else moves it and when
  // an activity ends (this page's own MOVE keeps its targets on show while it runs)
  if (id && id === state.selected && (type === "activity_finished"
      || (type === "activity_started" && !ownMove(event)))) joints.follow();
  if (type === "confirm_answered" && state.question
      && state.question.id === event.question_id) closeQuestion();
  if (type === "activity_finished" || type === "run_finished") showRun();
  // A run's folder is closed (its report drawn) when its activity ends (a run of several
  // arms: when GET /run says done, showRun lists it).
  if (type === "activity_finished") loadRuns();
  const bad = /fault|halt|error|failed/i.test(type);
  const text = `${id ? `[${id}] ` : ""}${fmt(event.t)} s ${type}${event.message ? `: ${event.message}` : ""}${event.label ? `: ${event.label}` : ""}`;
  const li = el("li", { textContent: text, className: bad ? "bad" : "" });
  const list = $("#events");
  list.append(li);
  while (list.children.length > 300) list.firstChild.remove();
  // scroll the list only: scrollIntoView would scroll the page too, panels under STOP
  list.scrollTop = list.scrollHeight;
}

// Lost contact with the console: the whole page greys out, every arm's state is unknown.
function setLost(lost, why = "") {
  if (!markLost(state, lost, why, "The console is unreachable: the arms' state is unknown - use the emergency stop")) return;
  applyControl();
  paint();
}

watchContact(state, setLost);

// ---------------------------------------------------------------- control
function showControl(control) {
  if (!control || !("holder" in control)) return;
  state.control = control;
  applyControl();
}

function myName() {
  const clients = (state.control && state.control.clients) || [];
  const me = clients.find((c) => c.id === state.client);
  return me ? me.name : null;
}

function ownMove(e) {
  return e.kind === "move" && e.detail && e.detail.joints && e.detail.by && e.detail.by === myName();
}

function mine() {
  return !!(state.control && state.control.holder && state.client && state.control.holder.id === state.client);
}

function applyControl() {
  const badge = $("#control-state");
  const holder = state.control && state.control.holder;
  if (state.lost) { badge.textContent = "control: unknown"; badge.className = "badge unknown"; }
  else if (mine()) { badge.textContent = "control: this page"; badge.className = "badge mine"; }
  else { badge.textContent = holder ? `watching: ${holder.name} commands` : "watching: nobody commands"; badge.className = "badge watching"; }
  $("#take-control").hidden = state.lost || mine();
  for (const b of document.querySelectorAll(".needs-control")) b.disabled = !mine() || state.lost;
  const clients = (state.control && state.control.clients) || [];
  $("#clients").textContent = clients.length ? `connected: ${clients.map((c) => c.name).join(", ")}` : "";
}

$("#take-control").addEventListener("click", async () => {
  try {
    const holder = state.control && state.control.holder;
    if (holder && !window.confirm(`${holder.name} holds control. Take over? (Its motions are stopped first; it is told.)`)) return;
    showControl(await takeControl(state, Boolean(holder)));
  } catch (err) { say(`Take control: ${err.message}`, true); }
});

// ---------------------------------------------------------------- the arms
// An arm's condition as the page shows it: contact lost (grey), STOP FAILED, stopping
// (a STOP not read back yet), or its activity ("halted" only once its Halt was read back).
function condition(id) {
  const arm = state.arms[id];
  if (state.lost) return { text: "unknown", cls: "unknown", grey: true };
  const noContact = !arm.status || arm.status.stale || performance.now() - (arm.heardAt || 0) > LOST_MS;
  if (arm.stop && arm.stop.failed) return { text: "STOP FAILED", cls: "halted", grey: noContact };
  if (noContact) return { text: "no contact", cls: "unknown", grey: true };
  if (arm.stop && arm.stop.pending) return { text: "stopping", cls: "paused", grey: false };
  return { text: arm.status.activity || "idle", cls: arm.status.activity || "idle", grey: false };
}

function buildArm(id, info) {
  const rows = el("tbody");
  const panel = el("div", { className: "arm-panel", id: `arm-${id}` },
    el("h3", {}, el("span", { className: "arm-id", textContent: `arm ${id}` }), " ",
      el("span", { className: "badge activity", textContent: "-" }), " ",
      el("span", { className: "dim", textContent: info.name })),
    el("div", { className: "stop-line", hidden: true }),
    el("table", { className: "joints" },
      el("thead", {}, el("tr", {}, ...["joint", "position", "velocity", "state"].map((t) => el("th", { textContent: t })))), rows),
    el("table", { className: "kv" },
      el("tr", {}, el("th", { textContent: "fault" }), el("td", { className: "fault-text", textContent: "-" })),
      el("tr", {}, el("th", { textContent: "bus" }), el("td", { className: "bus", textContent: info.bus })),
      el("tr", {}, el("th", { textContent: "arm file" }), el("td", { className: "dim", textContent: info.arm_file || "-" }))));
  $("#arm-panels").append(panel);
  const b = el("button", { type: "button", textContent: `arm ${id}`, className: "arm-choice" });
  b.dataset.arm = id;
  b.setAttribute("role", "radio");
  b.addEventListener("click", () => select(id));
  $("#arm-select").append(b);
  return { panel, rows, status: null, heardAt: 0, stop: null, scene: null, info };
}

function paintArm(id) {
  const arm = state.arms[id];
  const c = condition(id);
  const badge = arm.panel.querySelector(".activity");
  if (badge.textContent !== c.text) badge.textContent = c.text;
  badge.className = `badge activity ${c.cls}`;
  arm.panel.classList.toggle("lost-arm", c.grey);
  if (state.view) state.view.setArmLost(id, c.grey);
  const line = arm.panel.querySelector(".stop-line");
  line.hidden = !(arm.stop && arm.stop.failed);
  if (arm.stop && arm.stop.failed) line.textContent = `STOP FAILED for arm ${id}: ${arm.stop.failed}`;
  const s = arm.status;
  if (!s) return;
  if (arm.rows.children.length !== s.joints.length) {
    arm.rows.replaceChildren(...s.joints.map((j) => el("tr", { id: `tlm-${id}-${j.name}` },
      el("td", { textContent: j.name }), el("td", { className: "pos" }), el("td", { className: "vel" }), el("td", { className: "flags" }))));
  }
  s.joints.forEach((j, i) => {
    const row = arm.rows.children[i];
    row.classList.toggle("fault", !!j.fault);
    row.children[1].textContent = fmt(j.position_deg);
    row.children[2].textContent = fmt(j.velocity_deg_s);
    row.children[3].textContent = (j.flags || []).join(" ");
  });
  arm.panel.querySelector(".fault-text").textContent = s.fault ? (s.message || "a module reports a fault") : "none";
}

function paint() {
  for (const id of state.ids) paintArm(id);
  joints.measured(selectedStatus());
  if (state.view) state.view.requestRender();
}

function nextPaint() {
  paint();
  setTimeout(nextPaint, 1000 / (document.hasFocus() ? PAINT_HZ : PAINT_HZ_UNFOCUSED));
}

async function select(id) {
  state.selected = id;
  for (const b of document.querySelectorAll(".arm-choice")) {
    b.classList.toggle("selected", b.dataset.arm === id);
    b.setAttribute("aria-checked", String(b.dataset.arm === id));
  }
  jog.release(true);
  const arm = state.arms[id];
  $("#jog").replaceChildren(...arm.scene.joints.filter((j) => j.locked === null).map((j) => jog.buttons(j.name)));
  joints.build(arm.scene.joints);
  $("#gripper-panel").hidden = true;
  $("#gripper-state").textContent = "";  // (never the other arm's state, even hidden)
  gripper.show();
  const poses = await api("GET", `/arms/${id}/poses`).catch(() => []);
  if (state.selected !== id) return;
  $("#poses").replaceChildren(...poses.map((p) => {
    const b = el("button", { type: "button", className: "needs-control", textContent: p.name });
    b.dataset.pose = p.name;
    if (!p.move_target) { b.dataset.noTarget = "1"; b.title = p.why || "not a move target"; }
    b.addEventListener("click", () => command(`move to ${p.name}`, "POST", "/move/pose", { name: p.name }));
    return b;
  }));
  applyControl();
  for (const b of document.querySelectorAll("#poses [data-no-target]")) b.disabled = true;
}

// ---- jog, MOVE sliders, ALLVEL, gripper: the selected arm's (seqrun/console/static/controls.js)
const jog = new Jog({ socket: () => state.ws, nextId: () => ++state.msgId, fields: () => ({ arm: state.selected }) });
const selectedStatus = () => (state.selected ? state.arms[state.selected].status : null);
const joints = new JointControls({ command, status: selectedStatus });
const gripper = new GripperPanel({
  command,
  read: async () => {
    const id = state.selected;
    if (!id) return undefined;
    const g = await api("GET", `/arms/${id}/gripper`);
    return state.selected === id ? g : undefined;
  },
});

$("#cmd-arm").addEventListener("click", () => command("Arm", "POST", "/arm-up"));
$("#cmd-home").addEventListener("click", () => command("Home", "POST", "/home"));
$("#cmd-reset").addEventListener("click", () => command("Reset", "POST", "/reset"));

// ---------------------------------------------------------------- sequences
// One that names the arms runs every arm it names (POST /run); one of one arm runs on the
// arm selected when Run is pressed (POST /arms/ID/run), as `seqrun run --arm-id ID` does.
async function loadSequences() {
  const list = await api("GET", "/sequences").catch(() => []);
  state.sequences = Object.fromEntries(list.map((q) => [q.name, q]));
  $("#sequence").replaceChildren(...list.map((q) => el("option", {
    value: q.name, textContent: `${q.name} ${q.arms ? "(every arm it names)" : "(one arm: the selected)"}` })));
}

// A run of one arm: its status says so (run: file, step), as the page of one arm shows it.
function oneArmRuns() {
  return state.ids.flatMap((a) => {
    const status = state.arms[a] && state.arms[a].status;
    const run = status && status.run;
    if (!run || !["running", "paused"].includes(status.activity)) return [];
    const file = String(run.file).split("/").pop();
    return [`arm ${a}: ${file} ${status.activity}${run.step ? `, step ${run.step}/${run.steps}${run.label ? ` (${run.label})` : ""}` : ""}`];
  });
}

async function showRun() {
  const run = await api("GET", "/run").catch(() => null);
  const single = oneArmRuns();
  if (single.length && (!run || run.done)) { $("#run-state").textContent = single.join("; "); return; }
  if (!run) { $("#run-state").textContent = ""; return; }
  // done: its records are written (arms.json last), so Past runs can list it whole
  if (run.done && state.runListed !== run.run_dir) { state.runListed = run.run_dir; loadRuns(); }
  const results = run.results ? Object.entries(run.results).map(([a, r]) => `arm ${a}: ${r.status}`).join(", ") : "";
  $("#run-state").textContent = run.done ? `${run.name}: ended (exit ${run.exit_code ?? "?"}) ${results}${run.error ? ` - ${run.error}` : ""}`
    : `${run.name}: running on arms ${run.arms.join(", ")}`;
}

$("#run").addEventListener("click", async () => {
  const name = $("#sequence").value;
  if (!name) return;
  const several = (state.sequences[name] || {}).arms !== false;
  if (!several) {
    await command(`Run ${name}`, "POST", "/run", { sequence: name });
    showRun();
    return;
  }
  try {
    const run = await api("POST", "/run", { sequence: name });
    say(`Run ${run.name} on arms ${run.arms.join(", ")}: started`);
  } catch (err) { /* on screen */ }
  showRun();
});

// ---------------------------------------------------------------- past runs
// Every run of the campaign: one of one arm links its report; one of several arms links
// each arm's part (each a run folder with its own report).
function runLink(arm, id, hasReport, text) {
  const file = hasReport ? "report.html" : "report.json";
  const path = id.split("/").map(encodeURIComponent).join("/");  // RUN or RUN/ARM (a part)
  return el("a", { href: `${API}/arms/${arm}/runs/${path}/${file}`, target: "_blank", textContent: text });
}

async function loadRuns() {
  const runs = await api("GET", "/runs").catch(() => []);
  $("#runs").replaceChildren(...runs.slice(0, 50).map((r) => {
    const text = `${r.when || "?"} ${r.sequence || "?"} ${r.result || "?"}${r.exit_code !== null && r.exit_code !== undefined ? ` (exit ${r.exit_code})` : ""}`
      + `${r.incomplete?.length ? " INCOMPLETE" : ""}${r.inputs_changed?.length ? " INPUTS CHANGED" : ""}`;  // (its report says what)
    const li = el("li", { className: r.result === "passed" ? "" : "failed" });
    if (r.parts) {
      li.append(`${text}: `, ...Object.entries(r.parts).flatMap(([a, part], i) => [i ? ", " : "", runLink(a, part.id, part.report, `arm ${a}`)]));
    } else {
      const arm = r.arm && state.ids.includes(r.arm) ? r.arm : state.ids[0];
      li.append(runLink(arm, r.id, r.report, `${text}${r.arm ? ` (arm ${r.arm})` : ""}`));
    }
    li.dataset.run = r.id;
    return li;
  }));
}
$("#runs-refresh").addEventListener("click", loadRuns);
$("#abort").addEventListener("click", () => api("POST", "/run/abort").then(() => say("Abort: every arm stops (controlled)")).catch(() => {}));
setInterval(() => { if (!state.lost) showRun(); }, 2000);

// A run's confirm step: asked by one arm's run (its question), answered through that arm.
function ask(arm, event) {
  state.question = { arm, id: event.question_id };
  $("#confirm-text").textContent = `arm ${arm} asks: ${event.text}`;
  $("#confirm-dialog").hidden = false;
  applyControl();
}

function closeQuestion() {
  state.question = null;
  $("#confirm-dialog").hidden = true;
}

async function answer(yes) {
  const q = state.question;
  if (!q) return;
  try {
    await api("POST", `/arms/${q.arm}/answer`, { question_id: q.id, yes });
    closeQuestion();
  } catch (err) { /* on screen */ }
}
$("#confirm-yes").addEventListener("click", () => answer(true));
$("#confirm-no").addEventListener("click", () => answer(false));

// ---------------------------------------------------------------- start
async function start() {
  let arms;
  try {
    arms = await api("GET", "/arms");
  } catch (err) {
    say("This page needs the console's token: open the URL seqrun console printed (STOP works without it).", true);
    return;
  }
  state.ids = arms.map((a) => a.id);
  document.title = `seqrun console: arms ${state.ids.join(", ")}${arms.every((a) => a.simulator) ? " (SIMULATOR)" : ""}`;
  $("#title").textContent = `seqrun console: arms ${state.ids.join(", ")}`;
  for (const a of arms) state.arms[a.id] = buildArm(a.id, a);
  const scenes = await Promise.all(arms.map((a) => api("GET", `/arms/${a.id}/arm`)));
  arms.forEach((a, i) => { state.arms[a.id].scene = scenes[i]; });
  try {
    state.view = new ArmsView($("#view3d"), arms.map((a, i) => ({ id: a.id, scene: scenes[i], base: a.base })));
  } catch (err) {
    $("#view3d").textContent = `3D view unavailable: ${err.message}`;
  }
  connect();
  loadSequences();
  loadRuns();
  showRun();
  await select(state.ids[0]);
  setInterval(() => { if (!state.lost) gripper.show(); }, 2000);
  nextPaint();
  state.ready = true;
}
start();
