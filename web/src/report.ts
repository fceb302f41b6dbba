// Report page: the workspace's report.json as a page: headline figures, time per stage, camera and point
// reprojection errors, the dense / mesh / texture / CAD-comparison figures, the georeference's accuracy and the
// report's pictures.
import { api, fileURL, STAGES } from './api';
import { h, fmtNumber } from './dom';
import { barChart, histogram, lineChart } from './plots';

type J = Record<string, unknown>;
const isObj = (v: unknown): v is J => typeof v === 'object' && v !== null && !Array.isArray(v);
const num = (v: unknown): number | null => (typeof v === 'number' && isFinite(v) ? v : null);

export function mountReport(el: HTMLElement, ws: string | null): () => void {
  if (!ws) { el.append(h('p', { class: 'muted pad' }, 'No workspace yet.')); return () => undefined; }
  const root = h('div', { class: 'report', id: 'report' }, h('p', { class: 'muted' }, 'loading the report…'));
  el.append(root);
  void render(ws, root);
  return () => undefined;
}

async function render(ws: string, root: HTMLElement): Promise<void> {
  let report: J;
  try { report = await api.report(ws); } catch (e) {
    root.replaceChildren(h('p', { class: 'muted' }, `${ws} has no report yet (${e instanceof Error ? e.message : e}).`));
    return;
  }
  const info = await api.workspace(ws).catch(() => null);
  // A CAD comparison made after the run's report (fmv3d compare ... -o WS/report/compare) is read from its own file.
  if (!isObj(report.compare) && info?.files?.compare) {
    const c = await fetch(fileURL(ws, info.files.compare)).then((r) => (r.ok ? r.json() as Promise<J> : null)).catch(() => null);
    if (c) report = { ...report, compare: c };
  }
  const [cams, sparse, georef] = await Promise.all([
    api.cameras(ws).catch(() => []), api.sparse(ws).catch(() => null),
    info?.georeferenced
      ? fetch(fileURL(ws, 'geo/georef.json')).then((r) => (r.ok ? r.json() as Promise<J> : null)).catch(() => null)
      : Promise.resolve(null),
  ]);
  const sections: HTMLElement[] = [];
  const figs: HTMLElement[] = [];
  const fig = (title: string, body: Node, note?: string) => {
    const f = h('figure', { class: 'plot' }, body, h('figcaption', {}, title, note ? h('span', { class: 'muted' }, ` — ${note}`) : null));
    figs.push(f);
    return f;
  };

  // Headline figures.
  const sp = isObj(report.sparse) ? report.sparse : {};
  const frames = isObj(report.frames) ? report.frames : {};
  const dense = isObj(report.dense) ? report.dense : null;
  const mesh = isObj(report.mesh) ? report.mesh : null;
  const cards: [string, unknown, string?][] = [
    ['frames', frames.count], ['registered', sp.registered_images !== undefined ? `${sp.registered_images} / ${sp.total_images ?? frames.count ?? '?'}` : null],
    ['sparse points', sp.points], ['mean track length', sp.mean_track_length], ['reprojection error', sp.mean_reprojection_error_px, 'px'],
    ['dense points', dense?.points], ['mesh faces', mesh?.faces],
  ];
  const cmp = isObj(report.compare) ? report.compare : null;
  if (cmp) {
    const tot = isObj(cmp.error) && isObj(cmp.error.total) ? cmp.error.total : {};
    cards.push(['CAD: RMS signed distance', tot.rms_percent, '% of H'], ['CAD: completeness', cmp.completeness_percent, '%']);
  }
  if (georef) {
    const rms = findNumber(georef, /rms|rmse/i);
    if (rms) cards.push([`georeference: ${rms.key.replace(/[._]/g, ' ')}`, rms.value, 'm']);
  }
  sections.push(h('section', { class: 'cards' }, ...cards.filter(([, v]) => v !== undefined && v !== null).map(([k, v, unit]) =>
    h('div', { class: 'card figure-card' }, h('div', { class: 'big' }, typeof v === 'number' ? fmtNumber(v, 3) : String(v), unit ? h('small', {}, ' ' + unit) : null), h('div', { class: 'muted' }, k)))));

  // Time per stage.
  const timings = isObj(report.timings_seconds) ? report.timings_seconds : {};
  // In pipeline order; anything else the report timed after.
  const order = (k: string) => { const i = (STAGES as readonly string[]).indexOf(k); return i < 0 ? STAGES.length : i; };
  const items = Object.entries(timings).filter(([, v]) => num(v) !== null).map(([label, v]) => ({ label, value: v as number }))
    .sort((a, b) => order(a.label) - order(b.label) || a.label.localeCompare(b.label));
  if (items.length) {
    const total = items.reduce((s, i) => s + i.value, 0);
    fig('Time per stage', barChart(items, { unit: ' s', xLabel: 'seconds' }), `${fmtNumber(total, 1)} s in all`);
  }

  // Cameras.
  const errs = cams.map((c) => c.reprojection_rms_px).filter((e): e is number => e !== null && e !== undefined);
  if (errs.length) {
    fig('Camera reprojection RMS', histogram(errs, { xLabel: 'RMS reprojection error (px)', yLabel: 'cameras' }),
      `${errs.length} cameras, median ${fmtNumber(median(errs), 3)} px, max ${fmtNumber(Math.max(...errs), 3)} px`);
    fig('Reprojection RMS per camera', lineChart(errs.map((e, i) => [i, e]), { xLabel: 'camera (in frame order)', yLabel: 'px' }));
  }
  if (sparse && sparse.errors?.length) {
    fig('Sparse point reprojection errors', histogram(sparse.errors, { xLabel: 'reprojection error (px)', yLabel: 'points', color: '#81c784' }),
      `${sparse.count} points, median ${fmtNumber(median(sparse.errors), 3)} px`);
  }
  // CAD comparison: RMS and 90th percentile of each error component.
  if (cmp && isObj(cmp.error)) {
    const err = cmp.error as J;
    const bars: { label: string; value: number; color?: string }[] = [];
    for (const k of ['x', 'y', 'z', 'total']) {
      const e = isObj(err[k]) ? err[k] as J : null;
      if (e && num(e.rms_percent) !== null) bars.push({ label: `${k === 'total' ? 'distance' : k.toUpperCase()} RMS`, value: e.rms_percent as number });
      if (e && num(e.p90_abs_percent) !== null) bars.push({ label: `${k === 'total' ? 'distance' : k.toUpperCase()} |e| 90%`, value: e.p90_abs_percent as number, color: '#ffb74d' });
    }
    if (bars.length) fig('Errors against the CAD model', barChart(bars, { unit: ' %', xLabel: '% of H' }),
      `${num(cmp.completeness_percent) !== null ? `completeness ${fmtNumber(cmp.completeness_percent as number, 1)}%, ` : ''}H = ${cmp.length ?? '?'}`);
  }
  // Any numeric histogram-like arrays in the dense / mesh / comparison figures.
  for (const key of ['dense', 'mesh', 'texture', 'compare']) {
    const sec = report[key];
    if (!isObj(sec)) continue;
    for (const [k, v] of Object.entries(sec)) {
      if (Array.isArray(v) && v.length >= 3 && v.every((x) => typeof x === 'number')) {
        fig(`${key}: ${k.replace(/_/g, ' ')}`, /hist|count|bins/i.test(k)
          ? barChart((v as number[]).map((x, i) => ({ label: String(i), value: x })).slice(0, 30), {})
          : lineChart((v as number[]).map((x, i) => [i, x]), { xLabel: k }));
      }
    }
  }
  sections.push(h('section', { class: 'plots' }, ...figs));

  // Figure tables.
  const tables: HTMLElement[] = [];
  for (const [key, title] of [['sparse', 'Sparse model'], ['dense', 'Dense points'], ['mesh', 'Mesh'], ['texture', 'Texture'], ['compare', 'Comparison with the CAD model'], ['matches', 'Matching'], ['features', 'Features']] as const) {
    const sec = report[key];
    if (isObj(sec)) tables.push(h('div', { class: 'card' }, h('h3', {}, title), figureTable(sec)));
  }
  if (georef) tables.push(h('div', { class: 'card', id: 'georef-figures' }, h('h3', {}, 'Georeference'), figureTable(georef)));
  sections.push(h('section', { class: 'tables' }, ...tables));

  // Pictures.
  const pics = Array.isArray(report.pictures) ? [...report.pictures as { file: string; title: string }[]] : [];
  if (cmp && info?.files?.compare) pics.push({ file: 'compare/histograms.png', title: 'CAD comparison: X, Y, Z error histograms' },
    { file: 'compare/top.png', title: 'CAD comparison: top view, points coloured by distance' },
    { file: 'compare/side.png', title: 'CAD comparison: side view' });
  if (pics.length) {
    sections.push(h('section', { class: 'pictures' }, h('h2', {}, 'Pictures'),
      ...pics.map((p) => h('figure', {}, h('img', { src: fileURL(ws, `report/${p.file}`), alt: p.title }), h('figcaption', {}, p.title)))));
  }
  root.replaceChildren(h('h1', {}, `Report: ${ws}`),
    h('p', { class: 'muted' }, typeof report.workspace === 'string' ? report.workspace : '', ' · ',
      h('a', { href: fileURL(ws, 'report/report.html'), target: '_blank' }, 'standalone report.html')),
    ...sections);
  root.dataset.figures = String(figs.length);
}

