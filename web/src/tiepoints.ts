// The keypoint and tie-point editor (#/tiepoints/WS): a frame strip (registered / left out and why), two frames
// side by side with their SIFT keypoints (scale circles, orientation ticks) and the verified matches of the pair
// (inliers / rejected). The operator clicks the same ground point in two or more frames (loupe; the epipolar
// line of the point in the other frame when the pair's geometry is known), moves points by dragging them (or by
// clicking again with the tie point chosen),
// deletes tie points and wrong automatic matches, adds single-frame points of interest, undoes / redoes, saves
// manual/tiepoints.json (or imports one, checked whole by the server) and re-runs the reconstruction from matching
// with one button.
import { api, fileURL, ApiError, type Job } from './api';
import { h } from './dom';
import { store } from './store';
import { FrameView, drawLine, drawMarker, frameStrip, markStrip } from './frameview';
import { manualApi, type FrameInfo, type Keypoints, type Pair, type TiePoints } from './manual_api';

type Mode = 'tie' | 'poi' | 'remove';

export function mountTiePoints(el: HTMLElement, ws: string | null): () => void {
  delete el.dataset.ready;  // the page element is shared with the other pages
  delete el.dataset.state;
  if (!ws) { el.append(h('p', { class: 'pad muted' }, 'No workspace yet.')); return () => undefined; }
  const msg = h('div', { class: 'msg', id: 'tp-msg' });
  const say = (text: string, kind: 'ok' | 'error' | '' = '') => { msg.textContent = text; msg.className = `msg ${kind}`; };
  const views = { a: new FrameView('a'), b: new FrameView('b') };
  let frames: FrameInfo[] = [];
  let frameA: string | null = null, frameB: string | null = null;
  const keypoints = new Map<string, Keypoints>();
  let pair: Pair | null = null;
  let doc: TiePoints = { format: 'fmv3d-tiepoints', version: 1, tie_points: [], keypoints: [], deleted_matches: [] };
  const undo: string[] = [], redo: string[] = [];
  let current: string | null = null;
  let mode: Mode = 'tie';
  let saved = JSON.stringify(doc);
  const show = { keypoints: true, inliers: true, rejected: false };
  let disposed = false;
  let jobId: string | null = null;
  // What the last `match` did with the manual input (matches/manual.json): where single-frame keypoints were
  // found in other frames (their tracks), and tie points that disagree with a pair's epipolar geometry.
  let found: { frame: string; index: number; id: string }[] = [];
  let manualKeypoints: Record<string, { first_index: number; keypoints: { id: string; x: number; y: number }[] }> = {};
  // A keypoint index of matches/manual.json: an appended (manual) keypoint, or one of the frame's automatic ones.
  const keypointAt = (frame: string, index: number): [number, number] | null => {
    const m = manualKeypoints[frame];
    if (m && index >= m.first_index) { const k = m.keypoints[index - m.first_index]; return k ? [k.x, k.y] : null; }
    const kp = keypoints.get(frame);
    return kp && 4 * index + 1 < kp.keypoints.length ? [kp.keypoints[4 * index], kp.keypoints[4 * index + 1]] : null;
  };
  const manualInfo = h('div', { class: 'muted', id: 'tp-manual' });

  const stripBox = h('div', { class: 'strip-box' });
  const leftOut = h('div', { class: 'left-out muted', id: 'tp-left-out' });
  const list = h('div', { class: 'tp-list', id: 'tp-list' });
  const counts = h('div', { class: 'muted', id: 'tp-counts' });
  const modeButtons: Record<Mode, HTMLButtonElement> = {
    tie: h('button', { id: 'tp-mode-tie', onclick: () => setMode('tie') }, 'Tie point'),
    poi: h('button', { id: 'tp-mode-poi', onclick: () => setMode('poi') }, 'Point of interest'),
    remove: h('button', { id: 'tp-mode-remove', onclick: () => setMode('remove') }, 'Delete matches'),
  };
  const toggle = (key: keyof typeof show, label: string) => h('label', {},
    h('input', { type: 'checkbox', id: `tp-show-${key}`, checked: show[key], onchange: (e: Event) => {
      show[key] = (e.target as HTMLInputElement).checked; redraw();
    } }), label);
  const jobLine = h('div', { class: 'muted', id: 'tp-job' });
  const fileIn = h('input', { type: 'file', id: 'tp-import', accept: '.json,application/json' });
  const side = h('div', { class: 'side tp-side' },
    h('h3', {}, 'Frames'), leftOut,
    h('h3', {}, 'Show'), toggle('keypoints', 'keypoints (scale, orientation)'), toggle('inliers', 'verified matches'),
    toggle('rejected', 'rejected matches'), h('div', { class: 'muted', id: 'tp-pair' }),
    h('h3', {}, 'Click adds'), h('div', { class: 'row' }, ...Object.values(modeButtons)),
    h('div', { class: 'row' },
      h('button', { id: 'tp-new', onclick: () => { current = null; setMode('tie'); renderList(); redraw(); } }, 'New tie point'),
      h('button', { id: 'tp-undo', onclick: () => step(undo, redo) }, 'Undo'),
      h('button', { id: 'tp-redo', onclick: () => step(redo, undo) }, 'Redo')),
    h('h3', {}, 'Tie points'), counts, list,
    h('div', { class: 'row' },
      h('button', { id: 'tp-save', onclick: () => void save() }, 'Save'),
      h('button', { id: 'tp-rerun', onclick: () => void rerun() }, 'Re-run from matching')),
    h('div', { class: 'row' }, h('label', { class: 'inline' }, 'import tiepoints.json ', fileIn)),
    msg, jobLine, manualInfo);
  const titleA = views.a.title, titleB = views.b.title;
  el.append(h('div', { class: 'tp' }, stripBox,
    h('div', { class: 'tp-main' }, h('div', { class: 'tp-views' }, views.a.el, views.b.el), side)));

  function setMode(m: Mode) {
    mode = m;
    for (const [k, b] of Object.entries(modeButtons)) b.classList.toggle('active', k === m);
  }
  setMode('tie');

  const snapshot = () => JSON.stringify(doc);
  function change(fn: () => void) {
    undo.push(snapshot());
    redo.length = 0;
    fn();
    renderList(); redraw();
  }
  function step(from: string[], to: string[]) {
    const s = from.pop();
    if (!s) return;
    to.push(snapshot());
    doc = JSON.parse(s) as TiePoints;
    if (current && !doc.tie_points.some((t) => t.id === current)) current = null;
    renderList(); redraw();
  }
  function nextId(prefix: string): string {
    const used = new Set([...doc.tie_points.map((t) => t.id), ...doc.keypoints.map((p) => p.id)]);
    for (let i = 1; ; i++) if (!used.has(`${prefix}${i}`)) return `${prefix}${i}`;
  }

  // Clicks: a tie point's observation in this frame (set or moved), a point of interest, or the removal of
  // the automatic match nearest to the click.
  function clicked(which: 'a' | 'b', x: number, y: number) {
    const frame = which === 'a' ? frameA : frameB;
    if (!frame) return;
    if (mode === 'poi') {
      change(() => doc.keypoints.push({ id: nextId('k'), frame, x, y }));
      say(`point of interest added in ${frame}`);
      return;
    }
    if (mode === 'remove') {
      if (!pair) return;
      const v = views[which];
      let best = -1, bestD = 12 / v.scale;
      pair.inliers.forEach((m, i) => {
        const [px, py] = which === 'a' ? [m[2], m[3]] : [m[4], m[5]];
        const d = Math.hypot(px - x, py - y);
        if (d < bestD && !isRemoved(m)) { bestD = d; best = i; }
      });
      if (best < 0) { say('no verified match near the click'); return; }
      const m = pair.inliers[best];
      change(() => doc.deleted_matches.push({ frame1: pair!.a, frame2: pair!.b, feature1: m[0], feature2: m[1] }));
      say(`match removed (${doc.deleted_matches.length} removed)`);
      return;
    }
    change(() => {
      let t = doc.tie_points.find((p) => p.id === current);
      if (!t) { t = { id: nextId('t'), observations: [] }; doc.tie_points.push(t); current = t.id; }
      const o = t.observations.find((p) => p.frame === frame);
      if (o) { o.x = x; o.y = y; } else t.observations.push({ frame, x, y });
    });
  }
  views.a.onClick = (x, y) => clicked('a', x, y);
  views.b.onClick = (x, y) => clicked('b', x, y);

  // Dragging a tie point's marker moves that observation: one undo step per drag.
  let held: { id: string; frame: string; before: string } | null = null;
  for (const which of ['a', 'b'] as const) {
    const v = views[which];
    v.onGrab = (x, y) => {
      const frame = which === 'a' ? frameA : frameB;
      held = null;
      if (mode !== 'tie' || !frame) return false;
      let bestD = 8 / v.scale;  // within 8 CSS px of the marker
      for (const t of doc.tie_points) {
        const o = t.observations.find((p) => p.frame === frame);
        const d = o ? Math.hypot(o.x - x, o.y - y) : Infinity;
        if (d < bestD) { bestD = d; held = { id: t.id, frame, before: snapshot() }; }
      }
      return held !== null;
    };
    v.onDrag = (x, y) => {
      const o = held && doc.tie_points.find((t) => t.id === held!.id)?.observations.find((p) => p.frame === held!.frame);
      if (!o) return;
      o.x = x; o.y = y;
      current = held!.id;
      redraw();
    };
    v.onDrop = (x, y) => {
      if (!held) return;
      const o = doc.tie_points.find((t) => t.id === held!.id)?.observations.find((p) => p.frame === held!.frame);
      if (o) {
        o.x = x; o.y = y;
        undo.push(held.before);
        redo.length = 0;
        say(`${held.id} moved in ${held.frame} to ${x.toFixed(2)}, ${y.toFixed(2)}`);
      }
      held = null;
      renderList(); redraw();
    };
  }

  function isRemoved(m: number[]): boolean {
    return doc.deleted_matches.some((r) => pair && ((r.frame1 === pair.a && r.frame2 === pair.b && r.feature1 === m[0] && r.feature2 === m[1]) ||
      (r.frame1 === pair.b && r.frame2 === pair.a && r.feature1 === m[1] && r.feature2 === m[0])));
  }

  // Epipolar line in frame b of a point of frame a (F maps a → b) and the reverse.
  function epiline(which: 'a' | 'b', x: number, y: number): [number, number, number] | null {
    const F = pair?.F;
    if (!F) return null;
    if (which === 'a') return [F[0] * x + F[1] * y + F[2], F[3] * x + F[4] * y + F[5], F[6] * x + F[7] * y + F[8]];
    return [F[0] * x + F[3] * y + F[6], F[1] * x + F[4] * y + F[7], F[2] * x + F[5] * y + F[8]];
  }

  const overlay = (which: 'a' | 'b') => ({
    draw(ctx: CanvasRenderingContext2D, v: FrameView) {
      const frame = which === 'a' ? frameA : frameB;
      if (!frame) return;
      const kp = keypoints.get(frame);
      if (show.keypoints && kp) {
        ctx.strokeStyle = 'rgba(79,195,247,.55)';
        ctx.lineWidth = 1;
        const k = kp.keypoints;
        for (let i = 0; i < k.length; i += 4) {
          const [cx, cy] = v.toCanvas(k[i], k[i + 1]);
          const r = Math.max(1.5, k[i + 2] * v.scale);
          ctx.beginPath();
          ctx.arc(cx, cy, r, 0, 2 * Math.PI);
          ctx.moveTo(cx, cy);
          ctx.lineTo(cx + r * Math.cos(k[i + 3]), cy + r * Math.sin(k[i + 3]));
          ctx.stroke();
        }
      }
      if (pair && (pair.a === frame || pair.b === frame)) {
        const own = pair.a === frame ? 2 : 4;
        const draw = (ms: number[][], colour: string) => {
          for (const m of ms) {
            const [cx, cy] = v.toCanvas(m[own], m[own + 1]);
            const [ox, oy] = v.toCanvas(m[6 - own], m[7 - own]);
            ctx.strokeStyle = colour;
            ctx.beginPath(); ctx.moveTo(cx, cy); ctx.lineTo(ox, oy); ctx.stroke();
            ctx.fillStyle = colour;
            ctx.fillRect(cx - 2, cy - 2, 4, 4);
          }
        };
        if (show.rejected) draw(pair.rejected, 'rgba(239,83,80,.8)');
        if (show.inliers) {
          draw(pair.inliers.filter((m) => !isRemoved(m)), 'rgba(102,187,106,.9)');
          draw(pair.inliers.filter((m) => isRemoved(m)), 'rgba(160,160,160,.7)');
        }
      }
      const other = which === 'a' ? 'b' : 'a';
      const otherFrame = which === 'a' ? frameB : frameA;
      for (const t of doc.tie_points) {
        const sel = t.id === current;
        const o = t.observations.find((p) => p.frame === frame);
        if (o) drawMarker(ctx, v, o.x, o.y, sel ? '#ffeb3b' : '#ff9800', t.id, sel);
        const oo = t.observations.find((p) => p.frame === otherFrame);
        if (sel && oo) {
          const l = epiline(other, oo.x, oo.y);
          if (l) drawLine(ctx, v, l, '#ffeb3b');
        }
      }
      for (const p of doc.keypoints) if (p.frame === frame) drawMarker(ctx, v, p.x, p.y, '#e040fb', p.id);
      for (const p of found) {
        const xy = p.frame === frame ? keypointAt(p.frame, p.index) : null;
        if (xy) drawMarker(ctx, v, xy[0], xy[1], '#ce93d8', `${p.id} (found)`);
      }
    },
  });
  views.a.overlays.push(overlay('a'));
  views.b.overlays.push(overlay('b'));
  const redraw = () => { views.a.draw(); views.b.draw(); };

  function renderList() {
    list.replaceChildren(...doc.tie_points.map((t) => h('div', { class: `tp-item${t.id === current ? ' current' : ''}`, 'data-id': t.id },
      h('button', { class: 'small link', onclick: () => { current = t.id; setMode('tie'); renderList(); redraw(); } }, t.id),
      h('span', { class: 'muted' }, `${t.observations.length} frames: ${t.observations.map((o) => o.frame.replace(/\.[a-z]+$/i, '')).join(', ')}`),
      h('button', { class: 'small danger', title: 'delete this tie point', onclick: () => change(() => {
        doc.tie_points = doc.tie_points.filter((p) => p.id !== t.id);
        if (current === t.id) current = null;
      }) }, '✕'))),
    ...doc.keypoints.map((p) => h('div', { class: 'tp-item poi', 'data-id': p.id },
      h('span', {}, p.id), h('span', { class: 'muted' }, `point of interest in ${p.frame}`),
      h('button', { class: 'small danger', onclick: () => change(() => {
        doc.keypoints = doc.keypoints.filter((q) => q.id !== p.id);
      }) }, '✕'))));
    const unsaved = JSON.stringify(doc) !== saved;
    counts.textContent = `${doc.tie_points.length} tie points, ${doc.keypoints.length} points of interest, ` +
      `${doc.deleted_matches.length} removed matches${unsaved ? ' — unsaved' : ''}`;
    const marks: Record<string, string> = {};
    if (frameA) marks[frameA] = 'A';
    if (frameB) marks[frameB] = 'B';
    const strip = stripBox.firstElementChild as HTMLElement | null;
    if (strip) markStrip(strip, marks);
  }

  function setTitle(which: 'a' | 'b') {
    const name = which === 'a' ? frameA : frameB;
    const f = frames.find((x) => x.name === name);
    const title = which === 'a' ? titleA : titleB;
    if (!f) { title.replaceChildren(); return; }
    title.replaceChildren(h('b', {}, `${which.toUpperCase()}: ${f.name}`), ' ',
      h('span', { class: f.registered ? 'ok-text' : 'error' }, f.registered ? 'registered' : f.left_out ? 'left out' : ''));
  }

  async function pick(name: string, which: 'a' | 'b') {
    if (which === 'a') frameA = name; else frameB = name;
    if (frameA === frameB) { if (which === 'a') frameB = null; else frameA = null; }
    const f = frames.find((x) => x.name === name)!;
    setTitle(which);
    await views[which].load(fileURL(ws!, `frames/${name}`), f.width, f.height);
    if (!keypoints.has(name) && f.features)
      try { keypoints.set(name, await manualApi.keypoints(ws!, name)); } catch (e) { say(String((e as Error).message), 'error'); }
    const fa = frames.find((x) => x.name === frameA);
    leftOut.textContent = fa && fa.left_out ? `${fa.name} left out: ${fa.left_out}` : fa ? `${fa.name}: registered` : '';
    pair = null;
    const pairInfo = document.getElementById('tp-pair');
    if (frameA && frameB) {
      try {
        pair = await manualApi.pair(ws!, frameA, frameB);
        if (pairInfo) pairInfo.textContent = `${pair.inliers.length} verified, ${pair.rejected.length} rejected matches; ` +
          (pair.F_source === 'poses' ? 'epipolar lines from the poses' : pair.F_source === 'matches' ? 'epipolar lines from the verified pair' : 'no epipolar geometry for this pair');
      } catch (e) { if (pairInfo) pairInfo.textContent = (e as Error).message; }
    }
    renderList(); redraw();
  }

  async function save(): Promise<boolean> {
    try {
      doc = await manualApi.saveTiepoints(ws!, doc);
      saved = JSON.stringify(doc);
      say(`saved manual/tiepoints.json: ${doc.tie_points.length} tie points`, 'ok');
      renderList();
      return true;
    } catch (e) {
      say(e instanceof ApiError ? `not saved: ${e.message}` : String(e), 'error');
      return false;
    }
  }

  // An imported file replaces the document only when the server accepted and saved all of it.
  fileIn.addEventListener('change', async () => {
    const file = fileIn.files?.[0];
    if (!file) return;
    try {
      let parsed: TiePoints;
      try { parsed = JSON.parse(await file.text()) as TiePoints; } catch (e) { throw new Error(`${file.name} is not JSON (${(e as Error).message})`); }
      const before = snapshot();
      doc = await manualApi.saveTiepoints(ws!, parsed);
      undo.push(before);
      redo.length = 0;
      saved = JSON.stringify(doc);
      current = null;
      say(`imported ${file.name}: ${doc.tie_points.length} tie points (saved)`, 'ok');
      renderList(); redraw();
    } catch (e) { say(`not imported: ${(e as Error).message}`, 'error'); }
    fileIn.value = '';
  });

  async function rerun() {
    if (!(await save())) return;
    try {
      const job = await api.startJob(ws!, { inputs: [], from: 'match', until: 'sparse' });
      jobId = job.id;
      say(`re-running from matching (job ${job.id})…`);
      showJob(job);
    } catch (e) { say(`cannot start: ${(e as Error).message}`, 'error'); }
  }
  function showJob(job: Job | undefined) {
    if (!job) return;
    jobLine.textContent = `job ${job.id}: ${job.state}${job.stage ? ` (${job.stage})` : ''}`;
    jobLine.dataset.state = job.state;
    if (job.state === 'done') {
      void Promise.all([loadFrames(), loadManualMatches().catch(() => undefined)]).then(() => {
        setTitle('a'); setTitle('b'); redraw();
        const n = frames.filter((f) => f.registered).length;
        say(`done: ${n} of ${frames.length} frames registered`, 'ok');
        jobLine.replaceChildren(`job ${job.id}: done — `, h('a', { href: `#/3d/${encodeURIComponent(ws!)}` }, 'see it in the 3D view'));
        jobLine.dataset.state = 'done';
      });
    } else if (job.state === 'failed' || job.state === 'stopped') say(`the re-run ${job.state}; see the Jobs page`, 'error');
  }
  const offJobs = store.onJobs((id) => { if (jobId && (id === jobId || id === null)) showJob(store.jobs.get(jobId)); });

  async function loadManualMatches() {
    found = [];
    manualInfo.textContent = '';
    const res = await fetch(fileURL(ws!, 'matches/manual.json'));
    if (!res.ok) return;
    const m = await res.json() as {
      frames?: Record<string, { first_index: number; keypoints: { id: string; x: number; y: number }[] }>;
      tracks?: { id: string; kind: string; observations: { frame: string; index: number }[] }[];
      disagreeing?: { id: string; frame1: string; frame2: string; epipolar_px: number }[];
    };
    manualKeypoints = m.frames ?? {};
    for (const t of m.tracks ?? [])
      if (t.kind === 'keypoint')
        for (const o of t.observations)
          if (!doc.keypoints.some((p) => p.id === t.id && p.frame === o.frame)) found.push({ frame: o.frame, index: o.index, id: t.id });
    const tracks = (m.tracks ?? []).filter((t) => t.kind === 'keypoint');
    const dis = m.disagreeing ?? [];
    manualInfo.textContent = `last matching: ${tracks.map((t) => `${t.id} tracked in ${t.observations.length} frames`).join(', ') || 'no keypoint tracks'}` +
      (dis.length ? `; disagreeing with the epipolar geometry: ${dis.map((d) => `${d.id} (${d.frame1}–${d.frame2}, ${d.epipolar_px.toFixed(1)} px)`).join(', ')}` : '');
  }

  async function loadFrames() {
    const r = await manualApi.frames(ws!);
    frames = r.frames;
    const strip = frameStrip(frames, (n) => fileURL(ws!, `frames/${n}`), (name, ev) => void pick(name, ev.shiftKey || ev.button === 1 ? 'b' : 'a'));
    for (const b of strip.querySelectorAll<HTMLElement>('.thumb'))
      b.addEventListener('contextmenu', (e) => { e.preventDefault(); void pick(b.dataset.frame!, 'b'); });
    stripBox.replaceChildren(h('div', { class: 'muted strip-help' },
      `${frames.filter((f) => f.registered).length} of ${frames.length} registered; click: frame A, shift-click or right-click: frame B`), strip);
    renderList();
  }

  (async () => {
    try {
      await loadFrames();
      doc = await manualApi.tiepoints(ws);
      saved = JSON.stringify(doc);
      await loadManualMatches().catch(() => undefined);
      if (disposed) return;
      const firstLeft = frames.find((f) => !f.registered && f.left_out);
      const a = firstLeft ?? frames[0];
      const b = frames.find((f) => f.registered && f.name !== a?.name) ?? frames[1];
      if (a) await pick(a.name, 'a');
      if (b) await pick(b.name, 'b');
      el.dataset.ready = '1';
    } catch (e) { say((e as Error).message, 'error'); }
  })();

  // For the browser tests: the views' image → page transforms and the document as the page holds it.
  (window as unknown as { fmv3dTiePoints: unknown }).fmv3dTiePoints = {
    views, pick: (n: string, w: 'a' | 'b') => pick(n, w), doc: () => doc, frames: () => frames,
  };
  return () => { disposed = true; offJobs(); views.a.dispose(); views.b.dispose(); };
}
