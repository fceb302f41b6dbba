// The console's shell: tabs routed by the URL hash (#/jobs, #/3d/WS, #/map/WS, #/report/WS), one event stream
// for the whole page, and the workspace picker shared by the pages.
import './style.css';
import { api, subscribe, type Workspace } from './api';
import { store } from './store';
import { mountJobs } from './jobs';
import { mountView3d } from './view3d';
import { mountMap } from './map';
import { mountReport } from './report';
import { mountTiePoints } from './tiepoints';
import { mountGcp } from './gcp';
import { mountCalibration } from './calibration';

type Mount = (el: HTMLElement, ws: string | null) => () => void;
const pages: Record<string, Mount> = { jobs: mountJobs, '3d': mountView3d, map: mountMap, report: mountReport,
  tiepoints: mountTiePoints, gcp: mountGcp, calibration: mountCalibration };

const app = document.getElementById('app')!;
const select = document.getElementById('ws-select') as HTMLSelectElement;
const conn = document.getElementById('conn')!;
let unmount: (() => void) | null = null;

function parseRoute(): { page: string; ws: string | null } {
  const parts = location.hash.replace(/^#\/?/, '').split('/');
  const page = parts[0] in pages ? parts[0] : 'jobs';
  const ws = parts[1] ? decodeURIComponent(parts[1]) : null;
  return { page, ws };
}

function pickWorkspace(page: string, ws: string | null): string | null {
  if (ws) return ws;
  const list = store.workspaces;
  const remembered = localStorage.getItem('fmv3d.ws');
  if (remembered && list.some((w) => w.name === remembered)) return remembered;
  // A page that shows a model opens the first workspace that has one.
  const useful = (w: Workspace) =>
    page === 'map' ? w.georeferenced : w.stages.some((s) => s.name === 'sparse' && s.state === 'done');
  return list.find(useful)?.name ?? list[0]?.name ?? null;
}

function route(): void {
  const { page, ws: wsInRoute } = parseRoute();
  const ws = page === 'jobs' ? wsInRoute : pickWorkspace(page, wsInRoute);
  if (ws) localStorage.setItem('fmv3d.ws', ws);
  for (const a of document.querySelectorAll<HTMLAnchorElement>('#tabs a')) {
    a.classList.toggle('active', a.dataset.route === page);
    const r = a.dataset.route!;
    const target = r === 'jobs' ? '' : (ws ?? localStorage.getItem('fmv3d.ws') ?? '');
    a.href = `#/${r}${target ? '/' + encodeURIComponent(target) : ''}`;
  }
  fillSelect(ws);
  unmount?.();
  app.replaceChildren();
  app.className = `page-${page}`;
  unmount = pages[page](app, ws);
}

function fillSelect(current: string | null): void {
  const names = store.workspaces.map((w) => w.name);
  select.replaceChildren(...names.map((n) => new Option(n, n, false, n === current)));
  if (current && !names.includes(current)) select.add(new Option(current, current, true, true));
}

select.addEventListener('change', () => {
  const { page } = parseRoute();
  localStorage.setItem('fmv3d.ws', select.value);
  location.hash = `#/${page === 'jobs' ? '3d' : page}/${encodeURIComponent(select.value)}`;
});

window.addEventListener('hashchange', route);

subscribe({
  snapshot: (jobs) => store.setJobs(jobs),
  job: (job) => store.updateJob(job),
  progress: (p) => store.progress(p),
  log: (l) => store.log(l.job, l.line),
  connection: (open) => {
    conn.textContent = open ? 'live' : 'reconnecting…';
    conn.classList.toggle('ok', open);
    if (open) void store.refreshWorkspaces();
  },
});

store.onWorkspaces(() => fillSelect(parseRoute().ws ?? localStorage.getItem('fmv3d.ws')));
api.health().then((h) => { document.title = `fmv3d console — ${h.ws_root}`; }).catch(() => undefined);
store.refreshWorkspaces().finally(route);
