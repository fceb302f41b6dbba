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
  fs.rmSync(path.join(root, 'fromthepage'), { recursive: true, force: true });

  const port = await freePort();
  server = spawn(fmv3d, ['serve', root, '--port', String(port), '--host', '127.0.0.1', '--assets', webDir],
    { stdio: ['ignore', 'pipe', 'pipe'] });
  const serverLog = fs.createWriteStream(path.join(outDir, 'server.log'));
  server.stdout.pipe(serverLog); server.stderr.pipe(serverLog);
  const base = `http://127.0.0.1:${port}/`;
  for (let i = 0; ; i++) {
    try { const r = await fetch(base + 'api/health'); if (r.ok) break; } catch { /* not up yet */ }
    if (i > 100 || server.exitCode !== null) throw new Error(`fmv3d serve did not come up on ${base} (see server.log)`);
    await new Promise((r) => setTimeout(r, 100));
  }
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

  await check('3D view: colour modes, mesh layer and a camera frame', async () => {
    await page.selectOption('#point-mode', '1');
    await page.evaluate(() => window.fmv3d.idle());
    await shot(page, '3d-normals', '#view3d-canvas');
    await page.selectOption('#point-mode', '0');
    await page.check('#show-mesh');
    await page.uncheck('#show-dense');
    await page.evaluate(() => window.fmv3d.idle());
    const img = await shot(page, '3d-mesh', '#view3d-canvas');
    log(`  mesh-only coverage ${(100 * coverage(img, [0x15, 0x18, 0x1d])).toFixed(1)}%`);
    await page.check('#show-dense');
    await page.uncheck('#show-mesh');
    // Click a camera drawn on the canvas: its frame shows in the side panel.
    const n = await page.evaluate(() => window.fmv3d.stats().cameras);
    let at = null;
    for (let i = 0; i < n && !at; i++) at = await page.evaluate((k) => window.fmv3d.cameraOnScreen(k), i);
    assert(at, 'no camera is on the canvas');
    await page.mouse.click(at.x, at.y);
    await waitFor(page, () => { const im = document.querySelector('#frame-panel img'); return im && im.complete && im.naturalWidth > 0; },
      null, 15000, 'the clicked camera\'s frame');
    await shot(page, '3d-camera-frame');
  });

  await check('map view shows the orthophoto', async () => {
    await page.goto(base + '#/map/demo');
    await waitFor(page, () => window.fmv3dMap && window.fmv3dMap.ready(), null, 60000, 'the map to render');
    const layers = await page.evaluate(() => window.fmv3dMap.layers());
    assert(layers.includes('orthophoto'), `no orthophoto layer (layers: ${layers.join(', ')})`);
    await page.waitForTimeout(1500);
    await shot(page, 'map');
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
    assert(/WGS84 -?\d+\.\d+°, -?\d+\.\d+°.*UTM \d+[NS] E \d+/.test(coords), `coordinates: "${coords}"`);
    await page.click('#draw-profile');
    await page.mouse.click(box.x + box.width * 0.35, box.y + box.height * 0.5);
    await page.mouse.click(box.x + box.width * 0.65, box.y + box.height * 0.5);
    await waitFor(page, () => document.querySelector('#profile svg polyline'), null, 20000, 'the profile plot');
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
