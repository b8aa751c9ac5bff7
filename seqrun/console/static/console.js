// seqrun operator console: one page over the /api/v1 HTTP API and the live WebSocket.
// STOP is sent on the WebSocket (HTTP when it is down) and never waits for anything else.
import { ArmView, frames } from "/static/view3d.js";
import { API, $, el, fmt, setText, say, apiOf, stopKeys, connectLive, watchContact, markLost, takeControl, Jog, JointControls, GripperPanel } from "/static/controls.js";

// ?draw=0 (benchmarks): count the telemetry, draw nothing (what drawing costs, isolated).
const DRAW = new URLSearchParams(location.search).get("draw") !== "0";

const state = {
  arm: null, view: null, ws: null, client: null, token: null, msgId: 0, status: null,
  latched: {}, poses: [], hoverPose: null, question: null, selected: null, checked: null,
  statusCount: 0, eventCount: 0, lastReplies: [], stopTimes: [],
  control: null, lost: true, lastHeardAt: 0, pendingStop: null,
};
window.seqrunConsole = state;  // for the browser tests and the bench
state.frames = frames;

// ---------------------------------------------------------------- HTTP
const api = apiOf(() => state.token);

async function command(label, method, path, body) {
  try {
    const result = await api(method, path, body);
    // A reply that arrives after contact was lost says nothing of the arm now: the
    // banner's words stay (a "MOVE: ok" under it read as if the arm were fine).
    if (!state.lost) say(result && result.message ? `${label}: ${result.message}` : `${label}: ok`);
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
  jog.release(false);
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

stopKeys(stop);

// ---------------------------------------------------------------- live connection
function connect() {
  connectLive(state, {
    setLost,
    closed: () => jog.release(false),
    onData: (data) => {
      if (data.type === "status") showStatus(data.status);
      else if (data.type === "event") showEvent(data.event);
      else if (data.type === "hello") {
        showControl(data.control);
        showStatus(data.status);
      } else if (data.type === "reply") onReply(data);
    },
  });
}
watchContact(state, setLost);

// Lost contact: whatever the page shows is old. Everything greys out under a banner, the
// activity reads "unknown"; STOP stays red and still tries (and says if it fails).
function setLost(lost, why = "") {
  if (!markLost(state, lost, why, "The console is unreachable: the arm's state is unknown - use the emergency stop")) return;
  if (lost) {
    setText($("#activity"), "unknown");
    $("#activity").className = "badge unknown";
  } else if (state.status) drawBadges(state.status);
  applyControl();
}

function onReply(reply) {
  state.lastReplies.push(reply);
  if (state.lastReplies.length > 50) state.lastReplies.shift();
  if (reply.id !== null && reply.id === state.pendingStop) state.pendingStop = null;
  if (reply.note) say(reply.note, true);
  if (!reply.ok) {
    say(reply.error, true);
    jog.release(false);
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

function drawBadges(s) {
  if (state.lost) return;  // "unknown" until contact is back
  const act = $("#activity");
  setText(act, s.stale ? `${s.activity} (stale)` : s.activity);
  act.className = `badge ${s.activity}`;
}

function drawStatus(s) {
  state.drawCount += 1;
  // one arm of a campaign's several (seqrun console --arm-id B): the page names it
  const which = state.arm && state.arm.arm_id ? ` - arm ${state.arm.arm_id}` : "";
  const title = s.simulator ? `seqrun console${which} - SIMULATOR` : `seqrun console${which} - ${s.bus}`;
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
  joints.measured(s);
  updateGhost();
  highlightStep(s.run);
  drawPause(s.run);
}

// A pause: asked for (the step under way finishes first), then where the run holds.
function drawPause(run) {
  const pause = run && run.pause;
  setText($("#run-pause"), pause === "paused" ? run.paused_before
    : pause === "requested" ? "Pause requested: the run holds after the step under way" : "");
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
  const warn = ["controlled_stop", "operator_abort", "abort_requested", "pause_requested", "run_paused", "resume_refused", "status_poll_failed"];
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
    if (took) {
      state.token = null;
      say(`Control taken by ${e.holder.name}${e.stopped ? ` (${e.stopped})` : ""}: this page watches now (STOP still works)`, true);
    }
    showControl(e);
  }
  if (e.type === "confirm_requested") askOperator(e);
  else if (e.type === "confirm_answered" && state.question && state.question.question_id === e.question_id) closeQuestion();
  else if (e.type === "run_finished" || e.type === "activity_finished") { if (e.type === "run_finished") loadRuns(); closeQuestionIfRunEnded(e); }
  else if (e.type === "step_started") markStep(e.step);
  else if (e.type === "run_started") { state.firstStep = e.first_step || 1; markStep(0); }
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
  if (holder && !window.confirm(`${holder.name} holds control. Take over? (Its motion is stopped first; it is told.)`)) return;
  takeControl(state, Boolean(holder)).then((control) => { showControl(control); say("Take control: this page holds control"); })
    .catch((err) => say(`Take control: ${err.message}`, true));
});

// ---------------------------------------------------------------- confirm dialog
function askOperator(e) {
  state.question = e;
  $("#confirm-text").textContent = e.text;
  // A signed question: whoever answers yes gives their name (kept in the run's record).
  $("#confirm-sign").hidden = !e.sign;
  $("#confirm-name-label").textContent = e.role ? `Signed by (${e.role}), your name` : "Signed by, your name";
  $("#confirm-name").value = "";
  $("#confirm-name-note").hidden = true;
  // A question with choices (a step's on_fail: pause: retry, skip, abort): a button each.
  const choices = Array.isArray(e.choices) ? e.choices : [];
  $("#confirm-yes").hidden = $("#confirm-no").hidden = choices.length > 0;
  const row = $("#confirm-choices");
  row.replaceChildren(...choices.map((choice) => {
    const button = document.createElement("button");
    button.type = "button";
    button.className = "needs-control";
    button.dataset.choice = choice;
    button.textContent = choice.charAt(0).toUpperCase() + choice.slice(1);
    button.disabled = !holdsControl();
    button.addEventListener("click", () => answerChoice(choice));
    return button;
  }));
  row.hidden = choices.length === 0;
  showQuestionWho(e);
  $("#confirm-dialog").hidden = false;
  if (e.sign) $("#confirm-name").focus();
}

async function answerChoice(choice) {
  if (!state.question) return;
  const id = state.question.question_id;
  closeQuestion();
  await command(choice.charAt(0).toUpperCase() + choice.slice(1), "POST", "/answer",
                { question_id: id, yes: true, choice });
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
  if (question.sign && yes) {
    const name = $("#confirm-name").value.trim();
    if (!name) {  // asked again: a signed yes needs a name
      state.question = question;
      $("#confirm-dialog").hidden = false;
      $("#confirm-name-note").hidden = false;
      $("#confirm-name").focus();
      return;
    }
    const answered = await command("Yes", "POST", "/answer", { question_id: id, yes, name });
    if (answered === null && !state.question) askOperator(question);  // refused: still open
    return;
  }
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

// ---- MOVE sliders and ALLVEL boxes, the gripper, the jog (seqrun/console/static/controls.js)
const joints = new JointControls({ command, status: () => state.status, changed: () => updateGhost() });
const jog = new Jog({ socket: () => state.ws, nextId: () => ++state.msgId });
new GripperPanel({ command, read: () => api("GET", "/gripper") }).poll();

function buildJointControls() {
  joints.build(state.arm.joints);
  $("#jog").replaceChildren(...state.arm.joints.filter((j) => j.locked === null).map((j) => jog.buttons(j.name)));
}

function updateGhost() {
  if (!state.view || !state.status) return;
  const measured = state.status.joints.map((j) => j.position_deg);
  if (state.hoverPose && state.hoverPose.joints_deg) {
    state.view.setGhost(state.arm.joints.map((j) => state.hoverPose.joints_deg[j.name] ?? 0));
    return;
  }
  if (joints.touched) {
    const targets = joints.targets();
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
  joints.follow();
}

function ownSliderMove(e) {
  return e.kind === "move" && e.detail && e.detail.joints && e.detail.by && e.detail.by === myName();
}

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
  $("#run-refused").textContent = "";
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
    const li = el("li", {}, el("span", { textContent: s.label }));
    li.dataset.step = s.number;
    // Run from here (step 1 is Run itself): as `seqrun run --from N`, checked by the
    // console from where the arm stands before anything moves.
    if (s.number > 1) {
      const b = el("button", { type: "button", className: "small from-here needs-control", textContent: "run from here",
        title: `Run steps ${s.number}-${check.steps.length} only; refused unless the arm stands where step ${s.number} expects it` });
      b.dataset.step = s.number;
      b.addEventListener("click", () => runFrom(s.number, s.label));
      li.append(b);
    }
    return li;
  }));
  applyControl();
  if (state.status) highlightStep(state.status.run);
}

