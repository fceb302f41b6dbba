// One frame on a canvas for the hand tools: fitted to its box, zoom with the wheel (about the cursor), pan by
// dragging with the right or middle button, drag with the left button what the page lets grab (its markers), a
// zoom loupe that follows the cursor, and overlays drawn by the page in image coordinates. Image coordinates are fmv3d's: origin at the image's top-left corner, pixel centres
// at +0.5, so a click at canvas position p is the image point (p − offset) / scale, unrounded.
import { h } from './dom';

export interface Overlay { draw(ctx: CanvasRenderingContext2D, view: FrameView): void; }

const LOUPE = 140;  // loupe size, CSS px
const LOUPE_ZOOM = 4;

export class FrameView {
  readonly el: HTMLElement;
  readonly canvas: HTMLCanvasElement;
  private loupe: HTMLCanvasElement;
  private img: HTMLImageElement | null = null;
  imageWidth = 0;
  imageHeight = 0;
  scale = 1;
  offX = 0;
  offY = 0;
  private zoom = 1;
  private cursor: [number, number] | null = null;
  private drag: { x: number; y: number; ox: number; oy: number } | null = null;
  overlays: Overlay[] = [];
  onClick: ((x: number, y: number, ev: MouseEvent) => void) | null = null;
  /** Left-button drag of something the page owns: onGrab says whether a press at image point (x, y) takes hold of
   *  it; onDrag follows the mouse once it has moved (≥ 2 CSS px); onDrop ends a drag. A press that never moves
   *  stays a click. */
  onGrab: ((x: number, y: number) => boolean) | null = null;
  onDrag: ((x: number, y: number) => void) | null = null;
  onDrop: ((x: number, y: number) => void) | null = null;
  private grab: { x: number; y: number; moved: boolean } | null = null;
  private swallowClick = false;
  private resize = new ResizeObserver(() => this.fit());

  constructor(readonly id: string, readonly title: HTMLElement = h('div', { class: 'fv-title' })) {
    this.canvas = h('canvas', { class: 'fv-canvas', 'data-view': id });
    this.loupe = h('canvas', { class: 'fv-loupe', width: LOUPE, height: LOUPE });
    const fitButton = h('button', { class: 'small fv-fit', title: 'fit the frame to the view', onclick: () => this.fit() }, 'fit');
    this.el = h('div', { class: 'fv' }, this.title, h('div', { class: 'fv-box' }, this.canvas, this.loupe, fitButton));
    this.resize.observe(this.canvas);
    this.canvas.addEventListener('contextmenu', (e) => e.preventDefault());
    this.canvas.addEventListener('wheel', (e) => {
      e.preventDefault();
      const [ix, iy] = this.toImage(e.offsetX, e.offsetY);
      this.zoom = Math.min(40, Math.max(1, this.zoom * (e.deltaY < 0 ? 1.25 : 0.8)));
      this.layout();
      this.offX = e.offsetX - ix * this.scale;
      this.offY = e.offsetY - iy * this.scale;
      this.draw();
    }, { passive: false });
    this.canvas.addEventListener('mousedown', (e) => {
      this.swallowClick = false;
      if (e.button === 0) {
        if (this.img && this.onGrab?.(...this.toImage(e.offsetX, e.offsetY))) this.grab = { x: e.clientX, y: e.clientY, moved: false };
        return;
      }
      this.drag = { x: e.clientX, y: e.clientY, ox: this.offX, oy: this.offY };
    });
    window.addEventListener('mouseup', (e) => {
      this.drag = null;
      const g = this.grab;
      this.grab = null;
      if (!g?.moved) return;
      this.swallowClick = true;  // the click that follows this mouseup ends the drag, it adds nothing
      const r = this.canvas.getBoundingClientRect();
      this.onDrop?.(...this.clampToImage(e.clientX - r.left, e.clientY - r.top));
    });
    this.canvas.addEventListener('mousemove', (e) => {
      if (this.grab) {
        this.grab.moved ||= Math.hypot(e.clientX - this.grab.x, e.clientY - this.grab.y) >= 2;
        if (this.grab.moved) this.onDrag?.(...this.clampToImage(e.offsetX, e.offsetY));
      }
      if (this.drag) {
        this.offX = this.drag.ox + e.clientX - this.drag.x;
        this.offY = this.drag.oy + e.clientY - this.drag.y;
      }
      this.cursor = [e.offsetX, e.offsetY];
      this.draw();
    });
    this.canvas.addEventListener('mouseleave', () => { this.cursor = null; this.draw(); });
    this.canvas.addEventListener('click', (e) => {
      if (this.swallowClick) { this.swallowClick = false; return; }
      if (!this.img || e.button !== 0) return;
      const [x, y] = this.toImage(e.offsetX, e.offsetY);
      if (x < 0 || y < 0 || x > this.imageWidth || y > this.imageHeight) return;
      this.onClick?.(x, y, e);
    });
  }

