// A 3D Tiles 1.0 tileset streamed by level of detail: tiles are refined while their screen-space error is above a
// threshold, loaded nearest-first with a few requests at a time, and evicted least-recently-used once the loaded
// points pass a budget, so the page's memory stays bounded whatever the cloud's size. The tileset's root transform
// (model frame → ECEF when georeferenced) is dropped: the console draws everything in the model frame.
import * as THREE from 'three';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';
import { parsePnts, b3dmGlb } from './pnts';
import { createPointMaterial, type PointUniforms } from './points';

interface RawTile {
  boundingVolume: { box?: number[]; sphere?: number[]; region?: number[] };
  geometricError: number; refine?: string; transform?: number[];
  content?: { uri?: string; url?: string }; children?: RawTile[];
}

export class TileNode {
  children: TileNode[] = [];
  state: 'none' | 'queued' | 'loading' | 'loaded' | 'failed' = 'none';
  object: THREE.Object3D | null = null;
  points = 0;
  bytes = 0;
  lastUsed = -1;
  priority = 0;
  constructor(
    readonly center: THREE.Vector3, readonly radius: number, readonly box: THREE.Box3 | null,
    readonly geometricError: number, readonly refine: 'ADD' | 'REPLACE', readonly url: string | null,
    readonly matrix: THREE.Matrix4, readonly depth: number, readonly parent: TileNode | null) {}
}

export interface TilesetStats { drawnPoints: number; drawnTiles: number; loadedTiles: number; loadedPoints: number; loadedBytes: number; pending: number; }

export interface TilesetOptions {
  /** Points kept loaded (GPU and JS); the drawn set is never larger. */
  pointBudget: number;
  /** Refine a tile while its geometric error covers more than this many pixels. */
  maxScreenSpaceError: number;
  concurrency: number;
}

export class TilesetLayer {
  readonly group = new THREE.Group();
  root: TileNode | null = null;
  /** The tileset's root transform (model frame → ECEF for a georeferenced workspace), or null. */
  rootTransform: THREE.Matrix4 | null = null;
  hasPoints = false;
  hasMeshes = false;
  hasViews = false;
  hasSigma = false;
  showPoints = true;
  showMeshes = true;
  private loaded = new Set<TileNode>();
  private inflight = 0;
  private frame = 0;
  private gltf = new GLTFLoader();
  private drawn: TileNode[] = [];
  private loadedPoints = 0;
  private loadedBytes = 0;
  private queue: TileNode[] = [];
  onChange: () => void = () => undefined;

  constructor(private readonly baseUrl: string, private readonly urlFor: (rel: string) => string,
              readonly uniforms: PointUniforms, readonly opts: TilesetOptions) {}

  async load(): Promise<void> {
    const res = await fetch(this.urlFor(this.baseUrl));
    if (!res.ok) throw new Error(`${this.baseUrl}: HTTP ${res.status}`);
    const json = await res.json() as { root: RawTile };
    this.rootTransform = json.root.transform ? new THREE.Matrix4().fromArray(json.root.transform) : null;
    // Everything below the root is drawn in the root's own frame.
    const raw = { ...json.root, transform: undefined };
    this.root = this.build(raw, new THREE.Matrix4(), dirname(this.baseUrl), 0, null);
  }

  private build(t: RawTile, parentM: THREE.Matrix4, dir: string, depth: number, parent: TileNode | null): TileNode {
    const m = parentM.clone();
    if (t.transform) m.multiply(new THREE.Matrix4().fromArray(t.transform));
    let center = new THREE.Vector3(), radius = Infinity, box: THREE.Box3 | null = null;
    const bv = t.boundingVolume ?? {};
    if (bv.box) {
      const b = bv.box;
      const c = new THREE.Vector3(b[0], b[1], b[2]);
      const axes = [new THREE.Vector3(b[3], b[4], b[5]), new THREE.Vector3(b[6], b[7], b[8]), new THREE.Vector3(b[9], b[10], b[11])];
      box = new THREE.Box3();
      for (let i = 0; i < 8; i++) {
        const p = c.clone();
        axes.forEach((a, k) => p.addScaledVector(a, (i >> k) & 1 ? 1 : -1));
        box.expandByPoint(p.applyMatrix4(m));
      }
      box.getCenter(center);
      radius = box.getSize(new THREE.Vector3()).length() / 2;
    } else if (bv.sphere) {
      center = new THREE.Vector3(bv.sphere[0], bv.sphere[1], bv.sphere[2]).applyMatrix4(m);
      radius = bv.sphere[3] * m.getMaxScaleOnAxis();
    }
    const uri = t.content?.uri ?? t.content?.url ?? null;
    const refine = (t.refine ?? parent?.refine ?? 'REPLACE').toUpperCase() === 'ADD' ? 'ADD' : 'REPLACE';
    const node = new TileNode(center, radius, box, t.geometricError ?? 0, refine, uri ? joinUrl(dir, uri) : null, m, depth, parent);
    for (const c of t.children ?? []) node.children.push(this.build(c, m, dir, depth + 1, node));
    return node;
  }

