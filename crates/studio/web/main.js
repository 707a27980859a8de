// The studio page: connects, keeps the object list, and turns pointer gestures into scene
// commands; redraws what each Change names. No modelling happens here.
import { Client, Kind } from './protocol.js';
import { SliceView, physical } from './slices.js';
import { View3D } from './view3d.js';
import { setupPanels } from './panels.js';

const $ = (id) => document.getElementById(id);

// The Scene's `map.kind` of a B-spline lattice map: the map JSON kind
// (`volmorph_lattice::json::LATTICE_JSON_KIND`; PROTOCOL.md).
export const LATTICE_KIND = 'bspline-lattice';

// Colour of deformed meshes in the 3D view (RGB, 0‥1), apart from other meshes.
export const DEFORMED_RGB = [0.45, 0.75, 0.95];

// A key typed into a text field (not a shortcut): text areas and inputs other than sliders,
// check boxes and buttons.
export function typing(e) {
  const t = e.target;
  return t.tagName === 'TEXTAREA' || (t.tagName === 'INPUT' && !['range', 'checkbox', 'radio', 'button'].includes(t.type));
}

class App {
  constructor() {
    this.objects = [];
    this.window = new Map();
    this.cursor = [0, 0, 0];
    this.tool = 'drag';
    this.radius = 0.45;
    this.gestureNo = 1;
    this.latencies = [];
    this.inputAt = new Map();
    this.handles = [];
    this.colormap = 'grey';
    // Long jobs of this page: request → {label, done, total} from Progress frames.
    this.jobs = new Map();
    // Requests already answered (a late Progress frame of one is ignored), and the abort
    // controllers of downloads.
    this.answered = new Set();
    this.aborts = new Map();
    // The lattice whose control points the 3D view shows and drags (null: the first).
    this.activeLattice = null;
    // Meshes the 3D view leaves out (unchecked in the object list).
    this.hiddenMeshes = new Set();
    // Whether the slices show the lobe labels of the Lobes panel's object.
    this.showLobes = true;
  }

  async start() {
    const url = new URL('ws', location.href);
    url.protocol = 'ws:';
    this.client = await new Client(url.href).open();
    const w = await this.client.request(Kind.Hello, {});
    this.page = w.header.page;
    this.client.page = this.page;
    this.luts = w.header.colormaps;
    this.roots = w.header.roots;
    for (const name of Object.keys(this.luts)) $('colormap').add(new Option(name, name));
    this.client.on(Kind.Changed, (f) => this.onChanged(f));
    this.client.on(Kind.Scene, (f) => this.setScene(f.header));
    this.client.on(Kind.Error, (f) => this.error(f.header.message, f.header));
    this.client.on(-1, (f) => this.error(f.header.message));
    this.client.on(Kind.Progress, (f) => this.onProgress(f.header));
    this.client.onAnswered = (r) => this.jobEnded(r);
    this.slices = [new SliceView($('slice-x'), 0, this), new SliceView($('slice-y'), 1, this), new SliceView($('slice-z'), 2, this)];
    this.view3d = new View3D($('view3d'), this);
    this.bind();
    setupPanels(this);
    await this.setScene(w.header.scene);
    this.status('ready');
    document.body.dataset.ready = '1';
  }

