// The studio's wire format (crates/studio/PROTOCOL.md): binary frames over one WebSocket.
export const VERSION = 1;
export const Kind = {
  Hello: 1, ListObjects: 2, GetSlice: 3, Drag: 4, EndGesture: 5, Undo: 6, Redo: 7,
  GetVolume: 8, GetProxy: 9, GetMesh: 10, GetLattice: 11, MoveControlPoints: 12, Setup: 13,
  Probe: 14, GetTransfer: 15, Command: 16, ListDir: 17, OpenFile: 18, SaveScene: 19,
  LoadScene: 20, Export: 21, GetJacobian: 22, Cancel: 23,
  Welcome: 100, Scene: 101, Changed: 102, Slice: 103, Error: 104, VolumeData: 105, Proxy: 106,
  MeshData: 107, LatticeData: 108, Probed: 109, Transfer: 110, Listing: 111, Done: 112,
  Progress: 113,
};
const enc = new TextEncoder();
const dec = new TextDecoder();

export function encode(kind, request, header, payload) {
  const h = enc.encode(JSON.stringify(header || {}));
  const p = payload ? new Uint8Array(payload) : new Uint8Array(0);
  const buf = new ArrayBuffer(16 + h.length + p.length);
  const u8 = new Uint8Array(buf);
  u8.set([0x56, 0x4d, 0x53, 0x54]);
  const dv = new DataView(buf);
  dv.setUint16(4, VERSION, true);
  dv.setUint16(6, kind, true);
  dv.setUint32(8, request, true);
  dv.setUint32(12, h.length, true);
  u8.set(h, 16);
  u8.set(p, 16 + h.length);
  return buf;
}

export function decode(buf) {
  const dv = new DataView(buf);
  const hl = dv.getUint32(12, true);
  const header = JSON.parse(dec.decode(new Uint8Array(buf, 16, hl)));
  return { kind: dv.getUint16(6, true), request: dv.getUint32(8, true), header, payload: buf.slice(16 + hl) };
}

// A connection: request/reply by request number, pushes to listeners.
export class Client {
  constructor(url) {
    this.url = url;
    this.next = 1;
    this.pending = new Map();
    this.listeners = new Map();
    this.sentAt = new Map();
    this.edits = new Map();
  }
  open() {
    return new Promise((resolve, reject) => {
      this.ws = new WebSocket(this.url);
      this.ws.binaryType = 'arraybuffer';
      this.ws.onopen = () => resolve(this);
      this.ws.onerror = (e) => reject(new Error('WebSocket failed'));
      this.ws.onclose = () => this.emit({ kind: -1, header: { message: 'connection to the studio closed' } });
      this.ws.onmessage = (ev) => {
        const f = decode(ev.data);
        // A Changed is a push (frame request 0) naming the request it answers in its header.
        const answers = f.kind === Kind.Changed ? f.header.request : f.request;
        // Every answer to one of this page's requests ends its job (its progress bar).
        if (answers && f.kind !== Kind.Progress && (f.kind !== Kind.Changed || f.header.page === this.page)) this.onAnswered?.(answers);
        let ed = answers && this.edits.get(answers);
        if (ed && (f.kind === Kind.Error || (f.kind === Kind.Changed && f.header.page === this.page))) {
          this.edits.delete(answers);
        } else {
          ed = null;
        }
        const p = f.request && this.pending.get(f.request);
        if (p && f.kind !== Kind.Changed) {
          this.pending.delete(f.request);
          if (f.kind === Kind.Error) p.reject(Object.assign(new Error(f.header.message), { header: f.header }));
          else p.resolve(f);
        } else {
          // An edit settles once the listeners have shown its result.
          const shown = this.emit(f);
          if (ed) {
            shown.then(() => {
              if (f.kind === Kind.Error) ed.reject(Object.assign(new Error(f.header.message), { header: f.header }));
              else ed.resolve(f);
            });
          }
        }
      };
    });
  }
  on(kind, fn) {
    if (!this.listeners.has(kind)) this.listeners.set(kind, []);
    this.listeners.get(kind).push(fn);
  }
  // Call the listeners of `f`; resolves once every listener's promise has settled.
  emit(f) {
    const done = [];
    for (const fn of this.listeners.get(f.kind) || []) done.push(fn(f));
    for (const fn of this.listeners.get('*') || []) done.push(fn(f));
    return Promise.allSettled(done);
  }
  // Send without waiting for a reply (edits: their result comes as a Changed push).
  send(kind, header, payload) {
    const r = this.next++;
    this.sentAt.set(r, performance.now());
    if (this.sentAt.size > 4096) this.sentAt.delete(this.sentAt.keys().next().value);
    this.ws.send(encode(kind, r, header, payload));
    return r;
  }
  // Send an edit; resolves to its Changed (rejects with its Error) once the listeners have
  // handled it. Not for coalesced moves.
  edit(kind, header) {
    return new Promise((resolve, reject) => {
      const r = this.send(kind, header);
      this.edits.set(r, { resolve, reject });
    });
  }
  // A request number for a job that does not go through the socket (a download).
  reserve() { return this.next++; }
  request(kind, header, payload) {
    const r = this.next++;
    return new Promise((resolve, reject) => {
      this.pending.set(r, { resolve, reject });
      this.ws.send(encode(kind, r, header, payload));
    });
  }
}

export function f32(buf, offsetBytes, count) {
  return new Float32Array(buf, offsetBytes, count);
}
