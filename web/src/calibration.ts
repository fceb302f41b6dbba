// The camera calibration window (#/calibration/WS): choose uploaded chessboard images or calibration videos (or
// upload more), board size and square; run `fmv3d calibrate` on the server (a video's frames are sampled, the
// board detected in each and a spread subset kept); then each image with its detected corners and the
// reprojection residual vectors (exaggerated), the per-image RMS as a bar chart (drop an image with one click and
// re-run), the distortion field and the fitted parameters with their standard deviations; save the camera as a
// sensor-database entry (`fmv3d frames --sensor NAME` then uses it).
import { api, fileURL, ApiError } from './api';
import { h, fmtNumber } from './dom';
import { manualApi, type Calibration, type CalibResult } from './manual_api';

const SVG = 'http://www.w3.org/2000/svg';

export function mountCalibration(el: HTMLElement, ws: string | null): () => void {
  delete el.dataset.ready;  // the page element is shared with the other pages
  delete el.dataset.state;
  if (!ws) { el.append(h('p', { class: 'pad muted' }, 'No workspace yet.')); return () => undefined; }
  const msg = h('div', { class: 'msg', id: 'cal-msg' });
  const say = (text: string, kind: 'ok' | 'error' | '' = '') => { msg.textContent = text; msg.className = `msg ${kind}`; };
  const chosen = new Set<string>();
  const dropped = new Set<string>();  // video frames left out (an image is dropped by unticking it)
  const isVideo = (p: string) => /\.(mp4|m4v|mov|avi|mkv|ts|mts|m2ts|mpg|mpeg|webm)$/i.test(p);
  let candidates: string[] = [];
  let timer: number | undefined;
  let disposed = false;
  let shownImage: string | null = null;

  const boardIn = h('input', { id: 'cal-board', value: '9x6', size: 6 });
  const squareIn = h('input', { id: 'cal-square', value: '0.025', size: 7 });
  const uploadIn = h('input', { type: 'file', id: 'cal-upload', multiple: true, accept: 'image/*,video/*' });
  const imageList = h('div', { class: 'cal-images', id: 'cal-images' });
  const params = h('div', { id: 'cal-params' });
  const bars = h('div', { id: 'cal-bars' });
  const viewer = h('div', { id: 'cal-viewer' });
  const field = h('div', { id: 'cal-field' });
  const sensorName = h('input', { id: 'cal-sensor-name', placeholder: 'sensor name', size: 16 });
  const logBox = h('pre', { class: 'log', id: 'cal-log' });
  el.append(h('div', { class: 'cal' },
    h('div', { class: 'card' }, h('h2', {}, 'Chessboard images or calibration video'),
      h('div', { class: 'row' }, h('label', { class: 'inline' }, 'upload ', uploadIn),
        h('label', { class: 'inline' }, 'inner corners ', boardIn), h('label', { class: 'inline' }, 'square (m) ', squareIn),
        h('button', { id: 'cal-run', onclick: () => void run() }, 'Calibrate')),
      imageList, msg),
    h('div', { class: 'cal-results' },
      h('div', { class: 'card' }, h('h2', {}, 'Parameters'), params,
        h('div', { class: 'row' }, sensorName, h('button', { id: 'cal-save', onclick: () => void saveSensor() }, 'Save as sensor'))),
      h('div', { class: 'card' }, h('h2', {}, 'Per-image RMS (click ✕ to drop an image and re-run)'), bars),
      h('div', { class: 'card' }, h('h2', {}, 'Corners and residuals'), viewer),
      h('div', { class: 'card' }, h('h2', {}, 'Distortion field'), field)),
    h('details', { class: 'card' }, h('summary', {}, 'log'), logBox)));

  function renderImages() {
    imageList.replaceChildren(...candidates.map((p) => h('label', { class: 'cal-img' },
      h('input', { type: 'checkbox', checked: chosen.has(p), 'data-path': p, onchange: (e: Event) => {
        if ((e.target as HTMLInputElement).checked) chosen.add(p); else chosen.delete(p);
      } }),
      isVideo(p) ? h('span', { class: 'cal-video' }, '▶ video') : h('img', { src: fileURL(ws!, p), alt: p }),
      h('span', {}, p.replace(/^uploads\//, '')))));
  }

  uploadIn.addEventListener('change', async () => {
    if (!uploadIn.files?.length) return;
    try {
      const r = await api.upload(ws!, uploadIn.files);
      for (const p of r.paths) { if (!candidates.includes(p)) candidates.push(p); chosen.add(p); }
      renderImages();
      say(`uploaded ${r.paths.length} file(s)`, 'ok');
    } catch (e) { say(`upload failed: ${(e as Error).message}`, 'error'); }
    uploadIn.value = '';
  });

  async function run() {
    try {
      const c = await manualApi.runCalibration(ws!, { images: [...chosen], board: boardIn.value.trim(), square: Number(squareIn.value),
        drop: [...dropped] });
      say('calibrating…');
      show(c);
      poll();
    } catch (e) { say(e instanceof ApiError ? e.message : String(e), 'error'); }
  }
  function poll() {
    window.clearTimeout(timer);
    timer = window.setTimeout(async () => {
      if (disposed) return;
      try {
        const c = await manualApi.calibration(ws!);
        show(c);
        if (c.state === 'running') poll();
      } catch (e) { say(String(e), 'error'); }
    }, 400);
  }

  function show(c: Calibration) {
    el.dataset.state = c.state;
    logBox.textContent = c.log.join('\n');
    for (const u of c.uploads) if (!candidates.includes(u)) candidates.push(u);
    if (c.request) {
      boardIn.value = `${c.request.board.cols}x${c.request.board.rows}`;
      squareIn.value = String(c.request.square);
      if (c.state !== 'running') {
        chosen.clear(); for (const p of c.request.images) chosen.add(p);
        dropped.clear(); for (const d of c.request.drop ?? []) dropped.add(d);
      }
      for (const p of c.request.images) if (!candidates.includes(p)) candidates.push(p);
    }
    renderImages();
    if (c.state === 'failed') {
      const last = c.log.filter((l) => l.trim()).pop() ?? 'calibrate failed';
      say(`calibration failed: ${last}`, 'error');
    }
    if (c.state !== 'done' || !c.result) { params.replaceChildren(); bars.replaceChildren(); viewer.replaceChildren(); field.replaceChildren(); return; }
    const videos = (c.result.videos ?? []).map((v) => `; ${v.video}: ${v.sampled} frames sampled, board in ${v.found}, ${v.kept} kept`).join('');
    say(`calibrated: RMS ${fmtNumber(c.result.rms, 3)} px over ${c.result.images.length} images${videos}` +
      (c.result.rejected.length ? ` (${c.result.rejected.length} without a board: ${c.result.rejected.join(', ')})` : ''), 'ok');
    renderParams(c.result);
    renderBars(c);
    field.replaceChildren(h('img', { class: 'cal-field', src: fileURL(ws!, c.distortion_png!) + `${fileURL(ws!, '').includes('?') ? '&' : '?'}t=${Date.now()}`, alt: 'distortion field' }));
    const names = c.result.images.map((i) => i.name);
    void showImage(c, shownImage && names.includes(shownImage) ? shownImage : names[0]);
  }

  function renderParams(r: CalibResult) {
    const rows: [string, number, number | undefined, number][] = [
      ['f (px)', r.f, r.stddev.f, 3], ['s_u (aspect)', r.aspect, r.stddev.aspect, 6], ['u0 (px)', r.u0, r.stddev.u0, 3],
      ['v0 (px)', r.v0, r.stddev.v0, 3], ['k1', r.k1, r.stddev.k1, 6], ['k2', r.k2, r.stddev.k2, 6],
      ['p1', r.p1, r.stddev.p1, 6], ['p2', r.p2, r.stddev.p2, 6]];
    params.replaceChildren(h('div', { class: 'muted' }, `${r.width} × ${r.height} px, board ${r.board.cols}×${r.board.rows}, square ${r.board.square} m`),
      h('table', { class: 'figures', id: 'cal-param-table' },
        ...rows.map(([n, v, s, d]) => h('tr', { 'data-param': n.split(' ')[0] }, h('th', {}, n), h('td', { class: 'val' }, v.toFixed(d)),
          h('td', { class: 'sd' }, s === undefined ? '' : `± ${s.toFixed(d)}`))),
        h('tr', {}, h('th', {}, 'RMS (px)'), h('td', { class: 'val', id: 'cal-rms' }, r.rms.toFixed(4)), h('td', {}))));
  }

  function renderBars(c: Calibration) {
    const r = c.result!;
    const max = Math.max(...r.images.map((i) => i.rms), 1e-9);
    const W = 520, row = 22, H = row * r.images.length + 24, left = 150;
    const svg = document.createElementNS(SVG, 'svg');
    svg.setAttribute('viewBox', `0 0 ${W} ${H}`);
    svg.setAttribute('width', String(W));
    svg.setAttribute('class', 'chart');
    svg.id = 'cal-rms-chart';
    const el2 = (tag: string, a: Record<string, string | number>, text?: string) => {
      const e = document.createElementNS(SVG, tag);
      for (const [k, v] of Object.entries(a)) e.setAttribute(k, String(v));
      if (text) e.textContent = text;
      svg.append(e);
      return e;
    };
    r.images.forEach((im, i) => {
      const y = 6 + i * row;
      const w = (W - left - 80) * im.rms / max;
      el2('text', { x: 4, y: y + 13, class: im.name === shownImage ? 'val' : '' }, im.name.length > 22 ? im.name.slice(0, 21) + '…' : im.name);
      const bar = el2('rect', { x: left, y, width: Math.max(1, w), height: row - 6, fill: im.rms > 2 * r.rms ? '#ef5350' : '#4fc3f7', 'data-image': im.name });
      bar.addEventListener('click', () => void showImage(c, im.name));
      (bar as SVGElement).style.cursor = 'pointer';
      el2('text', { x: left + w + 4, y: y + 13, class: 'val' }, `${im.rms.toFixed(3)} px`);
    });
    el2('line', { x1: left + (W - left - 80) * r.rms / max, x2: left + (W - left - 80) * r.rms / max, y1: 0, y2: H - 14, stroke: '#ffb300', 'stroke-dasharray': '4 3' });
    el2('text', { x: left, y: H - 2 }, `dashed: overall RMS ${r.rms.toFixed(3)} px`);
    const drops = h('div', { class: 'cal-drops' }, ...r.images.map((im) => h('button', {
      class: 'small danger', 'data-drop': im.name, title: `drop ${im.name} and re-run`,
      onclick: () => { dropImage(c, im.name); },
    }, `✕ ${im.name}`)));
    bars.replaceChildren(svg, drops);
  }

  function dropImage(c: Calibration, name: string) {
    let image = false;
    for (const p of [...chosen]) if (p.split('/').pop() === name) { chosen.delete(p); image = true; }
    if (!image) dropped.add(name);  // a frame of a video
    say(`dropped ${name}; re-running…`);
    void run();
    void c;
  }

  async function showImage(c: Calibration, name: string) {
    shownImage = name;
    const r = c.result!;
    const im = r.images.find((i) => i.name === name);
    const path = c.request?.images.find((p) => p.split('/').pop() === name) ??
      (c.frames_dir ? `${c.frames_dir}/${name}` : undefined);
    if (!im || !path) return;
    const canvas = h('canvas', { class: 'cal-canvas', id: 'cal-canvas', 'data-image': name });
    // Residual vectors exaggerated so that the largest of all images is ~25 px long, in steps of 1-2-5.
    let largest = 1e-9;
    for (const i of r.images) for (let k = 0; k + 1 < (i.residuals ?? []).length; k += 2) largest = Math.max(largest, Math.hypot(i.residuals![k], i.residuals![k + 1]));
    const raw = 25 / largest, decade = 10 ** Math.floor(Math.log10(raw));
    const gain = [5, 2, 1].map((m) => m * decade).find((g) => g <= raw) ?? decade;
    viewer.replaceChildren(h('div', { class: 'muted' }, `${name}: RMS ${im.rms.toFixed(3)} px; green: detected corners, red: residual vectors ×${gain}`), canvas);
    const img = new Image();
    img.src = fileURL(ws!, path);
    await img.decode();
    const scale = Math.min(1, 640 / img.naturalWidth);
    canvas.width = Math.round(img.naturalWidth * scale);
    canvas.height = Math.round(img.naturalHeight * scale);
    const ctx = canvas.getContext('2d')!;
    ctx.drawImage(img, 0, 0, canvas.width, canvas.height);
    const corners = im.corners ?? [], res = im.residuals ?? [];
    for (let k = 0; k + 1 < corners.length; k += 2) {
      const x = corners[k] * scale, y = corners[k + 1] * scale;
      ctx.strokeStyle = '#66bb6a';
      ctx.lineWidth = 1.5;
      ctx.beginPath(); ctx.arc(x, y, 3, 0, 2 * Math.PI); ctx.stroke();
      if (k + 1 < res.length) {
        ctx.strokeStyle = '#ef5350';
        ctx.beginPath(); ctx.moveTo(x, y);
        ctx.lineTo(x + res[k] * gain * scale, y + res[k + 1] * gain * scale); ctx.stroke();
      }
    }
    canvas.dataset.corners = String(corners.length / 2);
  }

  async function saveSensor() {
    try {
      const r = await manualApi.saveSensor(ws!, sensorName.value.trim());
      say(`saved as sensor '${r.name}' in ${r.database}; use it with: fmv3d frames --sensor "${r.name}"`, 'ok');
    } catch (e) { say(e instanceof ApiError ? `not saved: ${e.message}` : String(e), 'error'); }
  }

  (async () => {
    try {
      const c = await manualApi.calibration(ws);
      candidates = [...c.uploads];
      if (!c.request) for (const p of candidates) chosen.add(p);
      show(c);
      if (c.state === 'running') poll();
      el.dataset.ready = '1';
    } catch (e) { say((e as Error).message, 'error'); }
  })();
  return () => { disposed = true; window.clearTimeout(timer); };
}
