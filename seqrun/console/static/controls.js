// What the console's two pages share (console.js: one arm; arms.js: several arms, the
// commands going to the selected arm): the message bar, the HTTP API, STOP's keys, the
// hold-to-move jog, the MOVE sliders, the ALLVEL boxes and the gripper panel. Each page
// passes in how to reach its arm (one arm: /api/v1/...; several: /api/v1/arms/{id}/...).
export const API = "/api/v1";
export const $ = (sel) => document.querySelector(sel);
export const el = (tag, props = {}, ...children) => {
  const node = Object.assign(document.createElement(tag), props);
  for (const c of children) node.append(c);
  return node;
};
export const fmt = (v, digits = 2) => (v === null || v === undefined ? "-" : Number(v).toFixed(digits));

// textContent only when it changed: an unchanged field costs no layout.
export function setText(node, text) {
  if (node.textContent !== text) node.textContent = text;
}

export function say(text, isError = false) {
  const m = $("#message");
  m.textContent = text;
  m.className = isError ? "error" : "";
  m.title = text;
}

// The API over HTTP: JSON in and out, the page's control secret in a header (the console
// gave it to this page alone when it took control; kept in memory, never stored); a
// refusal is said in the message bar and thrown (with its HTTP status).
export function apiOf(secret) {
  return async function api(method, path, body) {
    const headers = { Accept: "application/json" };
    const token = secret();
    if (token) headers["X-Seqrun-Control"] = token;
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
  };
}

export function isTyping(target) {
  return target && target.tagName === "INPUT" && target.type === "text";
}

// Esc, and Space outside a text box, press STOP (before anything else on the page sees the
// key); Space would also click a focused button on release: never let it.
export function stopKeys(stop) {
  window.addEventListener("keydown", (e) => {
    if (e.key === "Escape" || (e.code === "Space" && !isTyping(e.target))) {
      e.preventDefault();
      e.stopPropagation();
      if (!e.repeat) stop(e);
    }
  }, true);
  window.addEventListener("keyup", (e) => {
    if (e.code === "Space" && !isTyping(e.target)) { e.preventDefault(); e.stopPropagation(); }
  }, true);
}

// ---------------------------------------------------------------- live connection
// The console sends a status at least every 0.5 s: a page that heard nothing for LOST_MS
// (a console killed, frozen or cut off without a TCP close) has lost contact.
export const LOST_MS = 2000;

// The live WebSocket (state.ws; state.client from its hello): a ping every 0.5 s (the
// server takes a page silent for 2 s during its motion as gone), reconnected a second after
// it closed. setLost(lost, why): the page's lost contact; closed(): its own clean-up (a
// held jog); onData(message): every message, the hello after the client id is known.
// Requests on the live connection that wait for their reply (id -> {resolve, reject}).
const waiting = new Map();
let liveIds = 0;

// A request on the live connection; a promise of its reply (rejected with its error).
export function liveRequest(state, fields) {
  return new Promise((resolve, reject) => {
    const ws = state.ws;
    if (!ws || ws.readyState !== WebSocket.OPEN) { reject(new Error("the live connection is closed")); return; }
    const id = `req-${++liveIds}`;
    waiting.set(id, { resolve, reject });
    ws.send(JSON.stringify({ ...fields, id }));
  });
}

// This page takes control (takeOver: from the page or client holding it, whose motion is
// stopped first and who is told); the secret comes back in the reply, for this page alone.
export async function takeControl(state, takeOver) {
  const answer = await liveRequest(state, { op: "take_control", take_over: takeOver });
  state.token = answer.token;
  return answer.control;
}

