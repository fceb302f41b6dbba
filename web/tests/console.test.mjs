#!/usr/bin/env node
// Browser tests of the operator console: Debian's Chromium (headless, driven by playwright-core) against
// `fmv3d serve` on a random loopback port, with a small synthetic georeferenced workspace made here.
//
//   node web/tests/console.test.mjs --fmv3d build/fmv3d --web build/web [--out build/test-artefacts/web] [--keep]
//
// Exit 0: every check passed; 1: a check failed; 77: skipped (no Chromium, no web build or no playwright-core).
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import net from 'node:net';
import { spawn, execFileSync } from 'node:child_process';
import { fileURLToPath } from 'node:url';
import { decodePng, coverage, distinctColours } from './png.mjs';

const SKIP = 77;
const here = path.dirname(fileURLToPath(import.meta.url));
const args = process.argv.slice(2);
const opt = (name, def) => { const i = args.indexOf(name); return i >= 0 ? args[i + 1] : def; };
const fmv3d = path.resolve(opt('--fmv3d', path.join(here, '../../build/fmv3d')));
const webDir = path.resolve(opt('--web', path.join(path.dirname(fmv3d), 'web')));
const outDir = path.resolve(opt('--out', path.join(path.dirname(fmv3d), 'test-artefacts/web')));
const chromiumPath = opt('--chromium', process.env.CHROMIUM ?? '/usr/bin/chromium');
const keep = args.includes('--keep');

function skip(why) { console.log(`SKIP: ${why}`); process.exit(SKIP); }
if (!fs.existsSync(chromiumPath)) skip(`no Chromium at ${chromiumPath} (scripts/install-deps.sh installs it)`);
if (!fs.existsSync(path.join(webDir, 'index.html'))) skip(`no web build at ${webDir} (make web)`);
if (!fs.existsSync(fmv3d)) skip(`no fmv3d binary at ${fmv3d}`);
let chromium;
try { ({ chromium } = await import('playwright-core')); } catch { skip('playwright-core is not installed (cd web && npm ci)'); }

fs.mkdirSync(outDir, { recursive: true });
// --work DIR reuses a work folder left by --keep (its workspace is not made again).
const root = opt('--work') ? path.resolve(opt('--work')) : fs.mkdtempSync(path.join(os.tmpdir(), 'fmv3d-console-'));
const results = [];
let server = null, context = null;
const log = (...a) => console.log(...a);

function run(argv, timeoutMs = 600000) {
  const t0 = Date.now();
  execFileSync(fmv3d, argv, { stdio: ['ignore', 'ignore', 'inherit'], timeout: timeoutMs });
  log(`  fmv3d ${argv.join(' ')}  (${((Date.now() - t0) / 1000).toFixed(1)} s)`);
}
function freePort() {
  return new Promise((resolve, reject) => {
    const s = net.createServer();
    s.listen(0, '127.0.0.1', () => { const p = s.address().port; s.close(() => resolve(p)); });
    s.on('error', reject);
  });
}
async function check(name, fn) {
  const t0 = Date.now();
  try { await fn(); results.push([name, true]); log(`ok   ${name} (${((Date.now() - t0) / 1000).toFixed(1)} s)`); }
  catch (e) { results.push([name, false]); log(`FAIL ${name}: ${e?.stack ?? e}`); }
}
function assert(cond, msg) { if (!cond) throw new Error(msg); }
async function waitFor(page, fn, arg, timeout, what) {
  try { await page.waitForFunction(fn, arg, { timeout, polling: 200 }); }
  catch (e) { throw new Error(`timed out waiting for ${what}`); }
}
/** Mean colour of the pixels that differ from the background. */
function meanColour(img, bg, tol = 12) {
  let n = 0; const m = [0, 0, 0];
  for (let i = 0; i < img.width * img.height; i++) {
    const r = img.data[4 * i], g = img.data[4 * i + 1], b = img.data[4 * i + 2];
    if (Math.abs(r - bg[0]) <= tol && Math.abs(g - bg[1]) <= tol && Math.abs(b - bg[2]) <= tol) continue;
    m[0] += r; m[1] += g; m[2] += b; n++;
  }
  return n ? m.map((v) => v / n) : [0, 0, 0];
}
async function shot(page, name, selector) {
  const file = path.join(outDir, `${name}.png`);
  const buf = selector ? await page.locator(selector).screenshot({ path: file }) : await page.screenshot({ path: file });
  return decodePng(buf);
}