  bind() {
    $('undo').onclick = () => this.client.send(Kind.Undo, {});
    $('redo').onclick = () => this.client.send(Kind.Redo, {});
    document.addEventListener('keydown', (e) => {
      if (typing(e)) return;
      if ((e.ctrlKey || e.metaKey) && e.key.toLowerCase() === 'z') {
        e.preventDefault();
        this.client.send(e.shiftKey ? Kind.Redo : Kind.Undo, {});
      } else if ((e.ctrlKey || e.metaKey) && e.key.toLowerCase() === 'y') {
        e.preventDefault(); this.client.send(Kind.Redo, {});
      }
    });
    $('tool').onchange = (e) => { this.tool = e.target.value; this.redrawSlices(); this.view3d.redraw(); };
    $('radius').oninput = (e) => { this.radius = Number(e.target.value); $('radius-out').value = e.target.value; this.redrawSlices(); this.view3d.redraw(); };
    $('layer').onchange = (e) => this.showLayer(Number(e.target.value));
    $('colormap').onchange = (e) => { this.colormap = e.target.value; this.redrawSlices(); };
    $('wl-lo').onchange = $('wl-hi').onchange = () => this.setWindow([Number($('wl-lo').value), Number($('wl-hi').value)]);
    $('wl-auto').onclick = () => { const v = this.volume(); if (v) { this.window.delete(v.id); this.reloadSlices(); } };
    $('new-teapot').onclick = () => this.client.send(Kind.Setup, { setup: 'phantom', model: 'teapot', size: Number($('teapot-size').value) });
    $('job-cancel').onclick = () => this.cancelJob(Number($('job-cancel').dataset.request));
    $('setup-handles').onclick = () => {
      const v = this.volume();
      if (v) this.client.send(Kind.Setup, { setup: 'handles', volume: v.id, method: $('handle-method').value });
    };
    $('setup-drag').onclick = () => {
      const v = this.volume();
      if (v) this.client.send(Kind.Setup, { setup: 'direct-manipulation', volume: v.id, counts: 9, level: 127 });
    };
    document.querySelectorAll('[data-view]').forEach((b) => { b.onclick = () => this.view3d.frame(null, b.dataset.view); });
    $('show-volume').onchange = (e) => { this.view3d.showVolume = e.target.checked; this.view3d.draw(); };
    $('show-grid').onchange = (e) => { this.view3d.showGrid = e.target.checked; this.refreshGrid(); };
    $('show-jacobian').onchange = (e) => { this.showJacobian = e.target.checked; this.reloadSlices(); };
    $('show-lobes').onchange = (e) => { this.showLobes = e.target.checked; this.reloadSlices(); };
    $('show-lattice').onchange = (e) => { this.view3d.showLattice = e.target.checked; this.view3d.draw(); };
  }

  status(m) { $('status').textContent = m; $('status').className = ''; }
  // A failure, shown in red; a job stopped by Cancel is not a failure.
  error(m, h) {
    const cancelled = h?.cancelled || m === 'cancelled';
    $('status').textContent = cancelled ? 'cancelled: nothing changed' : m;
    $('status').className = cancelled ? 'cancelled' : 'error';
  }

  // Progress of a long job of this page: the bar shows the newest job running.
  onProgress(h) {
    if (this.answered.has(h.request)) return;
    this.jobs.set(h.request, h);
    this.showJob();
  }

  jobEnded(r) {
    this.answered.add(r);
    if (this.answered.size > 4096) this.answered.delete(this.answered.values().next().value);
    this.aborts.delete(r);
    if (this.jobs.delete(r)) this.showJob();
  }

  showJob() {
    const last = [...this.jobs.entries()].pop();
    $('job').hidden = !last;
    if (!last) return;
    const [r, h] = last;
    $('job-label').textContent = h.total ? `${h.label} ${Math.round(100 * h.done / h.total)}%` : h.label;
    const bar = $('job-bar');
    if (h.total) bar.value = h.done / h.total; else bar.removeAttribute('value');
    $('job-cancel').dataset.request = r;
  }

  // Stop job `r`: the server answers it with a cancelled Error and changes nothing.
  cancelJob(r) {
    if (!r) return;
    this.aborts.get(r)?.abort();
    this.client.send(Kind.Cancel, { request: r });
  }

  // Download object `id` exported as `name` (format by extension), reporting progress and
  // cancellable like a job; resolves to the bytes (or null when cancelled).
  async download(id, name) {
    const r = this.client.reserve();
    const abort = new AbortController();
    this.aborts.set(r, abort);
    try {
      const res = await fetch(`download/${id}/${encodeURIComponent(name)}?page=${this.page}&request=${r}`, { signal: abort.signal });
      if (!res.ok) throw new Error(`export of ${name} failed: ${await res.text()}`);
      const bytes = await res.arrayBuffer();
      const a = document.createElement('a');
      a.href = URL.createObjectURL(new Blob([bytes], { type: 'application/octet-stream' }));
      a.download = name;
      document.body.append(a); a.click(); a.remove();
      setTimeout(() => URL.revokeObjectURL(a.href), 10000);
      this.status(`exported ${name} (${bytes.byteLength} bytes)`);
      return bytes;
    } catch (e) {
      if (e.name === 'AbortError' || /cancelled/.test(e.message)) { this.error('cancelled'); return null; }
      this.error(e.message);
      return null;
    } finally {
      this.jobEnded(r);
    }
  }

