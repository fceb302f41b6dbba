#!/usr/bin/env node
// Console bench: tile writing time, time to first picture and browser memory for big dense clouds.
// A synthetic terrain cloud of N points (fused.ply with normals, colours and visibility) is written to a
// workspace, tiled by `fmv3d tiles`, served by `fmv3d serve` and opened in headless Chromium.
//
//   node bench/console_web.mjs --fmv3d build/fmv3d --web build/web --points 1000000,10000000 [--root DIR]
//
// Prints one JSON line per cloud; bench/results/console-web.md keeps the figures.
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import net from 'node:net';
import { spawn, execFileSync } from 'node:child_process';
import { createRequire } from 'node:module';
import { fileURLToPath } from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));
const require = createRequire(path.join(here, '../web/package.json'));
const { chromium } = require('playwright-core');
const args = process.argv.slice(2);
const opt = (n, d) => { const i = args.indexOf(n); return i >= 0 ? args[i + 1] : d; };
const fmv3d = path.resolve(opt('--fmv3d', 'build/fmv3d'));
const web = path.resolve(opt('--web', 'build/web'));
const sizes = opt('--points', '1000000,10000000').split(',').map(Number);
const root = path.resolve(opt('--root', fs.mkdtempSync(path.join(os.tmpdir(), 'fmv3d-bench-console-'))));
const runs = Number(opt('--runs', '3'));

/** A rolling 1 km terrain sampled on a jittered grid: heights, analytic normals, colours by height and pattern. */
function writeCloud(file, n) {
  const side = Math.ceil(Math.sqrt(n)), L = 1000;
  const header = Buffer.from('ply\nformat binary_little_endian 1.0\ncomment fmv3d bench terrain\n' +
    `element vertex ${n}\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\n` +
    'property float nz\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nproperty list uchar int visibility\nend_header\n');
  const fd = fs.openSync(file, 'w');
  fs.writeSync(fd, header);
  const rec = 12 + 12 + 3 + 1 + 3 * 4;
  const chunk = 1 << 16;
  let seed = 12345;
  const rnd = () => ((seed = (seed * 1103515245 + 12345) & 0x7fffffff) / 0x7fffffff);
  for (let start = 0; start < n; start += chunk) {
    const m = Math.min(chunk, n - start);
    const b = Buffer.alloc(m * rec);
    for (let k = 0; k < m; k++) {
      const i = start + k, gx = i % side, gy = Math.floor(i / side);
      const x = ((gx + rnd()) / side) * L, y = ((gy + rnd()) / side) * L;
      const z = 30 * Math.sin(x / 130) * Math.cos(y / 170) + 8 * Math.sin(x / 23 + y / 31);
      const dzdx = (30 / 130) * Math.cos(x / 130) * Math.cos(y / 170) + (8 / 23) * Math.cos(x / 23 + y / 31);
      const dzdy = (-30 / 170) * Math.sin(x / 130) * Math.sin(y / 170) + (8 / 31) * Math.cos(x / 23 + y / 31);
      const nl = Math.hypot(dzdx, dzdy, 1);
      const t = (z + 38) / 76, stripe = ((Math.floor(x / 20) + Math.floor(y / 20)) & 1) ? 0.9 : 1;
      let o = k * rec;
      b.writeFloatLE(x, o); b.writeFloatLE(y, o + 4); b.writeFloatLE(z, o + 8);
      b.writeFloatLE(-dzdx / nl, o + 12); b.writeFloatLE(-dzdy / nl, o + 16); b.writeFloatLE(1 / nl, o + 20);
      b[o + 24] = Math.round(255 * stripe * (0.35 + 0.5 * t)); b[o + 25] = Math.round(255 * stripe * (0.55 + 0.25 * t)); b[o + 26] = Math.round(255 * stripe * (0.3 + 0.2 * (1 - t)));
      b[o + 27] = 3; o += 28;
      for (let v = 0; v < 3; v++) b.writeInt32LE(Math.floor(rnd() * 200), o + 4 * v);
    }
    fs.writeSync(fd, b);
  }
  fs.closeSync(fd);
}

const freePort = () => new Promise((res) => { const s = net.createServer(); s.listen(0, '127.0.0.1', () => { const p = s.address().port; s.close(() => res(p)); }); });

