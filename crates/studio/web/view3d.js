// The 3D view (WebGL2): slice-based volume rendering on the server's cube-cutting proxy
// geometry (McPhail ch. 2; polygons back to front, premultiplied blending), meshes, and the
// lattice and handle overlays, the deformed grid, the tool-radius sphere or sculpt brush; orbit (left drag), pan (right or shift drag), zoom (wheel),
// preset views; in the Sculpt tool the left button paints strokes on the sculpt object instead of orbiting.
import { Kind } from './protocol.js';

function sub(a, b) { return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]; }
function cross(a, b) { return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]; }
function norm(a) { const l = Math.hypot(a[0], a[1], a[2]) || 1; return [a[0] / l, a[1] / l, a[2] / l]; }
function dot(a, b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
function mul(a, b) { // column-major 4x4
  const o = new Float32Array(16);
  for (let c = 0; c < 4; c++) for (let r = 0; r < 4; r++) {
    let s = 0; for (let k = 0; k < 4; k++) s += a[k * 4 + r] * b[c * 4 + k]; o[c * 4 + r] = s;
  }
  return o;
}

const VS_VOL = `#version 300 es
layout(location=0) in vec3 pos; layout(location=1) in vec3 tex;
uniform mat4 mvp; out vec3 vTex;
void main() { vTex = tex; gl_Position = mvp * vec4(pos, 1.0); }`;
const FS_VOL = `#version 300 es
precision highp float; precision highp sampler3D;
in vec3 vTex; uniform sampler3D vol; uniform sampler2D lut; uniform float stepRatio; out vec4 o;
void main() {
  float v = texture(vol, vTex).r;
  vec4 c = texture(lut, vec2(v * (255.0 / 256.0) + 0.5 / 256.0, 0.5));
  float a = 1.0 - pow(max(1.0 - c.a, 0.0), stepRatio);
  o = vec4(c.rgb * a, a);
}`;
const VS_MESH = `#version 300 es
layout(location=0) in vec3 pos; layout(location=1) in vec3 nrm;
uniform mat4 mvp; out vec3 vN;
void main() { vN = nrm; gl_Position = mvp * vec4(pos, 1.0); }`;
const FS_MESH = `#version 300 es
precision highp float; in vec3 vN; uniform vec3 light; uniform vec3 color; out vec4 o;
void main() { vec3 n = normalize(vN); float d = abs(dot(n, light)); o = vec4(color * (0.25 + 0.75 * d), 1.0); }`;
const VS_FLAT = `#version 300 es
layout(location=0) in vec3 pos; uniform mat4 mvp; uniform float size;
void main() { gl_Position = mvp * vec4(pos, 1.0); gl_PointSize = size; }`;
const FS_FLAT = `#version 300 es
precision highp float; uniform vec4 color; out vec4 o; void main() { o = color; }`;

// Segments per great circle of the tool-radius sphere.
export const SPHERE_SEGMENTS = 64;
// Colour of the tool-radius sphere (RGBA, 0‥1).
export const SPHERE_RGBA = [80 / 255, 200 / 255, 1, 1];

// The tool-radius sphere as line segments: three great circles (in the xy, yz and zx planes)
// of radius `r` around `c`, SPHERE_SEGMENTS each, as pairs of endpoints (flat xyz).
export function sphereLines(c, r) {
  const out = [];
  const pt = (plane, t) => {
    const u = r * Math.cos(t), v = r * Math.sin(t);
    return plane === 0 ? [c[0] + u, c[1] + v, c[2]] : plane === 1 ? [c[0], c[1] + u, c[2] + v] : [c[0] + v, c[1], c[2] + u];
  };
  for (let plane = 0; plane < 3; plane++) for (let k = 0; k < SPHERE_SEGMENTS; k++) {
    out.push(...pt(plane, 2 * Math.PI * k / SPHERE_SEGMENTS), ...pt(plane, 2 * Math.PI * (k + 1) / SPHERE_SEGMENTS));
  }
  return new Float32Array(out);
}

// Lines per axis direction of the deformed grid (a GRID_LINES × GRID_LINES bundle along each
// axis) and samples along each line.
export const GRID_LINES = 5;
export const GRID_SAMPLES = 33;
// Colour of the deformed grid (RGBA, 0‥1).
export const GRID_RGBA = [1, 1, 0.4, 1];

// The undeformed grid in the box [lo, hi]: for each axis a, GRID_LINES² lines along a, each
// GRID_SAMPLES points from lo to hi (flat xyz, line after line).
export function gridPoints(lo, hi) {
  const out = [];
  const at = (a, t) => lo[a] + (hi[a] - lo[a]) * t;
  for (let a = 0; a < 3; a++) {
    const [b, c] = [(a + 1) % 3, (a + 2) % 3];
    for (let i = 0; i < GRID_LINES; i++) for (let j = 0; j < GRID_LINES; j++) {
      for (let k = 0; k < GRID_SAMPLES; k++) {
        const p = [0, 0, 0];
        p[a] = at(a, k / (GRID_SAMPLES - 1));
        p[b] = at(b, (i + 0.5) / GRID_LINES);
        p[c] = at(c, (j + 0.5) / GRID_LINES);
        out.push(p);
      }
    }
  }
  return out;
}

// Proxy planes while the user interacts (a drag, an orbit, a spin): software GL draws every
// plane over the whole view, so fewer planes keep the page responsive; the full count is
// drawn again INTERACTIVE_REFINE_MS after the last interaction.
export const INTERACTIVE_SLICES = 48;
const INTERACTIVE_REFINE_MS = 400;

export class View3D {
  constructor(canvas, app) {
    this.canvas = canvas;
    this.app = app;
    const gl = canvas.getContext('webgl2', { antialias: false, preserveDrawingBuffer: true, premultipliedAlpha: true });
    if (!gl) { app.error('WebGL2 is not available: the 3D view is off'); return; }
    this.gl = gl;
    this.progVol = this.program(VS_VOL, FS_VOL);
    this.progMesh = this.program(VS_MESH, FS_MESH);
    this.progFlat = this.program(VS_FLAT, FS_FLAT);
    this.cam = { target: [0, 0, 0], dist: 4, yaw: -0.6, pitch: 0.4, fov: 0.6 };
    this.meshes = new Map();
    this.proxy = null; this.proxyBusy = false; this.proxyWanted = false;
    this.frames = 0;
    this.selected = new Set();
    this.showVolume = true; this.showLattice = true; this.showGrid = false;
    canvas.addEventListener('pointerdown', (e) => this.down(e));
    canvas.addEventListener('pointermove', (e) => this.move(e));
    canvas.addEventListener('pointerup', (e) => this.up(e));
    canvas.addEventListener('wheel', (e) => { e.preventDefault(); this.cam.dist *= Math.exp(e.deltaY * 0.001); this.changed(); }, { passive: false });
    canvas.addEventListener('contextmenu', (e) => e.preventDefault());
  }

  program(vs, fs) {
    const gl = this.gl;
    const p = gl.createProgram();
    for (const [type, src] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
      const s = gl.createShader(type);
      gl.shaderSource(s, src); gl.compileShader(s);
      if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
      gl.attachShader(p, s);
    }
    gl.linkProgram(p);
    if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(p));
    return p;
  }

  eye() {
    const c = this.cam;
    return [c.target[0] + c.dist * Math.cos(c.pitch) * Math.cos(c.yaw),
      c.target[1] + c.dist * Math.cos(c.pitch) * Math.sin(c.yaw),
      c.target[2] + c.dist * Math.sin(c.pitch)];
  }
  forward() { return norm(sub(this.cam.target, this.eye())); }

  matrices() {
    const e = this.eye(), f = this.forward();
    const r = norm(cross(f, [0, 0, 1]));
    const u = cross(r, f);
    const view = new Float32Array([r[0], u[0], -f[0], 0, r[1], u[1], -f[1], 0, r[2], u[2], -f[2], 0,
      -dot(r, e), -dot(u, e), dot(f, e), 1]);
    const aspect = this.canvas.width / this.canvas.height;
    const near = this.cam.dist * 0.05, far = this.cam.dist * 10;
    const t = 1 / Math.tan(this.cam.fov / 2);
    const proj = new Float32Array([t / aspect, 0, 0, 0, 0, t, 0, 0, 0, 0, (far + near) / (near - far), -1, 0, 0, 2 * far * near / (near - far), 0]);
    return { mvp: mul(proj, view), right: r, up: u, f };
  }

  // Frame the volume (physical box) and use the preset view `name`.
  frame(box, name) {
    if (box) {
      this.box = box;
      this.cam.target = [0, 1, 2].map((i) => (box[0][i] + box[1][i]) / 2);
      const d = Math.hypot(...sub(box[1], box[0]));
      this.cam.dist = d * 1.4;
    }
    const presets = { front: [-Math.PI / 2, 0], side: [0, 0], top: [-Math.PI / 2, 1.55], iso: [-0.8, 0.5] };
    if (name && presets[name]) [this.cam.yaw, this.cam.pitch] = presets[name];
    this.changed();
  }

  async setVolume(id) {
    const gl = this.gl; if (!gl) return;
    const f = await this.app.client.request(Kind.GetVolume, { volume: id });
    const [nx, ny, nz] = f.header.dims;
    if (!this.tex) this.tex = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_3D, this.tex);
    gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
    gl.texImage3D(gl.TEXTURE_3D, 0, gl.R8, nx, ny, nz, 0, gl.RED, gl.UNSIGNED_BYTE, new Uint8Array(f.payload));
    gl.texParameteri(gl.TEXTURE_3D, gl.TEXTURE_MIN_FILTER, gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_3D, gl.TEXTURE_MAG_FILTER, gl.LINEAR);
    for (const w of [gl.TEXTURE_WRAP_S, gl.TEXTURE_WRAP_T, gl.TEXTURE_WRAP_R]) gl.texParameteri(gl.TEXTURE_3D, w, gl.CLAMP_TO_EDGE);
    const first = this.volumeId !== id;
    this.volumeId = id;
    this.range = [f.header.min, f.header.max];
    const g = f.header.geometry;
    this.voxel = Math.min(...g.spacing);
    this.slices = Math.min(512, Math.max(64, Math.round(1.5 * Math.max(...g.dims))));
    if (first) {
      const lo = g.origin.slice(), hi = g.origin.slice();
      for (const c of [0, 1, 2]) {
        const ext = [0, 1, 2].map((a) => g.direction[a][c] * g.spacing[a] * (g.dims[a] - 1));
        for (const e of ext) { if (e < 0) lo[c] += e; else hi[c] += e; }
      }
      this.frame([lo, hi], null);
      await this.app.transferChanged();
    }
    this.requestProxy();
  }

  setLut(rgba) {
    const gl = this.gl; if (!gl) return;
    if (!this.lutTex) this.lutTex = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, this.lutTex);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA8, 256, 1, 0, gl.RGBA, gl.UNSIGNED_BYTE, rgba);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
    this.changed();
  }

  // Ask the server for the proxy geometry of the current view direction (one request at a
  // time; the newest direction is asked for next).
  requestProxy() {
    if (this.volumeId === undefined) return;
    if (this.proxyBusy) { this.proxyWanted = true; return; }
    this.proxyBusy = true;
    const forward = this.forward();
    const planes = this.lod ? Math.min(this.slices, INTERACTIVE_SLICES) : this.slices;
    this.app.client.request(Kind.GetProxy, { volume: this.volumeId, forward, slices: planes })
      .then((f) => {
        const gl = this.gl;
        const nv = f.header.vertices, ni = f.header.indices;
        const vao = this.proxy?.vao || gl.createVertexArray();
        const vb = this.proxy?.vb || gl.createBuffer();
        const ib = this.proxy?.ib || gl.createBuffer();
        gl.bindVertexArray(vao);
        gl.bindBuffer(gl.ARRAY_BUFFER, vb);
        gl.bufferData(gl.ARRAY_BUFFER, new Float32Array(f.payload, 0, nv * 6), gl.DYNAMIC_DRAW);
        gl.enableVertexAttribArray(0); gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 24, 0);
        gl.enableVertexAttribArray(1); gl.vertexAttribPointer(1, 3, gl.FLOAT, false, 24, 12);
        gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, ib);
        gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, new Uint32Array(f.payload, nv * 24, ni), gl.DYNAMIC_DRAW);
        gl.bindVertexArray(null);
        const extent = this.box ? Math.abs(dot(sub(this.box[1], this.box[0]), forward)) + Math.hypot(...sub(this.box[1], this.box[0])) : 1;
        this.proxy = { vao, vb, ib, count: ni, planes, spacing: Math.hypot(...sub(this.box[1], this.box[0])) / planes, extent };
        this.redraw();
      })
      .catch((e) => this.app.error(e.message))
      .finally(() => { this.proxyBusy = false; if (this.proxyWanted) { this.proxyWanted = false; this.requestProxy(); } });
  }

  async setMesh(id, color) {
    const gl = this.gl; if (!gl) return;
    const f = await this.app.client.request(Kind.GetMesh, { id });
    const nv = f.header.vertices, nt = f.header.triangles;
    const m = this.meshes.get(id) || { vao: gl.createVertexArray(), pb: gl.createBuffer(), nb: gl.createBuffer(), ib: gl.createBuffer() };
    gl.bindVertexArray(m.vao);
    gl.bindBuffer(gl.ARRAY_BUFFER, m.pb);
    gl.bufferData(gl.ARRAY_BUFFER, new Float32Array(f.payload, 0, nv * 3), gl.DYNAMIC_DRAW);
    gl.enableVertexAttribArray(0); gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
    gl.bindBuffer(gl.ARRAY_BUFFER, m.nb);
    gl.bufferData(gl.ARRAY_BUFFER, new Float32Array(f.payload, nv * 12, nv * 3), gl.DYNAMIC_DRAW);
    gl.enableVertexAttribArray(1); gl.vertexAttribPointer(1, 3, gl.FLOAT, false, 0, 0);
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, m.ib);
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, new Uint32Array(f.payload, nv * 24, nt * 3), gl.DYNAMIC_DRAW);
    gl.bindVertexArray(null);
    m.count = nt * 3; m.color = color || [0.85, 0.75, 0.55];
    // CPU copies for picking (the sculpt brush lands where the cursor's ray meets the mesh).
    m.pos = new Float32Array(f.payload.slice(0, nv * 12));
    m.idx = new Uint32Array(f.payload.slice(nv * 24, nv * 24 + nt * 12));
    this.meshes.set(id, m);
    this.redraw();
  }

  dropMesh(id) { this.meshes.delete(id); this.redraw(); }

  // The deformed grid: the lines of gridPoints over the volume's box, mapped by `map` (the
  // server's Probe), drawn as line strips. Without a map or with the grid off, nothing.
  async setGrid(map) {
    const gl = this.gl; if (!gl) return;
    if (!this.showGrid || map === undefined || !this.box) { this.grid = null; this.redraw(); return; }
    const pts = gridPoints(this.box[0], this.box[1]);
    const f = await this.app.client.request(Kind.Probe, { map, points: pts });
    const images = new Float32Array(f.payload);
    const lines = [];
    const per = GRID_SAMPLES;
    for (let l = 0; l < pts.length / per; l++) for (let k = 0; k + 1 < per; k++) lines.push(l * per + k, l * per + k + 1);
    const g = this.grid || { vao: gl.createVertexArray(), vb: gl.createBuffer(), ib: gl.createBuffer() };
    gl.bindVertexArray(g.vao);
    gl.bindBuffer(gl.ARRAY_BUFFER, g.vb); gl.bufferData(gl.ARRAY_BUFFER, images, gl.DYNAMIC_DRAW);
    gl.enableVertexAttribArray(0); gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, g.ib); gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, new Uint32Array(lines), gl.DYNAMIC_DRAW);
    gl.bindVertexArray(null);
    Object.assign(g, { points: images, count: lines.length, map });
    this.grid = g;
    this.redraw();
  }

  // Lattice points and edges, or handle arrows (from an overlay frame).
  setOverlay(f) {
    const gl = this.gl; if (!gl) return;
    const pts = new Float32Array(f.payload);
    const lines = [];
    if (f.header.kind === 'lattice') {
      const [nu, nv, nw] = f.header.counts;
      const at = (i, j, k) => i + nu * (j + nv * k);
      for (let k = 0; k < nw; k++) for (let j = 0; j < nv; j++) for (let i = 0; i < nu; i++) {
        if (i + 1 < nu) lines.push(at(i, j, k), at(i + 1, j, k));
        if (j + 1 < nv) lines.push(at(i, j, k), at(i, j + 1, k));
        if (k + 1 < nw) lines.push(at(i, j, k), at(i, j, k + 1));
      }
    } else {
      for (let h = 0; h < f.header.count; h++) lines.push(2 * h, 2 * h + 1);
    }
    const o = this.overlay || { vao: gl.createVertexArray(), vb: gl.createBuffer(), ib: gl.createBuffer() };
    gl.bindVertexArray(o.vao);
    gl.bindBuffer(gl.ARRAY_BUFFER, o.vb); gl.bufferData(gl.ARRAY_BUFFER, pts, gl.DYNAMIC_DRAW);
    gl.enableVertexAttribArray(0); gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, o.ib); gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, new Uint32Array(lines), gl.DYNAMIC_DRAW);
    gl.bindVertexArray(null);
    Object.assign(o, { points: pts, count: pts.length / 3, lines: lines.length, kind: f.header.kind, map: f.header.map });
    this.overlay = o;
    this.redraw();
  }

  // The camera moved: new proxy geometry, and a redraw.
  changed() {
    this.interact();
    this.requestProxy();
    this.redraw();
  }

  // The user interacts: draw with INTERACTIVE_SLICES planes until INTERACTIVE_REFINE_MS
  // after the last call, then with the full count again.
  interact() {
    const was = this.lod;
    this.lod = true;
    clearTimeout(this.refineTimer);
    this.refineTimer = setTimeout(() => { this.lod = false; this.requestProxy(); }, INTERACTIVE_REFINE_MS);
    if (!was) this.requestProxy();
  }

  // Draw in the next frame (once, however often asked).
  redraw() {
    if (!this.rafPending) { this.rafPending = true; requestAnimationFrame(() => { this.rafPending = false; this.draw(); }); }
  }

  draw() {
    const gl = this.gl; if (!gl) return;
    const { mvp, f } = this.matrices();
    gl.viewport(0, 0, this.canvas.width, this.canvas.height);
    gl.clearColor(0.05, 0.05, 0.07, 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.enable(gl.DEPTH_TEST);
    gl.depthMask(true);
    gl.disable(gl.BLEND);
    gl.useProgram(this.progMesh);
    gl.uniformMatrix4fv(gl.getUniformLocation(this.progMesh, 'mvp'), false, mvp);
    gl.uniform3fv(gl.getUniformLocation(this.progMesh, 'light'), f);
    for (const m of this.meshes.values()) {
      gl.uniform3fv(gl.getUniformLocation(this.progMesh, 'color'), m.color);
      gl.bindVertexArray(m.vao); gl.drawElements(gl.TRIANGLES, m.count, gl.UNSIGNED_INT, 0);
    }
    if (this.overlay && this.showLattice) {
      const o = this.overlay;
      gl.useProgram(this.progFlat);
      gl.uniformMatrix4fv(gl.getUniformLocation(this.progFlat, 'mvp'), false, mvp);
      gl.bindVertexArray(o.vao);
      gl.uniform4fv(gl.getUniformLocation(this.progFlat, 'color'), [0.3, 0.8, 1, 1]);
      gl.drawElements(gl.LINES, o.lines, gl.UNSIGNED_INT, 0);
      gl.uniform1f(gl.getUniformLocation(this.progFlat, 'size'), 5);
      gl.uniform4fv(gl.getUniformLocation(this.progFlat, 'color'), [1, 0.6, 0.1, 1]);
      gl.drawArrays(gl.POINTS, 0, o.count);
    }
    if (this.proxy && this.tex && this.lutTex && this.showVolume) {
      gl.enable(gl.BLEND);
      gl.blendFunc(gl.ONE, gl.ONE_MINUS_SRC_ALPHA);
      gl.depthMask(false);
      gl.useProgram(this.progVol);
      gl.uniformMatrix4fv(gl.getUniformLocation(this.progVol, 'mvp'), false, mvp);
      gl.activeTexture(gl.TEXTURE0); gl.bindTexture(gl.TEXTURE_3D, this.tex);
      gl.uniform1i(gl.getUniformLocation(this.progVol, 'vol'), 0);
      gl.activeTexture(gl.TEXTURE1); gl.bindTexture(gl.TEXTURE_2D, this.lutTex);
      gl.uniform1i(gl.getUniformLocation(this.progVol, 'lut'), 1);
      // Opacity is per voxel length: correct it for the slice spacing.
      gl.uniform1f(gl.getUniformLocation(this.progVol, 'stepRatio'), this.proxy.spacing / this.voxel);
      gl.bindVertexArray(this.proxy.vao);
      gl.drawElements(gl.TRIANGLES, this.proxy.count, gl.UNSIGNED_INT, 0);
      gl.depthMask(true);
    }
    if (this.grid && this.showGrid) {
      gl.disable(gl.DEPTH_TEST); gl.disable(gl.BLEND);
      gl.useProgram(this.progFlat);
      gl.uniformMatrix4fv(gl.getUniformLocation(this.progFlat, 'mvp'), false, mvp);
      gl.uniform4fv(gl.getUniformLocation(this.progFlat, 'color'), GRID_RGBA);
      gl.bindVertexArray(this.grid.vao);
      gl.drawElements(gl.LINES, this.grid.count, gl.UNSIGNED_INT, 0);
      gl.enable(gl.DEPTH_TEST);
    }
    // The tool radius of a drag around the cursor, or the sculpt brush's reach where it last
    // touched the sculpt object, over everything.
    const brush = this.app.tool === 'sculpt' && this.brushAt ? [this.brushAt, this.app.panels.sculptSize()]
      : (this.app.tool === 'drag' || this.app.tool === 'sculpt') && this.app.volume() ? [this.app.cursorPhysical(), this.app.radius] : null;
    if (brush) {
      if (!this.sphere) this.sphere = { vao: gl.createVertexArray(), vb: gl.createBuffer() };
      const lines = sphereLines(brush[0], brush[1]);
      gl.bindVertexArray(this.sphere.vao);
      gl.bindBuffer(gl.ARRAY_BUFFER, this.sphere.vb);
      gl.bufferData(gl.ARRAY_BUFFER, lines, gl.DYNAMIC_DRAW);
      gl.enableVertexAttribArray(0); gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
      gl.disable(gl.DEPTH_TEST); gl.disable(gl.BLEND);
      gl.useProgram(this.progFlat);
      gl.uniformMatrix4fv(gl.getUniformLocation(this.progFlat, 'mvp'), false, mvp);
      gl.uniform4fv(gl.getUniformLocation(this.progFlat, 'color'), SPHERE_RGBA);
      gl.drawArrays(gl.LINES, 0, lines.length / 3);
      gl.enable(gl.DEPTH_TEST);
    }
    gl.bindVertexArray(null);
    this.frames++;
  }

  // Screen position of a world point (canvas pixels).
  project(p, mvp) {
    const x = mvp[0] * p[0] + mvp[4] * p[1] + mvp[8] * p[2] + mvp[12];
    const y = mvp[1] * p[0] + mvp[5] * p[1] + mvp[9] * p[2] + mvp[13];
    const w = mvp[3] * p[0] + mvp[7] * p[1] + mvp[11] * p[2] + mvp[15];
    return [(x / w * 0.5 + 0.5) * this.canvas.width, (0.5 - y / w * 0.5) * this.canvas.height];
  }

  canvasPoint(e) {
    const r = this.canvas.getBoundingClientRect();
    return [(e.clientX - r.left) * (this.canvas.width / r.width), (e.clientY - r.top) * (this.canvas.height / r.height)];
  }

  // The ray through the canvas pixel of event `e`: origin (the eye) and unit direction.
  ray(e) {
    const [x, y] = this.canvasPoint(e);
    const { right, up, f } = this.matrices();
    const t = Math.tan(this.cam.fov / 2);
    const aspect = this.canvas.width / this.canvas.height;
    const nx = (2 * x / this.canvas.width - 1) * t * aspect, ny = (1 - 2 * y / this.canvas.height) * t;
    return { o: this.eye(), d: norm([0, 1, 2].map((i) => f[i] + nx * right[i] + ny * up[i])) };
  }

  // The nearest point where the ray of event `e` meets mesh `id` as drawn (Möller–Trumbore
  // over its triangles), or null.
  hit(e, id) {
    const m = this.meshes.get(id);
    if (!m || !m.pos) return null;
    const { o, d } = this.ray(e);
    const P = m.pos, I = m.idx;
    let best = Infinity;
    for (let k = 0; k < I.length; k += 3) {
      const a = 3 * I[k], b = 3 * I[k + 1], c = 3 * I[k + 2];
      const e1 = [P[b] - P[a], P[b + 1] - P[a + 1], P[b + 2] - P[a + 2]];
      const e2 = [P[c] - P[a], P[c + 1] - P[a + 1], P[c + 2] - P[a + 2]];
      const pv = cross(d, e2);
      const det = dot(e1, pv);
      if (Math.abs(det) < 1e-12) continue;
      const tv = [o[0] - P[a], o[1] - P[a + 1], o[2] - P[a + 2]];
      const u = dot(tv, pv) / det;
      if (u < 0 || u > 1) continue;
      const qv = cross(tv, e1);
      const v = dot(d, qv) / det;
      if (v < 0 || u + v > 1) continue;
      const t = dot(e2, qv) / det;
      if (t > 0 && t < best) best = t;
    }
    return best < Infinity ? [0, 1, 2].map((i) => o[i] + best * d[i]) : null;
  }

  // The overlay point nearest the cursor within 10 pixels.
  pick(e) {
    if (!this.overlay) return -1;
    const { mvp } = this.matrices();
    const [x, y] = this.canvasPoint(e);
    let best = -1, bd = 100;
    const p = this.overlay.points;
    for (let i = 0; i < this.overlay.count; i++) {
      const [sx, sy] = this.project([p[3 * i], p[3 * i + 1], p[3 * i + 2]], mvp);
      const d = (sx - x) ** 2 + (sy - y) ** 2;
      if (d < bd) { bd = d; best = i; }
    }
    return best;
  }

  down(e) {
    this.canvas.setPointerCapture(e.pointerId);
    this.last = [e.clientX, e.clientY];
    this.mode = e.button === 2 || e.shiftKey ? 'pan' : 'orbit';
    // Sculpting freezes the view: the left button paints strokes where the cursor's ray
    // meets the sculpt object (pan stays on the right button and shift).
    const sculpt = this.app.tool === 'sculpt' && e.button === 0 && !e.shiftKey ? this.app.panels.sculptObject() : null;
    if (sculpt) {
      this.mode = 'sculpt';
      this.gesture = this.app.newGesture();
      this.brushAt = this.hit(e, sculpt.id);
      if (this.brushAt) this.app.panels.sculptStroke(this.gesture, [this.brushAt], e);
      this.redraw();
      return;
    }
    if (this.app.tool === 'lattice' && this.overlay?.kind === 'lattice' && e.button === 0) {
      const i = this.pick(e);
      if (i >= 0) {
        if (!e.ctrlKey && !e.metaKey && !this.selected.has(i)) this.selected.clear();
        this.selected.add(i);
        this.mode = 'points';
        this.start = [e.clientX, e.clientY];
        this.origin = new Map([...this.selected].map((k) => [k, [0, 1, 2].map((c) => this.overlay.points[3 * k + c])]));
        this.gesture = this.app.newGesture();
      }
    }
  }

  move(e) {
    if (!(e.buttons & 3) || !this.last) return;
    const dx = e.clientX - this.last[0], dy = e.clientY - this.last[1];
    this.last = [e.clientX, e.clientY];
    const c = this.cam;
    if (this.mode === 'sculpt') {
      const sculpt = this.app.panels.sculptObject();
      const at = sculpt && this.hit(e, sculpt.id);
      if (at) {
        this.interact();
        this.app.panels.sculptStroke(this.gesture, this.brushAt ? [this.brushAt, at] : [at], e);
        this.brushAt = at;
        this.redraw();
      }
      return;
    }
    if (this.mode === 'orbit') {
      c.yaw -= dx * 0.01; c.pitch = Math.max(-1.55, Math.min(1.55, c.pitch + dy * 0.01));
    } else if (this.mode === 'pan') {
      const { right, up } = this.matrices();
      const s = c.dist * Math.tan(c.fov / 2) * 2 / this.canvas.height;
      for (let i = 0; i < 3; i++) c.target[i] += (-dx * right[i] + dy * up[i]) * s;
    } else if (this.mode === 'points') {
      const { right, up } = this.matrices();
      const s = c.dist * Math.tan(c.fov / 2) * 2 / this.canvas.height;
      const tx = e.clientX - this.start[0], ty = e.clientY - this.start[1];
      const points = [...this.origin].map(([k, p]) => [k, ...[0, 1, 2].map((i) => p[i] + (tx * right[i] - ty * up[i]) * s)]);
      this.interact();
      this.app.moveControlPoints(this.overlay.map, this.gesture, points, e);
      return;
    }
    this.changed();
  }

  up() {
    if (this.mode === 'points' || this.mode === 'sculpt') this.app.endGesture(this.gesture);
    this.mode = null; this.last = null;
  }

  // Rotate for `ms` milliseconds, one step per frame; resolves to frames per second.
  spin(ms) {
    return new Promise((resolve) => {
      const t0 = performance.now(); const f0 = this.frames;
      const step = () => {
        this.cam.yaw += 0.03; this.interact(); this.requestProxy(); this.draw();
        if (performance.now() - t0 < ms) requestAnimationFrame(step);
        else resolve((this.frames - f0) / ((performance.now() - t0) / 1000));
      };
      requestAnimationFrame(step);
    });
  }
}
