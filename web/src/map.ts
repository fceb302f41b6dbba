// Map page (georeferenced workspaces): orthophoto and DSM hillshade straight from the workspace's Cloud-Optimised
// GeoTIFFs, the flight track and frame footprints, a height profile along a drawn line, and the cursor's WGS84 and
// UTM coordinates. No base map: nothing is fetched from outside the machine.
import 'ol/ol.css';
import OlMap from 'ol/Map';
import View from 'ol/View';
import WebGLTileLayer from 'ol/layer/WebGLTile';
import GeoTIFFSource from 'ol/source/GeoTIFF';
import VectorLayer from 'ol/layer/Vector';
import VectorSource from 'ol/source/Vector';
import Feature from 'ol/Feature';
import { LineString, Polygon, Point } from 'ol/geom';
import Draw from 'ol/interaction/Draw';
import DoubleClickZoom from 'ol/interaction/DoubleClickZoom';
import { Style, Stroke, Fill, Circle as CircleStyle } from 'ol/style';
import { ScaleLine, defaults as defaultControls } from 'ol/control';
import { transform, get as getProjection } from 'ol/proj';
import { register } from 'ol/proj/proj4';
import { boundingExtent } from 'ol/extent';
import proj4 from 'proj4';
import { fromUrl } from 'geotiff';
import { api, fileURL, type Geo } from './api';
import { h, fmtNumber } from './dom';
import { lineChart } from './plots';

export interface MapFeatures { track: number; footprints: number; trackDrawn: number; footprintsDrawn: number }
declare global {
  interface Window {
    fmv3dMap?: { ready: () => boolean; layers: () => string[]; features: () => MapFeatures;
      bounds: () => [number, number, number, number] | null; profile: () => { points: number; valid: number } | null };
  }
}

/** The proj4 definition of a WGS84 UTM zone code (326zz north, 327zz south), or null. */
export function utmDef(epsg: number): string | null {
  const zone = epsg % 100;
  if (zone < 1 || zone > 60) return null;
  if (Math.floor(epsg / 100) === 326) return `+proj=utm +zone=${zone} +datum=WGS84 +units=m +no_defs`;
  if (Math.floor(epsg / 100) === 327) return `+proj=utm +zone=${zone} +south +datum=WGS84 +units=m +no_defs`;
  return null;
}
export function utmZoneOf(lon: number, lat: number): number {
  return (lat >= 0 ? 32600 : 32700) + Math.min(60, Math.max(1, Math.floor((lon + 180) / 6) + 1));
}
function ensureProjection(epsg: number): string {
  const code = `EPSG:${epsg}`;
  if (!getProjection(code)) {
    const def = utmDef(epsg);
    if (def) { proj4.defs(code, def); register(proj4); }
  }
  return code;
}

