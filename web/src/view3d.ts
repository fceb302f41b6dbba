// 3D view: camera frusta coloured by reprojection error (click one to see its frame), the sparse points, the dense
// cloud streamed from the workspace's 3D Tiles (coloured by colour / normal / number of views / confidence / height),
// the textured mesh (GLB), the CAD model coloured by a comparison's errors (report/compare/cad_error.ply), orbit or
// fly navigation, distance / height / area measurement and "fit view". window.fmv3d.stats() reports what is drawn.
import * as THREE from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';
import { PLYLoader } from 'three/examples/jsm/loaders/PLYLoader.js';
import { FlyControls } from './fly';
import { api, fileURL, type Camera, type Workspace } from './api';
import { h, fmtNumber, ramp, rampCss } from './dom';
import { TilesetLayer, unlit } from './tiles';
import { createPointMaterial, createPointUniforms, PointMode } from './points';
import { fitCamera, robustFrame } from './fit';
import { Measurer, type MeasureMode } from './measure';

export interface ViewStats {
  workspace: string | null; drawnPoints: number; sparsePoints: number; densePoints: number; cameras: number;
  meshTriangles: number; tilesDrawn: number; tilesLoaded: number; loadedPoints: number; loadedBytes: number;
  pending: number; firstPictureMs: number | null; firstPictureSinceLoadMs: number | null; ready: boolean; canvas: { width: number; height: number };
  cadTriangles: number; cadCoveredPercent: number | null; navigation: 'orbit' | 'fly'; metresPerUnit: number | null;
  cameraErrorRange: [number, number] | null;
}
export interface Measured { mode: string; value: number; points: { x: number; y: number }[] }
declare global {
  interface Window {
    fmv3d?: { stats: () => ViewStats; fitView: () => void; idle: () => Promise<void>;
      cameraOnScreen: (i: number) => { x: number; y: number } | null; setNavigation: (m: 'orbit' | 'fly') => void;
      cameraPose: () => { position: number[]; direction: number[] }; measured: () => Measured | null };
  }
}

export function mountView3d(el: HTMLElement, ws: string | null): () => void {
  if (!ws) { el.append(h('p', { class: 'muted pad' }, 'No workspace yet: start one on the Jobs page.')); return () => undefined; }
  const v = new View3d(el, ws);
  return () => v.dispose();
}

class View3d {
  private renderer: THREE.WebGLRenderer;
  private scene = new THREE.Scene();
  private camera = new THREE.PerspectiveCamera(50, 1, 0.01, 1e5);
  private controls: OrbitControls;
  private fly: FlyControls;
  private navigation: 'orbit' | 'fly' = 'orbit';
  private cad: THREE.Object3D | null = null;
  private cadTriangles = 0;
  private cameraErrors: [number, number] | null = null;
  private cadInfo: { scale: number; covered: number | null; radius: number | null } | null = null;
  private uniforms = createPointUniforms();
  private tiles: TilesetLayer | null = null;
  private sparse: THREE.Points | null = null;
  private sparseXYZ: Float32Array | null = null;
  private frusta: THREE.LineSegments | null = null;
  private mesh: THREE.Object3D | null = null;
  private meshTriangles = 0;
  private cameras: Camera[] = [];
  private up = new THREE.Vector3(0, 0, 1);
  private needsRender = true;
  private raf = 0;
  private disposed = false;
  private userMoved = false;
  private fittedOnDense = false;
  private firstPictureMs: number | null = null;          // since the view was opened
  private firstPictureSinceLoadMs: number | null = null; // since the page's navigation started
  private mountedAt = performance.now();
  private drawnPoints = 0;
  private ready = false;
  private canvasBox: HTMLElement;
  private info: HTMLElement;
  private side: HTMLElement;
  private measurer: Measurer;
  private resizeObs: ResizeObserver;