  /** Picks the tiles to draw for this camera, requests missing ones and evicts beyond the budget. */
  update(camera: THREE.PerspectiveCamera, viewportHeight: number): void {
    if (!this.root) return;
    this.frame++;
    const frustum = new THREE.Frustum().setFromProjectionMatrix(
      new THREE.Matrix4().multiplyMatrices(camera.projectionMatrix, camera.matrixWorldInverse));
    const k = viewportHeight / (2 * Math.tan(THREE.MathUtils.degToRad(camera.fov) / 2));
    const camPos = camera.position;
    const sse = (n: TileNode) => {
      if (!isFinite(n.radius)) return Infinity;
      const d = Math.max(n.center.distanceTo(camPos) - n.radius, 1e-6 * n.radius + 1e-9);
      return (n.geometricError * k) / d;
    };
    const visible = (n: TileNode) => !isFinite(n.radius) || frustum.intersectsSphere(new THREE.Sphere(n.center, n.radius));

    const draw: TileNode[] = [];
    const want: TileNode[] = [];
    let budgetLeft = this.opts.pointBudget;
    // Best-first traversal: the tile with the largest screen-space error is refined first, so a budget cut keeps
    // the coarse levels everywhere and drops only the finest tiles.
    const open: TileNode[] = [this.root];
    this.root.priority = sse(this.root);
    while (open.length > 0) {
      let bi = 0;
      for (let i = 1; i < open.length; i++) if (open[i].priority > open[bi].priority) bi = i;
      const n = open.splice(bi, 1)[0];
      if (!visible(n)) continue;
      n.lastUsed = this.frame;
      const isMesh = n.url !== null && !/\.pnts($|\?)/.test(n.url) && !/\.json($|\?)/.test(n.url);
      const shown = isMesh ? this.showMeshes : this.showPoints;
      const ready = n.url === null || n.state === 'loaded' || n.state === 'failed';
      if (n.url !== null && n.state === 'none' && shown) want.push(n);
      const refineIt = n.children.length > 0 && n.priority > this.opts.maxScreenSpaceError && budgetLeft > 0;
      if (n.state === 'loaded' && shown) {
        const replacedByLoadedChildren = refineIt && n.refine === 'REPLACE' &&
            n.children.every((c) => c.url === null || c.state === 'loaded' || c.state === 'failed' || !visible(c));
        if (!replacedByLoadedChildren) { draw.push(n); budgetLeft -= n.points; }
      }
      if (refineIt && (ready || n.refine === 'ADD')) {
        for (const c of n.children) { c.priority = sse(c); open.push(c); }
      } else if (refineIt) {
        // REPLACE parent still loading: fetch its children meanwhile so the swap happens at once.
        for (const c of n.children) if (c.url && c.state === 'none' && visible(c)) { c.priority = sse(c); want.push(c); }
      }
    }

    // Draw exactly the chosen set.
    for (const n of this.drawn) if (n.object) n.object.visible = false;
    for (const n of draw) if (n.object) n.object.visible = true;
    this.drawn = draw;

    // Requests: coarse / near first, a few at a time; the queue is rebuilt every frame so stale wishes drop out.
    want.sort((a, b) => a.depth - b.depth || b.priority - a.priority);
    this.queue = want;
    this.pump();
    this.evict();
  }

  private pump(): void {
    while (this.inflight < this.opts.concurrency && this.queue.length > 0) {
      const n = this.queue.shift()!;
      if (n.state !== 'none') continue;
      if (this.loadedPoints > this.opts.pointBudget * 1.5) break;
      n.state = 'loading';
      this.inflight++;
      this.fetchTile(n).then(() => { n.state = 'loaded'; }, (e) => { console.warn('tile', n.url, e); n.state = 'failed'; })
        .finally(() => { this.inflight--; this.onChange(); });
    }
  }