try {
  // A small synthetic flight with KLV telemetry, reconstructed and tiled: the workspace the pages show.
  log(`work folder ${root}`);
  const inputs = path.join(root, 'inputs');
  const ws = path.join(root, 'demo');
  if (!fs.existsSync(path.join(ws, 'tiles', 'tileset.json'))) {
  run(['-q', 'synth', '--scene', 'building', '--path', 'orbit', '--frames', '90', '--fps', '15', '--size', '480x270',
    '--klv', '--seed', '5', '-o', inputs]);
  run(['-q', 'reconstruct', path.join(inputs, 'flight.ts'), '-o', ws, '--fast']);
  if (!fs.existsSync(path.join(ws, 'tiles', 'tileset.json'))) run(['-q', 'tiles', ws]);
  }
  // A CAD comparison in the workspace: the building's CAD model, aligned through the truth cameras.
  if (!fs.existsSync(path.join(ws, 'report', 'compare', 'cad_error.ply'))) {
    run(['-q', 'evaluate-sparse', ws, '--truth', path.join(inputs, 'truth')]);
    run(['-q', 'compare', path.join(ws, 'dense', 'fused.ply'), '--cad', path.join(here, '../../data/scenes/building.obj'),
      '--length', '30', '--transform', path.join(ws, 'report', 'sparse_eval.json'), '-o', path.join(ws, 'report', 'compare')]);
  }
  fs.rmSync(path.join(root, 'fromthepage'), { recursive: true, force: true });

  const port = await freePort();
  const serverLog = fs.createWriteStream(path.join(outDir, 'server.log'));
  const base = `http://127.0.0.1:${port}/`;
  const startServer = async () => {
    server = spawn(fmv3d, ['serve', root, '--port', String(port), '--host', '127.0.0.1', '--assets', webDir],
      { stdio: ['ignore', 'pipe', 'pipe'] });
    server.stdout.pipe(serverLog, { end: false }); server.stderr.pipe(serverLog, { end: false });
    for (let i = 0; ; i++) {
      try { const r = await fetch(base + 'api/health'); if (r.ok) break; } catch { /* not up yet */ }
      if (i > 100 || server.exitCode !== null) throw new Error(`fmv3d serve did not come up on ${base} (see server.log)`);
      await new Promise((r) => setTimeout(r, 100));
    }
  };
  await startServer();
  log(`fmv3d serve at ${base}`);

  const profile = fs.mkdtempSync(path.join(os.tmpdir(), 'fmv3d-chromium-'));
  context = await chromium.launchPersistentContext(profile, {
    executablePath: chromiumPath, headless: true, viewport: { width: 1280, height: 800 },
    args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run', '--disable-background-networking',
      '--disable-component-update', '--disable-sync', '--use-angle=swiftshader', '--enable-unsafe-swiftshader'],
  });
  const page = context.pages()[0] ?? await context.newPage();
  const foreign = [];
  const consoleErrors = [];
  context.on('request', (r) => {
    const u = r.url();
    if (!(u.startsWith(base) || u.startsWith('data:') || u.startsWith('blob:'))) foreign.push(u);
  });
  page.on('console', (m) => { if (m.type() === 'error') consoleErrors.push(m.text()); });
  page.on('pageerror', (e) => consoleErrors.push(String(e)));

  // A job started from the Jobs page; it runs while the other pages are checked.
  let jobId = null;
  await check('jobs page starts a reconstruction', async () => {
    await page.goto(base + '#/jobs');
    await waitFor(page, () => document.querySelector('tr[data-ws="demo"]'), null, 15000, 'the demo workspace in the table');
    await page.fill('#new-job input[name=workspace]', 'fromthepage');
    // The video goes up through the page's upload field (the server keeps it under the workspace's uploads/).
    await page.setInputFiles('#new-job input[type=file]', path.join(inputs, 'flight.ts'));
    await page.check('#new-job input[name=fast]');
    await page.selectOption('#new-job select[name=until]', 'sparse');
    await page.click('#start-job');
    await waitFor(page, () => document.querySelector('.job[data-job]'), null, 15000, 'the job to appear');
    jobId = await page.getAttribute('.job[data-job]', 'data-job');
    await shot(page, 'jobs-running');
  });

  await check('3D view draws the model and fit view frames it', async () => {
    await page.goto(base + '#/3d/demo');
    await waitFor(page, () => window.fmv3d && window.fmv3d.stats().ready && window.fmv3d.stats().drawnPoints > 0, null, 60000, 'points drawn');
    await page.evaluate(() => window.fmv3d.fitView());
    await page.evaluate(() => window.fmv3d.idle());
    const stats = await page.evaluate(() => window.fmv3d.stats());
    log(`  3D stats ${JSON.stringify(stats)}`);
    assert(stats.drawnPoints > 0, 'no point drawn');
    assert(stats.densePoints > 0, 'no dense point drawn from the 3D Tiles');
    assert(stats.cameras > 0, 'no camera drawn');
    const img = await shot(page, '3d-canvas', '#view3d-canvas');
    await shot(page, '3d-view');
    const cov = coverage(img, [0x15, 0x18, 0x1d]);
    const colours = distinctColours(img);
    log(`  3D canvas coverage after fit view ${(100 * cov).toFixed(1)}%, ${colours} colours`);
    assert(colours > 20, `the canvas looks blank (${colours} colours)`);
    assert(cov >= 0.30, `the model covers ${(100 * cov).toFixed(1)}% of the canvas after fit view (< 30%)`);
  });

  const BG = [0x15, 0x18, 0x1d];
  await check('3D view: the dense cloud in every colour mode, each with its legend', async () => {
    await page.uncheck('#show-cad');
    const means = {};
    for (const [value, name] of [['0', 'colour'], ['1', 'normal'], ['2', 'views'], ['4', 'confidence'], ['3', 'height']]) {
      await page.selectOption('#point-mode', value);
      await page.evaluate(() => window.fmv3d.idle());
      const img = await shot(page, `3d-${name}`, '#view3d-canvas');
      const cov = coverage(img, BG), colours = distinctColours(img);
      means[name] = meanColour(img, BG);
      const missing = await page.$('#legend-missing');
      const legend = await page.$('#legend-points');
      log(`  ${name}: ${(100 * cov).toFixed(1)}% covered, ${colours} colours, mean ${means[name].map((v) => v.toFixed(0)).join(',')}`);
      assert(cov >= 0.3 && colours > 20, `${name} mode draws nothing (${(100 * cov).toFixed(1)}%, ${colours} colours)`);
      assert(!missing, `${name} mode: ${missing && await missing.textContent()}`);
      if (name !== 'colour' && name !== 'normal') assert(legend, `${name} mode has no colour bar`);
    }
    for (const name of ['normal', 'views', 'confidence', 'height']) {
      const d = Math.hypot(...means[name].map((v, k) => v - means.colour[k]));
      assert(d > 8, `${name} mode looks like colour mode (mean colour differs by ${d.toFixed(1)})`);
    }
    await page.selectOption('#point-mode', '0');
  });

  await check('3D view: the CAD model with the comparison\'s error colours and its colour bar', async () => {
    await page.check('#show-cad');
    await page.uncheck('#show-dense');
    await page.uncheck('#show-sparse');
    await page.uncheck('#show-cameras');
    await page.click('#fit-view');
    await page.evaluate(() => window.fmv3d.idle());
    const stats = await page.evaluate(() => window.fmv3d.stats());
    log(`  CAD: ${stats.cadTriangles} triangles, ${stats.cadCoveredPercent?.toFixed(1)}% of its vertices near a point`);
    assert(stats.cadTriangles > 1000, `no CAD model drawn (${stats.cadTriangles} triangles)`);
    const legend = await page.textContent('#legend-cad');
    assert(/% of H/.test(legend), `no CAD colour bar: "${legend}"`);
    const img = await shot(page, '3d-cad', '#view3d-canvas');
    // Error colours: reds and blues, not just the grey of unknown vertices.
    let warm = 0, cold = 0;
    for (let i = 0; i < img.width * img.height; i++) {
      const r = img.data[4 * i], g = img.data[4 * i + 1], b = img.data[4 * i + 2];
      if (r > b + 30 && r > g + 20) warm++;
      if (b > r + 30 && b > g + 10) cold++;
    }
    const cov = coverage(img, BG);
    log(`  CAD pixels: ${warm} red-ish, ${cold} blue-ish; fit view puts it over ${(100 * cov).toFixed(1)}% of the canvas`);
    assert(cov >= 0.2, `fit view on the CAD alone covers ${(100 * cov).toFixed(1)}% of the canvas`);
    assert(warm > 200 && cold > 200, `the CAD shows no error colours (${warm} red, ${cold} blue pixels)`);
    await shot(page, '3d-cad-view');
    await page.check('#show-dense');
    await page.check('#show-sparse');
    await page.check('#show-cameras');
    await page.uncheck('#show-cad');
    await page.click('#fit-view');
  });

  await check('3D view: mesh layer, and cameras coloured by error open their frame on click', async () => {
    await page.check('#show-mesh');
    await page.uncheck('#show-dense');
    await page.evaluate(() => window.fmv3d.idle());
    const img = await shot(page, '3d-mesh', '#view3d-canvas');
    log(`  mesh-only coverage ${(100 * coverage(img, BG)).toFixed(1)}%`);
    await page.check('#show-dense');
    await page.uncheck('#show-mesh');
    const cams = await page.evaluate(async () => (await (await fetch('api/workspaces/demo/cameras')).json()));
    const range = await page.evaluate(() => window.fmv3d.stats().cameraErrorRange);
    const worst = Math.max(...cams.map((c) => c.reprojection_rms_px ?? 0));
    assert(range && range[1] >= worst - 1e-9, `the frusta's colour scale ${JSON.stringify(range)} does not reach the worst camera (${worst} px)`);
    assert(await page.$('#legend-cameras'), 'no colour bar for the cameras');
    // Click a camera drawn on the canvas: its frame shows in the side panel, with its own error.
    let at = null, k = 0;
    for (; k < cams.length && !at; k++) at = await page.evaluate((i) => window.fmv3d.cameraOnScreen(i), k);
    assert(at, 'no camera is on the canvas');
    await page.mouse.click(at.x, at.y);
    await waitFor(page, () => { const im = document.querySelector('#frame-panel img'); return im && im.complete && im.naturalWidth > 0; },
      null, 15000, 'the clicked camera\'s frame');
    const panel = await page.textContent('#frame-panel');
    const cam = cams[k - 1];
    assert(panel.includes(cam.name), `the panel shows "${panel.slice(0, 80)}", not camera ${cam.name}`);
    // The panel rounds to three significant digits below 1 px, to two decimals above: read its number back.
    const shown = /reprojection RMS ([0-9.,]+) px/.exec(panel);
    assert(shown && Math.abs(Number(shown[1].replace(/,/g, '')) - cam.reprojection_rms_px) <= 0.005,
      `the panel shows "${shown?.[0]}", not ${cam.name}'s error ${cam.reprojection_rms_px} px`);
    await shot(page, '3d-camera-frame');
  });

  await check('3D view: measure distance, height and area on the model, in metres', async () => {
    await page.evaluate(() => window.fmv3d.fitView());
    await page.evaluate(() => window.fmv3d.idle());
    const box = await page.locator('#view3d-canvas').boundingBox();
    const px = (fx, fy) => ({ x: box.x + box.width * fx, y: box.y + box.height * fy });
    const near = (p, q) => Math.hypot(p.x - q.x, p.y - q.y) < 8;
    const k = await page.evaluate(() => window.fmv3d.stats().metresPerUnit);
    assert(k > 0, `no metric scale on a georeferenced workspace (${k})`);
    for (const [mode, clicks] of [['distance', [[0.3, 0.5], [0.7, 0.5]]], ['height', [[0.5, 0.45], [0.3, 0.7]]],
      ['area', [[0.35, 0.35], [0.65, 0.35], [0.65, 0.65], [0.35, 0.65]]]]) {
      await page.click(`[data-measure="${mode}"]`);
      const pts = clicks.map(([fx, fy]) => px(fx, fy));
      for (const p of pts) { await page.mouse.click(p.x, p.y); await page.waitForTimeout(350); }
      if (mode === 'area') await page.mouse.dblclick(pts[0].x + 1, pts[0].y + 1);
      await page.evaluate(() => window.fmv3d.idle());
      const m = await page.evaluate(() => window.fmv3d.measured());
      const out = await page.textContent('#measure-out');
      log(`  ${mode}: ${out}`);
      assert(m && m.mode === mode, `no ${mode} measured ("${out}")`);
      // Every picked point lies on the model under its click.
      pts.forEach((p, i) => assert(near(m.points[i], p), `${mode}: point ${i} picked at ${JSON.stringify(m.points[i])}, clicked ${JSON.stringify(p)}`));
      assert(/ m/.test(out), `${mode} is not in metres: "${out}"`);
      if (mode === 'distance') assert(m.value > 1 && m.value < 1000, `distance ${m.value} m`);
      if (mode === 'height') assert(Math.abs(m.value) < 1000, `height ${m.value} m`);
      if (mode === 'area') assert(m.value > 1, `area ${m.value} m²`);
      await shot(page, `3d-measure-${mode}`);
    }
    await page.click('[data-measure="distance"]');
    await page.click('button:text-is("clear")');
  });

  await check('3D view: fly controls move and turn the camera, orbit comes back', async () => {
    await page.selectOption('#nav-mode', 'fly');
    const before = await page.evaluate(() => window.fmv3d.cameraPose());
    await page.locator('#view3d-canvas').focus();
    await page.keyboard.down('w');
    await page.waitForTimeout(600);
    await page.keyboard.up('w');
    const moved = await page.evaluate(() => window.fmv3d.cameraPose());
    const d = before.position.map((v, i) => moved.position[i] - v);
    const along = d.reduce((s, v, i) => s + v * before.direction[i], 0), len = Math.hypot(...d);
    log(`  W for 0.6 s moved ${len.toFixed(3)} units, ${(along / len).toFixed(3)} of it forward`);
    assert(len > 0 && along / len > 0.95, `W did not move the camera forward (moved ${len}, forward share ${along / len})`);
    const box = await page.locator('#view3d-canvas').boundingBox();
    await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
    await page.mouse.down();
    await page.mouse.move(box.x + box.width / 2 + 120, box.y + box.height / 2 + 40, { steps: 6 });
    await page.mouse.up();
    const turned = await page.evaluate(() => window.fmv3d.cameraPose());
    const cos = turned.direction.reduce((s, v, i) => s + v * moved.direction[i], 0);
    assert(cos < 0.99, `dragging did not turn the view (cos ${cos})`);
    await shot(page, '3d-fly');
    await page.selectOption('#nav-mode', 'orbit');
    const st = await page.evaluate(() => window.fmv3d.stats());
    assert(st.navigation === 'orbit', 'orbit controls did not come back');
    await page.evaluate(() => window.fmv3d.fitView());
  });

  await check('map view shows the orthophoto', async () => {
    await page.goto(base + '#/map/demo');
    await waitFor(page, () => window.fmv3dMap && window.fmv3dMap.ready(), null, 60000, 'the map to render');
    const layers = await page.evaluate(() => window.fmv3dMap.layers());
    assert(layers.includes('orthophoto'), `no orthophoto layer (layers: ${layers.join(', ')})`);
    await page.waitForTimeout(1500);
    const f = await page.evaluate(() => window.fmv3dMap.features());
    log(`  map features ${JSON.stringify(f)}`);
    assert(f.trackDrawn > 0 && f.footprintsDrawn > 0, `the flight track / frame footprints are not drawn (${JSON.stringify(f)})`);
    const withVectors = await shot(page, 'map');
    // The track and footprints change the picture: toggled off, fewer pixels are of their colours.
    const tinted = (img) => { let n = 0; for (let i = 0; i < img.width * img.height; i++) {
      const r = img.data[4 * i], g = img.data[4 * i + 1], b = img.data[4 * i + 2];
      if ((r > 200 && g > 140 && g < 200 && b < 60) || (b > 180 && g > 150 && r < 120)) n++; } return n; };
    await page.uncheck('#layer-track\\ and\\ footprints');
    await page.waitForTimeout(800);
    const without = await shot(page, 'map-no-vectors');
    await page.check('#layer-track\\ and\\ footprints');
    log(`  track/footprint-coloured pixels: ${tinted(withVectors)} with the layer, ${tinted(without)} without`);
    assert(tinted(withVectors) > tinted(without) + 200, 'the track and footprints do not show on the map');
    // The ortho alone: hillshade and vectors off.
    for (const id of ['#layer-DSM\\ hillshade', '#layer-track\\ and\\ footprints']) if (await page.$(id)) await page.uncheck(id);
    await page.waitForTimeout(1500);
    const img = await shot(page, 'map-ortho', '#map');
    const cov = coverage(img, [0x1b, 0x1f, 0x24]);
    log(`  ortho covers ${(100 * cov).toFixed(1)}% of the map, ${distinctColours(img)} colours`);
    assert(cov > 0.05 && distinctColours(img) > 50, `the map shows no orthophoto (${(100 * cov).toFixed(1)}% covered)`);
    for (const id of ['#layer-DSM\\ hillshade', '#layer-track\\ and\\ footprints']) if (await page.$(id)) await page.check(id);
  });

  await check('map view: height profile and coordinates under the cursor', async () => {
    const box = await page.locator('#map').boundingBox();
    await page.mouse.move(box.x + box.width * 0.5, box.y + box.height * 0.5);
    const coords = await page.textContent('#map-coords');
    const m = /WGS84 (-?\d+\.\d+)°, (-?\d+\.\d+)°.*UTM (\d+)([NS]) E (\d+\.\d) N (\d+\.\d)/.exec(coords);
    assert(m, `coordinates: "${coords}"`);
    const [w, s, e, n] = await page.evaluate(() => window.fmv3dMap.bounds());
    const lat = Number(m[1]), lon = Number(m[2]), E = Number(m[5]);
    assert(lat > s - 0.01 && lat < n + 0.01 && lon > w - 0.01 && lon < e + 0.01, `cursor at ${lat}, ${lon}: outside the workspace ${[w, s, e, n]}`);
    assert(Number(m[3]) === Math.floor((lon + 180) / 6) + 1 && m[4] === (lat >= 0 ? 'N' : 'S'), `UTM zone ${m[3]}${m[4]} for ${lat}, ${lon}`);
    // 100 px to the right: longitude and easting grow, by the same ground distance.
    await page.mouse.move(box.x + box.width * 0.5 + 100, box.y + box.height * 0.5);
    const m2 = /WGS84 (-?\d+\.\d+)°, (-?\d+\.\d+)°.*E (\d+\.\d)/.exec(await page.textContent('#map-coords'));
    const dE = Number(m2[3]) - E, dLonM = (Number(m2[2]) - lon) * 111320 * Math.cos((lat * Math.PI) / 180);
    log(`  ${coords}; 100 px right: ΔE ${dE.toFixed(2)} m, Δlon ${dLonM.toFixed(2)} m`);
    assert(dE > 0 && Math.abs(dE - dLonM) < 0.05 * dE + 0.5, `easting moved ${dE} m, longitude ${dLonM} m`);
    await page.click('#draw-profile');
    await page.mouse.click(box.x + box.width * 0.35, box.y + box.height * 0.5);
    await page.mouse.click(box.x + box.width * 0.65, box.y + box.height * 0.5);
    await waitFor(page, () => document.querySelector('#profile svg polyline'), null, 20000, 'the profile plot');
    const prof = await page.evaluate(() => window.fmv3dMap.profile());
    const head = await page.textContent('#profile h3');
    log(`  profile ${JSON.stringify(prof)}: ${head}`);
    assert(prof && prof.valid >= 0.5 * prof.points && prof.points >= 100, `the profile has ${JSON.stringify(prof)} samples on the DSM`);
    await shot(page, 'map-profile');
  });

  await check('report page shows its figures', async () => {
    await page.goto(base + '#/report/demo');
    await waitFor(page, () => document.querySelector('#report[data-figures]'), null, 30000, 'the report');
    const n = await page.evaluate(() => Number(document.querySelector('#report').dataset.figures));
    const marks = await page.evaluate(() => document.querySelectorAll('#report svg rect, #report svg polyline').length);
    const title = await page.evaluate(() => [...document.querySelectorAll('#report figcaption')].map((f) => f.textContent).join(' | '));
    log(`  report: ${n} plots, ${marks} marks: ${title.slice(0, 300)}`);
    assert(n >= 3 && marks >= 10, `the report shows ${n} plots with ${marks} marks`);
    assert(/Time per stage/.test(title) && /reprojection/i.test(title), 'the stage times or reprojection plots are missing');
    assert(/Errors against the CAD model/.test(title), 'the CAD comparison plot is missing');
    await page.screenshot({ path: path.join(outDir, 'report.png'), fullPage: true });
  });

  await check('the job started from the page completes, its progress seen live and after a reload', async () => {
    assert(jobId, 'no job was started');
    await page.goto(base + '#/jobs');
    await waitFor(page, (id) => { const e = document.querySelector(`.job[data-job="${id}"]`); return e && e.dataset.state !== 'running' && e.dataset.state !== 'queued'; },
      jobId, 900000, 'the job to finish');
    const state = await page.getAttribute(`.job[data-job="${jobId}"]`, 'data-state');
    const seen = Number(await page.getAttribute(`.job[data-job="${jobId}"]`, 'data-progress-events'));
    await shot(page, 'jobs-done');
    log(`  job ${jobId}: ${state}, ${seen} progress events seen by this page load`);
    assert(state === 'done', `job ended ${state}`);
    // The tabs change the URL's hash only (no reload), so these are the job's events as the page received them.
    assert(seen > 0, 'no progress event was seen by the page');
    await page.reload();
    await waitFor(page, (id) => document.querySelector(`.job[data-job="${id}"][data-state="done"]`), jobId, 15000, 'the finished job after a reload');
    const bars = await page.evaluate((id) => [...document.querySelectorAll(`.job[data-job="${id}"] .bar.done`)].length, jobId);
    assert(bars >= 4, `only ${bars} stage bars done after the reload`);
  });

  await check('the finished job is still listed after the server restarts', async () => {
    assert(jobId, 'no job was started');
    const stopped = new Promise((r) => server.once('exit', r));
    const errorsBefore = consoleErrors.length;
    server.kill('SIGTERM');
    await stopped;
    await startServer();
    await page.goto(base + '#/jobs');
    // The open event stream is cut by the restart (and its reconnection refused while the server is down):
    // those network errors are the point of this check, not page errors.
    const cut = consoleErrors.splice(errorsBefore).filter((e) => !/ERR_INCOMPLETE_CHUNKED_ENCODING|ERR_CONNECTION_REFUSED/.test(e));
    consoleErrors.push(...cut);
    await waitFor(page, (id) => document.querySelector(`.job[data-job="${id}"][data-state="done"]`), jobId, 20000, 'the job after the restart');
    const bars = await page.evaluate((id) => [...document.querySelectorAll(`.job[data-job="${id}"] .bar.done`)].length, jobId);
    assert(bars >= 4, `only ${bars} stage bars done after the restart`);
    await shot(page, 'jobs-after-restart');
  });

  await check('every request went to the loopback origin, no page error', async () => {
    assert(foreign.length === 0, `requests left the machine: ${foreign.slice(0, 5).join(', ')}`);
    const errs = consoleErrors.filter((e) => !/favicon/.test(e));
    if (errs.length) log(`  console errors: ${errs.slice(0, 5).join(' | ')}`);
    assert(errs.length === 0, `${errs.length} page errors`);
  });
} catch (e) {
  results.push(['setup', false]);
  log(`FAIL setup: ${e?.stack ?? e}`);
} finally {
  await context?.close().catch(() => undefined);
  if (server && server.exitCode === null) server.kill('SIGTERM');
  if (!keep && !opt('--work')) fs.rmSync(root, { recursive: true, force: true });
}
const passed = results.filter(([, ok]) => ok).length, failed = results.length - passed;
log(`artefacts in ${outDir}`);
log(`${passed} passed, ${failed} failed`);
process.exit(failed ? 1 : 0);