  byId(id) { return this.objects.find((o) => o.id === id); }
  volume() { return this.byId(this.layer); }
  // The lattice the 3D view shows and drags: the one made active (a mesh-FFD lattice), else
  // the first.
  lattice() {
    const all = this.objects.filter((o) => o.map && o.map.kind === LATTICE_KIND);
    return all.find((o) => o.id === this.activeLattice) || all[0];
  }
  // The lattice a slice drag moves: the map of the shown volume's warp, else lattice().
  volumeLattice() {
    const m = this.byId(this.volume()?.recipe?.map);
    return m?.map?.kind === LATTICE_KIND ? m : this.lattice();
  }
  setActiveLattice(id) {
    this.activeLattice = id;
    const l = this.lattice();
    if (l) this.loadOverlay(l.id).catch((e) => this.error(e.message));
    for (const li of document.querySelectorAll('#objects li')) li.classList.toggle('active', Number(li.dataset.id) === l?.id);
  }
  // Meshes the 3D view draws: not those hidden, nor the source of a deformed mesh (the
  // deformed one is drawn in its place).
  shownMeshes() {
    const sources = new Set(this.objects.filter((o) => o.recipe?.recipe === 'deformed-mesh').map((o) => o.recipe.mesh));
    return this.objects.filter((o) => o.mesh && !sources.has(o.id) && !this.hiddenMeshes.has(o.id));
  }
  // The newest handle map (the one a handle set-up made last).
  handleMap() { return this.objects.filter((o) => o.map && o.map.kind === 'handles').pop(); }
  lut() { return this.luts[this.colormap]; }

  // The map whose Jacobian the overlay shows: the shown volume's warp map, else the lattice,
  // else the newest handle map.
  jacobianMap() {
    const r = this.volume()?.recipe;
    return (r?.map !== undefined && r.map !== null && this.byId(r.map)) || this.lattice() || this.handleMap();
  }

  // Map the deformed grid again (through the shown volume's map).
  refreshGrid() { return this.view3d.setGrid(this.jacobianMap()?.id).catch((e) => this.error(e.message)); }

  // A slice view drew a Jacobian slice (or none): show the folded voxels it counted.
  jacobianShown() {
    const js = this.slices.map((s) => s.jacobian).filter(Boolean);
    $('jacobian-info').textContent = js.length ? `folded: ${js.map((j) => j.folded).join(' / ')}` : '';
  }
  // The lobe-label volume the slices colour (the Lobes panel's object), when the overlay is on
  // and it lies on the shown volume's voxel grid.
  lobesOverlay() {
    if (!this.showLobes) return null;
    const o = this.panels?.lobesObject();
    const v = this.volume();
    if (!o?.volume || !v) return null;
    const a = o.volume.geometry.dims, b = v.volume.geometry.dims;
    return a.every((d, i) => d === b[i]) ? o : null;
  }
  currentWindow() { return this.window.get(this.layer) || [0, 1]; }

  setWindow(w) {
    if (!(w[1] > w[0])) return;
    this.window.set(this.layer, w);
    this.windowChanged(true);
  }

  windowChanged(redraw) {
    const [lo, hi] = this.currentWindow();
    $('wl-lo').value = +lo.toPrecision(5); $('wl-hi').value = +hi.toPrecision(5);
    if (redraw) this.redrawSlices();
  }

