// The side panels: transfer-function editor, F-rep editor and parameter sliders, handles,
// registration, lobes, sculpting, files.
import { Kind } from './protocol.js';

const $ = (id) => document.getElementById(id);

const DEFAULT_FREP = `my_model(x[3], a[1]) {
  -- a sphere of radius a[1]
  my_model = a[1]*a[1] - x[1]*x[1] - x[2]*x[2] - x[3]*x[3];
}`;

export function setupPanels(app) {
  const P = {
    // Opacity nodes over the value range, as fractions (t, opacity per voxel length).
    nodes: [[0, 0], [0.45, 0], [0.6, 0.35], [1, 0.6]],
    sceneChanged() {
      const f = app.objects.find((o) => o.kind === 'frep');
      if (f && !P.frepEdited) $('frep-src').value = f.frep.source;
      P.frepSliders(f);
      P.morphChanged();
      P.ffdChanged();
      P.sculptChanged();
      P.registerChanged();
      P.lobesChanged();
      const hm = app.handleMap();
      if (hm) $('handle-method').value = String(hm.map.method).toLowerCase();
    },
  };
  app.panels = P;

  // Transfer function: drag a node; the table is computed by the server from the text.
  const tf = $('tf');
  const drawTf = () => {
    const c = tf.getContext('2d');
    c.fillStyle = '#111'; c.fillRect(0, 0, tf.width, tf.height);
    c.strokeStyle = '#9cf'; c.beginPath();
    P.nodes.forEach(([t, a], i) => { const x = t * tf.width, y = (1 - a) * tf.height; if (i) c.lineTo(x, y); else c.moveTo(x, y); });
    c.stroke();
    c.fillStyle = '#fc6';
    for (const [t, a] of P.nodes) { c.beginPath(); c.arc(t * tf.width, (1 - a) * tf.height, 4, 0, 7); c.fill(); }
  };
  P.transferText = (range) => {
    const lut = app.lut();
    const text = P.nodes.map(([t, a]) => {
      const c = lut[Math.round(t * 255)].map((x) => (x / 255).toFixed(3));
      return `${(range[0] + t * (range[1] - range[0])).toPrecision(6)}:${c.join(',')},${a.toFixed(3)}`;
    }).join('; ');
    $('tf-text').value = text;
    return text;
  };
  let dragNode = -1;
  tf.onpointerdown = (e) => {
    const r = tf.getBoundingClientRect();
    const x = (e.clientX - r.left) / r.width, y = 1 - (e.clientY - r.top) / r.height;
    let best = -1, bd = 0.01;
    P.nodes.forEach(([t, a], i) => { const d = (t - x) ** 2 + (a - y) ** 2; if (d < bd) { bd = d; best = i; } });
    dragNode = best; tf.setPointerCapture(e.pointerId);
  };
  tf.onpointermove = (e) => {
    if (dragNode < 0 || !(e.buttons & 1)) return;
    const r = tf.getBoundingClientRect();
    const x = Math.max(0, Math.min(1, (e.clientX - r.left) / r.width)), y = Math.max(0, Math.min(1, 1 - (e.clientY - r.top) / r.height));
    const lo = dragNode ? P.nodes[dragNode - 1][0] + 1e-3 : 0, hi = dragNode < P.nodes.length - 1 ? P.nodes[dragNode + 1][0] - 1e-3 : 1;
    P.nodes[dragNode] = [dragNode === 0 ? 0 : dragNode === P.nodes.length - 1 ? 1 : Math.max(lo, Math.min(hi, x)), y];
    drawTf(); app.transferChanged();
  };
  tf.onpointerup = () => { dragNode = -1; };
  $('tf-text').onchange = async () => {
    const v = app.view3d;
    try {
      const f = await app.client.request(Kind.GetTransfer, { text: $('tf-text').value, min: v.range[0], max: v.range[1] });
      v.setLut(new Uint8Array(f.payload));
    } catch (e) { app.error(e.message); }
  };
  drawTf();

  // F-rep: the model is replaced only when it compiles; an error names its line and column
  // and the previous model stays.
  $('frep-src').value = DEFAULT_FREP;
  $('frep-src').oninput = () => { P.frepEdited = true; };
  P.applyFrep = async () => {
    const source = $('frep-src').value;
    const params = { 1: 0.6 };
    const model = app.objects.find((o) => o.kind === 'frep');
    $('frep-error').textContent = '';
    try {
      if (model) {
        await app.client.edit(Kind.Command, { command: 'replace-frep', id: model.id, source, params });
      } else {
        const grid = app.volume();
        if (!grid) throw new Error('open or make a volume first: the model is sampled on its grid');
        const c = await app.client.edit(Kind.Command, { command: 'add-frep', name: 'model', source, params });
        const id = c.header.added[0];
        const s = await app.client.edit(Kind.Command, { command: 'add-derived', name: 'model-sampled', recipe: { recipe: 'frep-sampled', model: id, map: null, grid: grid.id } });
        await app.client.edit(Kind.Command, { command: 'add-derived', name: 'model-surface', recipe: { recipe: 'isosurface', volume: s.header.added[0], level: 0, inside_below: false, method: 'marching-cubes' } });
      }
      app.status('model updated');
    } catch (e) {
      const h = e.header || {};
      $('frep-error').textContent = h.line ? `line ${h.line}, column ${h.column}: ${e.message}` : e.message;
      $('frep-error').dataset.line = h.line || '';
    }
  };
  $('frep-apply').onclick = P.applyFrep;
  // Another model from the text (the two ends of a metamorphosis are two models).
  $('frep-new').onclick = async () => {
    $('frep-error').textContent = '';
    try {
      const n = app.objects.filter((o) => o.kind === 'frep').length + 1;
      await app.client.edit(Kind.Command, { command: 'add-frep', name: `model ${n}`, source: $('frep-src').value, params: { 1: 0.6 } });
      app.status('model added');
    } catch (e) {
      const h = e.header || {};
      $('frep-error').textContent = h.line ? `line ${h.line}, column ${h.column}: ${e.message}` : e.message;
    }
  };

  // Metamorphosis (Savchenko–Pasko Eq. 13): two models, a schedule and the time t. The
  // morph is a derived object (recipe frep-morph) sampled on the shown volume's grid, with its
  // zero isosurface; the slider sets t (a drag of it is one gesture: one undo step).
  const fill = (sel, items, label) => {
    const keep = sel.value;
    sel.textContent = '';
    for (const o of items) sel.add(new Option(label(o), o.id));
    if (items.some((o) => String(o.id) === keep)) sel.value = keep;
  };
  const morphObject = () => app.objects.filter((o) => o.recipe?.recipe === 'frep-morph').pop();
  let morphGesture = null;
  P.morphChanged = () => {
    const models = app.objects.filter((o) => o.kind === 'frep');
    fill($('morph-from'), models, (o) => `${o.id} ${o.name}`);
    fill($('morph-to'), models, (o) => `${o.id} ${o.name}`);
    if ($('morph-to').value === $('morph-from').value && models.length > 1) $('morph-to').value = models[models.length - 1].id;
    const m = morphObject();
    if (m && morphGesture === null) {
      $('morph-t').value = m.recipe.t; $('morph-t-out').value = (+m.recipe.t).toFixed(2);
      $('morph-schedule').value = m.recipe.schedule;
    }
  };
  $('morph-make').onclick = async () => {
    const grid = app.volume();
    const from = Number($('morph-from').value), to = Number($('morph-to').value);
    try {
      if (!grid) throw new Error('open or make a volume first: the metamorphosis is sampled on its grid');
      if (!from || !to || from === to) throw new Error('choose two different F-rep models ("New model" adds one)');
      const t = Number($('morph-t').value);
      const c = await app.client.edit(Kind.Command, { command: 'add-derived', name: 'morph', recipe: { recipe: 'frep-morph', from, to, t, schedule: $('morph-schedule').value, grid: grid.id } });
      await app.client.edit(Kind.Command, { command: 'add-derived', name: 'morph-surface', recipe: { recipe: 'isosurface', volume: c.header.added[0], level: 0, inside_below: false, method: 'marching-cubes' } });
      app.status('metamorphosis made');
    } catch (e) { app.error(e.message, e.header); }
  };
  const setMorph = (changes, gesture) => {
    const m = morphObject();
    if (!m) { app.error('no metamorphosis: press "Morph" first'); return null; }
    return app.client.send(Kind.Command, { command: 'set-recipe', id: m.id, recipe: { ...m.recipe, ...changes }, ...(gesture === undefined ? {} : { gesture }) });
  };
  $('morph-t').oninput = (e) => {
    if (!morphObject()) return;
    if (morphGesture === null) morphGesture = app.newGesture();
    $('morph-t-out').value = Number($('morph-t').value).toFixed(2);
    const r = setMorph({ t: Number($('morph-t').value) }, morphGesture);
    if (r) app.markInput(r, e);
  };
  $('morph-t').onchange = () => { if (morphGesture !== null) { app.endGesture(morphGesture); morphGesture = null; } };
  $('morph-schedule').onchange = () => { if (morphObject()) setMorph({ schedule: $('morph-schedule').value }); };

  // Mesh FFD (Feng 2002): a mesh (opened or generated), Feng's identity-Jacobian lattice
  // around it (degree, control points and form chosen here), its control points dragged with
  // the Lattice points tool (the vertex FFD follows live), and the accurate FFD exported as
  // STEP.
  P.ffdChanged = () => {
    const meshes = app.objects.filter((o) => o.mesh && o.recipe?.recipe !== 'deformed-mesh');
    fill($('ffd-mesh'), meshes, (o) => `${o.id} ${o.name}`);
  };
  for (const shape of ['sphere', 'box', 'torus']) {
    $(`mesh-${shape}`).onclick = () => app.client.edit(Kind.Setup, { setup: 'mesh', shape })
      .then((c) => { $('ffd-mesh').value = c.header.added[0]; app.status(`${shape} added`); })
      .catch((e) => app.error(e.message, e.header));
  }
  const triple = (id) => {
    const v = $(id).value.split(',').map((x) => Number(x.trim()));
    if (v.length !== 3 || !v.every((x) => Number.isInteger(x) && x > 0)) throw new Error(`${id.replace('ffd-', '')}: three whole numbers, e.g. 2,2,2`);
    return v;
  };
  $('ffd-place').onclick = async () => {
    try {
      const mesh = Number($('ffd-mesh').value);
      if (!mesh) throw new Error('open or make a mesh first');
      await app.client.edit(Kind.Setup, { setup: 'mesh-ffd', mesh, degree: triple('ffd-degree'), counts: triple('ffd-counts'), form: $('ffd-form').value });
      $('tool').value = 'lattice'; app.tool = 'lattice';
      app.status('lattice placed: drag its points in the 3D view');
    } catch (e) { app.error(e.message, e.header); }
  };
  // The deformed mesh of the chosen mesh (the newest), exported as its accurate FFD.
  P.deformedMesh = () => {
    const mesh = Number($('ffd-mesh').value);
    return app.objects.filter((o) => o.recipe?.recipe === 'deformed-mesh' && (!mesh || o.recipe.mesh === mesh)).pop();
  };
  $('ffd-step').onclick = () => {
    const d = P.deformedMesh();
    if (!d) { app.error('no deformed mesh: press "Place lattice" first'); return; }
    P.lastStep = app.download(d.id, `${d.name.replace(/[^A-Za-z0-9_.-]+/g, '_')}.step`);
  };

  // Sliders for the model's parameters a[1..k]: a move replaces the model with the new value
  // (one gesture per drag of a slider, coalesced; one undo step on release).
  let sliderGesture = null;
  P.frepSliders = (f) => {
    const box = $('frep-params');
    const count = f?.frep.paramCount || 0;
    const key = f ? `${f.id}:${count}:${f.frep.source}` : '';
    if (sliderGesture !== null) return; // a slider is being dragged: keep it
    if (box.dataset.key === key) {
      for (const input of box.querySelectorAll('input')) {
        const v = f.frep.params[input.dataset.k] ?? 0;
        input.value = v; input.nextElementSibling.value = (+v).toPrecision(3);
      }
      return;
    }
    box.dataset.key = key; box.textContent = '';
    for (let k = 1; k <= count; k++) {
      const v = f.frep.params[k] ?? 0;
      const span = Math.max(1, 2 * Math.abs(v));
      const label = document.createElement('label');
      label.textContent = `a[${k}] `;
      const input = Object.assign(document.createElement('input'), { type: 'range', min: -span, max: span, step: span / 500, value: v, id: `frep-a${k}` });
      input.dataset.k = k;
      const out = document.createElement('output'); out.value = (+v).toPrecision(3);
      input.oninput = () => {
        const model = app.objects.find((o) => o.id === f.id);
        if (!model) return;
        if (sliderGesture === null) sliderGesture = app.newGesture();
        const params = { ...model.frep.params, [k]: Number(input.value) };
        out.value = Number(input.value).toPrecision(3);
        const r = app.client.send(Kind.Command, { command: 'replace-frep', id: f.id, source: model.frep.source, params, gesture: sliderGesture });
        app.markInput(r);
      };
      input.onchange = () => { if (sliderGesture !== null) { app.endGesture(sliderGesture); sliderGesture = null; } };
      label.append(input, out);
      box.append(label);
    }
  };

  // Handles: click to add (source = target), drag a handle's target to move it; while
  // dragging the warp is previewed on a coarse grid, at full resolution on release.
  $('handle-method').onchange = (e) => {
    const hm = app.handleMap();
    if (hm) app.client.send(Kind.Command, { command: 'set-handle-method', map: hm.id, method: e.target.value });
  };
  const warpOf = (map) => app.objects.find((o) => (o.recipe?.recipe === 'warp' || o.recipe?.recipe === 'warp-onto') && o.recipe.map === map);
  const nearest = (p) => {
    let best = -1, bd = Infinity;
    app.handles.forEach((h, i) => { const d = Math.hypot(h.target[0] - p[0], h.target[1] - p[1], h.target[2] - p[2]); if (d < bd) { bd = d; best = i; } });
    // Within a quarter of the tool radius, or two voxels of the shown scan (scans in mm).
    const sp = app.volume()?.volume.geometry.spacing || [0, 0, 0];
    return bd < Math.max(app.radius * 0.25, 2 * Math.max(...sp)) ? best : -1;
  };
  P.handleDown = (g) => {
    const hm = app.handleMap();
    if (!hm) { app.error('no handle map: press "Handles" set-up first'); return; }
    g.handle = nearest(g.p);
    g.map = hm.id;
    if (g.handle >= 0) coarse(g);
  };
  // While a handle is dragged its warp is previewed on a coarse grid. The warp object may not
  // be in the object list yet when the drag begins (the list is refreshed after a set-up), so
  // each move looks for it until it is found.
  const coarse = (g) => {
    if (g.warp) return;
    const w = warpOf(g.map);
    if (!w) return;
    g.warp = w;
    app.client.send(Kind.Command, { command: 'set-recipe', id: w.id, recipe: { ...w.recipe, sampled_nodes: 17 }, gesture: g.id });
  };
  P.handleMove = (g, target, e) => {
    if (g.handle < 0 || g.map === undefined) return;
    coarse(g);
    const h = app.handles[g.handle];
    const r = app.client.send(Kind.Command, { command: 'move-handle', map: g.map, index: g.handle, source: h.source, target, gesture: g.id });
    app.markInput(r, e);
  };
  P.handleUp = (g, idx) => {
    if (g.map === undefined) return;
    if (g.handle < 0 && !g.moved) {
      app.client.send(Kind.Command, { command: 'add-handle', map: g.map, source: g.p, target: g.p });
    } else if (g.handle >= 0) {
      // Back to full resolution (when a coarse preview was set); the drag is one undo step.
      if (g.warp) app.client.send(Kind.Command, { command: 'set-recipe', id: g.warp.id, recipe: { ...g.warp.recipe, sampled_nodes: null }, gesture: g.id });
      app.endGesture(g.id);
    }
  };
  document.addEventListener('keydown', (e) => {
    if (app.tool !== 'handles' || (e.key !== 'Delete' && e.key !== 'Backspace') || app.typing(e)) return;
    const hm = app.handleMap();
    const v = app.volume();
    if (!hm || !v) return;
    const i = nearest(app.cursorPhysical());
    if (i >= 0) app.client.send(Kind.Command, { command: 'delete-handle', map: hm.id, index: i });
  });

  // Registration (McPhail ch. 5): handles selected on the fixed scan and matched in the
  // moving one become a handle map (the correspondences, shown and dragged with the Handles
  // tool: a wrong one is corrected by dragging its target, the registered scan follows), and
  // the moving scan registered onto the fixed grid is shown; the Jacobian overlay shows where
  // the map expands, compresses or folds.
  P.registerChanged = () => {
    const volumes = app.objects.filter((o) => o.volume);
    fill($('reg-fixed'), volumes, (o) => `${o.id} ${o.name}`);
    fill($('reg-moving'), volumes, (o) => `${o.id} ${o.name}`);
  };
  $('reg-run').onclick = async () => {
    try {
      const fixed = Number($('reg-fixed').value), moving = Number($('reg-moving').value);
      if (!fixed || !moving || fixed === moving) throw new Error('choose two different scans, fixed and moving');
      const c = await app.client.edit(Kind.Setup, {
        setup: 'register', fixed, moving, handles: Number($('reg-handles').value), radius: Number($('reg-radius').value),
        method: $('handle-method').value,
      });
      const [map, registered] = c.header.added;
      app.showLayer(registered);
      $('tool').value = 'handles'; app.tool = 'handles';
      const h = app.byId(map);
      app.status(`registered: ${h?.map?.handles ?? '?'} correspondences; drag a wrong one's target with the Handles tool`);
    } catch (e) { app.error(e.message, e.header); }
  };

  // Lobes (McPhail §5.6): the lungs of a CT segmented and its lobe boundaries enhanced (the
  // "lungs" set-up, which adds a lobes object), then, with the Lobe points tool, two clicks on
  // the lung outline of an axial section make the key of the chosen fissure there (a
  // trace-lobes command: the server traces the fissure through every section of its range by
  // Dijkstra and labels the lobes; the slices show the labels). Later sections inherit a key
  // until the next one; "First/Last here" set the sections a fissure is traced in. Each key,
  // range or removal is one undo step.
  let lobePending = null;
  P.lobesObject = () => {
    const all = app.objects.filter((o) => o.recipe?.recipe === 'lobes');
    const id = Number($('lobes-object').value);
    return all.find((o) => o.id === id) || all[all.length - 1];
  };
  const fissureOf = (o, kind) => o?.recipe.script.fissures.find((f) => f.kind === kind);
  // The keys (and a first point being placed) on axial section `slice`: {fissure, points}.
  P.lobeKeys = (slice) => {
    const o = P.lobesObject();
    if (!o) return [];
    const out = [];
    for (const f of o.recipe.script.fissures) {
      for (const k of f.keys) if (k.slice === slice) out.push({ fissure: f.kind, points: [k.from, k.to] });
    }
    if (lobePending && lobePending.id === o.id && lobePending.slice === slice) out.push({ fissure: lobePending.fissure, points: [lobePending.from] });
    return out;
  };
  P.lobesChanged = () => {
    fill($('lobes-ct'), app.objects.filter((o) => o.volume && o.recipe?.recipe !== 'lobes'), (o) => `${o.id} ${o.name}`);
    fill($('lobes-object'), app.objects.filter((o) => o.recipe?.recipe === 'lobes'), (o) => `${o.id} ${o.name}`);
    const o = P.lobesObject();
    if (lobePending && lobePending.id !== o?.id) lobePending = null;
    const ul = $('lobes-keys'); ul.textContent = '';
    for (const f of o?.recipe.script.fissures || []) {
      const head = document.createElement('li');
      head.className = 'fissure';
      head.textContent = `${f.kind}: sections ${f.first}–${f.last}`;
      ul.append(head);
      for (const k of f.keys) {
        const li = document.createElement('li');
        li.dataset.fissure = f.kind; li.dataset.slice = k.slice;
        const p = (x) => `(${x[0].toFixed(1)}, ${x[1].toFixed(1)})`;
        li.append(`k ${k.slice}: ${p(k.from)} → ${p(k.to)}`);
        li.title = 'show this section';
        li.onclick = (e) => { if (e.target === li) { const c = app.cursor.slice(); c[2] = k.slice; app.setCursor(c, -1); } };
        const x = Object.assign(document.createElement('button'), { textContent: '×', title: 'remove this key' });
        x.onclick = () => app.client.edit(Kind.Command, { command: 'remove-lobe-key', id: o.id, fissure: f.kind, slice: k.slice })
          .then(() => app.status(`key of ${f.kind} at section ${k.slice} removed`)).catch((e) => app.error(e.message, e.header));
        li.append(x);
        ul.append(li);
      }
    }
    // The axial view draws the keys of its section.
    if (o) app.redrawSlices();
  };
  $('lobes-object').onchange = () => { P.lobesChanged(); app.reloadSlices(); };
  $('lobes-setup').onclick = async () => {
    try {
      const ct = Number($('lobes-ct').value);
      if (!ct) throw new Error('open a chest CT first');
      const c = await app.client.edit(Kind.Setup, { setup: 'lungs', ct });
      $('lobes-object').value = c.header.added[2];
      P.lobesChanged();
      $('layer').value = ct;
      await app.showLayer(ct);
      $('tool').value = 'lobes'; app.tool = 'lobes';
      app.status('lungs found: click the two ends of a fissure on the lung outline in the axial view');
    } catch (e) { app.error(e.message, e.header); }
  };
  // A click of the Lobe points tool: the first sets the key's start on the axial section, the
  // second its end (same section), which sends the key.
  P.lobeClick = (g, e) => {
    const o = P.lobesObject();
    if (!o) { app.error('no lobes: press "Find lungs" first'); return; }
    if (g.axis !== 2) { app.error('click the fissure points in the axial (k) view'); return; }
    const slice = Math.round(g.idx[2]);
    const at = [g.idx[0], g.idx[1]].map((x) => Math.round(x * 100) / 100);
    const fissure = $('lobes-fissure').value;
    if (!lobePending || lobePending.id !== o.id || lobePending.slice !== slice || lobePending.fissure !== fissure) {
      lobePending = { id: o.id, slice, fissure, from: at };
      app.redrawSlices();
      app.status(`${fissure} at section ${slice}: now click its other end`);
      return;
    }
    const from = lobePending.from;
    lobePending = null;
    const r = app.client.send(Kind.Command, { command: 'trace-lobes', id: o.id, fissure, slice, from, to: at });
    app.markInput(r, e);
    app.redrawSlices();
  };
  document.addEventListener('keydown', (e) => {
    if (e.key === 'Escape' && lobePending) { lobePending = null; app.redrawSlices(); app.status('key cancelled'); }
  });
  const range = (end) => {
    const o = P.lobesObject();
    if (!o) { app.error('no lobes: press "Find lungs" first'); return; }
    const kind = $('lobes-fissure').value;
    const f = fissureOf(o, kind);
    if (!f) { app.error(`${kind} has no key yet: click one first`); return; }
    const here = Math.round(app.cursor[2]);
    const [first, last] = end === 'first' ? [here, f.last] : [f.first, here];
    app.client.edit(Kind.Command, { command: 'lobe-range', id: o.id, fissure: kind, first, last })
      .then(() => app.status(`${kind} traced in sections ${first}–${last}`)).catch((e) => app.error(e.message, e.header));
  };
  $('lobes-first').onclick = () => range('first');
  $('lobes-last').onclick = () => range('last');

  // Sculpting (McPhail ch. 3): a mesh made sculptable (a tri-dexel grid around it), then
  // strokes of a brush (sphere, box or any mesh object, of the chosen reach) painted on it
  // with the Sculpt tool: in the 3D view where the cursor's ray meets it (the view stays
  // still), or on a slice at the cursor. A stroke is one undo step.
  P.sculptObject = () => {
    const id = Number($('sculpt-object').value);
    return app.objects.find((o) => o.id === id && o.kind === 'sculpt') || app.objects.filter((o) => o.kind === 'sculpt').pop();
  };
  P.sculptSize = () => Number($('sculpt-size').value);
  P.sculptChanged = () => {
    const meshes = app.objects.filter((o) => o.mesh);
    fill($('sculpt-mesh'), meshes.filter((o) => o.kind !== 'sculpt'), (o) => `${o.id} ${o.name}`);
    fill($('sculpt-object'), app.objects.filter((o) => o.kind === 'sculpt'), (o) => `${o.id} ${o.name}`);
    const brush = $('sculpt-brush'); const keep = brush.value;
    brush.textContent = '';
    brush.add(new Option('sphere', 'sphere')); brush.add(new Option('box', 'box'));
    for (const o of meshes) brush.add(new Option(`mesh ${o.id} ${o.name}`, `mesh:${o.id}`));
    if ([...brush.options].some((x) => x.value === keep)) brush.value = keep;
  };
  $('sculpt-size').oninput = () => { $('sculpt-size-out').textContent = $('sculpt-size').value; app.view3d.redraw(); };
  $('sculpt-make').onclick = async () => {
    try {
      const mesh = Number($('sculpt-mesh').value);
      if (!mesh) throw new Error('open or make a mesh first');
      const grid = Number($('sculpt-grid').value);
      const c = await app.client.edit(Kind.Setup, { setup: 'sculpt', mesh, grid });
      P.sculptChanged();
      $('sculpt-object').value = c.header.added[0];
      $('tool').value = 'sculpt'; app.tool = 'sculpt';
      app.status('sculpt object made: paint on it in the 3D view with the left button');
    } catch (e) { app.error(e.message, e.header); }
  };
  // Send one stroke segment (the points in order; one point is a dab) of gesture `gesture`.
  P.sculptStroke = (gesture, points, e) => {
    const o = P.sculptObject();
    if (!o) { app.error('no sculpt object: press "Make sculptable" first'); return; }
    const b = $('sculpt-brush').value;
    const brush = b.startsWith('mesh:') ? { mesh: Number(b.slice(5)) } : b;
    const r = app.client.send(Kind.Command, { command: 'sculpt', gesture, id: o.id, brush, op: $('sculpt-op').value, size: P.sculptSize(), points });
    app.markInput(r, e);
  };
  // A drag on a slice: the stroke follows the cursor's physical point.
  P.sculptMove = (g, target, e) => {
    P.sculptStroke(g.id, g.sculptAt ? [g.sculptAt, target] : [target], e);
    g.sculptAt = target;
  };

  // Files: a browser confined to the server's roots, save/load, drag-and-drop upload.
  const rootSel = $('root');
  app.roots.forEach((r, i) => rootSel.add(new Option(i === app.roots.length - 1 ? `uploads (${r})` : r, i)));
  let cwd = '.';
  const list = async () => {
    try {
      const f = await app.client.request(Kind.ListDir, { root: Number(rootSel.value), path: cwd });
      $('path').textContent = cwd;
      const ul = $('files'); ul.textContent = '';
      if (cwd !== '.') { const up = document.createElement('li'); up.textContent = '⟵ up'; up.className = 'dir'; up.onclick = () => { cwd = cwd.split('/').slice(0, -1).join('/') || '.'; list(); }; ul.append(up); }
      for (const e of f.header.entries) {
        const li = document.createElement('li');
        li.textContent = e.name + (e.dir ? '/' : '');
        li.className = e.dir ? 'dir' : 'file';
        const rel = cwd === '.' ? e.name : `${cwd}/${e.name}`;
        li.onclick = () => {
          if (e.dir) { cwd = rel; list(); } else {
            $('save-name').value = rel;
            if (!rel.endsWith('.vmproj')) app.client.edit(Kind.OpenFile, { root: Number(rootSel.value), path: rel }).then(() => app.status(`opened ${rel}`)).catch((x) => app.error(x.message));
          }
        };
        ul.append(li);
      }
    } catch (e) { app.error(e.message); }
  };
  rootSel.onchange = () => { cwd = '.'; list(); };
  P.listFiles = list;
  $('save').onclick = () => app.client.request(Kind.SaveScene, { root: Number(rootSel.value), path: $('save-name').value })
    .then(() => { app.status(`saved ${$('save-name').value}`); list(); }).catch((e) => app.error(e.message));
  $('load').onclick = () => app.client.request(Kind.LoadScene, { root: Number(rootSel.value), path: $('save-name').value })
    .then(() => app.status(`loaded ${$('save-name').value}`)).catch((e) => app.error(e.message));
  const drop = $('drop');
  drop.ondragover = (e) => { e.preventDefault(); drop.classList.add('over'); };
  drop.ondragleave = () => drop.classList.remove('over');
  drop.ondrop = async (e) => {
    e.preventDefault(); drop.classList.remove('over');
    for (const file of e.dataTransfer.files) await P.upload(file.name, file);
  };
  P.upload = async (name, blob) => {
    const r = await fetch(`upload/${encodeURIComponent(name)}`, { method: 'POST', body: blob });
    if (!r.ok) { app.error(`upload of ${name} failed: ${await r.text()}`); return; }
    const j = await r.json();
    try {
      await app.client.edit(Kind.OpenFile, { root: j.root, path: j.path });
      app.status(`uploaded and opened ${name}`);
    } catch (e) { app.error(e.message); }
  };
  list();
  return P;
}
