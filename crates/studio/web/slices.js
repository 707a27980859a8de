// The three orthogonal slice views: window/level and a colour map applied to the server's
// f32 slice, the Jacobian overlay (the server's determinant slice, folded voxels
// highlighted), the lobe overlay (the server's slice of a lobe-label volume, one colour per
// lobe) with the fissure key points of the axial section, a crosshair shared by the views,
// physical position and value under the cursor, and the drag gestures of the active tool.
import { Kind } from './protocol.js';

const IN_PLANE = [[1, 2], [0, 2], [0, 1]];

// Colour of folded voxels (Jacobian determinant J ≤ 0) in the Jacobian overlay.
export const FOLD_RGB = [255, 0, 255];
// |ln J| at which the overlay's tint is strongest (J = 2 or 1/2).
const JACOBIAN_FULL = Math.LN2;
// Strongest tint over the picture.
const JACOBIAN_ALPHA = 0.6;

// Colours of the lobe labels (volmorph_register::phantom::lobe: 1 RUL, 2 RML, 3 RLL, 4 LUL,
// 5 LLL), blended over the picture with LOBE_ALPHA; other labels are clear.
export const LOBE_RGB = [null, [235, 80, 70], [250, 205, 50], [70, 200, 95], [70, 140, 250], [195, 95, 235]];
export const LOBE_ALPHA = 0.45;
// Colours of the fissures' key points in the axial view.
export const FISSURE_RGB = { 'right-oblique': '#ff9f40', 'right-horizontal': '#40e0ff', 'left-oblique': '#ff5ad2' };

// The picture's pixel `o` (RGBA array `d`) with label `l` blended over it.
export function blendLobe(d, o, l) {
  const c = LOBE_RGB[l];
  if (!c) return;
  for (let k = 0; k < 3; k++) d[o + k] = Math.round(d[o + k] * (1 - LOBE_ALPHA) + c[k] * LOBE_ALPHA);
}

// The Jacobian overlay of one determinant: [r, g, b, alpha] to blend over the picture.
// Folding (J ≤ 0, or not finite) is opaque FOLD_RGB; expansion (J > 1) tints red,
// compression (0 < J < 1) blue, in proportion to |ln J| up to JACOBIAN_FULL; J = 1 is clear.
export function jacobianTint(j) {
  if (!(j > 0) || !Number.isFinite(j)) return [FOLD_RGB[0], FOLD_RGB[1], FOLD_RGB[2], 1];
  const l = Math.log(j);
  const a = JACOBIAN_ALPHA * Math.min(1, Math.abs(l) / JACOBIAN_FULL);
  return l > 0 ? [255, 60, 30, a] : [40, 110, 255, a];
}

// Physical position of a continuous index (geometry as sent by the server).
export function physical(g, idx) {
  const p = g.origin.slice();
  for (let a = 0; a < 3; a++) for (let c = 0; c < 3; c++) p[c] += g.direction[a][c] * g.spacing[a] * idx[a];
  return p;
}

// Continuous index of a physical position.
export function indexOf(g, p) {
  // direction columns are orthonormal for every volume volmorph reads (polar factor rule).
  const d = [p[0] - g.origin[0], p[1] - g.origin[1], p[2] - g.origin[2]];
  return [0, 1, 2].map((a) => (g.direction[a][0] * d[0] + g.direction[a][1] * d[1] + g.direction[a][2] * d[2]) / g.spacing[a]);
}

export class SliceView {
  constructor(canvas, axis, app) {
    this.canvas = canvas;
    this.ctx = canvas.getContext('2d');
    this.axis = axis;
    this.app = app;
    this.slice = null;
    this.jacobian = null;
    this.off = document.createElement('canvas');
    this.loading = null;
    this.followUp = null;
    canvas.addEventListener('pointerdown', (e) => this.down(e));
    canvas.addEventListener('pointermove', (e) => this.move(e));
    canvas.addEventListener('pointerup', (e) => this.up(e));
    canvas.addEventListener('wheel', (e) => this.wheel(e), { passive: false });
    canvas.addEventListener('contextmenu', (e) => e.preventDefault());
  }

