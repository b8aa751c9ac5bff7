// The arm in 3D, from the chain the API serves (GET /api/v1/arm: 4x4 frames computed by
// the same code as the validator). The page only multiplies frames by Rz(q):
//   T(q) = base * Rz(q1) * F2 * Rz(q2) * ... * Fn * Rz(qn) * tool
// Millimetres, z up. Solid: the measured arm; translucent ghost: a target before it is sent.
import * as THREE from "/static/vendor/three/three.module.min.js";

function mul(a, b) {
  const out = [[0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0]];
  for (let i = 0; i < 4; i++)
    for (let j = 0; j < 4; j++)
      out[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j] + a[i][3] * b[3][j];
  return out;
}

function rotZ(q) {
  const c = Math.cos(q), s = Math.sin(q);
  return [[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]];
}

// Frames of joints 1..n then the tool (as seqrun.kinematics.frame_transforms), q in degrees.
export function frames(chain, qDeg) {
  const q = qDeg.map((d) => (d * Math.PI) / 180);
  const out = [];
  let current = mul(chain.base, rotZ(q[0]));
  out.push(current);
  chain.links.forEach((link, k) => {
    current = mul(current, mul(link, rotZ(q[k + 1])));
    out.push(current);
  });
  out.push(mul(current, chain.tool));
  return out;
}

// Named points: "base" (the mount), joint names, "end_effector".
function points(arm, qDeg) {
  const f = frames(arm.chain, qDeg);
  const named = { base: new THREE.Vector3(0, 0, 0) };
  arm.joints.forEach((j, i) => { named[j.name] = new THREE.Vector3(f[i][0][3], f[i][1][3], f[i][2][3]); });
  const tool = f[f.length - 1];
  named.end_effector = new THREE.Vector3(tool[0][3], tool[1][3], tool[2][3]);
  return { named, frames: f };
}

function segmentsOf(arm) {
  if (arm.capsules && arm.capsules.length) return arm.capsules.map((c) => ({ start: c.start, end: c.end, r: c.radius_mm }));
  const names = ["base", ...arm.joints.map((j) => j.name), "end_effector"];
  return names.slice(1).map((n, i) => ({ start: names[i], end: n, r: 30 }));
}

// WebGL drawn by the CPU (no GPU, or none the browser may use): every frame then costs
// the CPU the control loop needs.
function softwareRendered(gl) {
  try {
    const info = gl.getExtension("WEBGL_debug_renderer_info");
    const name = String(gl.getParameter(info ? info.UNMASKED_RENDERER_WEBGL : gl.RENDERER));
    return /swiftshader|llvmpipe|softpipe|software/i.test(name);
  } catch (err) {
    return false;
  }
}

export class ArmFigure {
  constructor(scene, arm, material, jointMaterial) {
    this.arm = arm;
    this.group = new THREE.Group();
    // A link volume (capsule) as a unit cylinder stretched between its two points, with a
    // sphere at each end (a stretched CapsuleGeometry would stretch its caps too).
    this.links = segmentsOf(arm).map((s) => {
      const mesh = new THREE.Mesh(new THREE.CylinderGeometry(s.r, s.r, 1, 20), material);
      const ends = [0, 1].map(() => new THREE.Mesh(new THREE.SphereGeometry(s.r, 20, 12), material));
      this.group.add(mesh, ...ends);
      return { ...s, mesh, ends };
    });
    this.joints = arm.joints.map((j) => {
      const mesh = new THREE.Mesh(new THREE.CylinderGeometry(34, 34, 70, 20), jointMaterial);
      this.group.add(mesh);
      return mesh;
    });
    // The tools' volumes, carried by the end-effector frame (a tip line: a thin rod, so a
    // long probe is seen where the validator sees it).
    this.tools = (arm.tool_parts || []).map((t) => {
      const r = Math.max(t.radius_mm, 2);
      const mesh = new THREE.Mesh(new THREE.CylinderGeometry(r, r, 1, 16), material);
      const ends = [0, 1].map(() => new THREE.Mesh(new THREE.SphereGeometry(r, 16, 10), material));
      this.group.add(mesh, ...ends);
      return { start: new THREE.Vector3(...t.start_mm), end: new THREE.Vector3(...t.end_mm), mesh, ends };
    });
    this.tcp = new THREE.AxesHelper(90);
    this.group.add(this.tcp);
    scene.add(this.group);
  }