function median(v: number[]): number { const s = [...v].sort((a, b) => a - b); return s.length ? s[Math.floor(s.length / 2)] : NaN; }

function findNumber(o: J, re: RegExp, prefix = ''): { key: string; value: number } | null {
  for (const [k, v] of Object.entries(o)) {
    const key = prefix ? `${prefix}.${k}` : k;
    if (re.test(k) && num(v) !== null) return { key, value: v as number };
    if (isObj(v)) { const r = findNumber(v, re, key); if (r) return r; }
  }
  return null;
}

/** The scalar figures of a section (nested keys joined by "."), at most 40 rows. */
function figureTable(o: J): HTMLElement {
  const rows: [string, string][] = [];
  const walk = (v: unknown, key: string, depth: number) => {
    if (rows.length >= 40) return;
    if (num(v) !== null) rows.push([key, fmtNumber(v as number, 3)]);
    else if (typeof v === 'string' && v.length < 80) rows.push([key, v]);
    else if (typeof v === 'boolean') rows.push([key, v ? 'yes' : 'no']);
    else if (Array.isArray(v) && v.length <= 4 && v.every((x) => typeof x === 'number')) rows.push([key, (v as number[]).map((x) => fmtNumber(x, 3)).join(', ')]);
    else if (isObj(v) && depth < 2) for (const [k, w] of Object.entries(v)) walk(w, key ? `${key}.${k}` : k, depth + 1);
  };
  walk(o, '', 0);
  return h('table', { class: 'figures' }, ...rows.map(([k, v]) => h('tr', {}, h('th', {}, k.replace(/_/g, ' ')), h('td', {}, v))));
}
