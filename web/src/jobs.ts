// Jobs page: the workspaces with each stage's state, starting / stopping / resuming reconstructions, and each
// job's live progress (bars, ETA, log) from the server's event stream.
import { api, ApiError, STAGES, type Job, type Workspace } from './api';
import { store } from './store';
import { fmtDuration, h } from './dom';

export function mountJobs(el: HTMLElement): () => void {
  const msg = h('div', { class: 'msg', id: 'job-msg' });
  const form = newJobForm(msg);
  const wsTable = h('div', { id: 'ws-table' });
  const jobsBox = h('div', { id: 'jobs' });
  el.append(
    h('section', { class: 'card' }, h('h2', {}, 'New reconstruction'), form, msg),
    h('section', { class: 'card' }, h('h2', {}, 'Workspaces'), wsTable),
    h('section', { class: 'card' }, h('h2', {}, 'Jobs'), jobsBox),
  );

  const renderWs = () => wsTable.replaceChildren(workspacesTable(store.workspaces, msg));
  const jobViews = new Map<string, JobView>();
  let frame = 0;
  const renderJobs = () => {
    frame = 0;
    const jobs = [...store.jobs.values()].sort((a, b) => String(b.started ?? '').localeCompare(String(a.started ?? '')));
    if (jobs.length === 0) { jobsBox.replaceChildren(h('p', { class: 'muted' }, 'No job in this server\'s life yet.')); jobViews.clear(); return; }
    const nodes: HTMLElement[] = [];
    for (const j of jobs) {
      let v = jobViews.get(j.id);
      if (!v) { v = new JobView(msg); jobViews.set(j.id, v); }
      v.update(j, store.logs.get(j.id) ?? j.log ?? []);
      nodes.push(v.root);
    }
    if (nodes.some((n, i) => jobsBox.children[i] !== n) || jobsBox.children.length !== nodes.length) jobsBox.replaceChildren(...nodes);
  };
  const scheduleJobs = () => { if (!frame) frame = requestAnimationFrame(renderJobs); };

  renderWs();
  renderJobs();
  const offWs = store.onWorkspaces(renderWs);
  const offJobs = store.onJobs(scheduleJobs);
  const timer = window.setInterval(() => void store.refreshWorkspaces(), 10000);
  return () => { offWs(); offJobs(); clearInterval(timer); if (frame) cancelAnimationFrame(frame); };
}

function showError(msg: HTMLElement, e: unknown): void {
  const text = e instanceof ApiError ? `${e.message}${e.field ? ` (field: ${e.field})` : ''}` : String(e);
  msg.className = 'msg error';
  msg.textContent = text;
}
function showOk(msg: HTMLElement, text: string): void { msg.className = 'msg ok'; msg.textContent = text; }

function stageSelect(name: string, withNone: string): HTMLSelectElement {
  const s = h('select', { name }, h('option', { value: '' }, withNone));
  for (const st of STAGES) s.append(h('option', { value: st }, st));
  return s;
}

function newJobForm(msg: HTMLElement): HTMLElement {
  const wsName = h('input', { name: 'workspace', placeholder: 'workspace name', required: true, list: 'ws-names', pattern: '[A-Za-z0-9._ \\-]+' });
  const list = h('datalist', { id: 'ws-names' });
  const files = h('input', { type: 'file', name: 'file', multiple: true, accept: 'video/*,image/*,.ts,.mpg,.srt,.klv' });
  const paths = h('textarea', { name: 'paths', rows: 2, placeholder: 'or paths on the server (under the workspace root), one per line' });
  const fast = h('input', { type: 'checkbox', name: 'fast' });
  const from = stageSelect('from', 'from: start');
  const until = stageSelect('until', 'until: end');
  const start = h('button', { type: 'submit', id: 'start-job' }, 'Start reconstruct');
  const form = h('form', { id: 'new-job', class: 'grid-form' },
    h('label', {}, 'Workspace', wsName, list),
    h('label', {}, 'Upload', files),
    h('label', { class: 'wide' }, 'Server paths', paths),
    h('div', { class: 'row' }, h('label', { class: 'inline' }, fast, ' fast'), from, until, start));
  const fillList = () => list.replaceChildren(...store.workspaces.map((w) => h('option', { value: w.name })));
  fillList();
  store.onWorkspaces(fillList);

  form.addEventListener('submit', async (ev) => {
    ev.preventDefault();
    const name = wsName.value.trim();
    start.disabled = true;
    try {
      if (!store.workspaces.some((w) => w.name === name)) {
        try { await api.createWorkspace(name); } catch (e) { if (!(e instanceof ApiError && e.status === 409)) throw e; }
      }
      const inputs = paths.value.split(/\n|,/).map((s) => s.trim()).filter(Boolean);
      if (files.files && files.files.length > 0) {
        showOk(msg, `uploading ${files.files.length} file(s)…`);
        const up = await api.upload(name, files.files);
        inputs.push(...up.paths);
      }
      const job = await api.startJob(name, {
        inputs, fast: fast.checked, ...(from.value ? { from: from.value } : {}), ...(until.value ? { until: until.value } : {}),
      });
      store.updateJob(job);
      showOk(msg, `job ${job.id} started on ${name}`);
      await store.refreshWorkspaces();
    } catch (e) { showError(msg, e); } finally { start.disabled = false; }
  });
  return form;
}

