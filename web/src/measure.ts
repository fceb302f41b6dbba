// Measurement on the 3D view: distance (3D, with its horizontal and vertical parts), height difference along the
// model's up axis, and planimetric area of a polygon (clicks on the drawn model; double-click closes the polygon).
// In metres when the model frame's scale is known (the georeference's similarity), else in the model's own units.
import * as THREE from 'three';
import { h, fmtNumber } from './dom';

export type MeasureMode = 'off' | 'distance' | 'height' | 'area';

export class Measurer {
  mode: MeasureMode = 'off';
  private pts: THREE.Vector3[] = [];
  private group = new THREE.Group();
  private labels: { el: HTMLElement; at: THREE.Vector3 }[] = [];
  private out: HTMLElement | null = null;
  private raycaster = new THREE.Raycaster();
  /** The last finished measurement: its value (metres, m² or model units) and the picked model points. */
  last: { mode: MeasureMode; value: number; points: THREE.Vector3[] } | null = null;

  constructor(scene: THREE.Scene, private overlay: HTMLElement, private camera: THREE.PerspectiveCamera,
              private pickables: () => THREE.Object3D[], private up: () => THREE.Vector3, private changed: () => void,
              private metresPerUnit: () => number | null = () => null) {
    scene.add(this.group);
  }

  setMode(m: MeasureMode, out: HTMLElement): void {
    this.mode = m;
    this.out = out;
    this.clear();
    out.textContent = m === 'off' ? '' : m === 'area' ? 'Click the polygon\'s corners; double-click to close.' : 'Click two points on the model.';
  }

  private clear(): void {
    this.pts = [];
    this.last = null;
    for (const c of [...this.group.children]) { this.group.remove(c); ((c as THREE.Line).geometry)?.dispose(); }
    for (const l of this.labels) l.el.remove();
    this.labels = [];
    this.changed();
  }

  /** The nearest model point under the mouse. */
  pick(e: MouseEvent, canvas: HTMLCanvasElement): THREE.Vector3 | null {
    const r = canvas.getBoundingClientRect();
    const ndc = new THREE.Vector2(((e.clientX - r.left) / r.width) * 2 - 1, -((e.clientY - r.top) / r.height) * 2 + 1);
    this.raycaster.setFromCamera(ndc, this.camera);
    const dist = this.camera.position.distanceTo(new THREE.Vector3()) || 1;
    // A click hits a point within ~4 px of the ray at the point's depth.
    const pxAngle = (2 * Math.tan(THREE.MathUtils.degToRad(this.camera.fov) / 2)) / r.height;
    this.raycaster.params.Points = { threshold: 4 * pxAngle * dist };
    this.raycaster.params.Line = { threshold: 0 };
    const hits = this.raycaster.intersectObjects(this.pickables(), true).filter((x) => !(x.object instanceof THREE.Line));
    if (hits.length === 0) return null;
    // For points, prefer the hit nearest the ray among the closest few (the ray threshold is generous).
    hits.sort((a, b) => a.distance - b.distance);
    return hits[0].point.clone();
  }

  click(e: MouseEvent, canvas: HTMLCanvasElement): void {
    if (this.mode === 'off') return;
    const p = this.pick(e, canvas);
    if (!p) { if (this.out) this.out.textContent = 'No model under the mouse there.'; return; }
    const done = (this.mode === 'distance' || this.mode === 'height') && this.pts.length >= 2;
    if (done) this.clear();
    if (this.mode === 'area' && e.detail >= 2 && this.pts.length >= 3) { this.finishArea(); return; }
    this.pts.push(p);
    this.redraw();
  }

