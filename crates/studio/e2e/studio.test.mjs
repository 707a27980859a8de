// End-to-end tests of the studio in headless Chromium (Debian's package) driven by
// playwright-core: real clicks and drags, checked on the pixels shown. Screenshots and the
// timing report go to e2e/artifacts/ (git-ignored); the README's screenshot to docs/.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { spawn, spawnSync } from 'node:child_process';
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

// `volmorph studio ARGS…` and the URL it prints.
async function startStudio(args) {
  const proc = spawn(bin, ['studio', ...args], { stdio: ['ignore', 'pipe', 'inherit'] });
  const u = await new Promise((resolve, reject) => {
    let out = '';
    proc.stdout.on('data', (d) => { out += d; const m = out.match(/http:\/\/127\.0\.0\.1:\d+\/[0-9a-f]{32}\//); if (m) resolve(m[0]); });
    proc.on('exit', (c) => reject(new Error(`studio exited with ${c}`)));
  });
  return { server: proc, url: u };
}

// The head CT of /work/shared/data (tests using it skip when it is absent).
const CT = [process.env.STUDIO_CT, path.resolve(repo, '../shared/data/volumes/cranium_ct.nii.gz'),
  path.resolve(repo, '../../shared/data/volumes/cranium_ct.nii.gz')].find((f) => f && fs.existsSync(f));
const report = { size: SIZE };

before(async () => {
  root = fs.mkdtempSync(path.join(os.tmpdir(), 'studio-e2e-'));
  fs.writeFileSync(path.join(root, 'tetra.obj'), 'v 0 0 0\nv 0.5 0 0\nv 0 0.5 0\nv 0 0 0.5\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n');
  ({ server, url } = await startStudio(['--phantom', 'teapot', '--size', String(SIZE), '--lattice', '9', '--root', root]));
  browser = await chromium.launch({
    executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
    args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-background-networking', '--disable-component-update',
      '--disable-sync', '--no-first-run', '--enable-unsafe-swiftshader', '--use-angle=swiftshader'],
  });
  // Playwright's polling evaluates strings, which the studio's Content-Security-Policy forbids.
  page = await browser.newPage({ viewport: { width: 1400, height: 900 }, bypassCSP: true });
  page.on('pageerror', (e) => console.error('page error:', e.message));
  const external = [];
  page.on('request', (r) => { if (!r.url().startsWith(url.slice(0, url.indexOf('/', 8)))) external.push(r.url()); });
  await page.goto(url);
  await page.waitForSelector('body[data-ready="1"]', { timeout: 60000 });
  await waitIdle();
  report.externalRequests = external;
});

after(async () => {
  report.targets = TARGETS;
  fs.writeFileSync(path.join(artifacts, 'report.json'), JSON.stringify(report, null, 2));
  fs.mkdirSync(path.join(repo, 'target'), { recursive: true });
  fs.writeFileSync(path.join(repo, 'target/studio-latency.json'), JSON.stringify(report, null, 2));
  console.log('studio report', JSON.stringify(report));
  await browser?.close();
  server?.kill();
});

// Until no slice is loading and no edit is in flight for a short while.
async function waitIdle(ms = 300, p = page) {
  await p.waitForFunction(() => window.__studio.slices.every((s) => !s.loading && s.slice), null, { timeout: 60000 });
  await p.waitForTimeout(ms);
  await p.waitForFunction(() => window.__studio.slices.every((s) => !s.loading), null, { timeout: 60000 });
}

// Median, min, max and count of a list of numbers.
function stats(xs) {
  const v = xs.slice().sort((a, b) => a - b);
  const r = (x) => Math.round(x * 10) / 10;
  return { median: r(v[Math.floor(v.length / 2)]), min: r(v[0]), max: r(v[v.length - 1]), n: v.length };
}

// `n` small moves of a gesture pressed at `s` (page position), each waited for until its
// edit's pixels are on screen; returns the page's latency records of those moves
// (`{edit, ms, server, sent}`: input event to pixels, the edit's time on the server, event to
// send).
async function timedMoves(p, s, n, step = [1, 1]) {
  await p.evaluate(() => { window.__studio.latencies = []; });
  await p.mouse.move(s.x, s.y);
  await p.mouse.down();
  for (let k = 1; k <= n; k++) {
    await p.mouse.move(s.x + k * step[0], s.y + k * step[1]);
    await p.waitForFunction((k) => window.__studio.latencies.length >= k, k, { timeout: 30000 });
    await waitIdle(20, p);
  }
  await p.mouse.up();
  return p.evaluate(() => window.__studio.latencies);
}

// The share of world points `pts` that the 3D view shows in colour `rgba` (0‥1, exactly,
// within a pixel), after a fresh draw; points off the canvas do not count.
function shareDrawn(pts, rgba) {
  return page.evaluate(([pts, rgba]) => {
    const want = rgba.slice(0, 3).map((x) => Math.round(x * 255));
    const v = window.__studio.view3d;
    v.draw();
    const gl = v.gl, W = v.canvas.width, H = v.canvas.height;
    const px = new Uint8Array(W * H * 4);
    gl.readPixels(0, 0, W, H, gl.RGBA, gl.UNSIGNED_BYTE, px);
    const { mvp } = v.matrices();
    let n = 0, hit = 0;
    for (const p of pts) {
      const [x, y] = v.project(p, mvp);
      if (x < 2 || y < 2 || x > W - 3 || y > H - 3) continue;
      n++;
      let found = false;
      for (let dy = -1; dy <= 1 && !found; dy++) for (let dx = -1; dx <= 1 && !found; dx++) {
        const o = 4 * ((H - 1 - Math.floor(y + dy)) * W + Math.floor(x + dx));
        found = px[o] === want[0] && px[o + 1] === want[1] && px[o + 2] === want[2];
      }
      if (found) hit++;
    }
    return { n, share: hit / n };
  }, [pts, rgba]);
}

// Each target of issue 18 (ms), next to the median measured.
const TARGETS = { teapotDragMs: 50, ctDragMs: 150, handles200PreviewMs: 30, fps3dAim: 20 };

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
  // The README's screenshot is refreshed only on request (STUDIO_DOCS_PICTURE=1), so a test
  // run leaves the checkout clean.
  if (process.env.STUDIO_DOCS_PICTURE === '1') await page.screenshot({ path: path.join(repo, 'docs/studio.png') });

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

test('drag latency and 3D rotation rate on the teapot (report)', async () => {
  // Small drags at the spout, one at a time, timed from the input event to the slice drawn.
  const s = await screenOf(1, SPOUT);
  const lat = (await timedMoves(page, s, 9)).filter((l) => l.edit === 'drag');
  assert.equal(lat.length, 9, 'every move is one drag edit');
  report.teapot = { dragToPixelsMs: stats(lat.map((l) => l.ms)), serverMs: stats(lat.map((l) => l.server)) };
  await page.waitForFunction(() => window.__studio.lastChange?.edit === 'end-gesture', null, { timeout: 60000 });
  await page.keyboard.press('Control+z');
  await page.waitForFunction(() => window.__studio.lastChange?.edit === 'undo', null, { timeout: 60000 });
  await waitIdle();
  report.teapot.fps3d = await page.evaluate(() => window.__studio.view3d.spin(3000));
  report.teapot.fps3dPlanes = await page.evaluate(() => window.__studio.view3d.proxy.planes);
  const shot = await page.locator('#view3d').screenshot({ path: path.join(artifacts, 'view3d.png') });
  assert.ok(shot.length > 1000);
  assert.ok(report.teapot.fps3d > 0);
  assert.deepEqual(report.externalRequests, [], 'no request leaves the studio server');
});

test('3D view draws the volume and the isosurface', async () => {
  // After the interaction, the full number of proxy planes.
  await page.waitForFunction(() => { const v = window.__studio.view3d; return !v.lod && v.proxy?.planes === v.slices; }, null, { timeout: 30000 });
  const stats = await page.evaluate(() => {
    const v = window.__studio.view3d;
    v.draw();
    const gl = v.gl;
    const px = new Uint8Array(v.canvas.width * v.canvas.height * 4);
    gl.readPixels(0, 0, v.canvas.width, v.canvas.height, gl.RGBA, gl.UNSIGNED_BYTE, px);
    let lit = 0;
    for (let i = 0; i < px.length; i += 4) if (px[i] + px[i + 1] + px[i + 2] > 60) lit++;
    return { lit, meshes: v.meshes.size, proxy: v.proxy?.count || 0 };
  });
  assert.ok(stats.meshes >= 1, 'the isosurface is shown');
  assert.ok(stats.proxy > 1000, 'proxy geometry arrived');
  assert.ok(stats.lit > 2000, `only ${stats.lit} pixels are drawn`);
});

test('the tool radius is a sphere around the cursor in the 3D view', async () => {
  // Points on the three great circles of radius `r` around the cursor (computed here).
  const circles = (r) => page.evaluate((r) => {
    const c = window.__studio.cursorPhysical();
    const out = [];
    for (let k = 0; k < 48; k++) {
      const t = 2 * Math.PI * (k + 0.5) / 48, u = r * Math.cos(t), w = r * Math.sin(t);
      out.push([c[0] + u, c[1] + w, c[2]], [c[0], c[1] + u, c[2] + w], [c[0] + w, c[1], c[2] + u]);
    }
    return out;
  }, r);
  const rgba = await page.evaluate(async () => (await import('./app/view3d.js')).SPHERE_RGBA);
  const onSphere = async (r) => shareDrawn(await circles(r), rgba);
  await page.selectOption('#tool', 'drag');
  const r = await page.evaluate(() => window.__studio.radius);
  const drawn = await onSphere(r);
  assert.ok(drawn.n > 100 && drawn.share > 0.9, `the sphere of radius ${r}: ${JSON.stringify(drawn)}`);
  const other = await onSphere(r * 1.5);
  assert.ok(other.share < 0.2, `a sphere of another radius is not drawn: ${JSON.stringify(other)}`);
  await page.selectOption('#tool', 'probe');
  const off = await onSphere(r);
  assert.ok(off.share < 0.1, `no sphere for the probe tool: ${JSON.stringify(off)}`);
  await page.selectOption('#tool', 'drag');
});

test('lattice control points are dragged in the 3D view', async () => {
  await page.selectOption('#tool', 'lattice');
  const target = await page.evaluate(() => {
    const v = window.__studio.view3d;
    const { mvp } = v.matrices();
    const k = 4 + 9 * (4 + 9 * 6);
    const p = [0, 1, 2].map((c) => v.overlay.points[3 * k + c]);
    const [x, y] = v.project(p, mvp);
    const r = v.canvas.getBoundingClientRect();
    return { k, p, all: Array.from(v.overlay.points), x: r.left + x * r.width / v.canvas.width, y: r.top + y * r.height / v.canvas.height };
  });
  await page.mouse.move(target.x, target.y);
  await page.mouse.down();
  await page.mouse.move(target.x + 30, target.y - 20, { steps: 6 });
  await page.mouse.up();
  await page.waitForFunction(() => window.__studio.lastChange?.edit === 'end-gesture', null, { timeout: 60000 });
  await waitIdle();
  target.k = await page.evaluate(() => [...window.__studio.view3d.selected][0]);
  target.p = target.all.slice(3 * target.k, 3 * target.k + 3);
  const moved = await page.evaluate((k) => [0, 1, 2].map((c) => window.__studio.view3d.overlay.points[3 * k + c]), target.k);
  const d = Math.hypot(...moved.map((m, i) => m - target.p[i]));
  assert.ok(d > 0.02, `the control point moved by ${d}`);
  await page.keyboard.press('Control+z');
  await page.waitForFunction(() => window.__studio.lastChange?.edit === 'undo', null, { timeout: 60000 });
  await waitIdle();
  const back = await page.evaluate((k) => [0, 1, 2].map((c) => window.__studio.view3d.overlay.points[3 * k + c]), target.k);
  assert.ok(Math.hypot(...back.map((m, i) => m - target.p[i])) < 1e-6, 'undo puts it back');
  await page.selectOption('#tool', 'drag');
});

test('Jacobian overlay: folded voxels are highlighted exactly where the server finds J ≤ 0', async () => {
  // Fold the lattice: control points (4,4,4) and (5,4,4) cross each other along x.
  const fold = await page.evaluate(() => {
    const a = window.__studio;
    const o = a.view3d.overlay;
    const at = (i, j, k) => i + 9 * (j + 9 * k);
    const p = (n) => [0, 1, 2].map((c) => o.points[3 * n + c]);
    const p4 = p(at(4, 4, 4)), p5 = p(at(5, 4, 4));
    const h = p5[0] - p4[0];
    const g = a.newGesture();
    a.moveControlPoints(o.map, g, [[at(4, 4, 4), p4[0] + 3 * h, p4[1], p4[2]], [at(5, 4, 4), p5[0] - 3 * h, p5[1], p5[2]]]);
    a.endGesture(g);
    return [(p4[0] + p5[0]) / 2, p4[1], p4[2]];
  });
  await page.waitForFunction(() => window.__studio.lastChange?.edit === 'end-gesture', null, { timeout: 60000 });
  await page.selectOption('#tool', 'probe');
  await page.evaluate((p) => { const a = window.__studio; const g = a.volume().volume.geometry; a.setCursor(p.map((c, i) => Math.round((c - g.origin[i]) / g.spacing[i])), -1); }, fold);
  await page.check('#show-jacobian');
  await waitIdle();
  // Every sampled voxel centre of the axial view: folded voxels are drawn in the fold colour,
  // unchanged voxels (J = 1) as the plain picture; nothing else is magenta.
  const check = () => page.evaluate(async () => {
    const { Client, Kind } = await import('./app/protocol.js');
    const { FOLD_RGB } = await import('./app/slices.js');
    const app = window.__studio;
    const v = app.slices[2];
    const c = await new Client(app.client.url).open();
    await c.request(Kind.Hello, {});
    const f = await c.request(Kind.GetJacobian, { map: app.jacobianMap().id, volume: app.layer, axis: 2, index: v.slice.index });
    const det = new Float32Array(f.payload);
    const shown = v.ctx.getImageData(0, 0, v.canvas.width, v.canvas.height).data;
    const [cx, cy] = v.toCanvas(app.cursor);
    let folds = 0, foldOk = 0, clear = 0, clearOk = 0, magenta = 0;
    for (let row = 0; row < f.header.height; row++) for (let col = 0; col < f.header.width; col++) {
      const [x, y] = v.toCanvas([col, f.header.height - 1 - row, v.slice.index]);
      const px = Math.floor(x), py = Math.floor(y);
      if (Math.abs(px - cx) < 2 || Math.abs(py - cy) < 2) continue; // the crosshair
      const o = 4 * (py * v.canvas.width + px);
      const isFold = shown[o] === FOLD_RGB[0] && shown[o + 1] === FOLD_RGB[1] && shown[o + 2] === FOLD_RGB[2];
      if (isFold) magenta++;
      const j = det[row * f.header.width + col];
      if (j <= 0) { folds++; if (isFold) foldOk++; }
      if (Math.abs(j - 1) < 1e-6) { clear++; if (shown[o] === shown[o + 1] && shown[o + 1] === shown[o + 2]) clearOk++; }
    }
    c.ws.close();
    return { folded: f.header.folded, folds, foldOk, clear, clearOk, magenta };
  });
  const folded = await check();
  assert.ok(folded.folded > 0 && folded.folds > 0, `the crossed control points fold space: ${JSON.stringify(folded)}`);
  assert.equal(folded.foldOk, folded.folds, `every folded voxel is highlighted: ${JSON.stringify(folded)}`);
  assert.equal(folded.magenta, folded.folds, 'only folded voxels are highlighted');
  assert.ok(folded.clear > 100 && folded.clearOk === folded.clear, `voxels the map keeps are shown plain: ${JSON.stringify(folded)}`);
  await page.screenshot({ path: path.join(artifacts, 'jacobian.png') });
  await page.keyboard.press('Control+z');
  await page.waitForFunction(() => window.__studio.lastChange?.edit === 'undo', null, { timeout: 60000 });
  await waitIdle();
  const undone = await check();
  assert.equal(undone.folded, 0, 'undo unfolds');
  assert.equal(undone.magenta, 0, 'no voxel is highlighted after undo');
  await page.uncheck('#show-jacobian');
  await page.selectOption('#tool', 'drag');
});

test('deformed grid: the 3D view draws the grid lines where the map sends them', async () => {
  const rgba = await page.evaluate(async () => (await import('./app/view3d.js')).GRID_RGBA);
  const drawnAt = (pts) => shareDrawn(pts, rgba);
  const images = () => page.evaluate(() => { const g = window.__studio.view3d.grid; const out = []; for (let i = 0; i < g.points.length; i += 3) out.push([g.points[i], g.points[i + 1], g.points[i + 2]]); return out; });
  await page.check('#show-grid');
  await page.waitForFunction(() => window.__studio.view3d.grid?.points.length > 0, null, { timeout: 30000 });
  const before = await images();
  const shown = await drawnAt(before);
  assert.ok(shown.n > 1000 && shown.share > 0.9, `the grid is drawn: ${JSON.stringify(shown)}`);
  // Lift one control point by 2.5 lattice spacings (no fold below 4.5): the lines near it follow.
  await page.evaluate(() => {
    const a = window.__studio, o = a.view3d.overlay;
    const k = 4 + 9 * (4 + 9 * 4);
    const p = [0, 1, 2].map((c) => o.points[3 * k + c]);
    const h = o.points[3 * (k + 9 * 9) + 2] - p[2];
    const g = a.newGesture();
    a.moveControlPoints(o.map, g, [[k, p[0], p[1], p[2] + 2.5 * h]]);
    a.endGesture(g);
  });
  await page.waitForFunction(() => window.__studio.lastChange?.edit === 'end-gesture', null, { timeout: 60000 });
  await waitIdle();
  const after = await images();
  // Samples that moved across their line (lines along x come first, then y, then z: 5 × 5
  // lines of 33 samples per axis).
  const across = (i) => { const a = Math.floor(i / (5 * 5 * 33)); return [0, 1, 2].filter((c) => c !== a); };
  const moved = before.filter((p, i) => Math.hypot(...across(i).map((c) => p[c] - after[i][c])) > 0.04);
  assert.ok(moved.length > 10, `${moved.length} grid samples follow the control point`);
  const followed = await drawnAt(after);
  assert.ok(followed.share > 0.9, `the deformed lines are drawn: ${JSON.stringify(followed)}`);
  const left = await drawnAt(moved);
  // Other lines cross those places in the picture, so some stay lit; most do not.
  assert.ok(left.share < Math.min(0.8, followed.share - 0.15), `the lines left their old place: ${JSON.stringify(left)} vs ${JSON.stringify(followed)}`);
  await page.screenshot({ path: path.join(artifacts, 'deformed-grid.png') });
  await page.keyboard.press('Control+z');
  await page.waitForFunction(() => window.__studio.lastChange?.edit === 'undo', null, { timeout: 60000 });
  await waitIdle();
  await page.waitForFunction((b) => {
    const g = window.__studio.view3d.grid;
    return b.every((p, i) => Math.hypot(p[0] - g.points[3 * i], p[1] - g.points[3 * i + 1], p[2] - g.points[3 * i + 2]) < 1e-5);
  }, before, { timeout: 30000 });
  await page.uncheck('#show-grid');
});

test('an F-rep syntax error is shown at its line and the model is kept', async () => {
  await page.fill('#frep-src', 'm(x[3], a[1]) {\n  m = a[1] - x[1]*x[1] - x[2]*x[2] - x[3]*x[3];\n}');
  await page.click('#frep-apply');
  await page.waitForFunction(() => document.getElementById('status').textContent === 'model updated', null, { timeout: 60000 });
  const frep = await page.evaluate(() => window.__studio.objects.filter((o) => o.kind === 'frep').length);
  assert.equal(frep, 1);
  await page.fill('#frep-src', 'm(x[3], a[1]) {\n  m = a[1] - x[1]*x[1];\n  m = m + * 2;\n}');
  await page.click('#frep-apply');
  await page.waitForFunction(() => document.getElementById('frep-error').textContent.length > 0, null, { timeout: 30000 });
  const err = await page.textContent('#frep-error');
  assert.match(err, /^line 3, column \d+/);
  const src = await page.evaluate(() => window.__studio.objects.find((o) => o.kind === 'frep').frep.source);
  assert.match(src, /x\[3\]\*x\[3\]/, 'the previous valid model stays');
  await page.screenshot({ path: path.join(artifacts, 'frep-error.png') });
});

test('F-rep parameter slider: a drag re-renders the model live and undoes in one step', async () => {
  await page.waitForSelector('#frep-a1');
  // The sampled sphere's largest value on its middle slice: a[1]² at the centre.
  const peak = () => page.evaluate(async () => {
    const { Kind } = await import('./app/protocol.js');
    const a = window.__studio;
    const s = a.objects.find((o) => o.name === 'model-sampled');
    const f = await a.client.request(Kind.GetSlice, { volume: s.id, axis: 2 });
    return new Float32Array(f.payload).reduce((m, x) => Math.max(m, x), -Infinity);
  });
  // The model is a[1] − |x|²: it peaks at a[1] at the centre.
  const before = await peak();
  assert.ok(Math.abs(before - 0.6) < 0.01, `a[1] = 0.6 peaks at ${before}`);
  // The side panel scrolls: bring the slider on screen before dragging it.
  await page.locator('#frep-a1').scrollIntoViewIfNeeded();
  const box = await page.locator('#frep-a1').boundingBox();
  const [min, max] = await page.evaluate(() => { const i = document.getElementById('frep-a1'); return [Number(i.min), Number(i.max)]; });
  const at = (v) => box.x + 8 + (box.width - 16) * (v - min) / (max - min);
  await page.mouse.move(at(0.6), box.y + box.height / 2);
  await page.mouse.down();
  await page.mouse.move(at(0.3), box.y + box.height / 2, { steps: 8 });
  await page.mouse.up();
  await page.waitForFunction(() => window.__studio.lastChange?.edit === 'end-gesture', null, { timeout: 60000 });
  await waitIdle();
  const a1 = await page.evaluate(() => Number(document.getElementById('frep-a1').value));
  const server = await page.evaluate(() => window.__studio.objects.find((o) => o.kind === 'frep').frep.params[1]);
  assert.ok(Math.abs(a1 - 0.6) > 0.1, `the slider moved to ${a1}`);
  assert.ok(Math.abs(server - a1) < 1e-9, `the model has the slider's value: ${server} vs ${a1}`);
  const after = await peak();
  assert.ok(Math.abs(after - a1) < 0.01, `a[1] = ${a1} peaks at ${after}`);
  await page.keyboard.press('Control+z');
  await page.waitForFunction(() => window.__studio.lastChange?.edit === 'undo', null, { timeout: 60000 });
  await waitIdle();
  assert.ok(Math.abs(await peak() - 0.6) < 0.01, 'one undo restores a[1] = 0.6');
  assert.equal(await page.evaluate(() => Number(document.getElementById('frep-a1').value)), 0.6);
});

test('handles: set up, drag a handle with the coarse preview, full result on release', async () => {
  await page.selectOption('#layer', '1');
  await page.waitForTimeout(300);
  await waitIdle();
  await page.click('#setup-handles');
  await page.waitForFunction(() => window.__studio.handles.length === 9, null, { timeout: 60000 });
  await page.waitForFunction(() => window.__studio.objects.some((o) => o.name === 'handle-warp'), null, { timeout: 60000 });
  await page.selectOption('#tool', 'handles');
  const centre = await page.evaluate(() => window.__studio.handles[8].target);
  await page.evaluate((p) => { const a = window.__studio; const g = a.volume().volume.geometry; a.setCursor(p.map((c, i) => (c - g.origin[i]) / g.spacing[i]), -1); }, centre);
  await waitIdle();
  const s = await screenOf(2, centre);
  await page.mouse.move(s.x, s.y);
  await page.mouse.down();
  await page.mouse.move(s.x + 25, s.y, { steps: 5 });
  await page.mouse.up();
  // The full-resolution warp runs on release: allow for a loaded machine.
  await page.waitForFunction(() => window.__studio.lastChange?.edit === 'end-gesture', null, { timeout: 120000 });
  await waitIdle();
  const h = await page.evaluate(() => window.__studio.handles[8]);
  assert.ok(h.target[0] - h.source[0] > 0.05, `handle target moved: ${JSON.stringify(h)}`);
  const recipe = await page.evaluate(() => window.__studio.objects.find((o) => o.name === 'handle-warp').recipe);
  assert.equal(recipe.sampled_nodes, null, 'full resolution after release');
  await page.screenshot({ path: path.join(artifacts, 'handles.png') });
  await page.selectOption('#tool', 'drag');
});

test('handle move with 200 handles to the coarse preview (report)', async () => {
  // 200 identity handles on a 5×5×8 grid through the middle of the teapot's box.
  const pts = await page.evaluate(() => {
    const g = window.__studio.byId(1).volume.geometry;
    const out = [];
    for (let k = 0; k < 8; k++) for (let j = 0; j < 5; j++) for (let i = 0; i < 5; i++) {
      const idx = [0.2 + 0.6 * i / 4, 0.2 + 0.6 * j / 4, 0.15 + 0.7 * k / 7].map((t, a) => t * (g.dims[a] - 1));
      out.push([0, 1, 2].map((c) => g.origin[c] + [0, 1, 2].reduce((acc, a) => acc + g.direction[a][c] * g.spacing[a] * idx[a], 0)));
    }
    return out;
  });
  await page.evaluate(async (pts) => {
    const { Kind } = await import('./app/protocol.js');
    await window.__studio.client.edit(Kind.Setup, { setup: 'handles', volume: 1, method: 'affine', points: pts });
  }, pts);
  await page.waitForFunction(() => window.__studio.handles.length === 200, null, { timeout: 60000 });
  await page.selectOption('#tool', 'handles');
  await waitIdle();
  const grab = 2 + 5 * (2 + 5 * 4);
  const centre = await page.evaluate((i) => window.__studio.handles[i].target, grab);
  await page.evaluate((p) => { const a = window.__studio; const g = a.volume().volume.geometry; a.setCursor(p.map((c, i) => (c - g.origin[i]) / g.spacing[i]), -1); }, centre);
  await waitIdle();
  const s = await screenOf(2, centre);
  const lat = (await timedMoves(page, s, 7, [2, 0])).filter((l) => l.edit === 'command');
  assert.equal(lat.length, 7, 'every move is one handle command');
  report.handles200 = { previewToPixelsMs: stats(lat.map((l) => l.ms)), serverMs: stats(lat.map((l) => l.server)) };
  await page.waitForFunction(() => window.__studio.lastChange?.edit === 'end-gesture', null, { timeout: 120000 });
  await waitIdle();
  const h = await page.evaluate((i) => window.__studio.handles[i], grab);
  assert.ok(h.target[0] - h.source[0] > 0.02, `handle target moved: ${JSON.stringify(h)}`);
  const recipe = await page.evaluate(() => {
    const a = window.__studio; const map = a.handleMap().id;
    return a.objects.find((o) => o.recipe?.recipe === 'warp' && o.recipe.map === map).recipe;
  });
  assert.equal(recipe.sampled_nodes, null, 'full resolution after release');
  await page.selectOption('#tool', 'drag');
});

test('drag latency and 3D rotation rate on the head CT (report)', { skip: CT ? false : 'cranium_ct.nii.gz is absent' }, async () => {
  const ct = await startStudio([CT, '--lattice', '9', '--level', '300', '--root', root]);
  const p = await browser.newPage({ viewport: { width: 1400, height: 900 }, bypassCSP: true });
  p.on('pageerror', (e) => console.error('page error:', e.message));
  try {
    await p.goto(ct.url);
    await p.waitForSelector('body[data-ready="1"]', { timeout: 120000 });
    await waitIdle(300, p);
    // Grab the skull's top in the coronal view (a third of the way down its canvas).
    const s = await p.evaluate(() => {
      const r = window.__studio.slices[1].canvas.getBoundingClientRect();
      return { x: r.left + r.width * 0.5, y: r.top + r.height * 0.3 };
    });
    const lat = (await timedMoves(p, s, 7)).filter((l) => l.edit === 'drag');
    assert.equal(lat.length, 7, 'every move is one drag edit');
    report.ct = { dragToPixelsMs: stats(lat.map((l) => l.ms)), serverMs: stats(lat.map((l) => l.server)) };
    await p.waitForFunction(() => window.__studio.lastChange?.edit === 'end-gesture', null, { timeout: 60000 });
    await waitIdle(300, p);
    report.ct.fps3d = await p.evaluate(() => window.__studio.view3d.spin(3000));
    report.ct.fps3dPlanes = await p.evaluate(() => window.__studio.view3d.proxy.planes);
    await p.screenshot({ path: path.join(artifacts, 'ct.png') });
    assert.ok(report.ct.fps3d > 0);
  } finally {
    await p.close();
    ct.server.kill();
  }
});

test('files: open from the browser, drop to upload, save the scene', async () => {
  await page.click('#files li:has-text("tetra.obj")');
  await page.waitForFunction(() => window.__studio.objects.some((o) => o.name === 'tetra.obj'), null, { timeout: 30000 });
  // Drag-and-drop of a file onto the drop zone.
  await page.evaluate(() => {
    const dt = new DataTransfer();
    dt.items.add(new File(['v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n'], 'tri.obj'));
    document.getElementById('drop').dispatchEvent(new DragEvent('drop', { dataTransfer: dt, bubbles: true }));
  });
  await page.waitForFunction(() => window.__studio.objects.some((o) => o.name === 'tri.obj'), null, { timeout: 30000 });
  await page.fill('#save-name', 'e2e.vmproj');
  await page.click('#save');
  await page.waitForFunction(() => document.getElementById('status').textContent.startsWith('saved'), null, { timeout: 30000 });
  assert.ok(fs.existsSync(path.join(root, 'e2e.vmproj')));
  // Outside the roots: refused with a visible error.
  const err = await page.evaluate(async () => {
    const { Kind } = await import('./app/protocol.js');
    try { await window.__studio.client.request(Kind.ListDir, { root: 0, path: '../..' }); return 'listed'; } catch (e) { return e.message; }
  });
  assert.match(err, /must not contain/);
});

// The page's objects, undo depth and, from a fresh connection, the server's object list.
async function sceneState() {
  return page.evaluate(async () => {
    const { Client, Kind } = await import('./app/protocol.js');
    const app = window.__studio;
    const c = await new Client(app.client.url).open();
    await c.request(Kind.Hello, {});
    const s = await c.request(Kind.ListObjects, {});
    c.ws.close();
    return { objects: s.header.objects.map((o) => [o.id, o.name, o.kind]), undo: s.header.undo, redo: s.header.redo };
  });
}

test('a long job shows a progress bar with its stage; Cancel stops it and nothing changes', async () => {
  const before = await sceneState();
  await page.selectOption('#teapot-size', '512');
  await page.click('#new-teapot');
  // The bar appears with the library's stage and fills as the slices are sampled.
  await page.waitForSelector('#job', { state: 'visible', timeout: 30000 });
  await page.waitForFunction(() => document.getElementById('job-bar').value > 0, null, { timeout: 60000 });
  assert.match(await page.textContent('#job-label'), /^teapot density \d+%$/);
  await page.screenshot({ path: path.join(artifacts, 'progress.png') });
  const t0 = Date.now();
  await page.click('#job-cancel');
  await page.waitForSelector('#job', { state: 'hidden', timeout: 30000 });
  report.cancelToHiddenMs = Date.now() - t0;
  assert.equal(await page.textContent('#status'), 'cancelled: nothing changed');
  assert.deepEqual(await sceneState(), before, 'the cancelled set-up added nothing and kept the history');
  await page.selectOption('#teapot-size', '128');
});

test('metamorphosis: a slider drag shows Eq. 13 live and undoes in one step', async () => {
  // A second model beside the sphere of the F-rep tests: a slab |z| < a[1].
  await page.fill('#frep-src', 'slab(x[3], a[1]) {\n  slab = a[1]*a[1] - x[3]*x[3];\n}');
  await page.click('#frep-new');
  await page.waitForFunction(() => window.__studio.objects.filter((o) => o.kind === 'frep').length === 2, null, { timeout: 30000 });
  const [from, to] = await page.evaluate(() => window.__studio.objects.filter((o) => o.kind === 'frep').map((o) => o.id));
  await page.selectOption('#morph-from', String(from));
  await page.selectOption('#morph-to', String(to));
  await page.selectOption('#morph-schedule', 'linear');
  await page.click('#morph-make');
  await page.waitForFunction(() => window.__studio.objects.some((o) => o.name === 'morph-surface'), null, { timeout: 60000 });
  await waitIdle();
  // The sampled morph on its middle axial slice against (1 − t)·f + t·g computed here from the
  // two models' formulas with a[1] = 0.6: f = a[1] − |x|² (the F-rep tests' model),
  // g = a[1]² − z².
  const check = () => page.evaluate(async () => {
    const { Kind } = await import('./app/protocol.js');
    const a = window.__studio;
    const m = a.objects.find((o) => o.recipe?.recipe === 'frep-morph');
    const g = m.volume.geometry;
    const f = await a.client.request(Kind.GetSlice, { volume: m.id, axis: 2 });
    const vals = new Float32Array(f.payload);
    const k = f.header.index, t = m.recipe.t;
    let worst = 0;
    for (let row = 0; row < f.header.height; row += 5) for (let col = 0; col < f.header.width; col += 5) {
      const idx = [col, f.header.height - 1 - row, k];
      const x = [0, 1, 2].map((c) => g.origin[c] + [0, 1, 2].reduce((s, ax) => s + g.direction[ax][c] * g.spacing[ax] * idx[ax], 0));
      const fv = 0.6 - x[0] * x[0] - x[1] * x[1] - x[2] * x[2], gv = 0.36 - x[2] * x[2];
      worst = Math.max(worst, Math.abs(vals[row * f.header.width + col] - ((1 - t) * fv + t * gv)));
    }
    return { t, worst, undo: a.undoDepth };
  });
  const start = await check();
  assert.equal(start.t, 0);
  assert.ok(start.worst < 1e-5, `t = 0: Eq. 13 off by ${start.worst}`);
  // The side panel scrolls: bring the slider on screen before dragging it.
  await page.locator('#morph-t').scrollIntoViewIfNeeded();
  const box = await page.locator('#morph-t').boundingBox();
  const at = (v) => box.x + 8 + (box.width - 16) * v;
  await page.evaluate(() => { window.__studio.latencies = []; });
  await page.mouse.move(at(0), box.y + box.height / 2);
  await page.mouse.down();
  await page.mouse.move(at(0.7), box.y + box.height / 2, { steps: 8 });
  await page.mouse.up();
  await page.waitForFunction(() => window.__studio.lastChange?.edit === 'end-gesture', null, { timeout: 60000 });
  await waitIdle();
  const moved = await check();
  const slider = await page.evaluate(() => Number(document.getElementById('morph-t').value));
  assert.ok(moved.t > 0.4 && Math.abs(moved.t - slider) < 1e-9, `the morph is at the slider's t: ${moved.t} vs ${slider}`);
  assert.ok(moved.worst < 1e-5, `t = ${moved.t}: Eq. 13 off by ${moved.worst}`);
  assert.equal(moved.undo, start.undo + 1, 'the drag is one undo step');
  const lat = await page.evaluate(() => window.__studio.latencies.filter((l) => l.edit === 'command'));
  assert.ok(lat.length >= 1, 'the morph follows the slider while it moves');
  report.morphSliderToPixelsMs = stats(lat.map((l) => l.ms));
  await page.screenshot({ path: path.join(artifacts, 'morph.png') });
  await page.keyboard.press('Control+z');
  await page.waitForFunction(() => window.__studio.lastChange?.edit === 'undo', null, { timeout: 60000 });
  await waitIdle();
  const undone = await check();
  assert.equal(undone.t, 0, 'one undo takes the whole drag back');
  assert.ok(undone.worst < 1e-5);
  assert.equal(await page.evaluate(() => Number(document.getElementById('morph-t').value)), 0);
});

test('mesh FFD: a dragged lattice point moves the mesh pixels; STEP export is the accurate FFD', async () => {
  await page.click('#mesh-box');
  await page.waitForFunction(() => window.__studio.objects.some((o) => o.name === 'box'), null, { timeout: 30000 });
  await page.fill('#ffd-degree', '2,2,2');
  await page.fill('#ffd-counts', '4,4,4');
  await page.click('#ffd-place');
  await page.waitForFunction(() => {
    const a = window.__studio;
    const l = a.lattice();
    return a.objects.some((o) => o.name === 'box deformed') && l?.name === 'box lattice' && a.view3d.overlay?.map === l.id && a.view3d.meshes.size > 0;
  }, null, { timeout: 60000 });
  await waitIdle();
  // Only the deformed box in the 3D view: the other meshes unchecked, the volume off.
  const deformed = await page.evaluate(() => window.__studio.objects.find((o) => o.name === 'box deformed').id);
  for (const id of await page.evaluate(() => [...document.querySelectorAll('#objects input[data-mesh]')].map((e) => Number(e.dataset.mesh)))) {
    if (id !== deformed) await page.uncheck(`#objects input[data-mesh="${id}"]`);
  }
  await page.uncheck('#show-volume');
  assert.deepEqual(await page.evaluate(() => [...window.__studio.view3d.meshes.keys()]), [deformed], 'the source box is drawn as its deformed mesh');
  // The 3D view's pixels, the lattice overlay left out.
  const shot = () => page.evaluate(() => {
    const v = window.__studio.view3d;
    const show = v.showLattice;
    v.showLattice = false; v.draw(); v.showLattice = show;
    const gl = v.gl;
    const px = new Uint8Array(v.canvas.width * v.canvas.height * 4);
    gl.readPixels(0, 0, v.canvas.width, v.canvas.height, gl.RGBA, gl.UNSIGNED_BYTE, px);
    return Array.from(px);
  });
  const lit = (px) => { let n = 0; for (let i = 0; i < px.length; i += 4) if (px[i] + px[i + 1] + px[i + 2] > 60) n++; return n; };
  const before = await shot();
  assert.ok(lit(before) > 500, `the box is drawn: ${lit(before)} pixels`);
  const mesh0 = await page.evaluate(async (id) => {
    const { Kind } = await import('./app/protocol.js');
    const f = await window.__studio.client.request(Kind.GetMesh, { id });
    return Array.from(new Float32Array(f.payload, 0, 3 * f.header.vertices));
  }, deformed);
  // Drag the control point at the box's (+x, +y, +z) corner in the 3D view.
  await page.selectOption('#tool', 'lattice');
  const target = await page.evaluate(() => {
    const v = window.__studio.view3d;
    const { mvp } = v.matrices();
    const k = 63;
    const p = [0, 1, 2].map((c) => v.overlay.points[3 * k + c]);
    const [x, y] = v.project(p, mvp);
    const r = v.canvas.getBoundingClientRect();
    return { p, x: r.left + x * r.width / v.canvas.width, y: r.top + y * r.height / v.canvas.height };
  });
  assert.deepEqual(target.p.map((c) => Math.round(c * 1000) / 1000), [0.4, 0.4, 0.4], 'Feng\'s end-interpolating lattice has its corner on the box');
  await page.mouse.move(target.x, target.y);
  await page.mouse.down();
  await page.mouse.move(target.x + 45, target.y - 35, { steps: 6 });
  await page.mouse.up();
  await page.waitForFunction(() => window.__studio.lastChange?.edit === 'end-gesture', null, { timeout: 60000 });
  await waitIdle();
  const mesh1 = await page.evaluate(async (id) => {
    const { Kind } = await import('./app/protocol.js');
    const f = await window.__studio.client.request(Kind.GetMesh, { id });
    return Array.from(new Float32Array(f.payload, 0, 3 * f.header.vertices));
  }, deformed);
  let movedVertices = 0;
  for (let i = 0; i < mesh0.length; i += 3) if (Math.hypot(mesh0[i] - mesh1[i], mesh0[i + 1] - mesh1[i + 1], mesh0[i + 2] - mesh1[i + 2]) > 1e-3) movedVertices++;
  assert.ok(movedVertices >= 1, 'the deformed mesh follows the control point');
  const after = await shot();
  let changed = 0;
  for (let i = 0; i < before.length; i += 4) if (before[i] !== after[i] || before[i + 1] !== after[i + 1] || before[i + 2] !== after[i + 2]) changed++;
  assert.ok(changed > 200, `only ${changed} pixels of the mesh changed`);
  await page.check('#show-lattice');
  await page.screenshot({ path: path.join(artifacts, 'mesh-ffd.png') });
  // Export the accurate FFD as STEP: a download of the trimmed surfaces.
  const [download] = await Promise.all([page.waitForEvent('download', { timeout: 120000 }), page.click('#ffd-step')]);
  assert.equal(download.suggestedFilename(), 'box_deformed.step');
  const text = fs.readFileSync(await download.path(), 'utf8');
  assert.ok(text.startsWith('ISO-10303-21;') && text.trimEnd().endsWith('END-ISO-10303-21;'));
  assert.equal((text.match(/=MANIFOLD_SOLID_BREP\(/g) || []).length, 1, 'a closed shell bounding a solid');
  // Feng's Fig. 7: a cube in a 4×4×4 lattice of degree 2 gives 24 trimmed faces.
  assert.equal((text.match(/=ADVANCED_FACE\(/g) || []).length, 24);
  fs.writeFileSync(path.join(artifacts, 'box_deformed.step'), text);
  await page.waitForFunction(() => /^exported box_deformed.step/.test(document.getElementById('status').textContent), null, { timeout: 30000 });
  await page.check('#show-volume');
  await page.selectOption('#tool', 'drag');
});

test('sculpt: a stroke dragged on a sphere cuts a closed groove live, the view stays still, undo restores it', async () => {
  await page.click('#mesh-sphere');
  await page.waitForFunction(() => window.__studio.objects.some((o) => o.name === 'sphere'), null, { timeout: 30000 });
  const sphere = await page.evaluate(() => window.__studio.objects.filter((o) => o.name === 'sphere').pop().id);
  await page.selectOption('#sculpt-mesh', String(sphere));
  await page.fill('#sculpt-grid', '96');
  await page.click('#sculpt-make');
  await page.waitForFunction(() => {
    const a = window.__studio;
    const o = a.objects.find((x) => x.name === 'sphere sculpt');
    return o && a.view3d.meshes.get(o.id)?.pos && a.tool === 'sculpt';
  }, null, { timeout: 60000 });
  const id = await page.evaluate(() => window.__studio.objects.find((x) => x.name === 'sphere sculpt').id);
  // Only the sculpt object in the 3D view.
  for (const m of await page.evaluate(() => [...document.querySelectorAll('#objects input[data-mesh]')].map((e) => Number(e.dataset.mesh)))) {
    if (m !== id) await page.uncheck(`#objects input[data-mesh="${m}"]`);
  }
  await page.uncheck('#show-volume');
  await page.selectOption('#sculpt-op', 'subtract');
  await page.selectOption('#sculpt-brush', 'sphere');
  await page.$eval('#sculpt-size', (e) => { e.value = '0.12'; e.dispatchEvent(new Event('input')); });
  await waitIdle();
  // The 3D view's pixels without the brush overlay, and the mesh's enclosed volume and open
  // edges (edges not shared by exactly two triangles).
  const shot = () => page.evaluate(() => {
    const a = window.__studio, v = a.view3d;
    const tool = a.tool; a.tool = 'probe'; v.draw(); a.tool = tool;
    const px = new Uint8Array(v.canvas.width * v.canvas.height * 4);
    v.gl.readPixels(0, 0, v.canvas.width, v.canvas.height, v.gl.RGBA, v.gl.UNSIGNED_BYTE, px);
    return Array.from(px);
  });
  const mesh = () => page.evaluate(async (id) => {
    const { Kind } = await import('./app/protocol.js');
    const f = await window.__studio.client.request(Kind.GetMesh, { id });
    const nv = f.header.vertices, nt = f.header.triangles;
    const p = new Float32Array(f.payload, 0, 3 * nv), t = new Uint32Array(f.payload, 24 * nv, 3 * nt);
    const edges = new Map();
    let volume = 0;
    for (let k = 0; k < t.length; k += 3) {
      const [a, b, c] = [t[k], t[k + 1], t[k + 2]];
      const [ax, ay, az, bx, by, bz, cx, cy, cz] = [3 * a, 3 * a + 1, 3 * a + 2, 3 * b, 3 * b + 1, 3 * b + 2, 3 * c, 3 * c + 1, 3 * c + 2].map((i) => p[i]);
      volume += (ax * (by * cz - bz * cy) - ay * (bx * cz - bz * cx) + az * (bx * cy - by * cx)) / 6;
      for (const [u, w] of [[a, b], [b, c], [c, a]]) { const key = Math.min(u, w) * 4294967296 + Math.max(u, w); edges.set(key, (edges.get(key) || 0) + 1); }
    }
    let open = 0; for (const n of edges.values()) if (n !== 2) open++;
    return { volume, open, triangles: nt, bytes: Array.from(new Uint8Array(f.payload)) };
  }, id);
  const before = await shot();
  const m0 = await mesh();
  assert.equal(m0.open, 0, 'the sculpt object is closed');
  const cam0 = await page.evaluate(() => JSON.stringify(window.__studio.view3d.cam));
  // A stroke across the sphere's middle as seen: 80 pixels through the projected centre.
  const c = await page.evaluate(() => {
    const v = window.__studio.view3d;
    const [x, y] = v.project([0, 0, 0], v.matrices().mvp);
    const r = v.canvas.getBoundingClientRect();
    return { x: r.left + x * r.width / v.canvas.width, y: r.top + y * r.height / v.canvas.height };
  });
  await page.evaluate(() => { window.__studio.latencies = []; });
  await page.mouse.move(c.x - 40, c.y);
  await page.mouse.down();
  await page.mouse.move(c.x + 40, c.y, { steps: 10 });
  await page.mouse.up();
  await page.waitForFunction(() => window.__studio.lastChange?.edit === 'end-gesture', null, { timeout: 120000 });
  await waitIdle();
  const lat = (await page.evaluate(() => window.__studio.latencies)).filter((l) => l.edit === 'sculpt');
  assert.ok(lat.length >= 1, 'the stroke was applied while dragging');
  report.sculpt = { grid: 96, strokeEdits: lat.length, dabToPixelsMs: stats(lat.map((l) => l.ms)), serverMs: stats(lat.map((l) => l.server)) };
  assert.equal(await page.evaluate(() => JSON.stringify(window.__studio.view3d.cam)), cam0, 'sculpting does not move the view');
  const m1 = await mesh();
  assert.equal(m1.open, 0, 'the sculpted mesh is closed');
  assert.ok(m1.volume < m0.volume - 0.002, `the groove removes material: ${m0.volume} → ${m1.volume}`);
  const after = await shot();
  let changed = 0;
  for (let i = 0; i < before.length; i += 4) if (before[i] !== after[i] || before[i + 1] !== after[i + 1] || before[i + 2] !== after[i + 2]) changed++;
  assert.ok(changed > 200, `only ${changed} pixels changed`);
  await page.screenshot({ path: path.join(artifacts, 'sculpt.png') });
  // One undo takes the whole stroke back: the same mesh bytes and the same pixels.
  await page.click('#undo');
  await page.waitForFunction(() => window.__studio.lastChange?.edit === 'undo', null, { timeout: 60000 });
  await waitIdle();
  // The view has the restored mesh (its triangle count) before the pixels are compared.
  await page.waitForFunction(([id, n]) => window.__studio.view3d.meshes.get(id)?.idx?.length === 3 * n, [id, m0.triangles], { timeout: 30000 });
  const m2 = await mesh();
  assert.deepEqual(m2.bytes, m0.bytes, 'undo restores the mesh bit for bit');
  await page.waitForTimeout(500);
  const undone = await shot();
  let differ = 0;
  for (let i = 0; i < before.length; i++) if (before[i] !== undone[i]) differ++;
  assert.equal(differ, 0, 'undo restores the pixels');
  await page.check('#show-volume');
  await page.selectOption('#tool', 'drag');
});

test('registration: two scans registered from the page; a dragged correspondence updates the registered scan', async () => {
  // The breathing lung phantom (inhale fixed, exhale moving), written into the studio's root.
  const ph = spawnSync(bin, ['register', 'phantom', '-o', path.join(root, 'lungs'), '--dims', '56,48,40', '--spacing', '5,5,5.5']);
  assert.equal(ph.status, 0, String(ph.stderr));
  for (const f of ['inhale.nii.gz', 'exhale.nii.gz']) {
    await page.evaluate(async (p) => {
      const { Kind } = await import('./app/protocol.js');
      await window.__studio.client.edit(Kind.OpenFile, { root: 0, path: p });
    }, `lungs/${f}`);
  }
  await page.waitForFunction(() => ['inhale.nii.gz', 'exhale.nii.gz'].every((n) => window.__studio.objects.some((o) => o.name === n)), null, { timeout: 30000 });
  const ids = await page.evaluate(() => Object.fromEntries(window.__studio.objects.filter((o) => o.name.endsWith('hale.nii.gz')).map((o) => [o.name, o.id])));
  await page.selectOption('#reg-fixed', String(ids['inhale.nii.gz']));
  await page.selectOption('#reg-moving', String(ids['exhale.nii.gz']));
  await page.fill('#reg-handles', '80');
  await page.fill('#reg-radius', '12');
  await page.selectOption('#handle-method', 'tps');
  const t0 = Date.now();
  await page.click('#reg-run');
  await page.waitForFunction(() => {
    const a = window.__studio;
    const r = a.objects.find((o) => o.name === 'exhale.nii.gz registered');
    return r && a.layer === r.id && a.tool === 'handles' && a.handles.length > 10;
  }, null, { timeout: 120000 });
  report.registration = { setupMs: Date.now() - t0 };
  await waitIdle();
  const n = await page.evaluate(() => window.__studio.handles.length);
  const reg = await page.evaluate(() => window.__studio.objects.find((o) => o.name === 'exhale.nii.gz registered').id);
  // The registered scan is on the fixed grid and differs from the moving scan resampled as is.
  const geo = await page.evaluate(([a, b]) => [window.__studio.byId(a).volume.geometry, window.__studio.byId(b).volume.geometry], [reg, ids['inhale.nii.gz']]);
  assert.deepEqual(geo[0], geo[1], 'registered onto the fixed grid');
  // Drag the correspondence nearest the middle of the axial slice by 3 voxels in x.
  const h = await page.evaluate(() => {
    const a = window.__studio, g = a.volume().volume.geometry;
    const mid = [0, 1, 2].map((i) => g.origin[i] + g.spacing[i] * (g.dims[i] - 1) / 2);
    let best = 0, bd = Infinity;
    a.handles.forEach((h, i) => { const d = Math.hypot(...[0, 1, 2].map((c) => h.target[c] - mid[c])); if (d < bd) { bd = d; best = i; } });
    const t = a.handles[best].target;
    a.setCursor([0, 1, 2].map((c) => (t[c] - g.origin[c]) / g.spacing[c]), -1);
    return { i: best, target: t };
  });
  await waitIdle();
  const z = Math.round(await page.evaluate(() => window.__studio.cursor[2]));
  const slice = () => page.evaluate(async ([id, z]) => {
    const { Kind } = await import('./app/protocol.js');
    const f = await window.__studio.client.request(Kind.GetSlice, { volume: id, axis: 2, index: z });
    return Array.from(new Float32Array(f.payload));
  }, [reg, z]);
  const before = await slice();
  const s = await screenOf(2, h.target);
  await page.mouse.move(s.x, s.y);
  await page.mouse.down();
  await page.mouse.move(s.x + 12, s.y, { steps: 4 });
  await page.mouse.up();
  await page.waitForFunction(() => window.__studio.lastChange?.edit === 'end-gesture', null, { timeout: 120000 });
  await waitIdle();
  const moved = await page.evaluate((i) => window.__studio.handles[i].target, h.i);
  assert.ok(moved[0] - h.target[0] > 1, `the correspondence's target moved: ${h.target} → ${moved}`);
  assert.equal(await page.evaluate(() => window.__studio.handles.length), n, 'no correspondence added or lost');
  const after = await slice();
  assert.notDeepEqual(after, before, 'the registered scan follows the corrected correspondence');
  await page.check('#show-jacobian');
  await waitIdle();
  await page.screenshot({ path: path.join(artifacts, 'registration.png') });
  await page.uncheck('#show-jacobian');
  await page.selectOption('#tool', 'drag');
});

// Canvas position (whole CSS pixels on the page) of a continuous voxel index in slice view
// `axis`.
async function screenOfIndex(axis, idx) {
  return page.evaluate(([axis, idx]) => {
    const v = window.__studio.slices[axis];
    const [cx, cy] = v.toCanvas(idx);
    const r = v.canvas.getBoundingClientRect();
    return { x: Math.round(r.left + cx * r.width / v.canvas.width), y: Math.round(r.top + cy * r.height / v.canvas.height) };
  }, [axis, idx]);
}

test('lobes: lungs found from the page, two clicks on an axial section trace a fissure; the slice shows the lobe colours; undo and the key\'s removal restore it', async () => {
  const dir = path.join(root, 'lobes-ph');
  const ph = spawnSync(bin, ['register', 'phantom', '-o', dir, '--dims', '56,48,40', '--spacing', '5,5,5.5']);
  assert.equal(ph.status, 0, String(ph.stderr));
  const ct = await page.evaluate(async (p) => {
    const { Kind } = await import('./app/protocol.js');
    const c = await window.__studio.client.edit(Kind.OpenFile, { root: 0, path: p });
    return c.header.added[0];
  }, 'lobes-ph/inhale.nii.gz');
  await page.locator('#lobes-setup').scrollIntoViewIfNeeded();
  await page.selectOption('#lobes-ct', String(ct));
  const t0 = Date.now();
  await page.click('#lobes-setup');
  await page.waitForFunction((ct) => {
    const a = window.__studio;
    return a.layer === ct && a.tool === 'lobes' && a.panels.lobesObject()?.id > ct;
  }, ct, { timeout: 120000 });
  report.lobes = { setupMs: Date.now() - t0 };
  const lobes = await page.evaluate(() => window.__studio.panels.lobesObject().id);
  // A key of the phantom's right oblique fissure (its scripted end points), mid-range.
  const script = JSON.parse(fs.readFileSync(path.join(dir, 'lobe_script.json'), 'utf8'));
  const f = script.fissures.find((x) => x.kind === 'right-oblique');
  const key = f.keys[Math.floor(f.keys.length / 2)];
  const k = key.slice;
  await page.evaluate((k) => { const a = window.__studio; const c = a.cursor.slice(); c[2] = k; a.setCursor(c, -1); }, k);
  await waitIdle();
  const from = await screenOfIndex(2, [key.from[0], key.from[1], k]);
  const to = await screenOfIndex(2, [key.to[0], key.to[1], k]);
  // The crosshair where the second click leaves it, so pictures before and after compare.
  await page.evaluate((to) => { const a = window.__studio; a.setCursor(a.slices[2].point({ clientX: to.x, clientY: to.y }), -1); }, to);
  await waitIdle();
  // The lobe labels of the section, from the server; the picture of the axial view.
  const labels = () => page.evaluate(async ([id, k]) => {
    const { Kind } = await import('./app/protocol.js');
    const f = await window.__studio.client.request(Kind.GetSlice, { volume: id, axis: 2, index: k });
    return Array.from(new Float32Array(f.payload));
  }, [lobes, k]);
  const shot = () => page.evaluate(() => { const c = document.getElementById('slice-z'); return Array.from(c.getContext('2d').getImageData(0, 0, c.width, c.height).data); });
  const right = (ls) => new Set(ls.filter((l) => l >= 1 && l <= 3));
  const before = await labels();
  const pictureBefore = await shot();
  assert.equal(right(before).size, 1, `without a key the right lung is one lobe: ${[...right(before)]}`);

  await page.selectOption('#lobes-fissure', 'right-oblique');
  await page.evaluate(() => { window.__studio.latencies = []; });
  await page.mouse.click(from.x, from.y);
  await page.mouse.click(to.x, to.y);
  await page.waitForFunction(() => window.__studio.latencies.some((l) => l.edit === 'command'), null, { timeout: 60000 });
  await waitIdle();
  const lat = await page.evaluate(() => window.__studio.latencies.filter((l) => l.edit === 'command'));
  report.lobes.traceToPixelsMs = lat[0].ms;
  report.lobes.traceServerMs = lat[0].server;
  report.lobes.traceEventToSendMs = lat[0].sent;
  const after = await labels();
  assert.ok(right(after).has(3) && right(after).size >= 2, `the fissure splits the right lung: ${[...right(after)]}`);
  const keys = await page.evaluate(() => window.__studio.panels.lobesObject().recipe.script.fissures.map((x) => [x.kind, x.keys.map((y) => y.slice)]));
  assert.deepEqual(keys, [['right-oblique', [k]]]);
  const pictureAfter = await shot();
  let changed = 0;
  for (let i = 0; i < pictureBefore.length; i += 4) if (pictureBefore[i] !== pictureAfter[i] || pictureBefore[i + 2] !== pictureAfter[i + 2]) changed++;
  assert.ok(changed > 200, `only ${changed} pixels of the axial view changed`);
  await page.screenshot({ path: path.join(artifacts, 'lobes.png') });
  // Each labelled voxel shows its lobe's colour blended over the CT's grey.
  const colours = await page.evaluate(async ([ct, k, labels]) => {
    const { Kind } = await import('./app/protocol.js');
    const { LOBE_RGB, LOBE_ALPHA } = await import('./app/slices.js');
    const app = window.__studio;
    const v = app.slices[2];
    const f = await app.client.request(Kind.GetSlice, { volume: ct, axis: 2, index: k });
    const vals = new Float32Array(f.payload);
    const [lo, hi] = app.currentWindow();
    const lut = app.lut();
    const shown = v.canvas.getContext('2d').getImageData(0, 0, v.canvas.width, v.canvas.height).data;
    const per = {};
    for (let row = 0; row < f.header.height; row++) for (let col = 0; col < f.header.width; col++) {
      const l = Math.round(labels[row * f.header.width + col]);
      if (!LOBE_RGB[l]) continue;
      const t = Math.max(0, Math.min(255, Math.round((vals[row * f.header.width + col] - lo) * 255 / (hi - lo))));
      const want = lut[t].map((g, c) => Math.round(g * (1 - LOBE_ALPHA) + LOBE_RGB[l][c] * LOBE_ALPHA));
      const [x, y] = v.toCanvas([col, f.header.height - 1 - row, k]);
      const o = 4 * (Math.floor(y) * v.canvas.width + Math.floor(x));
      const p = per[l] || (per[l] = { n: 0, ok: 0 });
      p.n++;
      if ([0, 1, 2].every((c) => Math.abs(shown[o + c] - want[c]) <= 2)) p.ok++;
    }
    return per;
  }, [ct, k, after]);
  for (const [l, p] of Object.entries(colours)) assert.ok(p.ok >= 0.9 * p.n, `lobe ${l}: ${p.ok} of ${p.n} voxels in its colour`);
  assert.ok(colours[3]?.n > 10, 'the right lower lobe is shown');

  // Undo: the labels and the picture are as before the key; redo brings the key back.
  await page.keyboard.press('Control+z');
  await page.waitForFunction(() => window.__studio.lastChange?.edit === 'undo', null, { timeout: 60000 });
  await waitIdle(500);
  assert.deepEqual(await labels(), before);
  const undone = await shot();
  let differ = 0;
  for (let i = 0; i < undone.length; i++) if (undone[i] !== pictureBefore[i]) differ++;
  assert.equal(differ, 0, 'undo restores the picture');
  await page.keyboard.press('Control+Shift+z');
  await page.waitForFunction(() => window.__studio.lastChange?.edit === 'redo', null, { timeout: 60000 });
  await waitIdle();
  assert.deepEqual(await labels(), after);
  // The key listed in the panel is removed with its button.
  const x = page.locator(`#lobes-keys li[data-slice="${k}"] button`);
  await x.scrollIntoViewIfNeeded();
  await x.click();
  await page.waitForFunction(() => window.__studio.panels.lobesObject().recipe.script.fissures.length === 0, null, { timeout: 60000 });
  await waitIdle();
  assert.deepEqual(await labels(), before);
  // A click off the lungs' sections is refused with a message; nothing changes.
  const err = await page.evaluate(async (id) => {
    const { Kind } = await import('./app/protocol.js');
    try {
      await window.__studio.client.edit(Kind.Command, { command: 'trace-lobes', id, fissure: 'left-oblique', slice: 0, from: [1, 1], to: [500, 2] });
      return 'accepted';
    } catch (e) { return e.message; }
  }, lobes);
  assert.match(err, /outside|holds no left lung/);
  await page.selectOption('#tool', 'drag');
});