const results = [];
for (const n of sizes) {
  const name = `cloud${n >= 1e6 ? n / 1e6 + 'm' : n}`;
  const ws = path.join(root, name);
  fs.mkdirSync(path.join(ws, 'dense'), { recursive: true });
  // A workspace to the server: a project.json (no inputs: the cloud is all it has).
  fs.writeFileSync(path.join(ws, 'project.json'), JSON.stringify({ inputs: [] }));
  if (!fs.existsSync(path.join(ws, 'dense/fused.ply'))) writeCloud(path.join(ws, 'dense/fused.ply'), n);
  let t0 = Date.now();
  execFileSync(fmv3d, ['-q', 'tiles', ws], { stdio: 'inherit' });
  const tileS = (Date.now() - t0) / 1000;
  const tileBytes = execFileSync('du', ['-sb', path.join(ws, 'tiles')]).toString().split('\t')[0];

  const port = await freePort();
  const server = spawn(fmv3d, ['serve', root, '--port', String(port), '--assets', web], { stdio: 'ignore' });
  const base = `http://127.0.0.1:${port}/`;
  for (let i = 0; i < 100; i++) { try { if ((await fetch(base + 'api/health')).ok) break; } catch { /* starting */ } await new Promise((r) => setTimeout(r, 100)); }
  const firsts = [], heaps = [], rsss = [], sinceLoad = [];
  let last = null;
  for (let r = 0; r < runs; r++) {
    const profile = fs.mkdtempSync(path.join(os.tmpdir(), 'fmv3d-bench-chr-'));
    const ctx = await chromium.launchPersistentContext(profile, { executablePath: '/usr/bin/chromium', headless: true, viewport: { width: 1280, height: 800 },
      args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run', '--disable-background-networking',
        '--disable-component-update', '--disable-sync', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--enable-precise-memory-info'] });
    const page = ctx.pages()[0] ?? await ctx.newPage();
    const cdp = await ctx.newCDPSession(page);
    await cdp.send('Performance.enable');
    await page.goto(base + `#/3d/${name}`);
    await page.waitForFunction(() => window.fmv3d?.stats().firstPictureMs != null, null, { timeout: 120000, polling: 20 });
    const first = await page.evaluate(() => window.fmv3d.stats().firstPictureMs);
    const firstSinceLoad = await page.evaluate(() => window.fmv3d.stats().firstPictureSinceLoadMs);
    await page.evaluate(() => window.fmv3d.idle());
    // A tour: zoom in towards the ground and orbit, so finer tiles are loaded and older ones evicted.
    const box = await page.locator('#view3d-canvas').boundingBox();
    let peak = 0, peakRss = 0;
    // The browser's whole memory: resident set of every Chromium process of this profile (renderer, GPU, browser).
    const browserRss = () => {
      let kb = 0;
      for (const pid of fs.readdirSync('/proc').filter((d) => /^\d+$/.test(d))) {
        try {
          if (!fs.readFileSync(`/proc/${pid}/cmdline`, 'utf8').includes(profile)) continue;
          const m = /VmRSS:\s+(\d+)/.exec(fs.readFileSync(`/proc/${pid}/status`, 'utf8'));
          if (m) kb += Number(m[1]);
        } catch { /* gone */ }
      }
      return kb * 1024;
    };
    const heap = async () => { const m = (await cdp.send('Performance.getMetrics')).metrics; return m.find((x) => x.name === 'JSHeapUsedSize').value; };
    peakRss = browserRss();
    for (let step = 0; step < 8; step++) {
      await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
      await page.mouse.wheel(0, -300);
      await page.mouse.down(); await page.mouse.move(box.x + box.width / 2 + 60, box.y + box.height / 2, { steps: 3 }); await page.mouse.up();
      await page.evaluate(() => window.fmv3d.idle());
      peak = Math.max(peak, await heap());
      peakRss = Math.max(peakRss, browserRss());
    }
    const stats = await page.evaluate(() => window.fmv3d.stats());
    const pm = await page.evaluate(() => performance.memory ? performance.memory.usedJSHeapSize : null);
    last = { ...stats, jsHeapAfterTour: await heap(), performanceMemory: pm };
    firsts.push(first); heaps.push(peak); rsss.push(peakRss);
    sinceLoad.push(firstSinceLoad);
    await ctx.close();
    fs.rmSync(profile, { recursive: true, force: true });
  }
  server.kill('SIGTERM');
  const med = (v) => [...v].sort((a, b) => a - b)[Math.floor(v.length / 2)];
  const res = { points: n, tile_write_s: tileS, tiles_bytes: Number(tileBytes), first_picture_ms_median: Math.round(med(firsts)),
    first_picture_ms_runs: firsts.map(Math.round), first_picture_since_page_load_ms_median: Math.round(med(sinceLoad)),
    js_heap_peak_mb_median: +(med(heaps) / 2 ** 20).toFixed(1), browser_rss_peak_mb_median: +(med(rsss) / 2 ** 20).toFixed(0),
    loaded_points_after_tour: last.loadedPoints, drawn_points_after_tour: last.drawnPoints, tiles_loaded_after_tour: last.tilesLoaded,
    loaded_tile_bytes_mb: +(last.loadedBytes / 2 ** 20).toFixed(1) };
  res.load_average = os.loadavg().map((x) => +x.toFixed(1));
  console.log(JSON.stringify(res));
  results.push(res);
}
if (!args.includes('--keep')) fs.rmSync(root, { recursive: true, force: true });