  // The object list: pick the volume shown (the newest derived volume by default).
  async setScene(s) {
    this.objects = s.objects;
    this.undoDepth = s.undo; this.redoDepth = s.redo;
    const ul = $('objects'); ul.textContent = '';
    const sel = $('layer'); sel.textContent = '';
    for (const o of s.objects) {
      const li = document.createElement('li');
      if (o.mesh) {
        const eye = Object.assign(document.createElement('input'), { type: 'checkbox', checked: !this.hiddenMeshes.has(o.id), title: 'show in the 3D view' });
        eye.dataset.mesh = o.id;
        eye.onchange = () => { if (eye.checked) this.hiddenMeshes.delete(o.id); else this.hiddenMeshes.add(o.id); this.syncMeshes(); };
        li.append(eye);
      }
      li.append(`${o.id} ${o.name} (${o.kind}${o.recipe ? ' ' + o.recipe.recipe : ''})`);
      li.dataset.id = o.id;
      if (o.error) { li.classList.add('error'); li.title = o.error; }
      // A lattice clicked becomes the one the 3D view shows and drags.
      if (o.map?.kind === LATTICE_KIND) li.onclick = (e) => { if (e.target === li) this.setActiveLattice(o.id); };
      ul.append(li);
      if (o.volume) sel.add(new Option(`${o.id} ${o.name}`, o.id));
    }
    const vols = s.objects.filter((o) => o.volume);
    if (!this.byId(this.layer)?.volume) {
      const pick = vols.filter((o) => o.kind === 'derived' && o.recipe?.recipe === 'warp').pop() || vols[vols.length - 1];
      if (pick) await this.showLayer(pick.id);
    }
    if (this.layer !== undefined) sel.value = this.layer;
    if (this.activeLattice !== null && !this.byId(this.activeLattice)) this.activeLattice = null;
    const active = this.lattice();
    for (const li of ul.children) li.classList.toggle('active', Number(li.dataset.id) === active?.id);
    this.syncMeshes();
    for (const over of [this.lattice(), this.handleMap()]) if (over) this.loadOverlay(over.id).catch((e) => this.error(e.message));
    this.panels?.sceneChanged();
  }

  // The 3D view draws exactly the shown meshes (deformed meshes in their own colour).
  syncMeshes() {
    const meshes = this.shownMeshes();
    for (const id of [...this.view3d.meshes.keys()]) if (!meshes.some((m) => m.id === id)) this.view3d.dropMesh(id);
    for (const m of meshes) if (!this.view3d.meshes.has(m.id)) this.view3d.setMesh(m.id, this.meshColor(m)).catch((e) => this.error(e.message));
  }

  meshColor(o) { return o.recipe?.recipe === 'deformed-mesh' ? DEFORMED_RGB : undefined; }

  async showLayer(id) {
    const v = this.byId(id);
    if (!v || !v.volume) return;
    const first = this.layer === undefined;
    this.layer = id;
    const g = v.volume.geometry;
    if (first || this.cursor.some((c, a) => c < 0 || c > g.dims[a] - 1)) this.cursor = g.dims.map((d) => (d - 1) / 2);
    const ext = Math.max(...g.dims.map((d, a) => d * g.spacing[a]));
    const r = $('radius');
    r.max = (ext / 2).toPrecision(3); r.min = (ext / 200).toPrecision(3); r.step = (ext / 1000).toPrecision(3);
    if (this.radius > ext / 2 || this.radius < ext / 200) { this.radius = ext * 0.2; }
    r.value = this.radius; $('radius-out').value = (+this.radius).toPrecision(3);
    await Promise.all([...this.slices.map((s) => s.load()), this.view3d.setVolume(id).catch((e) => this.error(e.message))]);
  }

  async loadOverlay(id) {
    const f = await this.client.request(Kind.GetLattice, { map: id });
    if (f.header.kind === 'lattice' ? f.header.map === this.lattice()?.id : !this.lattice()) this.view3d.setOverlay(f);
    if (f.header.kind === 'handles') {
      const p = new Float32Array(f.payload);
      this.handles = [];
      for (let h = 0; h < f.header.count; h++) this.handles.push({ source: [...p.slice(6 * h, 6 * h + 3)], target: [...p.slice(6 * h + 3, 6 * h + 6)] });
      this.redrawSlices();
    }
  }

  reloadSlices() { return Promise.all(this.slices.map((s) => s.load())); }