  private evict(): void {
    const limit = this.opts.pointBudget * 1.25;
    if (this.loadedPoints <= limit) return;
    const candidates = [...this.loaded].filter((n) => n.lastUsed !== this.frame && n !== this.root)
      .sort((a, b) => a.lastUsed - b.lastUsed || b.depth - a.depth);
    for (const n of candidates) {
      if (this.loadedPoints <= this.opts.pointBudget) break;
      this.unload(n);
    }
  }

  private unload(n: TileNode): void {
    if (n.object) {
      this.group.remove(n.object);
      n.object.traverse((o) => {
        const m = o as THREE.Mesh;
        m.geometry?.dispose();
        const mats = Array.isArray(m.material) ? m.material : m.material ? [m.material] : [];
        for (const mat of mats) {
          for (const v of Object.values(mat)) if (v instanceof THREE.Texture) v.dispose();
          mat.dispose();
        }
      });
    }
    this.loadedPoints -= n.points;
    this.loadedBytes -= n.bytes;
    n.object = null; n.points = 0; n.bytes = 0; n.state = 'none';
    this.loaded.delete(n);
  }

  private async fetchTile(n: TileNode): Promise<void> {
    const res = await fetch(this.urlFor(n.url!));
    if (!res.ok) throw new Error(`HTTP ${res.status}`);
    const buf = await res.arrayBuffer();
    let obj: THREE.Object3D;
    if (/\.json($|\?)/.test(n.url!)) {
      // External tileset: graft its root as this tile's child.
      const sub = JSON.parse(new TextDecoder().decode(buf)) as { root: RawTile };
      n.children.push(this.build(sub.root, n.matrix, dirname(n.url!), n.depth + 1, n));
      obj = new THREE.Group();
    } else if (new TextDecoder().decode(new Uint8Array(buf, 0, 4)) === 'pnts') {
      const t = parsePnts(buf);
      const g = new THREE.BufferGeometry();
      g.setAttribute('position', new THREE.BufferAttribute(t.positions, 3));
      if (t.colors) g.setAttribute('color', new THREE.BufferAttribute(t.colors, 3, true));
      if (t.normals) g.setAttribute('normal', new THREE.BufferAttribute(t.normals, 3, true));
      if (t.views) { g.setAttribute('views', new THREE.BufferAttribute(t.views, 1)); this.hasViews = true; }
      if (t.sigma) { g.setAttribute('sigma', new THREE.BufferAttribute(t.sigma, 1)); this.hasSigma = true; }
      g.computeBoundingSphere();
      const spacing = estimateSpacing(n, t.count);
      const pts = new THREE.Points(g, createPointMaterial(this.uniforms, spacing, !!t.colors));
      pts.position.set(...t.center);
      pts.matrixAutoUpdate = false;
      pts.matrix.copy(n.matrix).multiply(new THREE.Matrix4().makeTranslation(...t.center));
      n.points = t.count;
      this.hasPoints = true;
      if (t.views) for (const v of t.views) if (v > this.uniforms.viewsMax.value) this.uniforms.viewsMax.value = v;
      if (t.sigma) {
        // The ramp ends at the 90th percentile of σ over the tiles loaded so far (a few wild points do not flatten it).
        const s = Float32Array.from(t.sigma.filter((v) => isFinite(v) && v > 0)).sort();
        if (s.length) this.uniforms.sigmaMax.value = Math.max(this.uniforms.sigmaMax.value, s[Math.floor(0.9 * (s.length - 1))]);
      }
      obj = pts;
    } else {
      const glb = new TextDecoder().decode(new Uint8Array(buf, 0, 4)) === 'b3dm' ? b3dmGlb(buf) : buf;
      const gltf = await this.gltf.parseAsync(glb, '');
      obj = new THREE.Group();
      // glTF is y-up; 3D Tiles turn it to z-up (+90° about x) before the tile's transform.
      const yUpToZUp = new THREE.Matrix4().makeRotationX(Math.PI / 2);
      obj.matrixAutoUpdate = false;
      obj.matrix.copy(n.matrix).multiply(yUpToZUp);
      obj.add(unlit(gltf.scene));
      this.hasMeshes = true;
    }
    n.bytes = buf.byteLength;
    obj.visible = false;
    n.object = obj;
    this.group.add(obj);
    this.loaded.add(n);
    this.loadedPoints += n.points;
    this.loadedBytes += n.bytes;
  }

