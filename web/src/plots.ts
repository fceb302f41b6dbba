// Small SVG charts for the report and the profile: horizontal bars, histograms and line plots with axes.
import { fmtNumber } from './dom';

const NS = 'http://www.w3.org/2000/svg';
function s<K extends keyof SVGElementTagNameMap>(tag: K, attrs: Record<string, string | number> = {}, text?: string): SVGElementTagNameMap[K] {
  const e = document.createElementNS(NS, tag);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, String(v));
  if (text !== undefined) e.textContent = text;
  return e;
}

/** "Nice" tick values covering [lo, hi]. */
export function ticks(lo: number, hi: number, n = 5): number[] {
  if (!(hi > lo)) return [lo];
  const step0 = (hi - lo) / n;
  const mag = 10 ** Math.floor(Math.log10(step0));
  const step = [1, 2, 5, 10].map((m) => m * mag).find((m) => m >= step0) ?? 10 * mag;
  const out: number[] = [];
  for (let v = Math.ceil(lo / step) * step; v <= hi + 1e-9 * step; v += step) out.push(Math.abs(v) < 1e-12 ? 0 : v);
  return out;
}

export interface ChartOpts { width?: number; height?: number; xLabel?: string; yLabel?: string; color?: string; }

/** Horizontal bars, one per label. */
export function barChart(items: { label: string; value: number; color?: string }[], opts: ChartOpts & { unit?: string } = {}): SVGSVGElement {
  const rowH = 22, left = 130, right = 70, top = 8;
  const width = opts.width ?? 560, height = top * 2 + rowH * items.length + 22;
  const svg = s('svg', { viewBox: `0 0 ${width} ${height}`, class: 'chart', width, height });
  const max = Math.max(...items.map((i) => i.value), 1e-12);
  const w = width - left - right;
  items.forEach((it, i) => {
    const y = top + i * rowH;
    svg.append(s('text', { x: left - 6, y: y + 15, 'text-anchor': 'end', class: 'lbl' }, it.label));
    svg.append(s('rect', { x: left, y: y + 3, width: Math.max(1, (w * it.value) / max), height: rowH - 6, fill: it.color ?? opts.color ?? '#4fc3f7' }));
    svg.append(s('text', { x: left + (w * it.value) / max + 5, y: y + 15, class: 'val' }, `${fmtNumber(it.value, 1)}${opts.unit ?? ''}`));
  });
  if (opts.xLabel) svg.append(s('text', { x: left + w / 2, y: height - 4, 'text-anchor': 'middle', class: 'axis-label' }, opts.xLabel));
  return svg;
}

function axes(svg: SVGSVGElement, x0: number, x1: number, y0: number, y1: number, box: { l: number; r: number; t: number; b: number; w: number; h: number }, o: ChartOpts) {
  const X = (v: number) => box.l + ((v - x0) / (x1 - x0 || 1)) * (box.w - box.l - box.r);
  const Y = (v: number) => box.h - box.b - ((v - y0) / (y1 - y0 || 1)) * (box.h - box.t - box.b);
  svg.append(s('line', { x1: box.l, y1: box.h - box.b, x2: box.w - box.r, y2: box.h - box.b, class: 'axis' }));
  svg.append(s('line', { x1: box.l, y1: box.t, x2: box.l, y2: box.h - box.b, class: 'axis' }));
  for (const t of ticks(x0, x1)) {
    svg.append(s('line', { x1: X(t), y1: box.h - box.b, x2: X(t), y2: box.h - box.b + 4, class: 'axis' }));
    svg.append(s('text', { x: X(t), y: box.h - box.b + 16, 'text-anchor': 'middle', class: 'tick' }, fmtNumber(t, 2)));
  }
  for (const t of ticks(y0, y1, 4)) {
    svg.append(s('line', { x1: box.l, y1: Y(t), x2: box.w - box.r, y2: Y(t), class: 'grid' }));
    svg.append(s('text', { x: box.l - 5, y: Y(t) + 4, 'text-anchor': 'end', class: 'tick' }, fmtNumber(t, 2)));
  }
  if (o.xLabel) svg.append(s('text', { x: (box.l + box.w - box.r) / 2, y: box.h - 3, 'text-anchor': 'middle', class: 'axis-label' }, o.xLabel));
  if (o.yLabel) svg.append(s('text', { x: 12, y: (box.t + box.h - box.b) / 2, 'text-anchor': 'middle', class: 'axis-label', transform: `rotate(-90 12 ${(box.t + box.h - box.b) / 2})` }, o.yLabel));
  return { X, Y };
}

/** Histogram of `values` in `bins` equal bins. */
export function histogram(values: number[], opts: ChartOpts & { bins?: number } = {}): SVGSVGElement {
  const width = opts.width ?? 420, height = opts.height ?? 200;
  const svg = s('svg', { viewBox: `0 0 ${width} ${height}`, class: 'chart', width, height });
  const v = values.filter(isFinite);
  if (v.length === 0) return svg;
  // From 0 when the values start near it, else over their own range (a tight cluster gets its own bins).
  const vmin = Math.min(...v), vmax = Math.max(...v);
  const lo = vmin > 0 && vmin > 0.5 * vmax ? vmin - 0.05 * (vmax - vmin) : Math.min(0, vmin);
  const hi = vmax > lo ? vmax : lo + 1;
  const bins = opts.bins ?? Math.min(30, Math.max(8, Math.ceil(Math.sqrt(v.length))));
  const counts = new Array(bins).fill(0);
  for (const x of v) counts[Math.min(bins - 1, Math.floor(((x - lo) / (hi - lo)) * bins))]++;
  const { X, Y } = axes(svg, lo, hi, 0, Math.max(...counts), { l: 46, r: 10, t: 10, b: 36, w: width, h: height }, opts);
  counts.forEach((c, i) => {
    const xa = X(lo + ((hi - lo) * i) / bins), xb = X(lo + ((hi - lo) * (i + 1)) / bins);
    svg.append(s('rect', { x: xa + 0.5, y: Y(c), width: Math.max(0.5, xb - xa - 1), height: Y(0) - Y(c), fill: opts.color ?? '#4fc3f7' }));
  });
  return svg;
}

/** A line through (x, y) points. */
export function lineChart(pts: [number, number][], opts: ChartOpts = {}): SVGSVGElement {
  const width = opts.width ?? 420, height = opts.height ?? 200;
  const svg = s('svg', { viewBox: `0 0 ${width} ${height}`, class: 'chart', width, height });
  if (pts.length === 0) return svg;
  const xs = pts.map((p) => p[0]), ys = pts.map((p) => p[1]);
  let y0 = Math.min(...ys), y1 = Math.max(...ys);
  if (y1 - y0 < 1e-9) { y0 -= 1; y1 += 1; }
  const pad = 0.05 * (y1 - y0);
  const { X, Y } = axes(svg, Math.min(...xs), Math.max(...xs), y0 - pad, y1 + pad, { l: 56, r: 12, t: 10, b: 36, w: width, h: height }, opts);
  svg.append(s('polyline', { points: pts.map(([x, y]) => `${X(x).toFixed(1)},${Y(y).toFixed(1)}`).join(' '), class: 'line', stroke: opts.color ?? '#4fc3f7' }));
  return svg;
}