  // Send the shown volume to the 3D view again: one transfer at a time, the newest state
  // next (a drag's moves do not queue volume transfers behind each other).
  refreshVolume() {
    if (this.volumeBusy) { this.volumeWanted = true; return; }
    this.volumeBusy = true;
    setTimeout(() => {
      this.view3d.setVolume(this.layer).catch((e) => this.error(e.message)).finally(() => {
        this.volumeBusy = false;
        if (this.volumeWanted) { this.volumeWanted = false; this.refreshVolume(); }
      });
    }, 150);
  }
  redrawSlices() { for (const s of this.slices) s.render(); }

  setCursor(idx, fromAxis) {
    const old = this.cursor;
    this.cursor = idx.slice();
    this.view3d.redraw();
    for (const s of this.slices) {
      if (Math.round(old[s.axis]) !== Math.round(idx[s.axis]) && s.axis !== fromAxis) s.load();
      else s.render();
    }
  }

  showCursor(idx, value) {
    const v = this.volume(); if (!v) return;
    const p = physical(v.volume.geometry, idx);
    $('cursor').textContent = `index (${idx.map((x) => x.toFixed(1)).join(', ')})  physical (${p.map((x) => x.toFixed(3)).join(', ')})  value ${value === null ? '–' : +value.toPrecision(6)}`;
  }

  cursorPhysical() { return physical(this.volume().volume.geometry, this.cursor); }

  newGesture() { return this.gestureNo++; }

  typing(e) { return typing(e); }

  // Request `r` was sent for input event `e`: its Changed is timed from the event (a
  // performance mark `input-R` at the event's time stamp).
  markInput(r, e) {
    const t = e && e.timeStamp > 0 ? e.timeStamp : performance.now();
    this.inputAt.set(r, t);
    if (this.inputAt.size > 4096) this.inputAt.delete(this.inputAt.keys().next().value);
    try { performance.mark(`input-${r}`, { startTime: t }); } catch (_) { /* marks are optional */ }
  }

  gestureStart(idx, e, axis) {
    const v = this.volume(); if (!v) return;
    this.view3d.interact();
    this.g = { idx, axis, p: physical(v.volume.geometry, idx), id: this.newGesture(), moved: false };
    if (this.tool === 'handles') this.panels.handleDown(this.g, e);
  }

  gestureMove(idx, e) {
    if (!this.g) return;
    const v = this.volume();
    const target = physical(v.volume.geometry, idx);
    this.g.moved = true;
    this.view3d.interact();
    if (this.tool === 'drag') {
      const l = this.volumeLattice();
      if (!l) { this.error('no lattice: press "Lattice + warp" first'); return; }
      const r = this.client.send(Kind.Drag, { gesture: this.g.id, map: l.id, start: this.g.p, target, radius: this.radius });
      this.markInput(r, e);
    } else if (this.tool === 'handles') {
      this.panels.handleMove(this.g, target, e);
    } else if (this.tool === 'sculpt') {
      this.panels.sculptMove(this.g, target, e);
    } else {
      this.setCursor(idx, -1);
    }
  }

  gestureEnd(idx, e) {
    if (!this.g) return;
    if ((this.tool === 'drag' || this.tool === 'sculpt') && this.g.moved) this.endGesture(this.g.id);
    if (this.tool === 'handles') this.panels.handleUp(this.g, idx, e);
    if (this.tool === 'lobes') this.panels.lobeClick(this.g, e);
    this.g = null;
  }

  endGesture(id) { this.client.send(Kind.EndGesture, { gesture: id }); }

  moveControlPoints(map, gesture, points, e) {
    this.markInput(this.client.send(Kind.MoveControlPoints, { gesture, map, points }), e);
  }

  async transferChanged() {
    const v = this.view3d;
    if (!v.range) return;
    const text = this.panels ? this.panels.transferText(v.range) : null;
    if (!text) return;
    try {
      const f = await this.client.request(Kind.GetTransfer, { text, min: v.range[0], max: v.range[1] });
      v.setLut(new Uint8Array(f.payload));
    } catch (e) { this.error(e.message); }
  }

