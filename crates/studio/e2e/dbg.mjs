// End-to-end tests of the studio in headless Chromium (Debian's package) driven by
// playwright-core: real clicks and drags, checked on the pixels shown. Screenshots and the
// timing report go to e2e/artifacts/ (git-ignored); the README's screenshot to docs/.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { spawn } from 'node:child_process';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

const here = path.dirname(fileURLToPath(import.meta.url));
const repo = path.resolve(here, '../../..');
const bin = process.env.VOLMORPH || path.join(repo, 'target/release/volmorph');
const artifacts = path.join(here, 'artifacts');
fs.mkdirSync(artifacts, { recursive: true });
const SIZE = Number(process.env.STUDIO_SIZE || 128);

let server, browser, page, url, root;
const report = { size: SIZE };

before(async () => {
  root = fs.mkdtempSync(path.join(os.tmpdir(), 'studio-e2e-'));
  fs.writeFileSync(path.join(root, 'tetra.obj'), 'v 0 0 0\nv 0.5 0 0\nv 0 0.5 0\nv 0 0 0.5\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n');
  server = spawn(bin, ['studio', '--phantom', 'teapot', '--size', String(SIZE), '--lattice', '9', '--root', root], { stdio: ['ignore', 'pipe', 'inherit'] });
  url = await new Promise((resolve, reject) => {
    let out = '';
    server.stdout.on('data', (d) => { out += d; const m = out.match(/http:\/\/127\.0\.0\.1:\d+\/[0-9a-f]{32}\//); if (m) resolve(m[0]); });
    server.on('exit', (c) => reject(new Error(`studio exited with ${c}`)));
  });
  browser = await chromium.launch({
    executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
    args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-background-networking', '--disable-component-update',
      '--disable-sync', '--no-first-run', '--enable-unsafe-swiftshader', '--use-angle=swiftshader'],
  });
  // Playwright's polling evaluates strings, which the studio's Content-Security-Policy forbids.
  page = await browser.newPage({ viewport: { width: 1400, height: 900 }, bypassCSP: true });
  page.on('console', (m) => console.log('PAGE', m.text()));
  page.on('pageerror', (e) => console.error('page error:', e.message));
  const external = [];
  page.on('request', (r) => { if (!r.url().startsWith(url.slice(0, url.indexOf('/', 8)))) external.push(r.url()); });
  await page.goto(url);
  await page.waitForSelector('body[data-ready="1"]', { timeout: 60000 });
  await waitIdle();
  await page.evaluate(() => window.__studio.client.on('*', (f) => console.log('FRAME', f.kind, f.request, JSON.stringify(f.header).slice(0, 400))));
  report.externalRequests = external;
});

after(async () => {
  fs.writeFileSync(path.join(artifacts, 'report.json'), JSON.stringify(report, null, 2));
  console.log('studio report', JSON.stringify(report));
  await browser?.close();
  server?.kill();
});

// Until no slice is loading and no edit is in flight for a short while.
async function waitIdle(ms = 300) {
  await page.waitForFunction(() => window.__studio.slices.every((s) => !s.loading && s.slice), null, { timeout: 60000 });
  await page.waitForTimeout(ms);
  await page.waitForFunction(() => window.__studio.slices.every((s) => !s.loading), null, { timeout: 60000 });
}

// Pixels of canvas `id` in a box (RGBA array).
function pixels(id, [x, y, w, h]) {
  return page.evaluate(([id, x, y, w, h]) => Array.from(document.getElementById(id).getContext('2d').getImageData(x, y, w, h).data), [id, x, y, w, h]);
}

// Canvas position (CSS pixels on the page) of a physical point in slice view `axis`.
async function screenOf(axis, p) {
  return page.evaluate(([axis, p]) => {
    const app = window.__studio;
    const v = app.slices[axis];
    const g = app.volume().volume.geometry;
    const d = [p[0] - g.origin[0], p[1] - g.origin[1], p[2] - g.origin[2]];
    const idx = [0, 1, 2].map((a) => (g.direction[a][0] * d[0] + g.direction[a][1] * d[1] + g.direction[a][2] * d[2]) / g.spacing[a]);
    const [cx, cy] = v.toCanvas(idx);
    const r = v.canvas.getBoundingClientRect();
    return { x: r.left + cx * r.width / v.canvas.width, y: r.top + cy * r.height / v.canvas.height, cx, cy };
  }, [axis, p]);
}

const SPOUT = [0.76, 0, 0.25];

test('drag moves the spout; the slice shown is the server slice; undo restores it', async () => {
  // Put the crosshair on the spout so the coronal (j) view cuts through it.
  await page.evaluate((p) => { const a = window.__studio; const g = a.volume().volume.geometry; a.setCursor(p.map((c, i) => Math.round((c - g.origin[i]) / g.spacing[i])), -1); }, SPOUT);
  await waitIdle();
  const s = await screenOf(1, SPOUT);
  // Put the crosshair where the drag will grab (a probe click), then take the picture.
  await page.selectOption('#tool', 'probe');
  await page.mouse.click(s.x, s.y);
  await page.selectOption('#tool', 'drag');
  await waitIdle();
  const box = [Math.round(s.cx - 40), Math.round(s.cy - 40), 80, 80];
  const before = await pixels('slice-y', box);
  await page.screenshot({ path: path.join(artifacts, 'before-drag.png') });
  const t = await screenOf(1, [SPOUT[0] + 0.05, 0, SPOUT[2] - 0.25]);
  await page.mouse.move(s.x, s.y);
  await page.mouse.down();
  await page.mouse.move(t.x, t.y, { steps: 12 });
  await page.mouse.up();
  await page.waitForFunction(() => window.__studio.lastChange?.edit === 'end-gesture', null, { timeout: 60000 });
  await waitIdle(500);
  const afterDrag = await pixels('slice-y', box);
  let changed = 0;
  for (let i = 0; i < before.length; i += 4) if (before[i] !== afterDrag[i]) changed++;
  assert.ok(changed > 100, `only ${changed} pixels of the spout region changed`);
  await page.screenshot({ path: path.join(artifacts, 'after-drag.png') });
  fs.mkdirSync(path.join(repo, 'docs'), { recursive: true });
  await page.screenshot({ path: path.join(repo, 'docs/studio.png') });

  // The picture on screen equals the server's slice through the window (grey map), voxel
  // by voxel at the voxel centres: a fresh connection asks for the same slice.
  const check = await page.evaluate(async () => {
    const { Client, Kind } = await import('./app/protocol.js');
    const app = window.__studio;
    const v = app.slices[1];
    const c = await new Client(app.client.url).open();
    await c.request(Kind.Hello, {});
    const f = await c.request(Kind.GetSlice, { volume: app.layer, axis: 1, index: v.slice.index });
    const vals = new Float32Array(f.payload);
    const [lo, hi] = app.currentWindow();
    const ctx = v.canvas.getContext('2d');
    const shown = ctx.getImageData(0, 0, v.canvas.width, v.canvas.height).data;
    let bad = 0, n = 0;
    for (let row = 0; row < f.header.height; row += 3) for (let col = 0; col < f.header.width; col += 3) {
      const idx = [col, v.slice.index, f.header.height - 1 - row];
      const [x, y] = v.toCanvas(idx);
      const px = Math.floor(x), py = Math.floor(y);
      // Skip the crosshair and tool circle.
      const expect = Math.max(0, Math.min(255, Math.round((vals[row * f.header.width + col] - lo) * 255 / (hi - lo))));
      const o = 4 * (py * v.canvas.width + px);
      n++;
      if (Math.abs(shown[o] - expect) > 1 && shown[o + 2] === shown[o]) bad++;
    }
    return { bad, n };
  });
  assert.ok(check.n > 500 && check.bad === 0, `${check.bad} of ${check.n} pixels differ from the server's slice`);

  await page.keyboard.press('Control+z');
  await page.waitForFunction(() => window.__studio.lastChange?.edit === 'undo', null, { timeout: 60000 });
  await waitIdle(500);
  const undone = await pixels('slice-y', box);
  let diff = 0;
  for (let i = 0; i < before.length; i++) if (before[i] !== undone[i]) diff++;
  assert.equal(diff, 0, 'undo restores the picture');
  await page.keyboard.press('Control+Shift+z');
  await page.waitForFunction(() => window.__studio.lastChange?.edit === 'redo', null, { timeout: 60000 });
  await waitIdle();
  const redone = await pixels('slice-y', box);
  assert.deepEqual(redone, afterDrag, 'redo shows the dragged spout again');
});