  constructor(private el: HTMLElement, private ws: string) {
    this.renderer = new THREE.WebGLRenderer({ antialias: false, preserveDrawingBuffer: true, powerPreference: 'high-performance' });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio, 2));
    this.scene.background = new THREE.Color(0x15181d);
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x444444, 2.0));
    const dl = new THREE.DirectionalLight(0xffffff, 1.2); dl.position.set(1, -1, 2); this.scene.add(dl);
    this.canvasBox = h('div', { class: 'canvas-box' });
    this.canvasBox.append(this.renderer.domElement);
    this.renderer.domElement.id = 'view3d-canvas';
    this.info = h('div', { class: 'overlay info', id: 'view3d-info' });
    this.side = h('aside', { class: 'side' });
    this.canvasBox.append(this.info);
    el.append(h('div', { class: 'view3d' }, this.canvasBox, this.side));
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.enableDamping = false;
    this.controls.screenSpacePanning = true;
    this.controls.addEventListener('change', () => { this.needsRender = true; });
    this.controls.addEventListener('start', () => { this.userMoved = true; });
    this.measurer = new Measurer(this.scene, this.canvasBox, this.camera, () => this.pickables(), () => this.up,
      () => { this.needsRender = true; }, () => this.metresPerUnit());
    this.fly = new FlyControls(this.camera, this.renderer.domElement, () => this.up, () => { this.needsRender = true; this.userMoved = true; });
    this.renderer.domElement.addEventListener('click', (e) => this.onClick(e));
    this.resizeObs = new ResizeObserver(() => this.resize());
    this.resizeObs.observe(this.canvasBox);
    this.resize();
    window.fmv3d = { stats: () => this.stats(), fitView: () => this.fitView(), idle: () => this.idle(),
      cameraOnScreen: (i) => this.cameraOnScreen(i), setNavigation: (m) => this.setNavigation(m),
      cameraPose: () => ({ position: this.camera.position.toArray(), direction: this.camera.getWorldDirection(new THREE.Vector3()).toArray() }),
      measured: () => this.measured() };
    this.buildSide();
    (this.side.querySelector("#show-cad") as HTMLInputElement).disabled = true;
    void this.load();
    this.loop();
  }

  private async load(): Promise<void> {
    let info: Workspace;
    try { info = await api.workspace(this.ws); } catch (e) { this.info.textContent = `workspace ${this.ws}: ${e}`; this.ready = true; return; }
    const files = info.files;
    const tasks: Promise<unknown>[] = [];
    tasks.push(api.cameras(this.ws).then((c) => this.addCameras(c)).catch(() => undefined));
    tasks.push(api.sparse(this.ws).then((s) => this.addSparse(s.positions, s.colors)).catch(() => undefined));
    if (files?.tileset) {
      const tiles = new TilesetLayer(files.tileset, (p) => fileURL(this.ws, p), this.uniforms,
        { pointBudget: 3_000_000, maxScreenSpaceError: 6, concurrency: 6 });
      tiles.onChange = () => { this.needsRender = true; };
      tiles.showMeshes = this.checked('#show-mesh');
      tiles.showPoints = this.checked('#show-dense');
      tasks.push(tiles.load().then(() => { this.tiles = tiles; this.scene.add(tiles.group); }).catch((e) => console.warn(e)));
    }
    await Promise.all(tasks);
    this.up = this.tiles?.upFromTransform() ?? this.estimateUp();
    this.uniforms.up.value.copy(this.up);
    if (!this.userMoved) this.fitView();
    // The mesh streams from the tileset when it has mesh tiles, else it is the workspace's one GLB.
    if (files?.mesh_glb && !this.tiles?.hasMeshContent()) {
      try {
        const gltf = await new GLTFLoader().loadAsync(fileURL(this.ws, files.mesh_glb));
        const g = new THREE.Group();
        g.rotation.x = Math.PI / 2; // glTF y-up → our z-up model frame
        g.add(unlit(gltf.scene));
        gltf.scene.traverse((o) => { const m = o as THREE.Mesh; if (m.isMesh) this.meshTriangles += (m.geometry.index?.count ?? m.geometry.getAttribute('position').count) / 3; });
        this.mesh = g;
        this.mesh.visible = this.checked('#show-mesh');
        this.scene.add(g);
      } catch (e) { console.warn('mesh', e); }
    }
    if (files?.cad_error && files?.compare) await this.loadCad(files.compare, files.cad_error).catch((e) => console.warn('CAD', e));
    this.updateLegend();
    this.ready = true;
    this.needsRender = true;
  }

  /** The CAD model coloured by the comparison's per-vertex error, brought from the CAD frame into the model frame. */
  private async loadCad(compareJson: string, ply: string): Promise<void> {
    const cmp = await (await fetch(fileURL(this.ws, compareJson))).json() as {
      transform?: { scale: number; rotation: number[][]; translation: number[] };
      error_mesh?: { scale_percent: number; covered_percent?: number; radius_percent?: number }; length?: number };
    if (!cmp.transform) throw new Error('compare.json has no transform');
    const geo = await new PLYLoader().loadAsync(fileURL(this.ws, ply));
    geo.computeVertexNormals();
    // compare.json's transform maps the reconstruction (model frame) into the CAD frame: x_cad = s R x + t.
    const { scale: sc, rotation: R, translation: t } = cmp.transform;
    const toCad = new THREE.Matrix4().set(
      sc * R[0][0], sc * R[0][1], sc * R[0][2], t[0],
      sc * R[1][0], sc * R[1][1], sc * R[1][2], t[1],
      sc * R[2][0], sc * R[2][1], sc * R[2][2], t[2], 0, 0, 0, 1);
    const mesh = new THREE.Mesh(geo, new THREE.MeshLambertMaterial({ vertexColors: true, side: THREE.DoubleSide }));
    mesh.matrixAutoUpdate = false;
    mesh.matrix.copy(toCad.invert());
    mesh.matrixWorldNeedsUpdate = true;
    mesh.visible = this.checked('#show-cad');
    this.cad = mesh;
    this.cadTriangles = (geo.index?.count ?? geo.getAttribute('position').count) / 3;
    this.cadInfo = { scale: cmp.error_mesh?.scale_percent ?? 1, covered: cmp.error_mesh?.covered_percent ?? null, radius: cmp.error_mesh?.radius_percent ?? null };
    this.scene.add(mesh);
    const box = this.side.querySelector('#show-cad') as HTMLInputElement | null;
    if (box) box.disabled = false;
  }

  /** Metres per model unit: the scale of the tileset's root transform (the georeference), else unknown. */
  private metresPerUnit(): number | null {
    const m = this.tiles?.rootTransform;
    if (!m || new THREE.Vector3().setFromMatrixPosition(m).length() < 1e6) return null;
    return new THREE.Vector3().setFromMatrixColumn(m, 0).length();
  }

  private setNavigation(mode: 'orbit' | 'fly'): void {
    this.navigation = mode;
    const sel = this.side.querySelector('#nav-mode') as HTMLSelectElement | null;
    if (sel && sel.value !== mode) sel.value = mode;
    const radius = Math.max(this.camera.position.distanceTo(this.controls.target), 1e-6);
    this.fly.enabled = mode === 'fly';
    this.controls.enabled = mode === 'orbit';
    if (mode === 'fly') {
      // About a tenth of the viewing distance per second.
      this.fly.speed = radius / 4;
      this.renderer.domElement.focus();
    } else {
      // Orbit again about the point the view looks at, as far as the view was from the old target.
      this.controls.target.copy(this.camera.position).addScaledVector(this.camera.getWorldDirection(new THREE.Vector3()), radius);
      this.controls.update();
    }
    const help = this.side.querySelector('#nav-help');
    if (help) help.textContent = mode === 'fly'
      ? 'W/S or ↑/↓ forward and back, A/D or ←/→ sideways, E/Q up and down, drag to look, wheel: speed, Shift: faster.'
      : 'Drag to orbit, right-drag to pan, wheel to zoom.';
    this.needsRender = true;
  }

  private measured(): Measured | null {
    const m = this.measurer.last;
    if (!m) return null;
    const r = this.renderer.domElement.getBoundingClientRect();
    return { mode: m.mode, value: m.value, points: m.points.map((p) => {
      const q = p.clone().project(this.camera);
      return { x: r.left + (q.x * 0.5 + 0.5) * r.width, y: r.top + (-q.y * 0.5 + 0.5) * r.height };
    }) };
  }

  private checked(sel: string): boolean { return (this.side.querySelector(sel) as HTMLInputElement | null)?.checked ?? false; }

  /** Without a georeference: the sky is where the cameras look from (the model frame is SfM's own). */
  private estimateUp(): THREE.Vector3 {
    if (this.cameras.length === 0) return new THREE.Vector3(0, 0, 1);
    // Cameras look at the scene: the sky is opposite to their mean viewing direction (and along their mean "up").
    const look = new THREE.Vector3(), camUp = new THREE.Vector3();
    for (const c of this.cameras) {
      const q = new THREE.Quaternion(c.rotation[1], c.rotation[2], c.rotation[3], c.rotation[0]).invert();
      look.add(new THREE.Vector3(0, 0, 1).applyQuaternion(q));
      camUp.add(new THREE.Vector3(0, -1, 0).applyQuaternion(q));
    }
    const est = look.lengthSq() > 0.25 * this.cameras.length ** 2 ? look.normalize().negate() : camUp.normalize();
    return est.z > Math.cos(THREE.MathUtils.degToRad(35)) ? new THREE.Vector3(0, 0, 1) : est;
  }

  private addCameras(cams: Camera[]): void {
    this.cameras = cams;
    if (cams.length === 0) return;
    const centers = cams.map((c) => new THREE.Vector3(...c.center));
    // Frustum depth: about half the typical spacing between neighbouring cameras.
    const nn: number[] = centers.map((c, i) => Math.min(...centers.filter((_, j) => j !== i).map((d) => d.distanceTo(c)), Infinity));
    const finite = nn.filter(isFinite).sort((a, b) => a - b);
    const span = new THREE.Box3().setFromPoints(centers).getSize(new THREE.Vector3()).length() || 1;
    const depth = Math.min(finite.length ? finite[Math.floor(finite.length / 2)] * 0.8 : span * 0.05, span * 0.08) || 1;
    // The colour scale spans the cameras' own errors (the legend gives its ends in pixels), so the worst cameras
    // stand out whatever the model's overall accuracy.
    const errs = cams.map((c) => c.reprojection_rms_px ?? 0);
    const emin = Math.min(...errs), emax = Math.max(emin + 0.05, ...errs);
    const pos: number[] = [], col: number[] = [];
    cams.forEach((c, i) => {
      const q = new THREE.Quaternion(c.rotation[1], c.rotation[2], c.rotation[3], c.rotation[0]).invert();
      const C = centers[i];
      const s = depth;
      const corner = (u: number, v: number) => new THREE.Vector3(((u - c.cx) / c.fx) * s, ((v - c.cy) / c.fy) * s, s).applyQuaternion(q).add(C);
      const k = [corner(0, 0), corner(c.width, 0), corner(c.width, c.height), corner(0, c.height)];
      const segs: THREE.Vector3[][] = [[C, k[0]], [C, k[1]], [C, k[2]], [C, k[3]], [k[0], k[1]], [k[1], k[2]], [k[2], k[3]], [k[3], k[0]]];
      // A tick on the image's top edge shows which way is up in the frame.
      const top = k[0].clone().add(k[1]).multiplyScalar(0.5);
      segs.push([top, top.clone().add(k[0].clone().sub(k[3]).multiplyScalar(0.15))]);
      const [r, g, b] = ramp((errs[i] - emin) / (emax - emin));
      for (const [a, bb] of segs) { pos.push(a.x, a.y, a.z, bb.x, bb.y, bb.z); col.push(r, g, b, r, g, b); }
    });
    const geo = new THREE.BufferGeometry();
    geo.setAttribute('position', new THREE.Float32BufferAttribute(pos, 3));
    geo.setAttribute('color', new THREE.Float32BufferAttribute(col, 3));
    this.frusta = new THREE.LineSegments(geo, new THREE.LineBasicMaterial({ vertexColors: true }));
    this.scene.add(this.frusta);
    this.cameraErrors = [emin, emax];
    this.needsRender = true;
  }

  private addSparse(positions: number[], colors: number[]): void {
    if (!positions || positions.length === 0) return;
    this.sparseXYZ = Float32Array.from(positions);
    const g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.BufferAttribute(this.sparseXYZ, 3));
    if (colors && colors.length === positions.length) g.setAttribute('color', new THREE.BufferAttribute(Uint8Array.from(colors), 3, true));
    this.sparse = new THREE.Points(g, createPointMaterial(this.uniforms, 0, colors?.length === positions.length, 3));
    this.scene.add(this.sparse);
    this.needsRender = true;
  }

  /** Frames what is shown: the dense cloud, else the sparse points, the mesh, the CAD model, or the cameras. */
  fitView(): void {
    let xyz: ArrayLike<number> | null = null;
    const boxOf = (o: THREE.Object3D | null): number[] | null => {
      if (!o?.visible) return null;
      o.updateMatrixWorld(true);
      const b = new THREE.Box3().setFromObject(o);
      return b.isEmpty() ? null : [b.min.x, b.min.y, b.min.z, b.max.x, b.max.y, b.max.z];
    };
    const dense = this.tiles?.showPoints ? this.tiles.samplePoints(200_000) : null;
    if (dense && dense.length >= 30) xyz = dense;
    else if (this.sparse?.visible && this.sparseXYZ && this.sparseXYZ.length >= 30) xyz = this.sparseXYZ;
    else xyz = boxOf(this.mesh) ?? boxOf(this.cad);
    if (!xyz && this.cameras.length) xyz = this.cameras.flatMap((c) => c.center);
    if (!xyz) return;
    const f = robustFrame(xyz, this.up);
    if (!f) return;
    const rect = this.canvasBox.getBoundingClientRect();
    this.camera.aspect = Math.max(rect.width, 1) / Math.max(rect.height, 1);
    const target = fitCamera(this.camera, f);
    this.controls.target.copy(target);
    this.controls.update();
    // Height colouring spans the framed box.
    const cz = f.center.dot(this.up);
    this.uniforms.heightRange.value.set(cz - f.half.z, cz + f.half.z);
    this.needsRender = true;
  }

  private pickables(): THREE.Object3D[] {
    const out: THREE.Object3D[] = [];
    if (this.mesh?.visible) out.push(this.mesh);
    if (this.tiles) out.push(...this.tiles.drawnObjects());
    if (this.sparse?.visible) out.push(this.sparse);
    return out;
  }

  private onClick(e: MouseEvent): void {
    if (this.measurer.mode !== 'off') { this.measurer.click(e, this.renderer.domElement); return; }
    // Pick the camera whose frustum (centre or image plane) projects nearest the click, within 14 px.
    const rect = this.renderer.domElement.getBoundingClientRect();
    const mx = e.clientX - rect.left, my = e.clientY - rect.top;
    let best = -1, bestD = 14;
    this.cameras.forEach((c, i) => {
      const p = new THREE.Vector3(...c.center).project(this.camera);
      if (p.z > 1) return;
      const d = Math.hypot((p.x * 0.5 + 0.5) * rect.width - mx, (-p.y * 0.5 + 0.5) * rect.height - my);
      if (d < bestD) { bestD = d; best = i; }
    });
    if (best >= 0) this.showFrame(this.cameras[best]);
  }

  /** Where camera i's centre is drawn, in page pixels (null when behind the view or off the canvas). */
  cameraOnScreen(i: number): { x: number; y: number } | null {
    const c = this.cameras[i];
    if (!c) return null;
    const p = new THREE.Vector3(...c.center).project(this.camera);
    const r = this.renderer.domElement.getBoundingClientRect();
    const x = r.left + (p.x * 0.5 + 0.5) * r.width, y = r.top + (-p.y * 0.5 + 0.5) * r.height;
    return p.z > 1 || x < r.left || x > r.right || y < r.top || y > r.bottom ? null : { x, y };
  }

  private showFrame(c: Camera): void {
    const panel = this.side.querySelector('#frame-panel')!;
    panel.replaceChildren(h('h3', {}, c.name),
      h('img', { src: fileURL(this.ws, c.frame), alt: c.name, class: 'frame' }),
      h('p', {}, `${c.width}×${c.height}, f = ${fmtNumber(c.fx, 1)} px, reprojection RMS ${c.reprojection_rms_px === null ? '–' : fmtNumber(c.reprojection_rms_px, 2) + ' px'}`));
  }

  private buildSide(): void {
    const check = (id: string, label: string, on: boolean, fn: (v: boolean) => void) => {
      const i = h('input', { type: 'checkbox', id, checked: on });
      i.addEventListener('change', () => { fn(i.checked); this.needsRender = true; });
      return h('label', { class: 'inline' }, i, ' ', label);
    };
    const mode = h('select', { id: 'point-mode' },
      h('option', { value: String(PointMode.Color) }, 'colour'), h('option', { value: String(PointMode.Normal) }, 'normal'),
      h('option', { value: String(PointMode.Views) }, 'number of views'), h('option', { value: String(PointMode.Confidence) }, 'confidence'),
      h('option', { value: String(PointMode.Height) }, 'height'));
    mode.addEventListener('change', () => { this.uniforms.mode.value = Number(mode.value); this.updateLegend(); this.needsRender = true; });
    const nav = h('select', { id: 'nav-mode' }, h('option', { value: 'orbit' }, 'orbit'), h('option', { value: 'fly' }, 'fly (first person)'));
    nav.addEventListener('change', () => this.setNavigation(nav.value as 'orbit' | 'fly'));
    const size = h('input', { type: 'range', min: '0.3', max: '4', step: '0.1', value: String(this.uniforms.sizeScale.value) });
    size.addEventListener('input', () => { this.uniforms.sizeScale.value = Number(size.value); this.needsRender = true; });
    const measureBtns = (['distance', 'height', 'area'] as MeasureMode[]).map((m) =>
      h('button', { class: 'small', 'data-measure': m, onclick: () => this.setMeasure(m) }, m));
    this.side.append(
      h('button', { id: 'fit-view', onclick: () => this.fitView() }, 'Fit view'),
      h('h3', {}, 'Layers'),
      check('show-cameras', 'cameras', true, (v) => { if (this.frusta) this.frusta.visible = v; }),
      check('show-sparse', 'sparse points', true, (v) => { if (this.sparse) this.sparse.visible = v; }),
      check('show-dense', 'dense cloud (3D Tiles)', true, (v) => { if (this.tiles) this.tiles.showPoints = v; }),
      check('show-mesh', 'textured mesh', false, (v) => { if (this.mesh) this.mesh.visible = v; if (this.tiles) this.tiles.showMeshes = v; }),
      check('show-cad', 'CAD model (comparison error)', true, (v) => { if (this.cad) this.cad.visible = v; this.updateLegend(); }),
      h('label', {}, 'points coloured by ', mode),
      h('label', {}, 'point size ', size),
      h('div', { id: 'legend', class: 'legend' }),
      h('h3', {}, 'Navigation'),
      h('label', {}, 'controls ', nav),
      h('p', { id: 'nav-help', class: 'muted small' }, 'Drag to orbit, right-drag to pan, wheel to zoom.'),
      h('h3', {}, 'Measure'),
      h('div', { class: 'row' }, ...measureBtns, h('button', { class: 'small', onclick: () => this.setMeasure('off') }, 'clear')),
      h('div', { id: 'measure-out', class: 'measure-out' }),
      h('div', { id: 'frame-panel', class: 'frame-panel' }, h('p', { class: 'muted' }, 'Click a camera to see its frame.')));
  }

  private setMeasure(m: MeasureMode): void {
    this.measurer.setMode(m, this.side.querySelector('#measure-out') as HTMLElement);
    for (const b of this.side.querySelectorAll<HTMLButtonElement>('[data-measure]')) b.classList.toggle('active', b.dataset.measure === m);
    this.controls.enabled = true;
  }

  private updateLegend(): void {
    const lg = this.side.querySelector('#legend');
    if (!lg) return;
    const bar = (lo: string, hi: string, what: string, cls = 'ramp', id = '') =>
      h('div', { class: 'ramp-legend', ...(id ? { id } : {}) }, h('span', {}, lo), h('span', { class: cls }), h('span', {}, hi), h('span', { class: 'muted' }, ' ' + what));
    const parts: Node[] = [];
    if (this.cameraErrors) parts.push(bar(`${fmtNumber(this.cameraErrors[0], 2)}`, `${fmtNumber(this.cameraErrors[1], 2)} px`, 'camera reprojection RMS', 'ramp', 'legend-cameras'));
    const m = this.uniforms.mode.value;
    const noAttr = (what: string) => parts.push(h('p', { class: 'muted', id: 'legend-missing' }, `The point tiles carry no ${what}.`));
    if (m === PointMode.Views) {
      if (this.tiles?.hasViews) parts.push(bar(`${Math.round(this.uniforms.viewsMax.value)}`, '2', 'views per point (green: many)', 'ramp', 'legend-points'));
      else noAttr('per-point number of views (batch table "views")');
    }
    if (m === PointMode.Confidence) {
      const k = this.metresPerUnit();
      const s = this.uniforms.sigmaMax.value * (k ?? 1);
      if (this.tiles?.hasSigma) parts.push(bar('0', `≥ ${fmtNumber(s, 3)} ${k === null ? 'units' : 'm'}`, 'stated σ along the normal (green: confident)', 'ramp', 'legend-points'));
      else noAttr('per-point uncertainty (batch table "sigma")');
    }
    if (m === PointMode.Height) {
      const r = this.uniforms.heightRange.value;
      const k = this.metresPerUnit();
      parts.push(bar('0', `${fmtNumber((r.y - r.x) * (k ?? 1), 1)} ${k === null ? 'units' : 'm'}`, 'height above the framed base', 'ramp', 'legend-points'));
    }
    if (this.cad?.visible && this.cadInfo) {
      const sc = this.cadInfo.scale;
      parts.push(bar(`−${fmtNumber(sc, 2)}`, `+${fmtNumber(sc, 2)} % of H`, 'CAD: signed distance of the reconstruction (blue inside, red outside)', 'ramp diverging', 'legend-cad'));
      parts.push(h('p', { class: 'muted' }, h('span', { class: 'swatch grey' }), ` no reconstructed point within ${this.cadInfo.radius === null ? '–' : fmtNumber(this.cadInfo.radius, 2) + ' % of H'}` +
        (this.cadInfo.covered === null ? '' : ` (${fmtNumber(100 - this.cadInfo.covered, 1)}% of the CAD's vertices)`)));
    }
    lg.replaceChildren(...parts);
    void rampCss;
  }

  private resize(): void {
    const r = this.canvasBox.getBoundingClientRect();
    const w = Math.max(1, Math.floor(r.width)), hh = Math.max(1, Math.floor(r.height));
    this.renderer.setSize(w, hh, true);
    this.camera.aspect = w / hh;
    this.camera.updateProjectionMatrix();
    this.needsRender = true;
  }

  private loop = (): void => {
    if (this.disposed) return;
    this.raf = requestAnimationFrame(this.loop);
    this.fly.update();
    const busy = (this.tiles?.busy() ?? false) || this.fly.moving();
    if (!this.needsRender && !busy) return;
    this.needsRender = false;
    const size = this.renderer.getDrawingBufferSize(new THREE.Vector2());
    this.uniforms.projScale.value = size.y / (2 * Math.tan(THREE.MathUtils.degToRad(this.camera.fov) / 2));
    this.camera.updateMatrixWorld();
    if (this.tiles) this.tiles.update(this.camera, size.y);
    // The first dense tiles frame the model unless the operator has already moved the view.
    if (this.tiles && !this.fittedOnDense && !this.userMoved && this.tiles.stats().drawnPoints > 0) {
      this.fittedOnDense = true;
      this.fitView();
      this.tiles.update(this.camera, size.y);
    }
    this.renderer.render(this.scene, this.camera);
    this.measurer.updateLabels(this.renderer.domElement);
    const ts = this.tiles?.stats();
    const sparseN = this.sparse?.visible ? this.sparse.geometry.getAttribute('position').count : 0;
    this.drawnPoints = sparseN + (ts?.drawnPoints ?? 0);
    if (this.firstPictureMs === null && (ts ? ts.drawnPoints > 0 : this.drawnPoints > 0)) {
      this.firstPictureMs = performance.now() - this.mountedAt;
      this.firstPictureSinceLoadMs = performance.now();
    }
    this.info.textContent = `${fmtNumber(this.drawnPoints)} points drawn` +
      (ts ? ` · ${ts.drawnTiles} tiles (${ts.loadedTiles} loaded${ts.pending ? `, ${ts.pending} pending` : ''})` : '') +
      (this.cameras.length ? ` · ${this.cameras.length} cameras` : '') +
      (this.meshTriangles ? ` · mesh ${fmtNumber(this.meshTriangles)} triangles` : '');
  };

  stats(): ViewStats {
    const ts = this.tiles?.stats();
    const c = this.renderer.domElement;
    return {
      workspace: this.ws, drawnPoints: this.drawnPoints, sparsePoints: this.sparseXYZ ? this.sparseXYZ.length / 3 : 0,
      densePoints: ts?.drawnPoints ?? 0, cameras: this.cameras.length, meshTriangles: this.meshTriangles,
      tilesDrawn: ts?.drawnTiles ?? 0, tilesLoaded: ts?.loadedTiles ?? 0, loadedPoints: ts?.loadedPoints ?? 0,
      loadedBytes: ts?.loadedBytes ?? 0, pending: ts?.pending ?? 0, firstPictureMs: this.firstPictureMs,
      firstPictureSinceLoadMs: this.firstPictureSinceLoadMs,
      ready: this.ready && !(this.tiles?.busy() ?? false), canvas: { width: c.width, height: c.height },
      cadTriangles: this.cad?.visible ? this.cadTriangles : 0, cadCoveredPercent: this.cadInfo?.covered ?? null,
      navigation: this.navigation, metresPerUnit: this.metresPerUnit(),
      cameraErrorRange: this.cameraErrors,
    };
  }

  /** Resolves once the workspace is loaded, no tile is pending and a frame has been drawn. */
  async idle(): Promise<void> {
    for (;;) {
      if (this.disposed) return;
      if (this.stats().ready && !this.needsRender) {
        await new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r)));
        if (this.stats().ready && !this.needsRender) return;
      }
      await new Promise((r) => setTimeout(r, 50));
    }
  }

  dispose(): void {
    this.disposed = true;
    cancelAnimationFrame(this.raf);
    this.resizeObs.disconnect();
    this.controls.dispose();
    this.fly.dispose();
    this.measurer.dispose();
    this.scene.traverse((o) => {
      const m = o as THREE.Mesh;
      m.geometry?.dispose();
      const mats = Array.isArray(m.material) ? m.material : m.material ? [m.material] : [];
      mats.forEach((x) => x.dispose());
    });
    this.renderer.dispose();
    this.renderer.forceContextLoss();
    delete window.fmv3d;
    void this.el;
  }
}