  stats(): TilesetStats {
    let drawnPoints = 0;
    for (const n of this.drawn) if (n.object?.visible && n.object instanceof THREE.Points) drawnPoints += n.points;
    return { drawnPoints, drawnTiles: this.drawn.length, loadedTiles: this.loaded.size, loadedPoints: this.loadedPoints,
      loadedBytes: this.loadedBytes, pending: this.inflight + this.queue.length };
  }

  /** Positions of the drawn point tiles (a sample of at most `max`), in the model frame: for fit view. */
  samplePoints(max: number): Float32Array {
    const pts = this.drawn.filter((n) => n.object instanceof THREE.Points);
    const total = pts.reduce((s, n) => s + n.points, 0);
    const step = Math.max(1, Math.floor(total / max));
    const out: number[] = [];
    const v = new THREE.Vector3();
    for (const n of pts) {
      const p = n.object as THREE.Points;
      const a = p.geometry.getAttribute('position') as THREE.BufferAttribute;
      for (let i = 0; i < a.count; i += step) { v.fromBufferAttribute(a, i).applyMatrix4(p.matrix); out.push(v.x, v.y, v.z); }
    }
    return Float32Array.from(out);
  }

  /** The local vertical in the model frame, from the root transform to ECEF (the ellipsoid normal there). */
  upFromTransform(): THREE.Vector3 | null {
    if (!this.rootTransform) return null;
    const p = new THREE.Vector3().setFromMatrixPosition(this.rootTransform);
    if (p.length() < 1e6) return null; // not an Earth-centred frame
    // Geodetic normal of WGS84 at p: (x/a², y/a², z/b²) normalised.
    const a2 = 6378137 ** 2, b2 = 6356752.314245 ** 2;
    const n = new THREE.Vector3(p.x / a2, p.y / a2, p.z / b2).normalize();
    const lin = new THREE.Matrix3().setFromMatrix4(this.rootTransform).invert();
    const up = n.applyMatrix3(lin);
    return up.lengthSq() > 0 ? up.normalize() : null;
  }

  /** Whether any tile holds a mesh (.glb / .b3dm) rather than points. */
  hasMeshContent(): boolean {
    const walk = (n: TileNode): boolean => (n.url !== null && /\.(glb|b3dm)($|\?)/.test(n.url)) || n.children.some(walk);
    return this.root ? walk(this.root) : false;
  }

  drawnObjects(): THREE.Object3D[] { return this.drawn.map((n) => n.object!).filter((o) => o && o.visible); }
  busy(): boolean { return this.inflight > 0 || this.queue.length > 0; }
}

/** A photogrammetric mesh carries its light in its texture: draw it unlit, as photographed. */
export function unlit(root: THREE.Object3D): THREE.Object3D {
  root.traverse((o) => {
    const m = o as THREE.Mesh;
    if (!m.isMesh) return;
    const mats = Array.isArray(m.material) ? m.material : [m.material];
    const repl = mats.map((old) => {
      const src = old as THREE.MeshStandardMaterial;
      const mat = new THREE.MeshBasicMaterial({ map: src.map ?? null, color: src.map ? 0xffffff : (src.color ?? 0xcccccc), side: THREE.DoubleSide });
      old.dispose();
      return mat;
    });
    m.material = Array.isArray(m.material) ? repl : repl[0];
  });
  return root;
}

/** Mean distance between a tile's neighbouring points, from its bounding volume and count (points on a surface). */
function estimateSpacing(n: TileNode, count: number): number {
  if (count <= 0) return 0;
  let area: number;
  if (n.box) {
    const s = n.box.getSize(new THREE.Vector3());
    const d = [s.x, s.y, s.z].sort((a, b) => b - a);
    area = d[0] * d[1] || d[0] * d[0];
  } else if (isFinite(n.radius)) area = 4 * n.radius * n.radius;
  else return 0;
  return Math.sqrt(area / count);
}

function dirname(url: string): string { const i = url.lastIndexOf('/'); return i >= 0 ? url.slice(0, i + 1) : ''; }
function joinUrl(dir: string, rel: string): string {
  if (/^[a-z]+:/i.test(rel) || rel.startsWith('/')) return rel;
  const parts = (dir + rel).split('/');
  const out: string[] = [];
  for (const p of parts) { if (p === '..') out.pop(); else if (p !== '.') out.push(p); }
  return out.join('/');
}
