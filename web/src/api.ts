// The console's HTTP API client (docs/console-api.md). Every request goes to the page's own origin;
// the token (when the server needs one) comes from the page URL and is kept for the tab's session.

export const STAGES = [
  'frames', 'features', 'match', 'sparse', 'dense', 'mesh', 'texture', 'georef', 'dsm', 'ortho', 'tiles', 'report',
] as const;
export type StageName = (typeof STAGES)[number];
export type StageState = 'done' | 'stale' | 'pending' | 'running' | 'failed';

export interface JobStage { name: string; state: string; done?: number; total?: number; eta_s?: number | null; }
export interface Job {
  id: string; workspace: string; state: 'queued' | 'running' | 'done' | 'failed' | 'stopped';
  stage: string | null; stages: JobStage[]; started: string | number | null; finished: string | number | null;
  exit_code: number | null; log?: string[];
}
export interface WorkspaceFiles {
  sparse_ply: string | null; fused_ply: string | null; mesh_glb: string | null; tileset: string | null;
  ortho: string | null; dsm: string | null; hillshade: string | null; report_html: string | null;
  compare?: string | null; cad_error?: string | null;
}
export interface Workspace {
  name: string; stages: { name: string; state: StageState }[]; georeferenced: boolean; frames: number;
  registered: number; job: Job | null; files?: WorkspaceFiles;
}
export interface Camera {
  name: string; width: number; height: number; fx: number; fy: number; cx: number; cy: number;
  center: [number, number, number]; rotation: [number, number, number, number];
  reprojection_rms_px: number | null; frame: string;
}
export interface Sparse { count: number; positions: number[]; colors: number[]; errors: number[]; }
export interface Geo {
  epsg: number; origin: { lat: number; lon: number; alt: number }; bounds_wgs84: [number, number, number, number];
  track: [number, number, number][]; footprints: [number, number][][]; ortho: string | null; dsm: string | null;
  hillshade: string | null;
}
export interface ProfilePoint { lat: number; lon: number; distance_m: number; height_m: number | null; }

const params = new URLSearchParams(location.search);
const token: string | null = params.get('token') ?? sessionStorage.getItem('fmv3d.token');
if (token) sessionStorage.setItem('fmv3d.token', token);

/** Adds the token (when there is one) as a query parameter: for URLs handed to loaders that cannot set headers. */
export function withToken(url: string): string {
  if (!token) return url;
  return url + (url.includes('?') ? '&' : '?') + 'token=' + encodeURIComponent(token);
}

/** URL of a workspace file, each path component escaped. */
export function fileURL(ws: string, path: string): string {
  const parts = path.split('/').filter((p) => p.length > 0).map(encodeURIComponent);
  return withToken(`files/${encodeURIComponent(ws)}/${parts.join('/')}`);
}

export class ApiError extends Error {
  constructor(message: string, readonly status: number, readonly field?: string) { super(message); }
}

export async function request<T>(method: string, path: string, body?: unknown): Promise<T> {
  const headers: Record<string, string> = {};
  if (token) headers['Authorization'] = `Bearer ${token}`;
  let payload: BodyInit | undefined;
  if (body instanceof FormData || body instanceof Blob) payload = body;
  else if (body !== undefined) { headers['Content-Type'] = 'application/json'; payload = JSON.stringify(body); }
  const res = await fetch(path, { method, headers, body: payload });
  const text = await res.text();
  let data: unknown = null;
  try { data = text ? JSON.parse(text) : null; } catch { data = null; }
  if (!res.ok) {
    const err = (data ?? {}) as { error?: string; field?: string };
    throw new ApiError(err.error ?? `${method} ${path}: HTTP ${res.status}`, res.status, err.field);
  }
  return data as T;
}

export const api = {
  health: () => request<{ version: string; ws_root: string }>('GET', 'api/health'),
  workspaces: () => request<Workspace[]>('GET', 'api/workspaces'),
  workspace: (ws: string) => request<Workspace>('GET', `api/workspaces/${encodeURIComponent(ws)}`),
  createWorkspace: (name: string) => request<{ name: string }>('POST', 'api/workspaces', { name }),
  upload: (ws: string, files: FileList | File[]) => {
    const form = new FormData();
    for (const f of Array.from(files)) form.append('file', f, f.name);
    return request<{ paths: string[] }>('POST', `api/workspaces/${encodeURIComponent(ws)}/uploads`, form);
  },
  startJob: (ws: string, body: { inputs: string[]; from?: string; until?: string; fast?: boolean }) =>
    request<Job>('POST', `api/workspaces/${encodeURIComponent(ws)}/jobs`, body),
  jobs: () => request<Job[]>('GET', 'api/jobs'),
  job: (id: string) => request<Job>('GET', `api/jobs/${encodeURIComponent(id)}`),
  stopJob: (id: string) => request<Job>('POST', `api/jobs/${encodeURIComponent(id)}/stop`),
  cameras: (ws: string) => request<Camera[]>('GET', `api/workspaces/${encodeURIComponent(ws)}/cameras`),
  sparse: (ws: string) => request<Sparse>('GET', `api/workspaces/${encodeURIComponent(ws)}/sparse`),
  report: (ws: string) => request<Record<string, unknown>>('GET', `api/workspaces/${encodeURIComponent(ws)}/report`),
  geo: (ws: string) => request<Geo>('GET', `api/workspaces/${encodeURIComponent(ws)}/geo`),
  profile: (ws: string, from: [number, number], to: [number, number], n = 200) =>
    request<{ points: ProfilePoint[] }>('GET',
      `api/workspaces/${encodeURIComponent(ws)}/profile?from=${from[0]},${from[1]}&to=${to[0]},${to[1]}&n=${n}`),
};

export interface ProgressEvent { job: string; stage: string; label?: string; done: number; total: number; eta_s?: number | null; }
export interface EventHandlers {
  snapshot?: (jobs: Job[]) => void;
  job?: (job: Job) => void;
  progress?: (p: ProgressEvent) => void;
  log?: (l: { job: string; line: string }) => void;
  connection?: (open: boolean) => void;
}

/** One EventSource for the page; EventSource reconnects by itself and the server's snapshot catches the page up. */
export function subscribe(h: EventHandlers): EventSource {
  const es = new EventSource(withToken('api/events'));
  const on = <T>(name: string, fn?: (v: T) => void) => {
    if (!fn) return;
    es.addEventListener(name, (ev) => {
      try { fn(JSON.parse((ev as MessageEvent).data) as T); } catch (e) { console.warn('bad event', name, e); }
    });
  };
  on('snapshot', h.snapshot);
  on('job', h.job);
  on('progress', h.progress);
  on('log', h.log);
  es.onopen = () => h.connection?.(true);
  es.onerror = () => h.connection?.(false);
  return es;
}