  set(qDeg) {
    const { named, frames: f } = points(this.arm, qDeg);
    const up = new THREE.Vector3(0, 1, 0);
    for (const link of this.links) {
      const a = named[link.start], b = named[link.end];
      const d = new THREE.Vector3().subVectors(b, a);
      const len = Math.max(d.length(), 1e-3);
      link.mesh.position.copy(a).addScaledVector(d, 0.5);
      link.mesh.quaternion.setFromUnitVectors(up, d.clone().divideScalar(len));
      link.mesh.scale.set(1, len, 1);
      link.ends[0].position.copy(a);
      link.ends[1].position.copy(b);
    }
    this.joints.forEach((mesh, i) => {
      const m = new THREE.Matrix4().set(...f[i].flat());
      mesh.matrixAutoUpdate = false;
      // the cylinder's axis is y: turn it onto the joint's z axis
      mesh.matrix.copy(m).multiply(new THREE.Matrix4().makeRotationX(Math.PI / 2));
    });
    const tool = f[f.length - 1];
    const flange = new THREE.Matrix4().set(...tool.flat());
    for (const part of this.tools) {
      const a = part.start.clone().applyMatrix4(flange), b = part.end.clone().applyMatrix4(flange);
      const d = new THREE.Vector3().subVectors(b, a);
      const len = Math.max(d.length(), 1e-3);
      part.mesh.position.copy(a).addScaledVector(d, 0.5);
      part.mesh.quaternion.setFromUnitVectors(up, d.clone().divideScalar(len));
      part.mesh.scale.set(1, len, 1);
      part.ends[0].position.copy(a);
      part.ends[1].position.copy(b);
    }
    this.tcp.matrixAutoUpdate = false;
    this.tcp.matrix.set(...tool.flat());
  }

  set visible(v) { this.group.visible = v; }
}