  // Ask for the slice at the cursor and draw it. A request while one is loading runs once
  // after it; every caller gets a promise that settles once a slice asked for after its call
  // is on the canvas.
  load() {
    const app = this.app;
    const vol = app.volume();
    if (!vol) return Promise.resolve();
    if (this.loading) {
      if (!this.followUp) this.followUp = this.loading.then(() => { this.followUp = null; return this.load(); });
      return this.followUp;
    }
    const g = vol.volume.geometry;
    const n = g.dims[this.axis];
    const index = Math.max(0, Math.min(n - 1, Math.round(app.cursor[this.axis])));
    const map = app.showJacobian ? app.jacobianMap() : undefined;
    const jac = map === undefined ? Promise.resolve(null)
      : app.client.request(Kind.GetJacobian, { map: map.id, volume: vol.id, axis: this.axis, index });
    const lobes = app.lobesOverlay();
    const lob = lobes ? app.client.request(Kind.GetSlice, { volume: lobes.id, axis: this.axis, index }) : Promise.resolve(null);
    this.loading = Promise.all([app.client.request(Kind.GetSlice, { volume: vol.id, axis: this.axis, index }), jac, lob])
      .then(([f, j, l]) => {
        this.slice = { ...f.header, values: new Float32Array(f.payload) };
        this.jacobian = j ? { ...j.header, values: new Float32Array(j.payload) } : null;
        this.lobes = l ? { ...l.header, values: new Float32Array(l.payload) } : null;
        app.jacobianShown(this);
        if (!app.window.has(vol.id)) app.window.set(vol.id, f.header.window.slice());
        app.windowChanged(false);
        this.render();
      })
      .catch((e) => app.error(e.message))
      .finally(() => { this.loading = null; });
    return this.loading;
  }

  // The slice as RGBA through the window and colour map (what the canvas shows, unscaled).
  image() {
    const s = this.slice;
    const [lo, hi] = this.app.currentWindow();
    const lut = this.app.lut();
    const img = new ImageData(s.width, s.height);
    const d = img.data;
    const scale = hi > lo ? 255 / (hi - lo) : 0;
    for (let i = 0; i < s.values.length; i++) {
      const v = s.values[i];
      let t = hi > lo ? (v - lo) * scale : (v >= lo ? 255 : 0);
      t = Number.isFinite(t) ? Math.max(0, Math.min(255, Math.round(t))) : 0;
      const c = lut[t];
      d[4 * i] = c[0]; d[4 * i + 1] = c[1]; d[4 * i + 2] = c[2]; d[4 * i + 3] = 255;
    }
    const jac = this.jacobian;
    if (jac && jac.values.length === s.values.length) {
      for (let i = 0; i < jac.values.length; i++) {
        const [r, g, b, a] = jacobianTint(jac.values[i]);
        if (a === 0) continue;
        d[4 * i] = Math.round(d[4 * i] * (1 - a) + r * a);
        d[4 * i + 1] = Math.round(d[4 * i + 1] * (1 - a) + g * a);
        d[4 * i + 2] = Math.round(d[4 * i + 2] * (1 - a) + b * a);
      }
    }
    const lob = this.lobes;
    if (lob && lob.values.length === s.values.length) {
      for (let i = 0; i < lob.values.length; i++) blendLobe(d, 4 * i, Math.round(lob.values[i]));
    }
    return img;
  }

  layout() {
    const s = this.slice;
    const cw = this.canvas.width, ch = this.canvas.height;
    const pw = s.width * s.pixelSpacing[0], ph = s.height * s.pixelSpacing[1];
    const k = Math.min(cw / pw, ch / ph);
    const sa = s.pixelSpacing[0] * k, sb = s.pixelSpacing[1] * k;
    return { sa, sb, ox: (cw - s.width * sa) / 2, oy: (ch - s.height * sb) / 2 };
  }

  // Canvas position of a continuous index's in-plane coordinates.
  toCanvas(idx) {
    const s = this.slice, L = this.layout();
    const [a, b] = IN_PLANE[this.axis];
    return [L.ox + (idx[a] + 0.5) * L.sa, L.oy + (s.height - 0.5 - idx[b]) * L.sb];
  }

  // Continuous index under a canvas position (on this slice's plane).
  toIndex(x, y) {
    const s = this.slice, L = this.layout();
    const [a, b] = IN_PLANE[this.axis];
    const idx = [0, 0, 0];
    idx[this.axis] = s.index;
    idx[a] = (x - L.ox) / L.sa - 0.5;
    idx[b] = s.height - 0.5 - (y - L.oy) / L.sb;
    return idx;
  }