export function mountMap(el: HTMLElement, ws: string | null): () => void {
  if (!ws) { el.append(h('p', { class: 'muted pad' }, 'No workspace yet.')); return () => undefined; }
  const mapEl = h('div', { id: 'map', class: 'map' });
  const coords = h('div', { class: 'overlay coords', id: 'map-coords' }, 'move the mouse over the map');
  const side = h('aside', { class: 'side' });
  const profileBox = h('div', { id: 'profile', class: 'profile' });
  el.append(h('div', { class: 'mapview' }, h('div', { class: 'map-box' }, mapEl, coords), side), profileBox);
  let map: OlMap | null = null;
  let ready = false;
  const layerNames: string[] = [];
  let features: () => MapFeatures = () => ({ track: 0, footprints: 0, trackDrawn: 0, footprintsDrawn: 0 });
  let bounds: [number, number, number, number] | null = null;
  let profile: { points: number; valid: number } | null = null;
  window.fmv3dMap = { ready: () => ready, layers: () => layerNames, features: () => features(), bounds: () => bounds,
    profile: () => profile };

  (async () => {
    let geo: Geo;
    try { geo = await api.geo(ws); } catch (e) {
      mapEl.append(h('p', { class: 'muted pad' }, `${ws} is not georeferenced (${e instanceof Error ? e.message : e}).`));
      ready = true; return;
    }
    const code = ensureProjection(geo.epsg);
    const projOk = !!getProjection(code);
    const viewProj = projOk ? code : 'EPSG:3857';
    const toView = (lon: number, lat: number) => transform([lon, lat], 'EPSG:4326', viewProj);

    const layers: (WebGLTileLayer | VectorLayer)[] = [];
    const toggles: HTMLElement[] = [];
    const addToggle = (name: string, layer: WebGLTileLayer | VectorLayer, on = true) => {
      const i = h('input', { type: 'checkbox', checked: on, id: `layer-${name}` });
      layer.setVisible(on);
      i.addEventListener('change', () => layer.setVisible(i.checked));
      toggles.push(h('label', { class: 'inline' }, i, ' ', name));
      layerNames.push(name);
    };

    if (geo.dsm) {
      const range = await dsmRange(fileURL(ws, geo.dsm)).catch(() => null);
      const dsm = new GeoTIFFSource({ sources: [{ url: fileURL(ws, geo.dsm) }], normalize: false, interpolate: false, projection: projOk ? code : undefined });
      const layer = new WebGLTileLayer({ source: dsm, style: hillshadeStyle(range ?? [geo.origin.alt - 50, geo.origin.alt + 50]) });
      layers.push(layer);
      addToggle('DSM hillshade', layer);
      if (range) side.append(h('div', { class: 'ramp-legend' }, h('span', {}, `${fmtNumber(range[0], 1)} m`), h('span', { class: 'ramp' }), h('span', {}, `${fmtNumber(range[1], 1)} m`)));
    }
    if (geo.ortho) {
      const ortho = new GeoTIFFSource({ sources: [{ url: fileURL(ws, geo.ortho) }], projection: projOk ? code : undefined });
      const layer = new WebGLTileLayer({ source: ortho });
      layers.push(layer);
      addToggle('orthophoto', layer);
      const op = h('input', { type: 'range', min: '0', max: '1', step: '0.05', value: '1' });
      op.addEventListener('input', () => layer.setOpacity(Number(op.value)));
      toggles.push(h('label', {}, 'ortho opacity ', op));
    }
    const vec = new VectorSource();
    if (geo.footprints?.length) {
      for (const fp of geo.footprints) {
        const ring = fp.map(([lat, lon]) => toView(lon, lat));
        vec.addFeature(new Feature({ geometry: new Polygon([[...ring, ring[0]]]), kind: 'footprint' }));
      }
    }
    if (geo.track?.length) {
      vec.addFeature(new Feature({ geometry: new LineString(geo.track.map(([lat, lon]) => toView(lon, lat))), kind: 'track' }));
      const [lat0, lon0] = geo.track[0];
      vec.addFeature(new Feature({ geometry: new Point(toView(lon0, lat0)), kind: 'start' }));
    }
    const vecLayer = new VectorLayer({
      source: vec,
      style: (f) => f.get('kind') === 'track' ? new Style({ stroke: new Stroke({ color: '#ffb300', width: 2.5 }) })
        : f.get('kind') === 'start' ? new Style({ image: new CircleStyle({ radius: 5, fill: new Fill({ color: '#ffb300' }) }) })
        : new Style({ stroke: new Stroke({ color: 'rgba(79,195,247,0.7)', width: 1 }), fill: new Fill({ color: 'rgba(79,195,247,0.05)' }) }),
    });
    layers.push(vecLayer);
    const trackLayerToggle = vecLayer;
    addToggle('track and footprints', trackLayerToggle);

    const profSrc = new VectorSource();
    const profLayer = new VectorLayer({ source: profSrc, style: new Style({ stroke: new Stroke({ color: '#ff5252', width: 2.5 }) }) });
    layers.push(profLayer);

    const [w, s, e, n] = geo.bounds_wgs84;
    const extent = boundingExtent([toView(w, s), toView(e, n), toView(w, n), toView(e, s)]);
    map = new OlMap({
      target: mapEl, layers, controls: defaultControls({ attribution: false }).extend([new ScaleLine()]),
      view: new View({ projection: viewProj }),
    });
    map.getView().fit(extent, { padding: [20, 20, 20, 20] });
    bounds = geo.bounds_wgs84;
    // What the vector layer holds, and how much of it is drawn: visible layer, inside the current view.
    features = () => {
      const all = vec.getFeatures();
      const viewExtent = map!.getView().calculateExtent(map!.getSize());
      const shown = vecLayer.getVisible() ? vec.getFeaturesInExtent(viewExtent) : [];
      const count = (fs: Feature[], kind: string) => fs.filter((f) => f.get('kind') === kind).length;
      return { track: count(all, 'track'), footprints: count(all, 'footprint'), trackDrawn: count(shown, 'track'), footprintsDrawn: count(shown, 'footprint') };
    };

    const utmCode = projOk && utmDef(geo.epsg) ? code : ensureProjection(utmZoneOf(geo.origin.lon, geo.origin.lat));
    map.on('pointermove', (ev) => {
      const [lon, lat] = transform(ev.coordinate, viewProj, 'EPSG:4326');
      const [E, N] = transform(ev.coordinate, viewProj, utmCode);
      const zone = Number(utmCode.slice(5)) % 100, hemi = Math.floor(Number(utmCode.slice(5)) / 100) === 326 ? 'N' : 'S';
      coords.textContent = `WGS84 ${lat.toFixed(6)}°, ${lon.toFixed(6)}°  ·  UTM ${zone}${hemi} E ${E.toFixed(1)} N ${N.toFixed(1)}`;
    });

    const drawBtn = h('button', { id: 'draw-profile' }, 'Draw profile line');
    let draw: Draw | null = null;
    // The line's two clicks must not zoom the map as a double click would.
    const dblZoom = map.getInteractions().getArray().find((i) => i instanceof DoubleClickZoom);
    drawBtn.addEventListener('click', () => {
      dblZoom?.setActive(false);
      if (draw) { map!.removeInteraction(draw); draw = null; drawBtn.classList.remove('active'); return; }
      profSrc.clear();
      draw = new Draw({ source: profSrc, type: 'LineString', maxPoints: 2 });
      drawBtn.classList.add('active');
      draw.on('drawend', async (ev) => {
        const line = ev.feature.getGeometry() as LineString;
        const [a, b] = [line.getFirstCoordinate(), line.getLastCoordinate()];
        map!.removeInteraction(draw!); draw = null; drawBtn.classList.remove('active');
        setTimeout(() => dblZoom?.setActive(true), 600);
        profile = await showProfile(ws, transform(a, viewProj, 'EPSG:4326'), transform(b, viewProj, 'EPSG:4326'), profileBox);
      });
      map!.addInteraction(draw);
    });
    side.append(h('h3', {}, 'Layers'), ...toggles, h('h3', {}, 'Height profile'), drawBtn,
      h('p', { class: 'muted' }, 'Click the start and end of the line on the map.'),
      h('h3', {}, 'Georeference'), h('p', {}, `EPSG:${geo.epsg}`), h('p', {}, `origin ${geo.origin.lat.toFixed(6)}°, ${geo.origin.lon.toFixed(6)}°, ${fmtNumber(geo.origin.alt, 1)} m`),
      h('p', {}, `${geo.track?.length ?? 0} track samples, ${geo.footprints?.length ?? 0} footprints`));
    map.once('rendercomplete', () => { ready = true; });
  })().catch((e) => { mapEl.append(h('p', { class: 'error pad' }, String(e))); ready = true; });

  return () => { map?.setTarget(undefined); map?.dispose(); delete window.fmv3dMap; };
}

