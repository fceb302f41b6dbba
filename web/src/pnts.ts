// Parsers for 3D Tiles 1.0 tile contents: `.pnts` point tiles (feature table + batch table) and `.b3dm` (a glTF
// with a header). Positions come out in the tile's frame with RTC_CENTER / quantisation applied.

export interface PointTile {
  count: number;
  positions: Float32Array;          // xyz, relative to `center`
  center: [number, number, number]; // RTC_CENTER (or 0)
  colors: Uint8Array | null;        // rgb, 0-255
  normals: Int8Array | null;        // xyz, normalised to [-127, 127]
  views: Float32Array | null;       // number of views that saw each point (from the batch table), when present
  sigma: Float32Array | null;       // per-point stated σ along the normal (batch table "sigma"), when present
}

const HEADER = 28;

interface BinaryRef { byteOffset: number; componentType?: string; type?: string; }

function u32(view: DataView, o: number): number { return view.getUint32(o, true); }

export function parsePnts(buf: ArrayBuffer): PointTile {
  const view = new DataView(buf);
  const magic = String.fromCharCode(...new Uint8Array(buf, 0, 4));
  if (magic !== 'pnts') throw new Error(`not a .pnts tile (magic "${magic}")`);
  const ftJsonLen = u32(view, 12), ftBinLen = u32(view, 16), btJsonLen = u32(view, 20), btBinLen = u32(view, 24);
  const dec = new TextDecoder();
  const ft = JSON.parse(dec.decode(new Uint8Array(buf, HEADER, ftJsonLen)).trim() || '{}') as Record<string, unknown>;
  const ftBin = HEADER + ftJsonLen;
  const btJsonOff = ftBin + ftBinLen;
  const btBin = btJsonOff + btJsonLen;
  const count = Number(ft.POINTS_LENGTH ?? 0);
  const ref = (k: string) => ft[k] as BinaryRef | undefined;
  const globalVec = (k: string): [number, number, number] | null => {
    const v = ft[k];
    if (Array.isArray(v)) return [v[0], v[1], v[2]];
    if (v && typeof v === 'object' && 'byteOffset' in v) {
      const o = ftBin + (v as BinaryRef).byteOffset;
      return [view.getFloat32(o, true), view.getFloat32(o + 4, true), view.getFloat32(o + 8, true)];
    }
    return null;
  };

  let positions: Float32Array;
  if (ref('POSITION')) {
    positions = new Float32Array(buf.slice(ftBin + ref('POSITION')!.byteOffset, ftBin + ref('POSITION')!.byteOffset + 12 * count));
  } else if (ref('POSITION_QUANTIZED')) {
    const q = new Uint16Array(buf.slice(ftBin + ref('POSITION_QUANTIZED')!.byteOffset, ftBin + ref('POSITION_QUANTIZED')!.byteOffset + 6 * count));
    const off = globalVec('QUANTIZED_VOLUME_OFFSET') ?? [0, 0, 0];
    const sc = globalVec('QUANTIZED_VOLUME_SCALE') ?? [1, 1, 1];
    positions = new Float32Array(3 * count);
    for (let i = 0; i < 3 * count; i++) positions[i] = off[i % 3] + (q[i] / 65535) * sc[i % 3];
  } else {
    throw new Error('.pnts tile without POSITION');
  }

  let colors: Uint8Array | null = null;
  if (ref('RGB')) {
    colors = new Uint8Array(buf.slice(ftBin + ref('RGB')!.byteOffset, ftBin + ref('RGB')!.byteOffset + 3 * count));
  } else if (ref('RGBA')) {
    const rgba = new Uint8Array(buf, ftBin + ref('RGBA')!.byteOffset, 4 * count);
    colors = new Uint8Array(3 * count);
    for (let i = 0; i < count; i++) { colors[3 * i] = rgba[4 * i]; colors[3 * i + 1] = rgba[4 * i + 1]; colors[3 * i + 2] = rgba[4 * i + 2]; }
  } else if (ref('RGB565')) {
    const c = new Uint16Array(buf.slice(ftBin + ref('RGB565')!.byteOffset, ftBin + ref('RGB565')!.byteOffset + 2 * count));
    colors = new Uint8Array(3 * count);
    for (let i = 0; i < count; i++) {
      colors[3 * i] = ((c[i] >> 11) & 31) * 255 / 31; colors[3 * i + 1] = ((c[i] >> 5) & 63) * 255 / 63; colors[3 * i + 2] = (c[i] & 31) * 255 / 31;
    }
  }

  let normals: Int8Array | null = null;
  if (ref('NORMAL')) {
    const n = new Float32Array(buf.slice(ftBin + ref('NORMAL')!.byteOffset, ftBin + ref('NORMAL')!.byteOffset + 12 * count));
    normals = new Int8Array(3 * count);
    for (let i = 0; i < 3 * count; i++) normals[i] = Math.round(Math.max(-1, Math.min(1, n[i])) * 127);
  } else if (ref('NORMAL_OCT16P')) {
    const o = new Uint8Array(buf, ftBin + ref('NORMAL_OCT16P')!.byteOffset, 2 * count);
    normals = new Int8Array(3 * count);
    for (let i = 0; i < count; i++) {
      let x = (o[2 * i] / 255) * 2 - 1, y = (o[2 * i + 1] / 255) * 2 - 1;
      const z = 1 - Math.abs(x) - Math.abs(y);
      if (z < 0) { const ox = x; x = (1 - Math.abs(y)) * Math.sign(ox); y = (1 - Math.abs(ox)) * Math.sign(y); }
      const l = Math.hypot(x, y, z) || 1;
      normals[3 * i] = Math.round((127 * x) / l); normals[3 * i + 1] = Math.round((127 * y) / l); normals[3 * i + 2] = Math.round((127 * z) / l);
    }
  }

  // Batch table: per-point properties, either JSON arrays or binary references.
  let views: Float32Array | null = null, sigma: Float32Array | null = null;
  if (btJsonLen > 0) {
    const bt = JSON.parse(dec.decode(new Uint8Array(buf, btJsonOff, btJsonLen)).trim() || '{}') as Record<string, unknown>;
    const prop = (names: string[]): Float32Array | null => {
      for (const name of names) {
        const p = bt[name];
        if (Array.isArray(p)) return Float32Array.from(p as number[]);
        if (p && typeof p === 'object' && 'byteOffset' in p) {
          const r = p as BinaryRef;
          const off = btBin + r.byteOffset;
          if (off > buf.byteLength || btBinLen === 0) continue;
          const out = new Float32Array(count);
          const ct = r.componentType ?? 'FLOAT';
          for (let i = 0; i < count; i++) {
            switch (ct) {
              case 'UNSIGNED_BYTE': out[i] = view.getUint8(off + i); break;
              case 'BYTE': out[i] = view.getInt8(off + i); break;
              case 'UNSIGNED_SHORT': out[i] = view.getUint16(off + 2 * i, true); break;
              case 'SHORT': out[i] = view.getInt16(off + 2 * i, true); break;
              case 'UNSIGNED_INT': out[i] = view.getUint32(off + 4 * i, true); break;
              case 'INT': out[i] = view.getInt32(off + 4 * i, true); break;
              case 'DOUBLE': out[i] = view.getFloat64(off + 8 * i, true); break;
              default: out[i] = view.getFloat32(off + 4 * i, true);
            }
          }
          return out;
        }
      }
      return null;
    };
    views = prop(['views', 'num_views', 'NUM_VIEWS', 'visibility', 'n_views']);
    sigma = prop(['sigma', 'SIGMA']);
  }
  return { count, positions, center: globalVec('RTC_CENTER') ?? [0, 0, 0], colors, normals, views, sigma };
}

/** The glTF binary inside a `.b3dm` tile. */
export function b3dmGlb(buf: ArrayBuffer): ArrayBuffer {
  const view = new DataView(buf);
  const start = HEADER + u32(view, 12) + u32(view, 16) + u32(view, 20) + u32(view, 24);
  return buf.slice(start, u32(view, 8));
}