  render() {
    const s = this.slice;
    if (!s) return;
    const ctx = this.ctx;
    this.off.width = s.width; this.off.height = s.height;
    this.off.getContext('2d').putImageData(this.image(), 0, 0);
    const L = this.layout();
    ctx.fillStyle = '#000';
    ctx.fillRect(0, 0, this.canvas.width, this.canvas.height);
    ctx.imageSmoothingEnabled = false;
    ctx.drawImage(this.off, L.ox, L.oy, s.width * L.sa, s.height * L.sb);
    this.overlay();
  }

  // Crosshair, tool radius, handles: drawn over the picture.
  overlay() {
    const ctx = this.ctx, app = this.app;
    const [cx, cy] = this.toCanvas(app.cursor);
    ctx.strokeStyle = 'rgba(255,220,0,0.6)';
    ctx.lineWidth = 1;
    ctx.beginPath();
    ctx.moveTo(cx, 0); ctx.lineTo(cx, this.canvas.height);
    ctx.moveTo(0, cy); ctx.lineTo(this.canvas.width, cy);
    ctx.stroke();
    if (app.tool === 'drag' || app.tool === 'sculpt') {
      const g = app.volume().volume.geometry;
      const [a] = IN_PLANE[this.axis];
      const L = this.layout();
      const r = (app.radius / g.spacing[a]) * L.sa;
      ctx.strokeStyle = 'rgba(80,200,255,0.8)';
      ctx.beginPath(); ctx.arc(cx, cy, r, 0, 2 * Math.PI); ctx.stroke();
    }
    // The fissure keys of this axial section (and the first point of one being placed).
    if (this.axis === 2) {
      for (const k of app.panels?.lobeKeys(this.slice.index) || []) {
        ctx.strokeStyle = FISSURE_RGB[k.fissure] || '#fff';
        ctx.lineWidth = 2;
        for (const p of k.points) {
          const [x, y] = this.toCanvas([p[0], p[1], this.slice.index]);
          ctx.beginPath(); ctx.arc(x, y, 4, 0, 2 * Math.PI); ctx.stroke();
        }
        ctx.lineWidth = 1;
      }
    }
    for (const h of app.handles || []) {
      const g = app.volume().volume.geometry;
      const [sx, sy] = this.toCanvas(indexOf(g, h.source));
      const [tx, ty] = this.toCanvas(indexOf(g, h.target));
      ctx.strokeStyle = '#ff0'; ctx.fillStyle = '#f80';
      ctx.beginPath(); ctx.moveTo(sx, sy); ctx.lineTo(tx, ty); ctx.stroke();
      ctx.beginPath(); ctx.arc(tx, ty, 3, 0, 2 * Math.PI); ctx.fill();
    }
  }

  point(e) {
    const r = this.canvas.getBoundingClientRect();
    const x = (e.clientX - r.left) * (this.canvas.width / r.width);
    const y = (e.clientY - r.top) * (this.canvas.height / r.height);
    return this.toIndex(x, y);
  }

  down(e) {
    if (!this.slice) return;
    this.canvas.setPointerCapture(e.pointerId);
    const idx = this.point(e);
    if (e.button === 2 || e.shiftKey) {
      this.wl = { x: e.clientX, y: e.clientY, w: this.app.currentWindow().slice() };
      return;
    }
    this.app.setCursor(idx, this.axis);
    this.app.gestureStart(idx, e, this.axis);
  }

  move(e) {
    if (!this.slice) return;
    const idx = this.point(e);
    this.app.showCursor(idx, this.valueAt(idx));
    if (this.wl) {
      const [lo, hi] = this.wl.w;
      const width = Math.max(1e-6, (hi - lo) * Math.exp((e.clientX - this.wl.x) / 200));
      const center = (lo + hi) / 2 - ((e.clientY - this.wl.y) / 200) * (hi - lo);
      this.app.setWindow([center - width / 2, center + width / 2]);
      return;
    }
    if (e.buttons & 1) this.app.gestureMove(idx, e);
  }

  up(e) {
    if (this.wl) { this.wl = null; return; }
    this.app.gestureEnd(this.point(e), e);
  }

  wheel(e) {
    e.preventDefault();
    const c = this.app.cursor.slice();
    c[this.axis] += e.deltaY > 0 ? -1 : 1;
    this.app.setCursor(c, -1);
  }

  valueAt(idx) {
    const s = this.slice;
    const [a, b] = IN_PLANE[this.axis];
    const col = Math.round(idx[a]), row = s.height - 1 - Math.round(idx[b]);
    if (col < 0 || row < 0 || col >= s.width || row >= s.height) return null;
    return s.values[row * s.width + col];
  }
}
