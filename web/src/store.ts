// The page's shared state: workspaces and jobs, kept current by the server's event stream.
import { api, type Job, type ProgressEvent, type Workspace } from './api';

type Listener = () => void;
const MAX_LOG = 500;

class Store {
  workspaces: Workspace[] = [];
  jobs = new Map<string, Job>();
  logs = new Map<string, string[]>();
  /** Progress events seen by this page, per job: the browser test reads this count. */
  progressSeen = new Map<string, number>();
  private wsListeners = new Set<Listener>();
  private jobListeners = new Set<(id: string | null) => void>();

  async refreshWorkspaces(): Promise<void> {
    try { this.workspaces = await api.workspaces(); } catch (e) { console.warn(e); }
    this.wsListeners.forEach((l) => l());
  }
  onWorkspaces(l: Listener): () => void { this.wsListeners.add(l); return () => this.wsListeners.delete(l); }
  onJobs(l: (id: string | null) => void): () => void { this.jobListeners.add(l); return () => this.jobListeners.delete(l); }
  private emitJob(id: string | null): void { this.jobListeners.forEach((l) => l(id)); }

  setJobs(jobs: Job[]): void {
    this.jobs = new Map(jobs.map((j) => [j.id, j]));
    // A reloaded page fetches each job's recent log once; later lines arrive as events.
    for (const j of jobs) {
      if (!this.logs.has(j.id)) {
        api.job(j.id).then((full) => {
          if (full.log) this.logs.set(j.id, full.log.slice(-MAX_LOG));
          this.emitJob(j.id);
        }).catch(() => undefined);
      }
    }
    this.emitJob(null);
  }
  updateJob(job: Job): void {
    const prev = this.jobs.get(job.id);
    this.jobs.set(job.id, job);
    this.emitJob(job.id);
    if (!prev || prev.state !== job.state || prev.stage !== job.stage) void this.refreshWorkspaces();
  }
  progress(p: ProgressEvent): void {
    this.progressSeen.set(p.job, (this.progressSeen.get(p.job) ?? 0) + 1);
    const job = this.jobs.get(p.job);
    if (!job) return;
    let st = job.stages.find((s) => s.name === p.stage);
    if (!st) { st = { name: p.stage, state: 'running' }; job.stages.push(st); }
    st.done = p.done; st.total = p.total; st.eta_s = p.eta_s ?? null;
    if (st.state !== 'done') st.state = 'running';
    job.stage = p.stage;
    (st as { label?: string }).label = p.label;
    this.emitJob(p.job);
  }
  log(id: string, line: string): void {
    const l = this.logs.get(id) ?? [];
    l.push(line);
    if (l.length > MAX_LOG) l.splice(0, l.length - MAX_LOG);
    this.logs.set(id, l);
    this.emitJob(id);
  }
}

export const store = new Store();
