// The hand tools' part of the console's API (docs/console-api.md, "Hand tools").
import { request } from './api';

export interface FrameInfo {
  id: number; name: string; width: number; height: number; registered: boolean; features: boolean;
  left_out: string | null;
}
export interface Keypoints { frame: string; width: number; height: number; count: number; keypoints: number[]; }
/** [idx_a, idx_b, xa, ya, xb, yb] */
export type PairMatch = [number, number, number, number, number, number];
export interface Pair {
  a: string; b: string; inliers: PairMatch[]; rejected: PairMatch[]; F: number[] | null;
  F_source: 'poses' | 'matches' | null;
}
/** manual/tiepoints.json (docs/manual-inputs.md). */
export interface Obs { frame: string; x: number; y: number; }
export interface TiePoint { id: string; label?: string; observations: Obs[]; }
export interface ManualKeypoint extends Obs { id: string; label?: string; }
export interface DeletedMatch { frame1: string; frame2: string; feature1: number; feature2: number; }
export interface TiePoints {
  format: 'fmv3d-tiepoints'; version: 1; tie_points: TiePoint[]; keypoints: ManualKeypoint[]; deleted_matches: DeletedMatch[];
}
export interface Gcp { name: string; x: number; y: number; z: number; check: boolean; observations: Obs[]; }
export interface Gcps { crs: string | null; points: Gcp[]; }
export interface CalibImage { name: string; rms: number; corners?: number[]; residuals?: number[]; }
export interface CalibResult {
  width: number; height: number; f: number; aspect: number; u0: number; v0: number; k1: number; k2: number;
  p1: number; p2: number; rms: number; stddev: Record<string, number>; images: CalibImage[]; rejected: string[];
  board: { cols: number; rows: number; square: number };
  videos?: { video: string; sampled: number; found: number; kept: number; dropped: string[] }[];
}
export interface Calibration {
  state: 'none' | 'running' | 'done' | 'failed'; log: string[];
  request: { board: { cols: number; rows: number }; square: number; images: string[]; drop?: string[] } | null;
  result: CalibResult | null; distortion_png?: string; corners_dir?: string; frames_dir?: string; uploads: string[];
}

const w = (ws: string) => `api/workspaces/${encodeURIComponent(ws)}`;
export const manualApi = {
  frames: (ws: string) => request<{ frames: FrameInfo[]; has_model: boolean }>('GET', `${w(ws)}/frames`),
  keypoints: (ws: string, frame: string) =>
    request<Keypoints>('GET', `${w(ws)}/frames/${encodeURIComponent(frame)}/keypoints`),
  pair: (ws: string, a: string, b: string) =>
    request<Pair>('GET', `${w(ws)}/pair?a=${encodeURIComponent(a)}&b=${encodeURIComponent(b)}`),
  tiepoints: (ws: string) => request<TiePoints>('GET', `${w(ws)}/tiepoints`),
  saveTiepoints: (ws: string, t: TiePoints) => request<TiePoints>('PUT', `${w(ws)}/tiepoints`, t),
  gcps: (ws: string) => request<Gcps>('GET', `${w(ws)}/gcps`),
  saveGcps: (ws: string, g: Gcps) => request<Gcps>('PUT', `${w(ws)}/gcps`, g),
  importGcpText: async (ws: string, text: string): Promise<Gcps> => {
    const blob = new Blob([text], { type: 'text/plain' });
    return request<Gcps>('PUT', `${w(ws)}/gcps`, blob);
  },
  gcpExportPath: (ws: string) => `${w(ws)}/gcp_list.txt`,
  calibration: (ws: string) => request<Calibration>('GET', `${w(ws)}/calibration`),
  runCalibration: (ws: string, body: { images: string[]; board: string; square: number; drop?: string[] }) =>
    request<Calibration>('POST', `${w(ws)}/calibration`, body),
  saveSensor: (ws: string, name: string) =>
    request<{ name: string; database: string }>('POST', `${w(ws)}/calibration/save`, { name }),
};