  dispose(): void { this.resize.disconnect(); }

  async load(url: string | null, width = 0, height = 0): Promise<void> {
    if (!url) { this.img = null; this.draw(); return; }
    const img = new Image();
    img.src = url;
    await img.decode();
    this.img = img;
    this.imageWidth = width || img.naturalWidth;
    this.imageHeight = height || img.naturalHeight;
    this.zoom = 1;
    this.fit();
  }

  /** Image coordinates of a canvas (CSS px) position. */
  toImage(cx: number, cy: number): [number, number] { return [(cx - this.offX) / this.scale, (cy - this.offY) / this.scale]; }
  private clampToImage(cx: number, cy: number): [number, number] {
    const [x, y] = this.toImage(cx, cy);
    return [Math.min(this.imageWidth, Math.max(0, x)), Math.min(this.imageHeight, Math.max(0, y))];
  }
  /** Canvas (CSS px) position of an image point. */
  toCanvas(x: number, y: number): [number, number] { return [this.offX + x * this.scale, this.offY + y * this.scale]; }
  /** Page (client) position of an image point: what a test clicks. */
  toClient(x: number, y: number): [number, number] {
    const r = this.canvas.getBoundingClientRect();
    const [cx, cy] = this.toCanvas(x, y);
    return [r.left + cx, r.top + cy];
  }

  private layout(): void {
    const w = this.canvas.clientWidth, ht = this.canvas.clientHeight;
    if (!this.imageWidth || !w || !ht) return;
    this.scale = Math.min(w / this.imageWidth, ht / this.imageHeight) * this.zoom;
  }

  fit(): void {
    const w = this.canvas.clientWidth, ht = this.canvas.clientHeight;
    const dpr = window.devicePixelRatio || 1;
    this.canvas.width = Math.max(1, Math.round(w * dpr));
    this.canvas.height = Math.max(1, Math.round(ht * dpr));
    this.zoom = 1;
    this.layout();
    this.offX = (w - this.imageWidth * this.scale) / 2;
    this.offY = (ht - this.imageHeight * this.scale) / 2;
    this.draw();
  }

  draw(): void {
    const ctx = this.canvas.getContext('2d')!;
    const dpr = window.devicePixelRatio || 1;
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.fillStyle = '#0b0d10';
    ctx.fillRect(0, 0, this.canvas.width, this.canvas.height);
    if (!this.img) return;
    ctx.imageSmoothingEnabled = this.scale < 2;
    ctx.drawImage(this.img, this.offX, this.offY, this.imageWidth * this.scale, this.imageHeight * this.scale);
    for (const o of this.overlays) { ctx.save(); o.draw(ctx, this); ctx.restore(); }
    this.drawLoupe();
  }

  private drawLoupe(): void {
    const c = this.cursor;
    this.loupe.style.display = c && this.img ? 'block' : 'none';
    if (!c || !this.img) return;
    const box = this.canvas.getBoundingClientRect();
    this.loupe.style.left = `${Math.min(c[0] + 20, box.width - LOUPE)}px`;
    this.loupe.style.top = `${Math.max(0, c[1] - LOUPE - 20)}px`;
    const lc = this.loupe.getContext('2d')!;
    const dpr = window.devicePixelRatio || 1;
    const sw = LOUPE / LOUPE_ZOOM;  // source size in canvas CSS px
    lc.imageSmoothingEnabled = false;
    lc.fillStyle = '#000';
    lc.fillRect(0, 0, LOUPE, LOUPE);
    lc.drawImage(this.canvas, (c[0] - sw / 2) * dpr, (c[1] - sw / 2) * dpr, sw * dpr, sw * dpr, 0, 0, LOUPE, LOUPE);
    lc.strokeStyle = '#fff';
    lc.beginPath();
    lc.moveTo(LOUPE / 2, 0); lc.lineTo(LOUPE / 2, LOUPE / 2 - 6); lc.moveTo(LOUPE / 2, LOUPE / 2 + 6); lc.lineTo(LOUPE / 2, LOUPE);
    lc.moveTo(0, LOUPE / 2); lc.lineTo(LOUPE / 2 - 6, LOUPE / 2); lc.moveTo(LOUPE / 2 + 6, LOUPE / 2); lc.lineTo(LOUPE, LOUPE / 2);
    lc.stroke();
    const [ix, iy] = this.toImage(c[0], c[1]);
    lc.fillStyle = 'rgba(0,0,0,.6)';
    lc.fillRect(0, LOUPE - 16, LOUPE, 16);
    lc.fillStyle = '#fff';
    lc.font = '11px ui-monospace, monospace';
    lc.fillText(`${ix.toFixed(1)}, ${iy.toFixed(1)}`, 4, LOUPE - 4);
  }
}