  private redraw(): void {
    for (const c of [...this.group.children]) { this.group.remove(c); ((c as THREE.Line).geometry)?.dispose(); }
    for (const l of this.labels) l.el.remove();
    this.labels = [];
    const mat = new THREE.LineBasicMaterial({ color: 0x4fc3f7, depthTest: false });
    const dots = new THREE.Points(new THREE.BufferGeometry().setFromPoints(this.pts),
      new THREE.PointsMaterial({ color: 0xffffff, size: 7, sizeAttenuation: false, depthTest: false }));
    dots.renderOrder = 10;
    this.group.add(dots);
    if (this.pts.length >= 2) {
      const line = new THREE.Line(new THREE.BufferGeometry().setFromPoints(this.pts), mat);
      line.renderOrder = 10;
      this.group.add(line);
    }
    const up = this.up().clone().normalize();
    if ((this.mode === 'distance' || this.mode === 'height') && this.pts.length === 2) {
      const [a, b] = this.pts;
      const k = this.metresPerUnit() ?? 1, u = this.unit();
      const d = b.clone().sub(a);
      const dv = d.dot(up) * k;
      const len = d.length() * k;
      const dh = Math.sqrt(Math.max(0, len * len - dv * dv));
      const text = this.mode === 'distance'
        ? `${fmtNumber(len, 2)} ${u} (horizontal ${fmtNumber(dh, 2)}, vertical ${fmtNumber(dv, 2)})`
        : `height difference ${fmtNumber(dv, 2)} ${u}`;
      this.label(a.clone().add(b).multiplyScalar(0.5), this.mode === 'distance' ? `${fmtNumber(len, 2)} ${u}` : `Δh ${fmtNumber(dv, 2)} ${u}`);
      const value = this.mode === 'distance' ? len : dv;
      this.last = { mode: this.mode, value, points: [a.clone(), b.clone()] };
      if (this.out) { this.out.textContent = text; this.out.dataset.value = String(value); }
    }
    this.changed();
  }

  private finishArea(): void {
    const up = this.up().clone().normalize();
    const tmp = Math.abs(up.x) < 0.9 ? new THREE.Vector3(1, 0, 0) : new THREE.Vector3(0, 1, 0);
    const e1 = tmp.sub(up.clone().multiplyScalar(tmp.dot(up))).normalize();
    const e2 = new THREE.Vector3().crossVectors(up, e1);
    const xy = this.pts.map((p) => [p.dot(e1), p.dot(e2)]);
    let area = 0, perim = 0;
    for (let i = 0; i < xy.length; i++) {
      const [x0, y0] = xy[i], [x1, y1] = xy[(i + 1) % xy.length];
      area += x0 * y1 - x1 * y0;
      perim += this.pts[i].distanceTo(this.pts[(i + 1) % this.pts.length]);
    }
    const k = this.metresPerUnit() ?? 1, u = this.unit();
    area = (Math.abs(area) / 2) * k * k;
    perim *= k;
    const corners = this.pts.map((p) => p.clone());
    this.pts.push(this.pts[0].clone());
    this.redraw();
    const c = this.pts.slice(0, -1).reduce((s, p) => s.add(p), new THREE.Vector3()).multiplyScalar(1 / (this.pts.length - 1));
    this.label(c, `${fmtNumber(area, 1)} ${u}²`);
    this.last = { mode: 'area', value: area, points: corners };
    if (this.out) { this.out.textContent = `area ${fmtNumber(area, 2)} ${u}² (planimetric), perimeter ${fmtNumber(perim, 2)} ${u}`; this.out.dataset.value = String(area); }
    this.pts = [];
  }

  /** Metres when the model's scale is known (a georeferenced workspace), else the model's own units. */
  private unit(): string { return this.metresPerUnit() === null ? 'units' : 'm'; }

  private label(at: THREE.Vector3, text: string): void {
    const el = h('div', { class: 'overlay measure-label' }, text);
    this.overlay.append(el);
    this.labels.push({ el, at });
  }

  updateLabels(canvas: HTMLCanvasElement): void {
    const r = canvas.getBoundingClientRect();
    for (const l of this.labels) {
      const p = l.at.clone().project(this.camera);
      l.el.style.display = p.z > 1 ? 'none' : '';
      l.el.style.left = `${(p.x * 0.5 + 0.5) * r.width}px`;
      l.el.style.top = `${(-p.y * 0.5 + 0.5) * r.height}px`;
    }
  }

  dispose(): void { this.clear(); }
}