  // A Change: refresh what it names; time an edit from its input event to the pixels.
  //
  // Changes are handled concurrently, and a light one (an end of gesture) can finish before a
  // heavy one that arrived earlier. `lastChange` follows the server's order: it is the newest
  // change that, with every change before it, has been handled (or failed).
  async onChanged(f) {
    const seq = this.changeSeq = (this.changeSeq || 0) + 1;
    try {
      await this.applyChanged(f);
    } finally {
      this.settled = this.settled || new Map();
      this.settled.set(seq, f.header);
      this.handledSeq = this.handledSeq || 0;
      while (this.settled.has(this.handledSeq + 1)) {
        this.handledSeq += 1;
        this.lastChange = this.settled.get(this.handledSeq);
        this.settled.delete(this.handledSeq);
      }
      this.changes = (this.changes || 0) + 1;
    }
  }

  async applyChanged(f) {
    const h = f.header;
    const mine = h.page === this.page;
    const t0 = mine ? this.inputAt.get(h.request) : undefined;
    const sent = mine ? this.client.sentAt.get(h.request) : undefined;
    this.undoDepth = h.undo; this.redoDepth = h.redo;
    const jobs = [];
    const structural = h.added.length || h.removed.length || h.edit === 'undo' || h.edit === 'redo' || h.edit === 'setup';
    if (structural) {
      const s = await this.client.request(Kind.ListObjects, {});
      await this.setScene(s.header);
      // A set-up that made a warped volume shows it.
      const warp = h.added.map((id) => this.byId(id)).find((o) => o?.recipe?.recipe === 'warp');
      if (h.edit === 'setup' && warp) { $('layer').value = warp.id; await this.showLayer(warp.id); }
      // A mesh-FFD set-up of this page: its lattice is the one the 3D view shows and drags.
      const ffd = h.added.map((id) => this.byId(id)).find((o) => o?.recipe?.recipe === 'deformed-mesh');
      if (h.edit === 'setup' && ffd && h.page === this.page) this.setActiveLattice(ffd.recipe.map);
    } else if (h.edit === 'command') {
      // A command that added or removed nothing (a recipe, a handle, a model's text) changes
      // only the objects' descriptions: refresh them while the pictures reload.
      jobs.push(this.client.request(Kind.ListObjects, {}).then((s) => this.setScene(s.header)));
    }
    const touched = new Set([...h.modified, ...h.added]);
    // The slices first: an edit is timed from its input event to the frame that composites
    // its new slice pixels.
    let slices = Promise.resolve();
    if (touched.has(this.layer)) {
      slices = this.reloadSlices();
      this.refreshVolume();
    } else if (touched.has(this.lobesOverlay()?.id)) {
      slices = this.reloadSlices();
    }
    const timed = t0 === undefined ? Promise.resolve()
      : slices.then(() => new Promise((r) => requestAnimationFrame(() => r()))).then(() => {
        const end = performance.now();
        this.latencies.push({ edit: h.edit, ms: end - t0, server: h.ms, sent: sent - t0, request: h.request });
        if (this.latencies.length > 4096) this.latencies.shift();
        try { performance.measure(`${h.edit}-to-pixels`, { start: t0, end }); } catch (_) { /* marks are optional */ }
        $('timing').textContent = `server ${h.ms.toFixed(1)} ms · on screen ${(end - t0).toFixed(1)} ms`;
      });
    jobs.push(slices, timed);
    if (this.view3d.showGrid && (touched.has(this.jacobianMap()?.id) || structural)) jobs.push(this.refreshGrid());
    const shown = new Set(this.shownMeshes().map((m) => m.id));
    for (const id of touched) {
      const o = this.byId(id);
      if (o?.mesh && shown.has(id)) jobs.push(this.view3d.setMesh(id, this.meshColor(o)).catch((e) => this.error(e.message)));
      if (o?.map) jobs.push(this.loadOverlay(id).catch((e) => this.error(e.message)));
    }
    if (t0 === undefined) $('timing').textContent = `server ${h.ms.toFixed(1)} ms`;
    await Promise.all(jobs);
    const errs = h.errors.map((e) => `${e.object}: ${e.message}`).join('; ');
    if (errs) this.error(errs);
    else if (h.edit !== 'end-gesture') this.status(`${h.edit} done`);
  }
}

const app = new App();
window.__studio = app;
app.start().catch((e) => { document.getElementById('status').textContent = e.message; document.getElementById('status').className = 'error'; });