/** 2nd–98th percentile of the DSM's heights, read from its smallest overview. */
async function dsmRange(url: string): Promise<[number, number]> {
  const tiff = await fromUrl(url, { allowFullFile: false });
  const n = await tiff.getImageCount();
  const img = await tiff.getImage(n - 1);
  const full = await tiff.getImage(0);
  const nodata = full.getGDALNoData();
  const [band] = await img.readRasters({ samples: [0] }) as unknown as ArrayLike<number>[];
  const vals: number[] = [];
  for (let i = 0; i < band.length; i++) {
    const v = band[i];
    if (isFinite(v) && (nodata === null || v !== nodata) && v > -100000) vals.push(v);
  }
  if (vals.length === 0) throw new Error('empty DSM');
  vals.sort((a, b) => a - b);
  return [vals[Math.floor(0.02 * (vals.length - 1))], vals[Math.floor(0.98 * (vals.length - 1))]];
}

/** Hillshade of a single-band elevation COG (sun at 315°, 45°), tinted by height, computed on the GPU. */
function hillshadeStyle([lo, hi]: [number, number]) {
  const dp = ['*', 2, ['resolution']];
  const z = (dx: number, dy: number) => ['band', 1, dx, dy];
  const dzdx = ['/', ['-', z(1, 0), z(-1, 0)], dp];
  const dzdy = ['/', ['-', z(0, 1), z(0, -1)], dp];
  const slope = ['atan', ['sqrt', ['+', ['^', dzdx, 2], ['^', dzdy, 2]]]];
  const aspect = ['clamp', ['atan', ['-', 0, dzdx], dzdy], -Math.PI, Math.PI];
  const el = (45 * Math.PI) / 180, az = (315 * Math.PI) / 180;
  const shade = ['clamp', ['+', ['*', Math.sin(el), ['cos', slope]], ['*', Math.cos(el), ['sin', slope], ['cos', ['-', az, aspect]]]], 0.15, 1];
  const t = ['clamp', ['/', ['-', ['band', 1], lo], Math.max(hi - lo, 1e-6)], 0, 1];
  const r = ['*', 255, shade, ['case', ['<', t, 0.5], ['*', 2, t], 1]];
  const g = ['*', 255, shade, ['case', ['<', t, 0.5], 0.8, ['*', 0.8, ['-', 2, ['*', 2, t]]]]];
  const b = ['*', 255, shade, 0.35];
  const valid = ['all', ['>', ['band', 2], 0], ['>', ['band', 1], -100000]];
  return { color: ['case', valid, ['color', r, g, b, 1], ['color', 0, 0, 0, 0]] } as never;
}

