// What the console's browser tests share: their command line (--fmv3d, --web, --out, --chromium, --keep,
// --work), the skip rules (exit 77 without Chromium, a web build, the binary or playwright-core), checks with
// their results, waiting in the page, `fmv3d serve` on a free loopback port and a headless Chromium.
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import net from 'node:net';
import { spawn, execFileSync } from 'node:child_process';

export const SKIP = 77;
export const log = (...a) => console.log(...a);

/** Parses the common options; exits 77 when something the test needs is missing. */
export async function setup(here, artefacts) {
  const args = process.argv.slice(2);
  const opt = (name, def) => { const i = args.indexOf(name); return i >= 0 ? args[i + 1] : def; };
  const fmv3d = path.resolve(opt('--fmv3d', path.join(here, '../../build/fmv3d')));
  const webDir = path.resolve(opt('--web', path.join(path.dirname(fmv3d), 'web')));
  const outDir = path.resolve(opt('--out', path.join(path.dirname(fmv3d), 'test-artefacts', artefacts)));
  const chromiumPath = opt('--chromium', process.env.CHROMIUM ?? '/usr/bin/chromium');
  const skip = (why) => { log(`SKIP: ${why}`); process.exit(SKIP); };
  if (!fs.existsSync(chromiumPath)) skip(`no Chromium at ${chromiumPath} (scripts/install-deps.sh installs it)`);
  if (!fs.existsSync(path.join(webDir, 'index.html'))) skip(`no web build at ${webDir} (make web)`);
  if (!fs.existsSync(fmv3d)) skip(`no fmv3d binary at ${fmv3d}`);
  let chromium;
  try { ({ chromium } = await import('playwright-core')); } catch { skip('playwright-core is not installed (cd web && npm ci)'); }
  fs.mkdirSync(outDir, { recursive: true });
  // --work DIR reuses a work folder left by --keep (what is already there is not made again).
  const work = opt('--work');
  const root = work ? path.resolve(work) : fs.mkdtempSync(path.join(os.tmpdir(), `fmv3d-${artefacts}-`));
  return { opt, fmv3d, webDir, outDir, chromiumPath, chromium, root, keep: args.includes('--keep') || !!work };
}

/** Runs our binary (an argv list), logging its time; returns its stdout. */
export function runFmv3d(fmv3d, argv, env = {}, timeoutMs = 900000) {
  const t0 = Date.now();
  const out = execFileSync(fmv3d, argv, { stdio: ['ignore', 'pipe', 'inherit'], timeout: timeoutMs, env: { ...process.env, ...env } });
  log(`  fmv3d ${argv.join(' ')}  (${((Date.now() - t0) / 1000).toFixed(1)} s)`);
  return out.toString();
}

export function freePort() {
  return new Promise((resolve, reject) => {
    const s = net.createServer();
    s.listen(0, '127.0.0.1', () => { const p = s.address().port; s.close(() => resolve(p)); });
    s.on('error', reject);
  });
}

/** Named checks: each logs ok/FAIL with its time; `finish()` prints the tally and exits 0 or 1. */
export function checks() {
  const results = [];
  return {
    results,
    async check(name, fn) {
      const t0 = Date.now();
      try { await fn(); results.push([name, true]); log(`ok   ${name} (${((Date.now() - t0) / 1000).toFixed(1)} s)`); }
      catch (e) { results.push([name, false]); log(`FAIL ${name}: ${e?.stack ?? e}`); }
    },
    fail(name, e) { results.push([name, false]); log(`FAIL ${name}: ${e?.stack ?? e}`); },
    finish(outDir) {
      const failed = results.filter(([, ok]) => !ok).length;
      log(`artefacts in ${outDir}`);
      log(`${results.length - failed} passed, ${failed} failed`);
      process.exit(failed ? 1 : 0);
    },
  };
}

export function assert(cond, msg) { if (!cond) throw new Error(msg); }

export async function waitFor(page, fn, arg, timeout, what) {
  try { await page.waitForFunction(fn, arg, { timeout, polling: 200 }); }
  catch { throw new Error(`timed out waiting for ${what}`); }
}

/** `fmv3d serve WS_ROOT` on a free loopback port, its output in OUT/server.log; resolves when it answers. */
export async function startServer({ fmv3d, webDir, outDir }, wsRoot, env = {}) {
  const port = await freePort();
  const server = spawn(fmv3d, ['serve', wsRoot, '--port', String(port), '--host', '127.0.0.1', '--assets', webDir],
    { stdio: ['ignore', 'pipe', 'pipe'], env: { ...process.env, ...env } });
  const serverLog = fs.createWriteStream(path.join(outDir, 'server.log'));
  server.stdout.pipe(serverLog); server.stderr.pipe(serverLog);
  const base = `http://127.0.0.1:${port}/`;
  for (let i = 0; ; i++) {
    try { const r = await fetch(base + 'api/health'); if (r.ok) break; } catch { /* not up yet */ }
    if (i > 100 || server.exitCode !== null) throw new Error(`fmv3d serve did not come up on ${base} (see server.log)`);
    await new Promise((r) => setTimeout(r, 100));
  }
  log(`fmv3d serve at ${base}`);
  return { server, base };
}

/** Headless Chromium (software GL) with a fresh profile. */
export async function launchBrowser({ chromium, chromiumPath }, viewport = { width: 1280, height: 800 }) {
  const profile = fs.mkdtempSync(path.join(os.tmpdir(), 'fmv3d-chromium-'));
  return chromium.launchPersistentContext(profile, {
    executablePath: chromiumPath, headless: true, viewport,
    args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run', '--disable-background-networking',
      '--disable-component-update', '--disable-sync', '--use-angle=swiftshader', '--enable-unsafe-swiftshader'],
  });
}

/** Closes the browser and the server; removes the work folder unless it is kept. */
export async function closeAll({ context, server, root, keep }) {
  await context?.close().catch(() => undefined);
  if (server && server.exitCode === null) server.kill('SIGTERM');
  if (!keep) fs.rmSync(root, { recursive: true, force: true });
}
