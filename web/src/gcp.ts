// Ground control points (#/gcp/WS): enter a GCP by its coordinates (WGS84 latitude / longitude / ellipsoidal
// height, or easting / northing / height in a projected CRS given by its EPSG code), click it in two or more
// frames (loupe), mark check points, import / export OpenDroneMap's gcp_list.txt, save to manual/gcp_list.txt
// and run georef; the georeference's GCP residuals are shown when georef.json has them.
import { api, fileURL, withToken, ApiError, type Job } from './api';
import { h, fmtNumber } from './dom';
import { store } from './store';
import { FrameView, drawMarker, frameStrip, markStrip } from './frameview';
import { manualApi, type FrameInfo, type Gcp, type Gcps } from './manual_api';

export function mountGcp(el: HTMLElement, ws: string | null): () => void {
  delete el.dataset.ready;  // the page element is shared with the other pages
  delete el.dataset.state;
  if (!ws) { el.append(h('p', { class: 'pad muted' }, 'No workspace yet.')); return () => undefined; }
  const msg = h('div', { class: 'msg', id: 'gcp-msg' });
  const say = (text: string, kind: 'ok' | 'error' | '' = '') => { msg.textContent = text; msg.className = `msg ${kind}`; };
  const view = new FrameView('gcp');
  let frames: FrameInfo[] = [];
  let frame: string | null = null;
  let points: Gcp[] = [];
  let current: string | null = null;
  let jobId: string | null = null;
  const crsKind = h('select', { id: 'gcp-crs-kind' }, new Option('WGS84 lat / lon / height', 'wgs84'),
    new Option('Projected E / N / H (EPSG)', 'epsg'));
  const epsg = h('input', { id: 'gcp-epsg', placeholder: 'EPSG code, e.g. 32618', size: 10 });
  const crs = () => crsKind.value === 'wgs84' ? 'EPSG:4326' : `EPSG:${epsg.value.trim()}`;
  const labels = () => crsKind.value === 'wgs84' ? ['latitude °', 'longitude °', 'height m'] : ['easting m', 'northing m', 'height m'];
  const f = {
    name: h('input', { id: 'gcp-name', placeholder: 'name', size: 8 }),
    a: h('input', { id: 'gcp-a', size: 12 }), b: h('input', { id: 'gcp-b', size: 12 }), z: h('input', { id: 'gcp-z', size: 8 }),
    check: h('input', { type: 'checkbox', id: 'gcp-check' }),
  };
  const table = h('table', { class: 'figures gcp-table', id: 'gcp-table' });
  const result = h('div', { id: 'gcp-result' });
  const jobLine = h('div', { class: 'muted', id: 'gcp-job' });
  const fileIn = h('input', { type: 'file', id: 'gcp-import', accept: '.txt,text/plain' });
  const stripBox = h('div', { class: 'strip-box' });
  const side = h('div', { class: 'side gcp-side' },
    h('h3', {}, 'Coordinates'), h('label', {}, crsKind), epsg,
    h('h3', {}, 'New GCP'),
    h('div', { class: 'gcp-form' }, f.name, h('span', { id: 'gcp-la' }), f.a, h('span', { id: 'gcp-lb' }), f.b,
      h('span', { id: 'gcp-lz' }), f.z, h('label', {}, f.check, 'check point (left out of the fit)')),
    h('button', { id: 'gcp-add', onclick: () => add() }, 'Add GCP, then click it in ≥ 2 frames'),
    h('h3', {}, 'GCPs'), table,
    h('div', { class: 'row' },
      h('button', { id: 'gcp-save', onclick: () => void save() }, 'Save'),
      h('button', { id: 'gcp-georef', onclick: () => void georef() }, 'Run georef')),
    h('div', { class: 'row' }, h('label', { class: 'inline' }, 'import gcp_list.txt ', fileIn),
      h('a', { id: 'gcp-export', href: withToken(manualApi.gcpExportPath(ws)), download: 'gcp_list.txt' }, 'export gcp_list.txt')),
    msg, jobLine, result);
  el.append(h('div', { class: 'tp' }, stripBox, h('div', { class: 'tp-main' }, h('div', { class: 'tp-views' }, view.el), side)));

  function setLabels() {
    const [la, lb, lz] = labels();
    document.getElementById('gcp-la')!.textContent = la;
    document.getElementById('gcp-lb')!.textContent = lb;
    document.getElementById('gcp-lz')!.textContent = lz;
    epsg.style.display = crsKind.value === 'wgs84' ? 'none' : '';
    renderTable();
  }
  crsKind.addEventListener('change', setLabels);

  function add() {
    const name = f.name.value.trim() || `gcp${points.length + 1}`;
    const nums = [f.a.value, f.b.value, f.z.value].map((v) => Number(v.trim()));
    if ([f.a.value, f.b.value, f.z.value].some((v) => v.trim() === '') || nums.some((v) => !isFinite(v))) {
      say('enter three numbers for the GCP\'s coordinates', 'error'); return;
    }
    if (/\s/.test(name) || points.some((p) => p.name === name)) { say(`the name '${name}' is taken or has spaces`, 'error'); return; }
    // gcp_list.txt puts x = longitude, y = latitude for EPSG:4326.
    const [x, y] = crsKind.value === 'wgs84' ? [nums[1], nums[0]] : [nums[0], nums[1]];
    points.push({ name, x, y, z: nums[2], check: f.check.checked, observations: [] });
    current = name;
    f.name.value = ''; f.a.value = ''; f.b.value = ''; f.z.value = ''; f.check.checked = false;
    say(`${name}: now click it in two or more frames`);
    renderTable(); view.draw();
  }

  function renderTable() {
    const [la, lb, lz] = labels();
    table.replaceChildren(h('tr', {}, h('th', {}, 'name'), h('th', {}, la), h('th', {}, lb), h('th', {}, lz), h('th', {}, 'frames'), h('th', {}, '')),
      ...points.map((p) => {
        const [a, b] = crsKind.value === 'wgs84' ? [p.y, p.x] : [p.x, p.y];
        return h('tr', { class: p.name === current ? 'current' : '', 'data-name': p.name },
          h('th', {}, h('button', { class: 'small', onclick: () => { current = p.name; renderTable(); view.draw(); } }, p.name + (p.check ? ' (check)' : ''))),
          h('td', {}, String(a)), h('td', {}, String(b)), h('td', {}, String(p.z)), h('td', {}, String(p.observations.length)),
          h('td', {}, h('button', { class: 'small danger', onclick: () => { points = points.filter((q) => q !== p); renderTable(); view.draw(); } }, '✕')));
      }));
    const marks: Record<string, string> = {};
    const cur = points.find((p) => p.name === current);
    for (const o of cur?.observations ?? []) marks[o.frame] = '✓';
    if (frame) marks[frame] = (marks[frame] ?? '') + '▶';
    const strip = stripBox.querySelector<HTMLElement>('.strip');
    if (strip) markStrip(strip, marks);
  }

  view.onClick = (x, y) => {
    const p = points.find((q) => q.name === current);
    if (!p || !frame) { say('add a GCP (or choose one in the table) first', 'error'); return; }
    const o = p.observations.find((q) => q.frame === frame);
    if (o) { o.x = x; o.y = y; } else p.observations.push({ frame, x, y });
    say(`${p.name} marked in ${p.observations.length} frame(s)`);
    renderTable(); view.draw();
  };
  view.overlays.push({
    draw(ctx, v) {
      for (const p of points) {
        const o = p.observations.find((q) => q.frame === frame);
        if (o) drawMarker(ctx, v, o.x, o.y, p.check ? '#e040fb' : p.name === current ? '#ffeb3b' : '#ff9800', p.name, p.name === current);
      }
    },
  });

  function load(g: Gcps) {
    points = g.points;
    if (g.crs === 'EPSG:4326' || !g.crs) crsKind.value = 'wgs84';
    else { crsKind.value = 'epsg'; epsg.value = g.crs.replace(/^EPSG:/i, ''); }
    current = points[0]?.name ?? null;
    setLabels(); view.draw();
  }

  async function save(): Promise<boolean> {
    if (crsKind.value === 'epsg' && !/^\d+$/.test(epsg.value.trim())) { say('enter the EPSG code of the coordinates', 'error'); return false; }
    try {
      load(await manualApi.saveGcps(ws!, { crs: crs(), points }));
      say(`saved manual/gcp_list.txt: ${points.length} GCPs`, 'ok');
      return true;
    } catch (e) { say(e instanceof ApiError ? `not saved: ${e.message}` : String(e), 'error'); return false; }
  }

  fileIn.addEventListener('change', async () => {
    const file = fileIn.files?.[0];
    if (!file) return;
    try {
      load(await manualApi.importGcpText(ws!, await file.text()));
      say(`imported ${file.name}: ${points.length} GCPs (saved)`, 'ok');
    } catch (e) { say(`not imported: ${(e as Error).message}`, 'error'); }
    fileIn.value = '';
  });

  async function georef() {
    if (!(await save())) return;
    try {
      const job = await api.startJob(ws!, { inputs: [], from: 'georef', until: 'georef' });
      jobId = job.id;
      say(`georef running (job ${job.id})…`);
    } catch (e) { say(`cannot start: ${(e as Error).message}`, 'error'); }
  }
  function showJob(job: Job | undefined) {
    if (!job) return;
    jobLine.textContent = `job ${job.id}: ${job.state}${job.stage ? ` (${job.stage})` : ''}`;
    jobLine.dataset.state = job.state;
    if (job.state === 'done') void showGeoref();
    if (job.state === 'failed') say('georef failed; see the Jobs page for its log', 'error');
  }
  const offJobs = store.onJobs((id) => { if (jobId && (id === jobId || id === null)) showJob(store.jobs.get(jobId)); });

  // geo/georef.json's GCP section, whatever its exact layout: residuals per GCP and the check points' figures.
  async function showGeoref() {
    try {
      const res = await fetch(fileURL(ws!, 'geo/georef.json'));
      if (!res.ok) { result.replaceChildren(h('p', { class: 'muted' }, 'no geo/georef.json yet')); return; }
      const g = await res.json() as Record<string, unknown>;
      const gcp = (g.gcps ?? g.gcp ?? null) as Record<string, unknown> | unknown[] | null;
      const rows: HTMLElement[] = [];
      const list = Array.isArray(gcp) ? gcp : (gcp && Array.isArray((gcp as Record<string, unknown>).points) ? (gcp as { points: unknown[] }).points : []);
      for (const item of list as Record<string, unknown>[]) {
        const r = item.residual_m ?? item.residual ?? item.error_m;
        rows.push(h('tr', {}, h('th', {}, String(item.name ?? item.id ?? '')), h('td', {}, item.check ? 'check' : 'control'),
          h('td', {}, typeof r === 'number' ? `${fmtNumber(r, 3)} m` : JSON.stringify(r ?? ''))));
      }
      result.replaceChildren(h('h3', {}, 'Georeference'),
        h('div', { class: 'muted', id: 'gcp-source' }, `source: ${String(g.source ?? g.method ?? '?')}`),
        rows.length ? h('table', { class: 'figures', id: 'gcp-residuals' }, h('tr', {}, h('th', {}, 'GCP'), h('th', {}, 'kind'), h('th', {}, 'residual')), ...rows)
          : h('pre', { class: 'log' }, JSON.stringify(gcp ?? g, null, 1).slice(0, 2000)));
    } catch (e) { result.textContent = String(e); }
  }

  async function pick(name: string) {
    frame = name;
    const fr = frames.find((x) => x.name === name)!;
    view.title.replaceChildren(h('b', {}, name));
    await view.load(fileURL(ws!, `frames/${name}`), fr.width, fr.height);
    renderTable();
  }

  (async () => {
    try {
      frames = (await manualApi.frames(ws)).frames;
      stripBox.replaceChildren(frameStrip(frames, (n) => fileURL(ws!, `frames/${n}`), (n) => void pick(n)));
      load(await manualApi.gcps(ws));
      if (frames[0]) await pick(frames[0].name);
      void showGeoref();
      el.dataset.ready = '1';
    } catch (e) { say((e as Error).message, 'error'); }
  })();
  setLabels();
  (window as unknown as { fmv3dGcp: unknown }).fmv3dGcp = { view, points: () => points, pick: (n: string) => pick(n) };
  return () => { offJobs(); view.dispose(); };
}
