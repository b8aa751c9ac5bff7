// Several arms in one 3D view, in the campaign's facility frame: each arm's figure (its
// chain, link volumes and tools: GET /api/v1/arms/{id}/arm) is carried by its base pose
// (GET /api/v1/arms: "base", 4x4, mm, from seqrun.toml) and labelled with its id. An arm
// the console has lost contact with is drawn grey.
import * as THREE from "/static/vendor/three/three.module.min.js";
import { ArmFigure, ArmView } from "/static/view3d.js";

const COLOURS = [0x9aa7b4, 0xc7a36b, 0x8fb58f, 0xb58fb0];

function label(text) {
  const canvas = document.createElement("canvas");
  canvas.width = 128; canvas.height = 64;
  const g = canvas.getContext("2d");
  g.fillStyle = "rgba(13,15,18,0.75)";
  g.fillRect(0, 0, 128, 64);
  g.fillStyle = "#fde047";
  g.font = "bold 44px system-ui, sans-serif";
  g.textAlign = "center";
  g.textBaseline = "middle";
  g.fillText(text, 64, 34);
  const sprite = new THREE.Sprite(new THREE.SpriteMaterial({ map: new THREE.CanvasTexture(canvas), depthTest: false }));
  sprite.scale.set(200, 100, 1);
  return sprite;
}

export class ArmsView extends ArmView {
  // arms: [{ id, scene (GET .../arm), base (4x4) }]
  constructor(container, arms) {
    super(container, null);
    this.figures = {};
    const grey = this.material({ color: 0x4b5563, transparent: true, opacity: 0.55, metalness: 0.1, roughness: 0.9 });
    const centre = new THREE.Vector3();
    arms.forEach((a, i) => {
      const holder = new THREE.Group();
      holder.matrixAutoUpdate = false;
      holder.matrix.set(...a.base.flat());
      this.scene.add(holder);
      for (const g of a.scene.guards || []) this.addGuard(g, holder);
      const body = this.material({ color: COLOURS[i % COLOURS.length], metalness: 0.3, roughness: 0.5 });
      const joints = this.material({ color: 0x2f6fd6, metalness: 0.3, roughness: 0.4 });
      const figure = new ArmFigure(holder, a.scene, body, joints);
      const tag = label(a.id);
      tag.position.set(0, 0, 1150);
      holder.add(tag);
      this.figures[a.id] = { id: a.id, figure, holder, tag, body, joints, grey, measured: null, drawn: null, lost: false };
      centre.add(new THREE.Vector3(a.base[0][3], a.base[1][3], a.base[2][3]));
    });
    if (arms.length) centre.divideScalar(arms.length);
    this.target.set(centre.x, centre.y, 500);
    this.orbit.distance = 3000;
  }

  // The measured joints of one arm (degrees), drawn at the next frame if it moved visibly.
  setArmMeasured(id, qDeg) {
    const f = this.figures[id];
    if (!f || qDeg.some((v) => v === null || v === undefined)) return;
    if (f.drawn && qDeg.every((v, i) => Math.abs(v - f.drawn[i]) < ArmView.STILL_DEG)) return;
    f.measured = qDeg;
    this.dirty = true;
  }

  // Lost contact with one arm: its figure grey (what it shows is its last known pose).
  setArmLost(id, lost) {
    const f = this.figures[id];
    if (!f || f.lost === lost) return;
    f.lost = lost;
    const body = lost ? f.grey : f.body, joints = lost ? f.grey : f.joints;
    f.figure.group.traverse((node) => {
      if (node.isMesh) node.material = node.geometry.type === "CylinderGeometry"
        && f.figure.joints.includes(node) ? joints : body;
    });
    this.dirty = true;
    this.requestRender();
  }

  render() {
    for (const f of Object.values(this.figures)) {
      if (f.measured && f.measured !== f.drawn) {
        f.figure.set(f.measured);
        f.drawn = f.measured;
      }
    }
    super.render();
  }
}