/** A cross with a label at an image point. */
export function drawMarker(ctx: CanvasRenderingContext2D, v: FrameView, x: number, y: number, colour: string,
    label?: string, selected = false): void {
  const [cx, cy] = v.toCanvas(x, y);
  ctx.strokeStyle = colour;
  ctx.lineWidth = selected ? 2.5 : 1.5;
  const r = selected ? 9 : 6;
  ctx.beginPath();
  ctx.moveTo(cx - r, cy); ctx.lineTo(cx + r, cy); ctx.moveTo(cx, cy - r); ctx.lineTo(cx, cy + r);
  ctx.stroke();
  ctx.beginPath(); ctx.arc(cx, cy, r, 0, 2 * Math.PI); ctx.stroke();
  if (label) {
    ctx.font = '12px system-ui, sans-serif';
    ctx.fillStyle = 'rgba(0,0,0,.7)';
    const w = ctx.measureText(label).width;
    ctx.fillRect(cx + r + 2, cy - 8, w + 6, 16);
    ctx.fillStyle = colour;
    ctx.fillText(label, cx + r + 5, cy + 4);
  }
}

/** The line a·x + b·y + c = 0 (image coordinates) clipped to the image, drawn dashed. */
export function drawLine(ctx: CanvasRenderingContext2D, v: FrameView, l: [number, number, number], colour: string): void {
  const [a, b, c] = l;
  const W = v.imageWidth, H = v.imageHeight;
  const pts: [number, number][] = [];
  if (Math.abs(b) > 1e-12) { pts.push([0, -c / b]); pts.push([W, -(c + a * W) / b]); }
  if (Math.abs(a) > 1e-12) { pts.push([-c / a, 0]); pts.push([-(c + b * H) / a, H]); }
  const inside = pts.filter(([x, y]) => x >= -1e-6 && x <= W + 1e-6 && y >= -1e-6 && y <= H + 1e-6);
  if (inside.length < 2) return;
  const [p, q] = [v.toCanvas(...inside[0]), v.toCanvas(...inside[inside.length - 1])];
  ctx.strokeStyle = colour;
  ctx.lineWidth = 1.5;
  ctx.setLineDash([6, 4]);
  ctx.beginPath(); ctx.moveTo(p[0], p[1]); ctx.lineTo(q[0], q[1]); ctx.stroke();
  ctx.setLineDash([]);
}

/** A strip of frame thumbnails; coloured by state, the chosen ones marked. */
export function frameStrip(frames: { name: string; registered: boolean; left_out: string | null }[],
    url: (name: string) => string, onPick: (name: string, ev: MouseEvent) => void): HTMLElement {
  const strip = h('div', { class: 'strip' });
  for (const f of frames) {
    const state = f.registered ? 'registered' : f.left_out ? 'left-out' : 'unknown';
    const tip = f.registered ? `${f.name}: registered` : f.left_out ? `${f.name}: left out — ${f.left_out}` : f.name;
    const item = h('button', { class: `thumb ${state}`, title: tip, 'data-frame': f.name, onclick: ((e: MouseEvent) => onPick(f.name, e)) as EventListener },
      h('img', { src: url(f.name), loading: 'lazy', alt: f.name }), h('span', {}, f.name.replace(/\.[a-z]+$/i, '')));
    strip.append(item);
  }
  return strip;
}

export function markStrip(strip: HTMLElement, marks: Record<string, string>): void {
  for (const b of strip.querySelectorAll<HTMLElement>('.thumb')) {
    b.dataset.mark = marks[b.dataset.frame!] ?? '';
  }
}