// A run from step N: the steps before N are not run (marked so, never "done").
function markStep(step) {
  const first = state.firstStep || 1;
  document.querySelectorAll("#seq-steps li").forEach((li) => {
    const n = Number(li.dataset.step);
    li.classList.toggle("current", n === step);
    li.classList.toggle("done", n < step && n >= first);
    li.classList.toggle("not-run", n < first);
  });
}

// The step under way stays marked after the run ends (where it ended); a new run clears it.
function highlightStep(run) {
  if (!run || !state.checked || !run.file) return;
  if (!run.file.endsWith(state.checked.sequence)) return;
  state.firstStep = run.first_step || 1;
  if (run.step) markStep(run.step);
}

// A refused run says why below the buttons in full (the message bar is one line, cut).
async function runSequence(label, firstStep) {
  const name = state.selected;
  $("#run-refused").textContent = "";
  const body = { sequence: name, speed: Number($("#run-speed").value), step_mode: $("#run-step-mode").checked };
  if (firstStep > 1) body.first_step = firstStep;
  try {
    const result = await api("POST", "/run", body);
    if (!state.lost) say(`${label}: ${result && result.message ? result.message : "ok"}`);
  } catch (err) {
    if (err.status && state.selected === name) $("#run-refused").textContent = `${label} refused: ${err.message}`;
  }
}

function runFrom(step, label) {
  if (!state.selected) return;
  const notRun = step === 2 ? "Step 1 is not run." : `Steps 1-${step - 1} are not run.`;
  if (!window.confirm(`Run from step ${step} (${label})? ${notRun}`)) return;
  runSequence(`Run ${state.selected} from step ${step}`, step);
}

$("#run").addEventListener("click", () => {
  if (!state.selected) return;
  runSequence(`Run ${state.selected}`, 1);
});
for (const verb of ["pause", "resume", "step", "abort"]) {
  $(`#${verb}`).addEventListener("click", () => command(verb, "POST", `/run/${verb}`));
}

// ---------------------------------------------------------------- past runs
async function loadRuns() {
  const runs = await api("GET", "/runs").catch(() => []);
  $("#runs").replaceChildren(...runs.slice(0, 50).map((r) => {
    const text = `${r.when || "?"} ${r.sequence || "?"} ${r.result || "?"}${r.exit_code !== null && r.exit_code !== undefined ? ` (exit ${r.exit_code})` : ""}`
      + `${r.incomplete?.length ? " INCOMPLETE" : ""}${r.inputs_changed?.length ? " INPUTS CHANGED" : ""}`;  // (its report says what)
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