// arm null: the scene, camera and controls only (a view of several arms adds its own
// figures: arms3d.js).
export class ArmView {
  constructor(container, arm) {
    this.arm = arm;
    this.container = container;
    // Software WebGL: no multisampling, plain shading (each costs the CPU on every frame).
    this.software = softwareRendered(document.createElement("canvas").getContext("webgl2"));
    this.renderer = new THREE.WebGLRenderer({ antialias: !this.software, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(window.devicePixelRatio || 1);
    container.appendChild(this.renderer.domElement);
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0x0b0d10);
    THREE.Object3D.DEFAULT_UP.set(0, 0, 1);
    this.camera = new THREE.PerspectiveCamera(40, 1, 10, 20000);
    this.camera.up.set(0, 0, 1);
    this.target = new THREE.Vector3(0, 0, 420);
    this.orbit = { azimuth: -0.9, elevation: 0.35, distance: 2000 };
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x334455, 2.2));
    const sun = new THREE.DirectionalLight(0xffffff, 1.6);
    sun.position.set(1000, -1500, 2500);
    this.scene.add(sun);
    const grid = new THREE.GridHelper(2000, 20, 0x3a4450, 0x252b33);
    grid.rotation.x = Math.PI / 2;
    this.scene.add(grid);
    this.scene.add(new THREE.AxesHelper(200));
    this.solid = this.ghost = null;
    if (arm) {
      for (const g of arm.guards || []) this.addGuard(g);
      this.solid = new ArmFigure(this.scene, arm,
        this.material({ color: 0x9aa7b4, metalness: 0.3, roughness: 0.5 }),
        this.material({ color: 0x2f6fd6, metalness: 0.3, roughness: 0.4 }));
      const ghostMaterial = this.material({ color: 0x5eead4, transparent: true, opacity: 0.28, depthWrite: false });
      this.ghost = new ArmFigure(this.scene, arm, ghostMaterial, ghostMaterial);
      this.ghost.visible = false;
    }
    this.measured = null;  // the newest measured joints (degrees), drawn at the next frame
    this.drawn = null;     // the joints the solid arm was last drawn at
    this.ghostKey = null;  // what the ghost shows (null: hidden)
    this.dirty = true;
    this.pending = false;
    this.last = -Infinity;
    this.renderCount = 0;  // frames drawn (tests, bench)
    this.attachControls();
    new ResizeObserver(() => this.resize()).observe(container);
    document.addEventListener("visibilitychange", () => this.requestRender());
    this.resize();
  }

  // The page paints the measured arm in its own frames (renderIfDirty); an operator's
  // orbit, zoom or ghost is drawn at once, at most MAX_FPS, never while the page is hidden.
  fps() {
    return document.hidden ? 0 : ArmView.MAX_FPS;
  }

  material({ metalness, roughness, ...common }) {
    return this.software ? new THREE.MeshLambertMaterial(common)
      : new THREE.MeshStandardMaterial({ metalness, roughness, ...common });
  }

  renderIfDirty() {
    if (this.dirty) this.render();
  }

  // A frame is drawn on the next animation frame once the cap allows, with what is newest
  // then; any number of changes before it cost one frame.
  requestRender() {
    if (this.pending || !this.dirty) return;
    const fps = this.fps();
    if (fps === 0) return;  // drawn when the page is shown again (visibilitychange)
    this.pending = true;
    const wait = Math.max(0, this.last + 1000 / fps - performance.now());
    setTimeout(() => requestAnimationFrame((now) => {
      this.pending = false;
      if (document.hidden) return;
      this.last = now;
      this.render();
    }), wait);
  }

  addGuard(g, parent = this.scene) {
    const plane = new THREE.Mesh(new THREE.PlaneGeometry(1800, 1800),
      new THREE.MeshBasicMaterial({ color: 0xef4444, transparent: true, opacity: 0.13, side: THREE.DoubleSide, depthWrite: false }));
    plane.position.z = g.min_z_mm;
    parent.add(plane);
    const edge = new THREE.LineSegments(new THREE.EdgesGeometry(new THREE.PlaneGeometry(1800, 1800)),
      new THREE.LineBasicMaterial({ color: 0xef4444 }));
    edge.position.z = g.min_z_mm;
    parent.add(edge);
  }

  attachControls() {
    const el = this.renderer.domElement;
    let drag = null;
    el.addEventListener("pointerdown", (e) => { drag = { x: e.clientX, y: e.clientY }; el.setPointerCapture(e.pointerId); });
    el.addEventListener("pointerup", () => { drag = null; });
    el.addEventListener("pointermove", (e) => {
      if (!drag) return;
      this.orbit.azimuth -= (e.clientX - drag.x) * 0.008;
      this.orbit.elevation = Math.min(1.5, Math.max(-0.2, this.orbit.elevation + (e.clientY - drag.y) * 0.008));
      drag = { x: e.clientX, y: e.clientY };
      this.dirty = true;
      this.requestRender();
    });
    el.addEventListener("wheel", (e) => {
      e.preventDefault();
      this.orbit.distance = Math.min(8000, Math.max(600, this.orbit.distance * Math.exp(e.deltaY * 0.001)));
      this.dirty = true;
      this.requestRender();
    }, { passive: false });
  }

  resize() {
    const w = this.container.clientWidth || 400, h = this.container.clientHeight || 300;
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.dirty = true;
    this.requestRender();
  }

  render() {
    if (this.solid && this.measured && this.measured !== this.drawn) {
      this.solid.set(this.measured);
      this.drawn = this.measured;
    }
    const o = this.orbit;
    this.camera.position.set(
      this.target.x + o.distance * Math.cos(o.elevation) * Math.cos(o.azimuth),
      this.target.y + o.distance * Math.cos(o.elevation) * Math.sin(o.azimuth),
      this.target.z + o.distance * Math.sin(o.elevation));
    this.camera.lookAt(this.target);
    this.renderer.render(this.scene, this.camera);
    this.renderCount += 1;
    this.dirty = false;
  }

  // The measured arm (degrees): drawn at the page's next frame if it moved visibly.
  setMeasured(qDeg) {
    if (qDeg.some((v) => v === null || v === undefined)) return;
    const base = this.drawn;
    if (base && qDeg.every((v, i) => Math.abs(v - base[i]) < ArmView.STILL_DEG)) return;
    this.measured = qDeg;
    this.dirty = true;
  }

  // A target to show before it is sent (null hides the ghost); redrawn only if it changed.
  setGhost(qDeg) {
    const hide = !qDeg || qDeg.some((v) => v === null || v === undefined || Number.isNaN(v));
    const key = hide ? null : qDeg.map((v) => v.toFixed(2)).join(",");
    if (key === this.ghostKey) return;
    this.ghostKey = key;
    if (hide) {
      this.ghost.visible = false;
    } else {
      this.ghost.set(qDeg);
      this.ghost.visible = true;
    }
    this.dirty = true;
    this.requestRender();
  }
}

ArmView.MAX_FPS = 30;
// Joint motion (degrees) below which the drawn arm would not visibly change.
ArmView.STILL_DEG = 0.01;