/** Samples the DSM along the line and plots it; returns how many samples came back and how many hit the DSM. */
async function showProfile(ws: string, from: number[], to: number[], box: HTMLElement): Promise<{ points: number; valid: number } | null> {
  box.replaceChildren(h('p', { class: 'muted' }, 'sampling the DSM…'));
  try {
    const p = await api.profile(ws, [from[1], from[0]], [to[1], to[0]], 200);
    const pts = p.points.filter((q) => q.height_m !== null);
    if (pts.length === 0) { box.replaceChildren(h('p', { class: 'muted' }, 'The line does not cross the DSM.')); return { points: p.points.length, valid: 0 }; }
    const hs = pts.map((q) => q.height_m!);
    box.replaceChildren(
      h('h3', {}, `Height profile: ${fmtNumber(p.points[p.points.length - 1].distance_m, 1)} m, heights ${fmtNumber(Math.min(...hs), 1)}–${fmtNumber(Math.max(...hs), 1)} m`),
      lineChart(pts.map((q) => [q.distance_m, q.height_m!]), { xLabel: 'distance along the line (m)', yLabel: 'height (m)', width: 900, height: 220 }));
    return { points: p.points.length, valid: pts.length };
  } catch (e) { box.replaceChildren(h('p', { class: 'error' }, String(e))); return null; }
}