function workspacesTable(list: Workspace[], msg: HTMLElement): HTMLElement {
  if (list.length === 0) return h('p', { class: 'muted' }, 'No workspace under the server\'s root yet.');
  const table = h('table', { class: 'ws' },
    h('thead', {}, h('tr', {}, h('th', {}, 'workspace'), h('th', {}, 'stages'), h('th', {}, 'frames'),
      h('th', {}, 'registered'), h('th', {}, 'geo'), h('th', {}, ''))));
  const body = h('tbody');
  for (const w of list) {
    const running = w.job && (w.job.state === 'running' || w.job.state === 'queued');
    const chips = h('div', { class: 'chips' }, ...w.stages.map((s) => h('span', { class: `chip ${s.state}`, title: `${s.name}: ${s.state}` }, s.name)));
    const rerun = stageSelect('rerun', 're-run from…');
    rerun.addEventListener('change', async () => {
      if (!rerun.value) return;
      try { const j = await api.startJob(w.name, { inputs: [], from: rerun.value }); store.updateJob(j); showOk(msg, `job ${j.id}: ${w.name} from ${rerun.value}`); }
      catch (e) { showError(msg, e); }
      rerun.value = '';
    });
    const resume = h('button', { class: 'small', disabled: !!running, onclick: async () => {
      try { const j = await api.startJob(w.name, { inputs: [] }); store.updateJob(j); showOk(msg, `job ${j.id}: resuming ${w.name}`); }
      catch (e) { showError(msg, e); }
    } }, 'resume');
    const enc = encodeURIComponent(w.name);
    body.append(h('tr', { 'data-ws': w.name },
      h('td', {}, h('b', {}, w.name)), h('td', {}, chips), h('td', { class: 'num' }, w.frames), h('td', { class: 'num' }, w.registered),
      h('td', {}, w.georeferenced ? 'yes' : ''),
      h('td', { class: 'actions' }, h('a', { href: `#/3d/${enc}` }, '3D'), ' ',
        w.georeferenced ? h('a', { href: `#/map/${enc}` }, 'map') : null, ' ', h('a', { href: `#/report/${enc}` }, 'report'), ' ',
        resume, running ? null : rerun)));
  }
  table.append(body);
  return table;
}

class JobView {
  root = h('div', { class: 'job' });
  private head = h('div', { class: 'job-head' });
  private bars = h('div', { class: 'bars' });
  private logEl = h('pre', { class: 'log' });
  private stopBtn: HTMLButtonElement;
  private job: Job | null = null;
  private lastLogLen = -1;

  constructor(msg: HTMLElement) {
    this.stopBtn = h('button', { class: 'small danger', onclick: async () => {
      if (!this.job) return;
      try { store.updateJob(await api.stopJob(this.job.id)); } catch (e) { showError(msg, e); }
    } }, 'stop');
    const details = h('details', {}, h('summary', {}, 'log'), this.logEl);
    details.open = true;
    this.root.append(this.head, this.bars, details);
  }

  update(job: Job, log: string[]): void {
    this.job = job;
    this.root.dataset.job = job.id;
    this.root.dataset.state = job.state;
    this.root.dataset.progressEvents = String(store.progressSeen.get(job.id) ?? 0);
    const active = job.state === 'running' || job.state === 'queued';
    this.head.replaceChildren(h('span', { class: 'job-title' },
      h('b', {}, job.workspace), h('span', { class: 'muted' }, ` job ${job.id} `),
      h('span', { class: `state ${job.state}` }, job.state), job.stage && active ? h('span', {}, ` · ${job.stage}`) : null,
      job.exit_code !== null && job.exit_code !== undefined && !active ? h('span', { class: 'muted' }, ` · exit ${job.exit_code}`) : null,
      active ? this.stopBtn : null));
    this.bars.replaceChildren(...job.stages.map((s) => {
      const frac = s.state === 'done' ? 1 : s.total ? Math.min(1, (s.done ?? 0) / s.total) : 0;
      const label = (s as { label?: string }).label;
      const txt = s.state === 'running' && s.total ? `${s.done ?? 0}/${s.total}${label ? ' ' + label : ''}${s.eta_s ? ` · ETA ${fmtDuration(s.eta_s)}` : ''}` : s.state;
      return h('div', { class: `bar ${s.state}`, 'data-stage': s.name },
        h('span', { class: 'bar-name' }, s.name),
        h('span', { class: 'bar-track' }, h('span', { class: 'bar-fill', style: `width:${(100 * frac).toFixed(1)}%` })),
        h('span', { class: 'bar-text' }, txt));
    }));
    if (log.length !== this.lastLogLen) {
      const atBottom = this.logEl.scrollTop + this.logEl.clientHeight >= this.logEl.scrollHeight - 4;
      this.logEl.textContent = log.slice(-200).join('\n');
      if (atBottom) this.logEl.scrollTop = this.logEl.scrollHeight;
      this.lastLogLen = log.length;
    }
  }
}