export function connectLive(state, handlers) {
  const { setLost, closed, onData } = handlers;
  const ws = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}${API}/live`);
  state.ws = ws;
  let ping = null;
  ws.onopen = () => {
    $("#conn").textContent = "live"; $("#conn").className = "badge on";
    ping = setInterval(() => { if (ws.readyState === WebSocket.OPEN) ws.send('{"op":"ping"}'); }, 500);
  };
  ws.onclose = () => {
    clearInterval(ping);
    $("#conn").textContent = "offline"; $("#conn").className = "badge off";
    state.client = null;
    state.token = null;  // control ends with the connection
    for (const w of waiting.values()) w.reject(new Error("the live connection closed"));
    waiting.clear();
    closed();
    setLost(true, "The live connection closed.");
    setTimeout(() => connectLive(state, handlers), 1000);
  };
  ws.onmessage = (msg) => {
    state.lastHeardAt = performance.now();
    if (state.lost && state.client) setLost(false);  // a console that was frozen, back
    const data = JSON.parse(msg.data);
    if (data.type === "hello") {
      state.client = data.client;
      state.token = data.token || null;  // this page got control on joining
      setLost(false);
    }
    if (data.type === "reply" && waiting.has(data.id)) {
      const w = waiting.get(data.id);
      waiting.delete(data.id);
      if (data.ok) w.resolve(data); else w.reject(new Error(data.error || "refused"));
      return;
    }
    onData(data);
  };
}

// Lost contact (lost: true) or back (false): the whole page greys out under the banner
// (why: its line) and the message bar says so (text); STOP stays red and still tries.
// False when nothing changed (lost again without a new reason, or back while not lost).
export function markLost(state, lost, why, text) {
  if (lost === state.lost && (!lost || !why)) return false;
  const already = state.lost;
  state.lost = lost;
  document.body.classList.toggle("lost", lost);
  $("#lost-banner").hidden = !lost;
  $("#lost-why").textContent = why;
  if (!lost) $("#lost-stop").hidden = true;
  // said once when contact is lost: each failed reconnection must not cover a STOP FAILED
  if (lost && !already) say(text, true);
  else if ($("#message").textContent.startsWith("The console is unreachable")) say("");
  return true;
}

// No word for LOST_MS on a connection that was live: contact lost.
export function watchContact(state, setLost) {
  setInterval(() => {
    if (!state.lost && performance.now() - state.lastHeardAt > LOST_MS) setLost(true, `No word from the console for ${LOST_MS / 1000} s.`);
  }, 250);
}

// ---------------------------------------------------------------- jog
// Hold to move, renewed every 100 ms on the live connection (the server stops the joint
// 200 ms after the last); released (or the page hidden or blurred): jog_stop.
// socket(): the live WebSocket; nextId(): a message id; fields(): what a press names
// besides the joint (several arms: the arm), kept for its renewals and its stop.
export class Jog {
  constructor({ socket, nextId, fields = () => ({}) }) {
    Object.assign(this, { socket, nextId, fields });
    this.held = null;
    window.addEventListener("blur", () => this.release(true));
    document.addEventListener("visibilitychange", () => { if (document.hidden) this.release(true); });
    $("#jog-scale").addEventListener("input", () => { $("#jog-scale-value").textContent = `${Math.round($("#jog-scale").value * 100)} %`; });
  }

  open() {
    const ws = this.socket();
    return ws && ws.readyState === WebSocket.OPEN ? ws : null;
  }

  send() {
    const ws = this.open();
    if (!this.held || !ws) return;
    const scale = Number($("#jog-scale").value) * this.held.direction;
    const mode = $("#jog-velocity-mode") && $("#jog-velocity-mode").checked ? "velocity" : "position";
    ws.send(JSON.stringify({ op: "jog", id: this.nextId(), ...this.held.fields, joint: this.held.joint, speed_scale: scale, mode }));
  }

  // The two buttons of a joint (needs control), held to move.
  buttons(joint) {
    const pair = [["-", -1, "jog-minus"], ["+", 1, "jog-plus"]].map(([sign, direction, cls]) => {
      const b = el("button", { type: "button", textContent: `${joint} ${sign}`, className: `${cls} needs-control` });
      b.dataset.joint = joint;
      b.dataset.jog = `${joint}${sign}`;
      this.hold(b, joint, direction);
      return b;
    });
    return el("span", { className: "jog-pair" }, ...pair);
  }

  hold(button, joint, direction) {
    button.addEventListener("pointerdown", (e) => {
      e.preventDefault();
      button.setPointerCapture(e.pointerId);
      this.release(false);
      this.held = { joint, direction, button, fields: this.fields(), timer: setInterval(() => this.send(), 100) };
      button.classList.add("held");
      this.send();
    });
    for (const ev of ["pointerup", "pointercancel", "lostpointercapture"]) button.addEventListener(ev, () => this.release(true));
    button.addEventListener("contextmenu", (e) => e.preventDefault());  // a tablet's long press
  }

  release(sendStop) {
    const held = this.held;
    if (!held) return;
    clearInterval(held.timer);
    held.button.classList.remove("held");
    this.held = null;
    const ws = this.open();
    if (sendStop && ws) ws.send(JSON.stringify({ op: "jog_stop", id: this.nextId(), ...held.fields }));
  }
}

// ---------------------------------------------------------------- MOVE and ALLVEL
// A slider and a number per joint (its limits), MOVE to the targets, "From arm"; a velocity
// box per joint and ALLVEL. The sliders follow the measured joints until the operator
// touches one; command(label, method, path, body) sends to the page's arm; status() is its
// newest status; changed() is called when the targets change (the page's ghost).
export class JointControls {
  constructor({ command, status, changed = () => {} }) {
    Object.assign(this, { command, status, changed });
    this.joints = [];
    this.touched = false;
    $("#move-from-arm").addEventListener("click", () => this.follow());
    $("#cmd-move").addEventListener("click", () => this.move());
    $("#cmd-allvel").addEventListener("click", () => this.allvel());
  }

  // joints: the arm's (GET .../arm "joints": name, limits_deg, max_velocity_deg_s, locked)
  build(joints) {
    this.joints = joints;
    this.touched = false;
    const rows = [], boxes = [];
    for (const j of joints) {
      const [lo, hi] = j.limits_deg;
      const locked = j.locked !== null && j.locked !== undefined;
      const slider = el("input", { type: "range", min: lo, max: hi, step: 0.1, value: 0, className: "move-slider", disabled: locked });
      const number = el("input", { type: "number", min: lo, max: hi, step: 0.1, value: 0, className: "move-number", disabled: locked });
      slider.dataset.joint = j.name; number.dataset.joint = j.name;
      slider.addEventListener("input", () => { number.value = slider.value; this.touch(); });
      number.addEventListener("input", () => { slider.value = number.value; this.touch(); });
      rows.push(el("tr", {}, el("td", { textContent: j.name }), el("td", {}, slider), el("td", {}, number)));
      const box = el("input", { type: "number", min: 0.1, max: j.max_velocity_deg_s, step: 0.5, className: "vel-box", title: `${j.name}, at most ${j.max_velocity_deg_s} deg/s`, disabled: locked });
      box.dataset.joint = j.name;
      box.placeholder = j.name;
      boxes.push(box);
    }
    $("#move-table tbody").replaceChildren(...rows);
    $("#vel-boxes").replaceChildren(...boxes);
    const s = this.status();
    if (s) this.show(s.joints.map((j) => j.position_deg));
  }

  touch() {
    this.touched = true;
    this.changed();
  }

  // The sliders at q (degrees, the arm's joint order): where the arm is, unless touched.
  show(q) {
    const numbers = document.querySelectorAll(".move-number");
    document.querySelectorAll(".move-slider").forEach((s, i) => {
      const v = q[this.joints.findIndex((j) => j.name === s.dataset.joint)];
      if (v === null || v === undefined) return;
      const text = v.toFixed(1);
      if (numbers[i].value !== text) { s.value = text; numbers[i].value = text; }
    });
  }

  measured(status) {
    if (!this.touched && status) this.show(status.joints.map((j) => j.position_deg));
  }

  // The sliders follow the arm again (something else moves it, an activity ended).
  follow() {
    this.touched = false;
    this.measured(this.status());
    this.changed();
  }

  targets() {
    const out = {};
    document.querySelectorAll(".move-number").forEach((n) => { if (!n.disabled) out[n.dataset.joint] = Number(n.value); });
    return out;
  }

  // MOVE sends the joints whose target differs from where they are: the others stay (and a
  // joint that stands just outside its limits, after a power-off there, is not asked to go
  // there).
  changedTargets() {
    const s = this.status();
    const now = s ? s.joints : [];
    const changed = {};
    for (const [name, value] of Object.entries(this.targets())) {
      const joint = now.find((j) => j.name === name);
      if (!joint || joint.position_deg === null || Math.abs(value - joint.position_deg) > 0.05) changed[name] = value;
    }
    return changed;
  }

  move() {
    const joints = this.changedTargets();
    if (Object.keys(joints).length === 0) { say("MOVE: every target is where the arm is already"); return null; }
    return this.command("MOVE", "POST", "/move/joints", { joints });
  }

  allvel() {
    const joints = {};
    document.querySelectorAll(".vel-box").forEach((b) => { if (b.value !== "") joints[b.dataset.joint] = Number(b.value); });
    return this.command("ALLVEL", "POST", "/velocities", { joints });
  }
}

// ---------------------------------------------------------------- gripper
// Its state (read while the arm's session is idle), Grip and Release (need control); the
// panel hidden for an arm without one. read(): GET the arm's /gripper.
// The module's condition as its state word says: a fault bit (FAULT and the word), else not
// homed (a module powers on so: no fault, the arm's Home homes it too), else ready.
export function gripperCondition(g) {
  if (g.faulted) return `FAULT ${g.state}`;
  if (!g.homed) return `not homed (${g.state}): Home homes it with the arm`;
  return g.moving ? "moving" : "ready";
}

export class GripperPanel {
  constructor({ command, read }) {
    Object.assign(this, { command, read });
    $("#cmd-grip").addEventListener("click", () => this.command("Grip", "POST", "/gripper/grip",
      { part_width_mm: Number($("#grip-width").value), force_n: Number($("#grip-force").value) }));
    $("#cmd-release").addEventListener("click", () => this.command("Release", "POST", "/gripper/release",
      { width_mm: Number($("#release-width").value) }));
  }

  async show() {
    let g;
    try { g = await this.read(); } catch (err) { return; }
    if (g === undefined) return;  // (the page asked about another arm meanwhile)
    const panel = $("#gripper-panel");
    panel.hidden = g === null;
    if (g === null) return;
    $("#gripper-name").textContent = `(${g.name}, module ${g.module}, stroke ${g.stroke_mm} mm, at most ${g.max_force_n} N)`;
    $("#gripper-state").textContent = g.error ? `no reading: ${g.error}`
      : `${g.width_mm.toFixed(1)} mm open, ${g.holding ? "holding a part" : "not holding"}, ${gripperCondition(g)}`;
    $("#gripper-state").classList.toggle("fault", !g.error && g.faulted);
  }

  poll(everyMs = 2000) {
    this.show();
    setInterval(() => this.show(), everyMs);
  }
}
