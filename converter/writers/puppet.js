// The facesvg puppet player (converter/writers/puppet.py inlines it): a 2D face driven by named weights and head
// and eye angles, from the embedded take, the sliders, a live WebSocket feed or window.puppet.set(...).
// It evaluates no strings and fetches nothing: the only connection it opens is the WebSocket a user names.
(function () {
  "use strict";

  const $ = (id) => document.getElementById(id);
  const DEG = Math.PI / 180;
  const FORMAT = "facesvg-puppet", VERSIONS = [3];  // the package formats this player reads (writers/puppet.py)

  function say(text) {
    const el = $("puppet-status");
    if (el) el.textContent = text;
  }

  function base64Bytes(text) {
    const s = atob(text.replace(/\s+/g, ""));
    const out = new Uint8Array(s.length);
    for (let i = 0; i < s.length; i++) out[i] = s.charCodeAt(i);
    return out;
  }

  // Inflate a zlib block with the browser's DecompressionStream into one buffer of the stated length.
  async function inflate(bytes, expected) {
    const out = new Uint8Array(expected);
    if (!bytes.length) return out;
    if (typeof DecompressionStream !== "function") {
      throw new Error("this browser cannot unpack the puppet (it has no DecompressionStream); use a current one.");
    }
    const reader = new Blob([bytes]).stream().pipeThrough(new DecompressionStream("deflate")).getReader();
    let n = 0;
    for (;;) {
      const { done, value } = await reader.read();
      if (done) break;
      if (n + value.length > expected) throw new Error("the puppet's data block is longer than stated: corrupt.");
      out.set(value, n);
      n += value.length;
    }
    if (n !== expected) throw new Error("the puppet's data block is shorter than stated: corrupt.");
    return out;
  }

  // One array of a block from its index entry [offset, dtype, length]; "p" dtypes are byte planes, "zp" zigzag
  // signed integers (0, -1, 1, -2, ...).
  function view(buf, entry) {
    const [off, kind, n] = entry;
    if (kind === "zp") {
      const lo = buf.subarray(off, off + n), hi = buf.subarray(off + n, off + 2 * n), out = new Int32Array(n);
      for (let i = 0; i < n; i++) {
        const u = lo[i] | (hi[i] << 8);
        out[i] = (u >>> 1) ^ -(u & 1);
      }
      return out;
    }
    if (kind.endsWith("p")) {
      const lo = buf.subarray(off, off + n), hi = buf.subarray(off + n, off + 2 * n);
      const out = kind.startsWith("i") ? new Int16Array(n) : new Uint16Array(n);
      for (let i = 0; i < n; i++) out[i] = lo[i] | (hi[i] << 8);
      return out;
    }
    const at = buf.byteOffset + off;
    switch (kind) {
      case "f4": return new Float32Array(buf.buffer, at, n);
      case "i4": return new Int32Array(buf.buffer, at, n);
      case "i2": return new Int16Array(buf.slice(off, off + 2 * n).buffer);
      case "u2": return new Uint16Array(buf.slice(off, off + 2 * n).buffer);
      case "i1": return new Int8Array(buf.buffer, at, n);
      default: return new Uint8Array(buf.buffer, at, n);
    }
  }

  // Capture names as converter.blendshapes.normalise reads them: (base, side).
  const SIDE = /(?:[._\s-](l|r|left|right)|(left|right))$/i;
  const PREFIX = /^(?:arkit|bs|blendshapes?|shapes?|morphs?)[_\-\s]+/i;
  function normalise(name) {
    let s = String(name).trim(), side = "";
    const m = SIDE.exec(s);
    if (m && m.index > 0) {
      side = (m[1] || m[2])[0].toUpperCase();
      s = s.slice(0, m.index);
    }
    if (/[.:|]/.test(s)) {
      const parts = s.split(/[.:|]/);
      s = parts[parts.length - 1];
    }
    s = s.replace(PREFIX, "");
    return [s.replace(/[\s_\-.]/g, "").toLowerCase(), side];
  }

  // Interval i and fraction of x on a sorted axis, extrapolating from the end intervals.
  function segment(axis, x) {
    let i = 0;
    while (i < axis.length - 2 && x >= axis[i + 1]) i++;
    return [i, (x - axis[i]) / (axis[i + 1] - axis[i])];
  }

  const CLOCK_MS = 250;  // the playing clock's refresh period
  const POSE_NAMES = ["headYaw", "headPitch", "headRoll", "eyeYawLeft", "eyePitchLeft", "eyeYawRight", "eyePitchRight"];

  class Model {
    constructor(meta, buf) {
      this.meta = meta;
      const a = meta.arrays;
      this.V = meta.vertices;
      this.F = meta.triangles;
      const V = this.V, qxy = view(buf, a.xy), qz = view(buf, a.z), qt = view(buf, a.tris);
      this.xy0 = new Float32Array(2 * V);
      this.z0 = new Float32Array(V);
      let x = 0, y = 0, d = 0;  // stored as differences from the previous vertex: x column, then y
      for (let i = 0; i < V; i++) {
        x += qxy[i];
        y += qxy[V + i];
        d += qz[i];
        this.xy0[2 * i] = x * meta.xyUnit;
        this.xy0[2 * i + 1] = y * meta.xyUnit;
        this.z0[i] = d * meta.zUnit;
      }
      this.tris = new Int32Array(3 * this.F);
      let first = 0;  // the gap from the previous triangle's first corner, then the others' offsets from it
      for (let f = 0; f < this.F; f++) {
        first += qt[3 * f];
        this.tris[3 * f] = first;
        this.tris[3 * f + 1] = first + qt[3 * f + 1];
        this.tris[3 * f + 2] = first + qt[3 * f + 2];
      }
      if (a.colors) this.colors = view(buf, a.colors);
      else {  // a palette and an index into it per triangle (or vertex)
        const palette = view(buf, a.palette), index = view(buf, a.colorIndex);
        this.colors = new Uint8Array(3 * index.length);
        for (let i = 0; i < index.length; i++) this.colors.set(palette.subarray(3 * index[i], 3 * index[i] + 3), 3 * i);
      }
      // unlit base colours and rest normals, lit as converter/lighting.py lights them; a normal is an octahedral
      // int8 pair, each column stored as byte differences from the previous element (model.unoctahedral)
      const cols = view(buf, a.normals), N = cols.length / 2;
      this.normals = new Float32Array(3 * N);
      let cu = 0, cv = 0;
      for (let i = 0; i < N; i++) {
        cu = (cu + cols[i]) & 255;
        cv = (cv + cols[N + i]) & 255;
        let x = (cu << 24 >> 24) / 127, y = (cv << 24 >> 24) / 127;
        const z = 1 - Math.abs(x) - Math.abs(y), t = Math.max(-z, 0);
        x -= x >= 0 ? t : -t;
        y -= y >= 0 ? t : -t;
        const l = Math.hypot(x, y, z) || 1;
        this.normals[3 * i] = x / l; this.normals[3 * i + 1] = y / l; this.normals[3 * i + 2] = z / l;
      }
      this.head = [0, 0, 0];
      this.headMatrix = null;  // evaluate's head turn (NDC -> clip), null at rest
      this.placed = false;
      const param = (p) => {
        const v = view(buf, a[p.key + ".v"]).slice(), rows = view(buf, a[p.key + ".xy"]), z = view(buf, a[p.key + ".z"]);
        for (let m = 1; m < v.length; m++) v[m] += v[m - 1];  // stored as gaps
        if (p.residual) {  // inner keyforms: differences from the linear prediction floor(w * last + 1/2)
          const w = p.axes[0], S = w.length, M = v.length;
          const unpack = (arr, n) => {
            const last = (S - 1) * M * n;
            for (let s = 1; s < S - 1; s++) {
              for (let i = 0; i < M * n; i++) arr[s * M * n + i] += Math.floor(w[s] * arr[last + i] + 0.5);
            }
          };
          unpack(rows, 2);
          unpack(z, 1);
        }
        const M = v.length, S = p.axes[0].length, xy = new Int32Array(2 * M * S);
        for (let s = 0; s < S; s++) {  // each keyform stored as its x row, then its y row
          for (let i = 0; i < M; i++) {
            xy[2 * (s * M + i)] = rows[2 * s * M + i];
            xy[2 * (s * M + i) + 1] = rows[(2 * s + 1) * M + i];
          }
        }
        return Object.assign({}, p, { v, xy, z });
      };
      this.morphs = meta.morphs.map(param);
      this.eyes = meta.eyes.map((e) => ({ centre: e.centre, v: view(buf, a[e.key + ".v"]) }));
      this.q = new Float64Array(3 * this.V);
      this.bxy = new Float32Array(2 * this.V);  // before the head turn (evaluate)
      this.bz = new Float32Array(this.V);
      this.bxy.set(this.xy0);
      this.bz.set(this.z0);
      this.version = 0;
      this.xy = new Float32Array(2 * this.V);  // after it (place)
      this.z = new Float32Array(this.V);
      this.own = new Map(this.morphs.map((p, k) => [p.name, k]));
      this.byKey = new Map();
      meta.keys.forEach((key, k) => {
        const s = key.join("\u0000");
        if (!this.byKey.has(s)) this.byKey.set(s, []);
        this.byKey.get(s).push(k);
      });
      this.resolved = new Map();
    }

    // What a name drives: [[morph index, factor], ...] (own name, alias, normalised name; sideless -> both sides).
    resolve(name) {
      if (this.resolved.has(name)) return this.resolved.get(name);
      let out = [];
      if (this.own.has(name)) out = [[this.own.get(name), 1]];
      else if (Object.prototype.hasOwnProperty.call(this.meta.aliases, name)) out = this.meta.aliases[name];
      else {
        const [base, side] = normalise(name);
        let hits = this.byKey.get(base + "\u0000" + side) || [];
        if (!hits.length && !side) {
          hits = (this.byKey.get(base + "\u0000L") || []).concat(this.byKey.get(base + "\u0000R") || []);
        }
        out = hits.map((k) => [k, 1]);
      }
      this.resolved.set(name, out);
      return out;
    }

    addKeyform(p, s, f, xy, z) {
      if (!f) return;
      const ids = p.v, dxy = p.xy, dz = p.z, M = ids.length, off = s * M, sx = f * p.xyStep, sz = f * p.zStep;
      for (let m = 0; m < M; m++) {
        const vi = ids[m], q = off + m;
        xy[2 * vi] += sx * dxy[2 * q];
        xy[2 * vi + 1] += sx * dxy[2 * q + 1];
        z[vi] += sz * dz[q];
      }
    }

    // The world direction towards the key light as the head's rest normals see it: R^T l, for n' = R n.
    light() {
      const l = this.meta.light.direction, [yaw, pitch, roll] = this.head;
      if (!(yaw || pitch || roll)) return l;
      const r = rotation(yaw, pitch, roll);
      return [r[0] * l[0] + r[3] * l[1] + r[6] * l[2], r[1] * l[0] + r[4] * l[1] + r[7] * l[2],
              r[2] * l[0] + r[5] * l[1] + r[8] * l[2]];
    }

    // Display colours (0..255, rounded) of each lit element (triangle or vertex) into out for light direction l:
    // srgb(linear(base) * (ambient + diffuse * max(n.l, 0))), converter.lighting.lambert.
    shade(l, out) {
      const n = this.normals, amb = this.meta.light.ambient, dif = this.meta.light.diffuse;
      // encode(c g) = 1.055 c^(1/2.4) g^(1/2.4) - 0.055 above the curve's linear toe: one pow per element
      const [c, root] = this.linearColours();
      for (let i = 0; i < n.length / 3; i++) {
        const g = amb + dif * Math.max(n[3 * i] * l[0] + n[3 * i + 1] * l[1] + n[3 * i + 2] * l[2], 0);
        const G = Math.pow(g, 1 / 2.4);
        for (let k = 0; k < 3; k++) {
          const x = c[3 * i + k] * g;
          const e = x <= 0.0031308 ? 12.92 * x : 1.055 * Math.min(root[3 * i + k] * G, 1) - 0.055;
          out[3 * i + k] = Math.round(255 * e);
        }
      }
      return out;
    }

    // Each lit element's linear base colour and its 2.4th root (the sRGB encode's pow, taken once).
    linearColours() {
      if (!this.linear) {
        this.linear = Float32Array.from(this.colors, (v) => decode(v / 255));
        this.linearRoot = Float32Array.from(this.linear, (v) => Math.pow(v, 1 / 2.4));
      }
      return [this.linear, this.linearRoot];
    }

    // World point of pixel (x, y) and NDC depth z into out[0..2]: the camera's inverse.
    unproject(x, y, z, out) {
      const m = this.meta.inverse, nx = 2 * x / this.meta.width - 1, ny = 1 - 2 * y / this.meta.height;
      const w = m[12] * nx + m[13] * ny + m[14] * z + m[15];
      out[0] = (m[0] * nx + m[1] * ny + m[2] * z + m[3]) / w;
      out[1] = (m[4] * nx + m[5] * ny + m[6] * z + m[7]) / w;
      out[2] = (m[8] * nx + m[9] * ny + m[10] * z + m[11]) / w;
    }

    // The pose's positions before the head turn (px and NDC depth in bxy, bz: the morphs summed, the eyes turned
    // about their centres) and the head turn as one matrix (headMatrix), converter.puppet.model.pose's arithmetic
    // in two steps: place() applies the turn in script, the WebGL2 vertex shader applies it itself. The morph sums
    // are skipped when the weights and eyes are those of the previous call (version counts the changes).
    evaluate(weights, head, eyes) {
      this.head = [head[0], head[1], head[2]];
      const [yaw, pitch, roll] = head, [px, py, pz] = this.meta.pivot;
      const r = yaw || pitch || roll ? rotation(yaw, pitch, roll) : null;
      // project . turn about the pivot . unproject: NDC in, clip out
      this.headMatrix = r ? product(this.meta.matrix, product([r[0], r[1], r[2], px - r[0] * px - r[1] * py - r[2] * pz,
                                                               r[3], r[4], r[5], py - r[3] * px - r[4] * py - r[5] * pz,
                                                               r[6], r[7], r[8], pz - r[6] * px - r[7] * py - r[8] * pz,
                                                               0, 0, 0, 1], this.meta.inverse)) : null;
      this.placed = false;
      const last = this.lastWeights, lastEyes = this.lastEyes;
      let same = !!last && last.length === weights.length;
      for (let k = 0; same && k < weights.length; k++) same = last[k] === weights[k];
      for (let k = 0; same && k < 4; k++) same = lastEyes[k] === (eyes[k] || 0);
      if (same) return;
      this.lastWeights = Float32Array.from(weights);
      this.lastEyes = [0, 1, 2, 3].map((k) => eyes[k] || 0);
      this.version = (this.version || 0) + 1;
      const xy = this.bxy, z = this.bz;
      xy.set(this.xy0);
      z.set(this.z0);
      this.morphs.forEach((p, k) => {
        let w = weights[k];
        if (p.clamp) w = Math.min(Math.max(w, 0), 1);
        if (p.binary) w = w > 0.5 ? 1 : 0;
        if (!w || !p.v.length) return;
        const [i, a] = segment(p.axes[0], w);
        if (i > 0) this.addKeyform(p, i, 1 - a, xy, z);  // keyform 0 (weight 0) moves nothing
        this.addKeyform(p, i + 1, a, xy, z);
      });
      const turnEyes = this.eyes.map((e, k) => eyes[2 * k] || eyes[2 * k + 1]);
      if (!turnEyes.some(Boolean)) return;
      // Rigid turns in world space, as blendshapes.drive turns the morphed face: eyes about their centres, projected
      // again (the head's turn follows, through headMatrix: it unprojects them to where they were turned).
      const q = this.q, t = [0, 0, 0], m = this.meta.matrix, W = this.meta.width, H = this.meta.height;
      const turned = this.turned || (this.turned = new Uint8Array(this.V));
      turned.fill(0);
      this.eyes.forEach((e, k) => {
        if (!turnEyes[k]) return;
        const re = rotation(eyes[2 * k], eyes[2 * k + 1], 0), [cx, cy, cz] = e.centre;
        for (const v of e.v) {
          if (!turned[v]) {
            this.unproject(xy[2 * v], xy[2 * v + 1], z[v], t);
            q[3 * v] = t[0]; q[3 * v + 1] = t[1]; q[3 * v + 2] = t[2];
            turned[v] = 1;
          }
          turn(q, 3 * v, re, cx, cy, cz);
        }
      });
      this.eyes.forEach((e) => {
        for (const v of e.v) {
          if (turned[v] !== 1) continue;
          turned[v] = 2;
          const X = q[3 * v], Y = q[3 * v + 1], Z = q[3 * v + 2];
          const cw = m[12] * X + m[13] * Y + m[14] * Z + m[15];
          xy[2 * v] = ((m[0] * X + m[1] * Y + m[2] * Z + m[3]) / cw + 1) * 0.5 * W;
          xy[2 * v + 1] = (1 - (m[4] * X + m[5] * Y + m[6] * Z + m[7]) / cw) * 0.5 * H;
          z[v] = (m[8] * X + m[9] * Y + m[10] * Z + m[11]) / cw;
        }
      });
    }

    // The evaluated pose's positions (px) and NDC depth in xy, z: the head turned in script (canvas, WebGL1 and
    // positions(); WebGL2 turns it in its vertex shader).
    place() {
      if (this.placed) return;
      this.placed = true;
      const xy = this.xy, z = this.z, bxy = this.bxy, bz = this.bz, c = this.headMatrix;
      if (!c) {
        xy.set(bxy);
        z.set(bz);
        return;
      }
      const W = this.meta.width, H = this.meta.height;
      for (let v = 0; v < this.V; v++) {
        const nx = 2 * bxy[2 * v] / W - 1, ny = 1 - 2 * bxy[2 * v + 1] / H, nz = bz[v];
        const cw = c[12] * nx + c[13] * ny + c[14] * nz + c[15];
        xy[2 * v] = ((c[0] * nx + c[1] * ny + c[2] * nz + c[3]) / cw + 1) * 0.5 * W;
        xy[2 * v + 1] = (1 - (c[4] * nx + c[5] * ny + c[6] * nz + c[7]) / cw) * 0.5 * H;
        z[v] = (c[8] * nx + c[9] * ny + c[10] * nz + c[11]) / cw;
      }
    }
  }

  // sRGB transfer curve (IEC 61966-2-1), as converter/lighting.py.
  const decode = (c) => (c <= 0.04045 ? c / 12.92 : Math.pow((c + 0.055) / 1.055, 2.4));
  const encode = (c) => (c <= 0.0031308 ? 12.92 * c : 1.055 * Math.pow(c, 1 / 2.4) - 0.055);

  // The product of two row-major 4x4 matrices.
  function product(a, b) {
    const o = new Array(16).fill(0);
    for (let i = 0; i < 4; i++) {
      for (let j = 0; j < 4; j++) {
        for (let k = 0; k < 4; k++) o[4 * i + j] += a[4 * i + k] * b[4 * k + j];
      }
    }
    return o;
  }

  // Ry(yaw) Rx(pitch) Rz(roll), row-major (converter.blendshapes.rotations).
  function rotation(yaw, pitch, roll) {
    const cy = Math.cos(yaw), sy = Math.sin(yaw), cp = Math.cos(pitch), sp = Math.sin(pitch);
    const cr = Math.cos(roll), sr = Math.sin(roll);
    const a = [cy, sy * sp, sy * cp, 0, cp, -sp, -sy, cy * sp, cy * cp];  // Ry Rx
    return [a[0] * cr + a[1] * sr, -a[0] * sr + a[1] * cr, a[2],
            a[3] * cr + a[4] * sr, -a[3] * sr + a[4] * cr, a[5],
            a[6] * cr + a[7] * sr, -a[6] * sr + a[7] * cr, a[8]];
  }

  // q[i..i+2] = r (q - c) + c.
  function turn(q, i, r, cx, cy, cz) {
    const x = q[i] - cx, y = q[i + 1] - cy, z = q[i + 2] - cz;
    q[i] = r[0] * x + r[1] * y + r[2] * z + cx;
    q[i + 1] = r[3] * x + r[4] * y + r[5] * z + cy;
    q[i + 2] = r[6] * x + r[7] * y + r[8] * z + cz;
  }

  // A row-major 4x4 matrix as GLSL's column-major floats (the identity for null).
  function columns(m) {
    const o = new Float32Array(16);
    for (let i = 0; i < 4; i++) {
      for (let j = 0; j < 4; j++) o[4 * j + i] = m ? m[4 * i + j] : +(i === j);
    }
    return o;
  }

  // WebGL: depth-tested triangles, back faces culled, each corner lit in the vertex shader. WebGL2 keeps the vertices
  // before the head turn in a float texture (those the morphs and eyes move first: a frame uploads only their rows,
  // and none when only the head turned), turns the head in the vertex shader (headMatrix) and draws indexed, so the
  // shader runs about once a vertex; WebGL1 rebuilds every corner in script.
  class GLView {
    constructor(canvas, model) {
      // The drawing buffer is handed to the compositor, not copied each frame (read the canvas in the task that
      // draws it); alpha is 0 or 1, so premultiplied or not are the same pixels.
      const opts = { antialias: false, preserveDrawingBuffer: false, alpha: true, premultipliedAlpha: true };
      const gl = canvas.getContext("webgl2", opts) || canvas.getContext("webgl", opts);
      if (!gl) throw new Error("no WebGL");
      this.gl = gl;
      this.model = model;
      const two = typeof window.WebGL2RenderingContext !== "undefined" && gl instanceof window.WebGL2RenderingContext;
      const gouraud = model.meta.gouraud, V = model.V, F = model.F, tris = model.tris;
      // srgb(linear(base) * g), g = ambient + diffuse * max(n.l, 0), from the base's linear value c and its root
      // r = c^(1/2.4) (model.shade's arithmetic: one pow a corner)
      const lit = "uniform vec3 light; uniform vec2 rig;" +
        " vec3 shade(vec3 c, vec3 r, vec3 n){ float g = rig.x + rig.y * max(dot(n, light), 0.0);" +
        " vec3 x = c * g, e = 1.055 * min(r * pow(g, 1.0 / 2.4), vec3(1.0)) - 0.055;" +
        " return mix(e, 12.92 * x, step(x, vec3(0.0031308))); }";
      // flat: the triangle's colour is its last corner's (GL's provoking vertex), not interpolated
      const q = two && !gouraud ? "flat " : "";
      const vs = two ?
        "#version 300 es\nprecision highp float; precision highp int; in int p; in vec3 c; in vec3 r; in vec3 n; " + q +
        "out vec3 vc; uniform highp sampler2D pos; uniform mat4 head; " + lit + " void main(){" +
        " int w = textureSize(pos, 0).x; vec3 b = texelFetch(pos, ivec2(p % w, p / w), 0).xyz; vc = shade(c, r, n);" +
        " vec4 h = head * vec4(b, 1.0); gl_Position = vec4(h.xyz / h.w, 1.0); }" :
        "precision highp float; attribute vec3 p; attribute vec3 c; attribute vec3 r; attribute vec3 n;" +
        " varying vec3 vc; " + lit + " void main(){ vc = shade(c, r, n); gl_Position = vec4(p, 1.0); }";
      const fs = two ?
        "#version 300 es\nprecision mediump float; " + q + "in vec3 vc; out vec4 o; void main(){ o = vec4(vc, 1.0); }" :
        "precision mediump float; varying vec3 vc; void main(){ gl_FragColor = vec4(vc, 1.0); }";
      const shader = (type, src) => {
        const s = gl.createShader(type);
        gl.shaderSource(s, src);
        gl.compileShader(s);
        if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
        return s;
      };
      const prog = gl.createProgram();
      gl.attachShader(prog, shader(gl.VERTEX_SHADER, vs));
      gl.attachShader(prog, shader(gl.FRAGMENT_SHADER, fs));
      ["p", "c", "r", "n"].forEach((name, k) => gl.bindAttribLocation(prog, k, name));
      gl.linkProgram(prog);
      if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(prog));
      gl.useProgram(prog);
      // what each drawn vertex reads: its model vertex (src) and its lit element (elem: a vertex, or a triangle)
      let src, elem, index;
      if (!two) {  // every corner apart
        src = tris;
        elem = gouraud ? tris : Int32Array.from({ length: 3 * F }, (_, i) => (i / 3) | 0);
      } else if (gouraud) {
        src = elem = Int32Array.from({ length: V }, (_, v) => v);
        index = tris;
      } else {  // each triangle's last corner a vertex of its own: one no triangle before took, else a copy of one
        const owner = new Int32Array(V).fill(-1), copies = [];
        index = new Int32Array(3 * F);
        for (let f = 0; f < F; f++) {
          let k = 0;
          while (k < 3 && owner[tris[3 * f + k]] >= 0) k++;
          if (k < 3) {  // rotated to the end: the same winding
            owner[tris[3 * f + k]] = f;
            for (let i = 0; i < 3; i++) index[3 * f + i] = tris[3 * f + (k + 1 + i) % 3];
          } else {
            index.set(tris.subarray(3 * f, 3 * f + 3), 3 * f);
            index[3 * f + 2] = V + copies.length;
            copies.push(f);
          }
        }
        src = new Int32Array(V + copies.length);
        elem = new Int32Array(V + copies.length);
        for (let v = 0; v < V; v++) { src[v] = v; elem[v] = Math.max(owner[v], 0); }
        copies.forEach((f, k) => { src[V + k] = tris[3 * f + 2]; elem[V + k] = f; });
      }
      const D = src.length, [linear, root] = model.linearColours(), normals = model.normals;
      const attrs = [new Float32Array(3 * D), new Float32Array(3 * D), new Float32Array(3 * D)];
      for (let d = 0; d < D; d++) {
        const e = 3 * elem[d];
        [linear, root, normals].forEach((a, k) => attrs[k].set(a.subarray(e, e + 3), 3 * d));
      }
      attrs.forEach((a, k) => {
        gl.bindBuffer(gl.ARRAY_BUFFER, gl.createBuffer());
        gl.bufferData(gl.ARRAY_BUFFER, a, gl.STATIC_DRAW);
        gl.enableVertexAttribArray(k + 1);
        gl.vertexAttribPointer(k + 1, 3, gl.FLOAT, false, 0, 0);
      });
      this.pos = gl.createBuffer();
      gl.bindBuffer(gl.ARRAY_BUFFER, this.pos);
      gl.enableVertexAttribArray(0);
      this.two = two;
      this.count = 3 * F;
      if (two) {
        // texture slots: the moved vertices first
        const moved = new Uint8Array(V), slot = new Int32Array(V), order = new Int32Array(V);
        model.morphs.forEach((p) => p.v.forEach((v) => { moved[v] = 1; }));
        model.eyes.forEach((e) => e.v.forEach((v) => { moved[v] = 1; }));
        let k = 0;
        for (let v = 0; v < V; v++) if (moved[v]) { slot[v] = k; order[k++] = v; }
        this.moved = k;
        for (let v = 0; v < V; v++) if (!moved[v]) { slot[v] = k; order[k++] = v; }
        this.order = order;
        gl.bufferData(gl.ARRAY_BUFFER, Int32Array.from(src, (v) => slot[v]), gl.STATIC_DRAW);
        gl.vertexAttribIPointer(0, 1, gl.INT, 0, 0);
        gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, gl.createBuffer());
        const wide = D > 65535;
        gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, wide ? Uint32Array.from(index) : Uint16Array.from(index), gl.STATIC_DRAW);
        this.indexType = wide ? gl.UNSIGNED_INT : gl.UNSIGNED_SHORT;
        this.TW = Math.min(Math.max(V, 1), 2048);
        this.TH = Math.ceil(Math.max(V, 1) / this.TW);
        this.texels = new Float32Array(4 * this.TW * this.TH);
        this.fill(model.xy0, model.z0, V);
        this.tex = gl.createTexture();
        gl.activeTexture(gl.TEXTURE0);
        gl.bindTexture(gl.TEXTURE_2D, this.tex);
        gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
        gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
        gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
        gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
        gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, this.TW, this.TH, 0, gl.RGBA, gl.FLOAT, this.texels);
        gl.uniform1i(gl.getUniformLocation(prog, "pos"), 0);
        this.headAt = gl.getUniformLocation(prog, "head");
        this.version = -1;
      } else {
        this.corners = new Float32Array(9 * F);
        gl.bufferData(gl.ARRAY_BUFFER, this.corners, gl.DYNAMIC_DRAW);
        gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
      }
      this.lightAt = gl.getUniformLocation(prog, "light");
      gl.uniform2f(gl.getUniformLocation(prog, "rig"), model.meta.light.ambient, model.meta.light.diffuse);
      gl.enable(gl.DEPTH_TEST);
      gl.depthFunc(gl.LEQUAL);
      gl.enable(gl.CULL_FACE);
      gl.frontFace(gl.CCW);
      gl.cullFace(gl.BACK);
      gl.clearColor(0, 0, 0, 0);
      gl.clearDepth(1);
      gl.viewport(0, 0, canvas.width, canvas.height);
      this.kind = gl instanceof window.WebGLRenderingContext ? "webgl" : "webgl2";
    }

    // The first n texture slots' texels (NDC) from positions xy (px) and depth z.
    fill(xy, z, n) {
      const t = this.texels, order = this.order, sx = 2 / this.model.meta.width, sy = 2 / this.model.meta.height;
      for (let k = 0; k < n; k++) {
        const v = order[k];
        t[4 * k] = xy[2 * v] * sx - 1;
        t[4 * k + 1] = 1 - xy[2 * v + 1] * sy;
        t[4 * k + 2] = z[v];
      }
    }

    draw() {
      const gl = this.gl, m = this.model;
      gl.uniform3fv(this.lightAt, m.light());
      if (this.two) {
        if (this.version !== m.version) {
          this.version = m.version;
          this.fill(m.bxy, m.bz, this.moved);
          const rows = Math.ceil(this.moved / this.TW);
          if (rows) gl.texSubImage2D(gl.TEXTURE_2D, 0, 0, 0, this.TW, rows, gl.RGBA, gl.FLOAT, this.texels);
        }
        gl.uniformMatrix4fv(this.headAt, false, columns(m.headMatrix));
        gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
        gl.drawElements(gl.TRIANGLES, this.count, this.indexType, 0);
        return;
      }
      m.place();
      const xy = m.xy, z = m.z, tris = m.tris, out = this.corners, n = this.count;
      const sx = 2 / m.meta.width, sy = 2 / m.meta.height;
      for (let i = 0; i < n; i++) {
        const v = tris[i];
        out[3 * i] = xy[2 * v] * sx - 1;
        out[3 * i + 1] = 1 - xy[2 * v + 1] * sy;
        out[3 * i + 2] = z[v];
      }
      gl.bindBuffer(gl.ARRAY_BUFFER, this.pos);
      gl.bufferSubData(gl.ARRAY_BUFFER, 0, out);
      gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
      gl.drawArrays(gl.TRIANGLES, 0, n);
    }
  }

  // Canvas 2D: the triangles rasterised in script into an image, as GL draws them without antialiasing (pixel
  // centres, a depth buffer, back faces dropped), then put on the canvas at once: a path and a fill per triangle
  // cost ~2 us each in Firefox, where a small triangle's few pixels cost a few ns each.
  class CanvasView {
    constructor(canvas, model) {
      this.ctx = canvas.getContext("2d");
      this.model = model;
      this.kind = "canvas";
      this.W = canvas.width;
      this.H = canvas.height;
      this.image = this.ctx.createImageData(this.W, this.H);
      this.pixels = new Uint32Array(this.image.data.buffer);
      this.depth = new Float32Array(this.W * this.H);
      this.lit = new Uint8Array(model.colors.length);
      this.rgba = new Uint32Array(model.colors.length / 3);  // each lit element's colour as one pixel (ABGR)
      this.lightKey = null;
    }

    relight(l) {
      const c = this.model.shade(l, this.lit), out = this.rgba;
      for (let i = 0; i < out.length; i++) out[i] = (0xff000000 | (c[3 * i + 2] << 16) | (c[3 * i + 1] << 8) | c[3 * i]) >>> 0;
      this.lightKey = l.join();
    }

    draw() {
      const m = this.model;
      m.place();
      const xy = m.xy, z = m.z, tris = m.tris, l = m.light();
      if (l.join() !== this.lightKey) this.relight(l);
      const W = this.W, H = this.H, px = this.pixels, depth = this.depth, rgba = this.rgba, lit = this.lit;
      const gouraud = m.meta.gouraud;
      px.fill(0);
      depth.fill(1);
      for (let f = 0; f < m.F; f++) {
        let a = tris[3 * f], b = tris[3 * f + 1], c = tris[3 * f + 2];
        const ax = xy[2 * a], ay = xy[2 * a + 1];
        const area2 = (xy[2 * b] - ax) * (xy[2 * c + 1] - ay) - (xy[2 * b + 1] - ay) * (xy[2 * c] - ax);
        if (!(area2 < 0)) continue;  // y down: a front (counter-clockwise in GL) triangle has negative area
        const t = b; b = c; c = t;  // now clockwise on screen: inside where every edge function is >= 0
        const x0 = ax, y0 = ay, x1 = xy[2 * b], y1 = xy[2 * b + 1], x2 = xy[2 * c], y2 = xy[2 * c + 1];
        const c0 = Math.max(0, Math.ceil(Math.min(x0, x1, x2) - 0.5)), c1 = Math.min(W - 1, Math.floor(Math.max(x0, x1, x2) - 0.5));
        const r0 = Math.max(0, Math.ceil(Math.min(y0, y1, y2) - 0.5)), r1 = Math.min(H - 1, Math.floor(Math.max(y0, y1, y2) - 0.5));
        if (c0 > c1 || r0 > r1) continue;
        const inv = -1 / area2, z0 = z[a], dz1 = z[b] - z0, dz2 = z[c] - z0;
        const ex1 = x1 - x0, ey1 = y1 - y0, ex2 = x2 - x0, ey2 = y2 - y0;
        // the edge functions over the doubled area are the corners' weights (opposite corner): depth is linear
        const gx = (dz1 * ey2 - dz2 * ey1) * inv, gy = (dz2 * ex1 - dz1 * ex2) * inv;
        const sx = c0 + 0.5, sy = r0 + 0.5;
        let e0r = (x2 - x1) * (sy - y1) - (y2 - y1) * (sx - x1);
        let e1r = (x0 - x2) * (sy - y2) - (y0 - y2) * (sx - x2);
        let e2r = (x1 - x0) * (sy - y0) - (y1 - y0) * (sx - x0);
        let zr = z0 + gx * (sx - x0) + gy * (sy - y0);
        const d0x = -(y2 - y1), d1x = -(y0 - y2), d2x = -(y1 - y0), d0y = x2 - x1, d1y = x0 - x2, d2y = x1 - x0;
        let flat = 0, ca = 0, cb = 0, cc = 0;
        if (gouraud) { ca = 3 * a; cb = 3 * b; cc = 3 * c; } else flat = rgba[f];
        for (let r = r0; r <= r1; r++) {
          let e0 = e0r, e1 = e1r, e2 = e2r, zc = zr, row = r * W, inside = false;
          for (let col = c0; col <= c1; col++) {
            if (e0 >= 0 && e1 >= 0 && e2 >= 0) {
              inside = true;
              const i = row + col;
              if (zc <= depth[i] && zc >= -1) {
                depth[i] = zc;
                if (gouraud) {  // screen-linear weights of the corners, as the WebGL path interpolates
                  const wa = e0 * inv, wb = e1 * inv, wc = 1 - wa - wb;
                  const R = wa * lit[ca] + wb * lit[cb] + wc * lit[cc], G = wa * lit[ca + 1] + wb * lit[cb + 1] + wc * lit[cc + 1];
                  const B = wa * lit[ca + 2] + wb * lit[cb + 2] + wc * lit[cc + 2];
                  px[i] = (0xff000000 | (Math.round(B) << 16) | (Math.round(G) << 8) | Math.round(R)) >>> 0;
                } else px[i] = flat;
              }
            } else if (inside) break;  // a row's inside is one run (the triangle is convex)
            e0 += d0x; e1 += d1x; e2 += d2x; zc += gx;
          }
          e0r += d0y; e1r += d1y; e2r += d2y; zr += gy;
        }
      }
      this.ctx.putImageData(this.image, 0, 0);
    }
  }

  // The embedded take: uint8 weights per name per frame, head and eye angles as small integers.
  class TakeData {
    constructor(meta, buf) {
      this.meta = meta;
      this.names = meta.names;
      this.K = meta.names.length;
      this.frames = meta.frames;
      this.weights = view(buf, meta.arrays.weights);
      this.head = meta.arrays.head ? view(buf, meta.arrays.head) : null;
      this.eyes = meta.arrays.eyes ? view(buf, meta.arrays.eyes) : null;
      this.times = new Float64Array(this.frames);
      if (meta.arrays.times) {
        const gaps = view(buf, meta.arrays.times);
        let t = 0;
        for (let k = 0; k < this.frames; k++) { t += gaps[k] / 1000; this.times[k] = t; }
      } else {
        for (let k = 0; k < this.frames; k++) this.times[k] = k / meta.fps;
      }
      this.duration = this.times[this.frames - 1] - this.times[0] + 1 / meta.fps;
    }

    // Frame and fraction towards the next one at t seconds (t from the first frame).
    locate(t) {
      const ts = this.times, t0 = ts[0] + t;
      let lo = 0, hi = this.frames - 1;
      if (t0 <= ts[0]) return [0, 0];
      if (t0 >= ts[hi]) return [hi, 0];
      while (hi - lo > 1) {
        const mid = (lo + hi) >> 1;
        if (ts[mid] <= t0) lo = mid; else hi = mid;
      }
      return [lo, (t0 - ts[lo]) / (ts[lo + 1] - ts[lo])];
    }
  }

  class Puppet {
    constructor(model, viewer, take) {
      this.model = model;
      this.viewer = viewer;
      this.take = take;
      this.inputs = new Map();  // normalised name -> [name, weight], from the take, set() and the live feed
      this.keys = new Map();  // name -> its normalised key
      this.pose = new Float64Array(7);  // head yaw, pitch, roll, eyes left yaw, pitch, right yaw, pitch (radians)
      this.weights = new Float32Array(model.morphs.length);
      this.time = 0;
      this.playing = false;
      this.dirty = true;
      this.socket = null;
      this.frameCount = 0;
      this.lastFrameMs = 0;
      this.sliders = new Map();
    }

    // Weights by name ({jawOpen: 0.4}); head: [yaw, pitch, roll] and eyes: [ly, lp, ry, rp] in radians, or their
    // own names (headYaw, eyePitchLeft, ...).
    set(values, head, eyes) {
      if (values && typeof values === "object") {
        for (const [name, v] of Object.entries(values)) {
          if (name === "head" && Array.isArray(v)) this.setPose(v, 0);
          else if (name === "eyes" && Array.isArray(v)) this.setPose(v, 3);
          else if (POSE_NAMES.includes(name)) this.pose[POSE_NAMES.indexOf(name)] = Number(v) || 0;
          else this.input(name, Number(v) || 0);
        }
      }
      if (Array.isArray(head)) this.setPose(head, 0);
      if (Array.isArray(eyes)) this.setPose(eyes, 3);
      this.dirty = true;
      this.syncSliders();
      return this;
    }

    // One named weight; spellings of one name (JawOpen, jawOpen, jaw_open) are one input.
    input(name, v) {
      let key = this.keys.get(name);
      if (key === undefined) {
        key = normalise(name).join("\u0000");
        this.keys.set(name, key);
      }
      this.inputs.set(key, [name, v]);
    }

    setPose(values, at) {
      values.forEach((v, i) => { if (at + i < 7) this.pose[at + i] = Number(v) || 0; });
    }

    reset() {
      this.inputs.clear();
      this.pose.fill(0);
      this.dirty = true;
      this.syncSliders();
    }

    weightsNow() {
      const w = this.weights;
      w.fill(0);
      for (const [name, v] of this.inputs.values()) {
        for (const [k, f] of this.model.resolve(name)) w[k] += f * v;
      }
      return w;
    }

    applyTake(t) {
      const tk = this.take;
      if (!tk) return;
      const [k, a] = tk.locate(t), k1 = Math.min(k + 1, tk.frames - 1), K = tk.K;
      for (let c = 0; c < K; c++) {
        const v = (1 - a) * tk.weights[k * K + c] + a * tk.weights[k1 * K + c];
        this.input(tk.names[c], v / 255);
      }
      if (tk.head) {
        for (let i = 0; i < 3; i++) {
          this.pose[i] = ((1 - a) * tk.head[3 * k + i] + a * tk.head[3 * k1 + i]) * tk.meta.headUnit;
        }
      }
      if (tk.eyes) {
        for (let i = 0; i < 4; i++) {
          this.pose[3 + i] = ((1 - a) * tk.eyes[4 * k + i] + a * tk.eyes[4 * k1 + i]) * tk.meta.eyeUnit;
        }
      }
      this.dirty = true;
    }

    render() {
      const t0 = performance.now();
      const p = this.pose;
      this.model.evaluate(this.weightsNow(), [p[0], p[1], p[2]], [p[3], p[4], p[5], p[6]]);
      this.viewer.draw();
      this.dirty = false;
      this.frameCount++;
      this.lastFrameMs = performance.now() - t0;
    }

    seek(t) {
      this.time = Math.max(0, Number(t) || 0);
      if (this.take) {
        this.time = Math.min(this.time, this.take.duration);
        this.applyTake(this.time);
      }
      this.updateClock();
      this.render();
      return this;
    }

    play() {
      if (!this.take || this.playing) return this;
      if (this.time >= this.take.duration) this.time = 0;
      this.playing = true;
      this.started = performance.now() - this.time * 1000;
      const button = $("puppet-play");
      if (button) { button.textContent = "Pause"; button.setAttribute("aria-pressed", "true"); }
      return this;
    }

    pause() {
      this.playing = false;
      const button = $("puppet-play");
      if (button) { button.textContent = "Play"; button.setAttribute("aria-pressed", "false"); }
      this.syncSliders();
      return this;
    }

    tick(now) {
      if (this.playing && this.take) {
        this.time = (now - this.started) / 1000;
        if (this.time >= this.take.duration) {
          this.time = this.time % this.take.duration;
          this.started = now - this.time * 1000;
        }
        this.applyTake(this.time);
        // the clock's text and slider at CLOCK_MS while playing: restyling them each frame cost more main-thread
        // time than evaluating the ICT head (1.6 ms a frame in Chromium)
        if (!(now - this.clockAt < CLOCK_MS)) {
          this.clockAt = now;
          this.updateClock();
        }
      }
      if (this.dirty) this.render();
    }

    updateClock() {
      const scrub = $("puppet-scrub"), out = $("puppet-time");
      if (scrub && this.take) scrub.value = String(this.time / this.take.duration);
      if (out) out.textContent = this.time.toFixed(2) + " s";
    }

    // Live weights: JSON messages {"weights": {name: w}, "head": [yaw, pitch, roll], "eyes": [...]}, radians.
    connect(url) {
      if (this.socket) this.socket.close();
      let socket;
      try {
        socket = new WebSocket(url);
      } catch (err) {
        say("Cannot connect: " + err.message);
        return null;
      }
      this.socket = socket;
      this.pause();
      socket.onopen = () => say("Live: " + url);
      socket.onclose = () => { if (this.socket === socket) say("Live feed closed."); };
      socket.onerror = () => say("Live feed error: " + url);
      socket.onmessage = (e) => {
        let msg;
        try { msg = JSON.parse(e.data); } catch (err) { return; }
        if (!msg || typeof msg !== "object") return;
        this.set(msg.weights || {}, msg.head, msg.eyes);
        this.lastMessage = performance.now();
      };
      return socket;
    }

    syncSliders() {
      if (this.playing) return;
      const w = this.weightsNow();
      for (const [key, input] of this.sliders) {
        let v;
        if (key.startsWith("#")) v = this.pose[Number(key.slice(1))] / DEG;
        else v = w[Number(key)];
        input.value = String(v);
        input.nextElementSibling.textContent = Number(v).toFixed(2);
      }
    }

    buildPanel() {
      const box = $("puppet-sliders");
      if (!box) return;
      const add = (label, key, min, max, step, onInput) => {
        const row = document.createElement("label");
        const name = document.createElement("span");
        name.textContent = label;
        const input = document.createElement("input");
        Object.assign(input, { type: "range", min: String(min), max: String(max), step: String(step), value: "0" });
        const out = document.createElement("output");
        out.textContent = "0.00";
        input.addEventListener("input", () => { this.pause(); onInput(Number(input.value)); });
        row.append(name, input, out);
        box.append(row);
        this.sliders.set(key, input);
      };
      this.model.morphs.forEach((p, k) => add(p.name, String(k), 0, 1, 0.01, (v) => this.set({ [p.name]: v })));
      const poses = [["head yaw", 40], ["head pitch", 40], ["head roll", 40]];
      if (this.model.eyes.length) {
        poses.push(["left eye yaw", 30], ["left eye pitch", 30], ["right eye yaw", 30], ["right eye pitch", 30]);
      }
      poses.forEach(([label, range], i) => add(label + " (\u00b0)", "#" + i, -range, range, 0.5,
        (v) => this.set({ [POSE_NAMES[i]]: v * DEG })));
    }
  }

  // True inside a frame (of the same origin) that carries data-puppet-embed: the embed mode without a URL change.
  function embedded() {
    try {
      const frame = window.frameElement;
      return !!frame && frame.hasAttribute("data-puppet-embed");
    } catch (err) {
      return false;
    }
  }

  async function start() {
    const meta = JSON.parse($("puppet-meta").textContent);
    if (meta.format !== FORMAT || !VERSIONS.includes(meta.version)) {
      throw new Error(`this file is puppet format ${meta.format} ${meta.version}, which this player does not know ` +
                      `(it plays ${FORMAT} ${VERSIONS.join(", ")}); write the puppet again with this facesvg.`);
    }
    const dataEl = $("puppet-data");
    const buf = await inflate(base64Bytes(dataEl.textContent), Number(dataEl.dataset.bytes));
    const model = new Model(meta, buf);
    const takeEl = $("puppet-take");
    let take = null;
    const takeMeta = takeEl && takeEl.dataset.meta ? JSON.parse(takeEl.dataset.meta) : null;
    if (takeMeta && takeEl.textContent.trim()) {
      take = new TakeData(takeMeta, await inflate(base64Bytes(takeEl.textContent), Number(takeEl.dataset.bytes)));
    }
    const params = new URLSearchParams(window.location.search);
    if (params.has("embed") || embedded()) {  // a page that drives the puppet itself: no Play or Live controls
      $("puppet-controls").hidden = true;
      $("puppet-live-row").hidden = true;
      document.documentElement.dataset.embed = "";
    }
    const canvas = $("puppet-canvas");
    let viewer = null;
    if (params.get("renderer") !== "canvas") {
      try { viewer = new GLView(canvas, model); } catch (err) { viewer = null; }
    }
    if (!viewer) {
      const fresh = canvas.cloneNode(false);  // a canvas that tried WebGL cannot give a 2D context
      canvas.replaceWith(fresh);
      viewer = new CanvasView(fresh, model);
    }
    const puppet = new Puppet(model, viewer, take);
    puppet.buildPanel();
    const api = {
      set: (values, head, eyes) => { puppet.set(values, head, eyes); return api; },
      play: () => { puppet.play(); return api; },
      pause: () => { puppet.pause(); return api; },
      seek: (t) => { puppet.seek(t); return api; },
      reset: () => { puppet.reset(); return api; },
      render: () => { puppet.render(); return api; },
      connect: (url) => puppet.connect(url),
      get time() { return puppet.time; },
      get duration() { return take ? take.duration : 0; },
      get playing() { return puppet.playing; },
      get renderer() { return viewer.kind; },
      get frames() { return puppet.frameCount; },
      get frameMs() { return puppet.lastFrameMs; },
      parameters: model.morphs.map((p) => p.name).concat(POSE_NAMES.slice(0, model.eyes.length ? 7 : 3)),
      weights: () => Object.fromEntries(model.morphs.map((p, k) => [p.name, puppet.weightsNow()[k]])),
      positions: () => { model.place(); return { xy: Array.from(model.xy), z: Array.from(model.z) }; },
    };
    window.puppet = api;
    const play = $("puppet-play"), scrub = $("puppet-scrub");
    if (take) {
      play.addEventListener("click", () => (puppet.playing ? puppet.pause() : puppet.play()));
      scrub.addEventListener("input", () => { puppet.pause(); puppet.seek(Number(scrub.value) * take.duration); });
      puppet.applyTake(0);
    } else {
      play.disabled = true;
      scrub.disabled = true;
    }
    $("puppet-reset").addEventListener("click", () => puppet.reset());
    const liveUrl = $("puppet-live-url");
    $("puppet-live").addEventListener("click", () => { if (liveUrl.value) puppet.connect(liveUrl.value); });
    say(`${model.F} triangles, ${model.morphs.length} parameters` + (take ? `, take of ${take.frames} frames` : "") +
        ` (${viewer.kind})`);
    const live = params.get("live");
    if (live) { liveUrl.value = live; puppet.connect(live); }
    else if (take && params.get("paused") === null) puppet.play();
    puppet.render();
    const loop = (now) => { puppet.tick(now); window.requestAnimationFrame(loop); };
    window.requestAnimationFrame(loop);
    document.documentElement.dataset.puppet = "ready";
  }

  start().catch((err) => {
    say("Cannot play this puppet: " + err.message);
    document.documentElement.dataset.puppet = "failed";
  });
})();
