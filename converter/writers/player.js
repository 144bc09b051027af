// facesvg player: decodes the page's data block and draws the face with WebGL (canvas 2D when WebGL is missing).
// The block's layout is documented in converter/writers/player.py. This script loads nothing and evaluates no
// strings; a corrupt or truncated block shows a message instead of the face.
"use strict";
(() => {
  const MAGIC = 0x50565346; // "FSVP" little-endian
  const VERSION = 1;
  const HEADER_BYTES = 64;
  const MAX_FRAMES = 65534;
  const MAX_EXPANDED = 1 << 27;
  const GOURAUD = 1;
  const WIDE = 2;
  const HEAD = 4;
  const STROKE_PX = 0.6; // the SVG's seam stroke (svg_anim.STROKE_PX), which only the canvas 2D fallback draws
  const SLIVER_PX = 1; // ... nor on an edge to a path at the outline narrower than this across it (seen edge-on)
  const SLOW_WINDOW = 30; // played frames judged together for multisampling
  const SLOW_FPS = 45; // below this median frame rate the player drops multisampling
  const LATE_SHARE = 0.05; // ... as it does when more of the last 2 * SLOW_WINDOW frames than this came late
  const WARM_UP = 10; // played frames not judged (the first draws upload and compile)
  const MSAA_BUDGET_MS = 8; // a multisampled frame that takes longer (half a 60 Hz frame) starts the player without
  const PROBES = 3; // timed multisampled draws at start (after one that compiles), their median judged

  const $ = (id) => document.getElementById(id);
  const root = $("facesvg-player");
  let canvas = $("facesvg-canvas");
  const message = $("facesvg-message");
  const playButton = $("facesvg-play");
  const scrub = $("facesvg-scrub");
  const loopBox = $("facesvg-loop");
  const timeLabel = $("facesvg-time");
  const api = { state: "loading", error: null, renderer: null };
  window.facesvgPlayer = api;

  class Corrupt extends Error {}

  function fail(text) {
    message.textContent = text;
    message.hidden = false;
    canvas.hidden = true;
    api.state = "error";
    api.error = text;
    root.dataset.state = "error";
  }

  // CRC-32 (IEEE), as Python's zlib.crc32.
  const CRC_TABLE = new Uint32Array(256);
  for (let n = 0; n < 256; n++) {
    let c = n;
    for (let k = 0; k < 8; k++) c = c & 1 ? 0xedb88320 ^ (c >>> 1) : c >>> 1;
    CRC_TABLE[n] = c >>> 0;
  }
  function crc32(bytes) {
    let c = 0xffffffff;
    for (let i = 0; i < bytes.length; i++) c = CRC_TABLE[(c ^ bytes[i]) & 255] ^ (c >>> 8);
    return (c ^ 0xffffffff) >>> 0;
  }

  function base64Bytes(text) {
    let bin;
    try {
      bin = atob(text.replace(/\s+/g, ""));
    } catch (e) {
      throw new Corrupt("the data block is not valid base64");
    }
    const out = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) out[i] = bin.charCodeAt(i);
    return out;
  }

  // Inflate with the browser's DecompressionStream, refusing more than the stated length.
  async function inflate(bytes, expected) {
    if (typeof DecompressionStream !== "function") {
      throw new Corrupt("this browser cannot unpack the animation (it has no DecompressionStream); " +
        "open the file in a current Chrome, Edge, Firefox or Safari");
    }
    const chunks = []; // kept as they arrive: a wrong stated length allocates nothing up front
    let filled = 0;
    const reader = new Blob([bytes]).stream().pipeThrough(new DecompressionStream("deflate")).getReader();
    try {
      for (;;) {
        const { done, value } = await reader.read();
        if (done) break;
        if (filled + value.length > expected) throw new Corrupt("the data block is longer than stated");
        chunks.push(value);
        filled += value.length;
      }
    } catch (e) {
      reader.cancel().catch(() => {});
      if (e instanceof Corrupt) throw e;
      throw new Corrupt("the data block does not unpack (it is truncated or damaged)");
    }
    if (filled !== expected) throw new Corrupt("the data block is shorter than stated");
    const out = new Uint8Array(expected);
    let at = 0;
    for (const c of chunks) {
      out.set(c, at);
      at += c.length;
    }
    return out;
  }

  // Header and sections, every length checked before anything is allocated.
  function parse(block) {
    if (block.length < HEADER_BYTES) throw new Corrupt("the data block is shorter than its header");
    const dv = new DataView(block.buffer, block.byteOffset, block.byteLength);
    const u32 = (o) => dv.getUint32(o, true);
    if (u32(0) !== MAGIC || dv.getUint16(4, true) !== VERSION) {
      throw new Corrupt("the data block is not a version " + VERSION + " facesvg player block");
    }
    const h = {
      flags: dv.getUint16(6, true), frames: u32(8), fps: dv.getFloat64(12, true), width: u32(20),
      height: u32(24), scale: u32(28), vertices: u32(32), paths: u32(36), posKeys: u32(40), colorTracks: u32(44),
      colorKeys: u32(48), changes: u32(52), size: u32(56), crc: u32(60),
    };
    const payload = block.subarray(HEADER_BYTES);
    if (h.size !== payload.length) throw new Corrupt("the data block's length does not match its header");
    if (crc32(payload) !== h.crc) throw new Corrupt("the data block fails its CRC-32 check");
    const gouraud = (h.flags & GOURAUD) !== 0;
    if (!(h.frames > 0 && h.frames <= MAX_FRAMES && h.fps > 0 && h.scale >= 1 && h.width > 0 && h.height > 0) ||
        (h.frames + 1) * Math.max(h.vertices, h.colorTracks, h.paths) * 3 > MAX_EXPANDED ||
        h.colorTracks !== (gouraud ? h.vertices : h.paths)) {
      throw new Corrupt("the data block's header holds impossible counts");
    }
    // Each section holds its elements' bytes as planes (all first bytes, then all second bytes, ...),
    // padded to 4 bytes; reassembled little-endian here.
    let pos = 0;
    function take(Type, n) {
      const width = Type.BYTES_PER_ELEMENT;
      const bytes = width * n;
      if (pos + bytes > payload.length) throw new Corrupt("the data block ends early");
      const arr = new Type(n);
      const b = payload.subarray(pos, pos + bytes);
      if (Type === Float32Array) {
        const bits = new Uint32Array(n);
        for (let i = 0; i < n; i++) bits[i] = b[i] | (b[n + i] << 8) | (b[2 * n + i] << 16) | (b[3 * n + i] << 24);
        arr.set(new Float32Array(bits.buffer));
      } else if (width === 1) {
        arr.set(b);
      } else if (width === 2) {
        for (let i = 0; i < n; i++) arr[i] = b[i] | (b[n + i] << 8); // Int16Array wraps the sign itself
      } else {
        for (let i = 0; i < n; i++) arr[i] = b[i] | (b[n + i] << 8) | (b[2 * n + i] << 16) | (b[3 * n + i] << 24);
      }
      pos += bytes + ((4 - (bytes % 4)) % 4);
      return arr;
    }
    const s = {
      vertexIds: take(Uint32Array, h.vertices), triangles: take(Uint32Array, h.paths),
      pathVertices: take(Uint32Array, 3 * h.paths),
      vis0: take(Uint8Array, h.paths), visCounts: take(Uint16Array, h.paths), visFrames: take(Uint16Array, h.changes),
      posCounts: take(Uint16Array, h.vertices), posFrames: take(Uint16Array, h.posKeys),
      posValues: take(h.flags & WIDE ? Int32Array : Int16Array, 2 * h.posKeys),
      colorCounts: take(Uint16Array, h.colorTracks), colorFrames: take(Uint16Array, h.colorKeys),
      colorValues: take(Uint8Array, 3 * h.colorKeys),
      head: h.flags & HEAD ? take(Float32Array, 6 * (h.frames + 1)) : null,
    };
    if (pos !== payload.length) throw new Corrupt("the data block's sections do not fill it");
    for (let i = 0; i < s.pathVertices.length; i++) {
      if (s.pathVertices[i] >= h.vertices) throw new Corrupt("a triangle names a vertex the block does not hold");
    }
    return { h, s, gouraud };
  }

  function sum(arr) {
    let t = 0;
    for (let i = 0; i < arr.length; i++) t += arr[i];
    return t;
  }

  // Keyed tracks (counts, frame deltas, value deltas) to per-frame values, frame-major: out[(f * n + track) * dims + d].
  // Between keys the values are linear, so linear interpolation between frames afterwards is SMIL's.
  function expand(counts, frameDeltas, valueDeltas, dims, frames1, scale, modulo, Out) {
    const n = counts.length;
    if (sum(counts) !== frameDeltas.length) throw new Corrupt("the key counts do not add up");
    const out = new Out(frames1 * n * dims);
    const prev = new Float64Array(dims);
    const cur = new Float64Array(dims);
    let k = 0;
    for (let track = 0; track < n; track++) {
      const m = counts[track];
      let lastFrame = -1;
      for (let j = 0; j < m; j++, k++) {
        const frame = j === 0 ? frameDeltas[k] : lastFrame + frameDeltas[k];
        if (frame > frames1 - 1 || (j > 0 && frame <= lastFrame)) throw new Corrupt("a key frame is out of order");
        for (let d = 0; d < dims; d++) {
          let v = j === 0 ? valueDeltas[k * dims + d] : prev[d] + valueDeltas[k * dims + d];
          if (modulo) v = ((v % modulo) + modulo) % modulo;
          cur[d] = v;
        }
        if (j === 0) {
          for (let f = 0; f <= frame; f++) {
            for (let d = 0; d < dims; d++) out[(f * n + track) * dims + d] = cur[d] / scale;
          }
        } else {
          const span = frame - lastFrame;
          for (let f = lastFrame + 1; f <= frame; f++) {
            const w = (f - lastFrame) / span;
            for (let d = 0; d < dims; d++) {
              out[(f * n + track) * dims + d] = (prev[d] + w * (cur[d] - prev[d])) / scale;
            }
          }
        }
        prev.set(cur);
        lastFrame = frame;
      }
      for (let f = lastFrame + 1; f < frames1 && m > 0; f++) {
        for (let d = 0; d < dims; d++) out[(f * n + track) * dims + d] = prev[d] / scale;
      }
    }
    return out;
  }

  // Visibility per frame and path from the initial state and the change frames.
  function visibility(h, s) {
    if (sum(s.visCounts) !== s.visFrames.length) throw new Corrupt("the visibility counts do not add up");
    const p = h.paths;
    const out = new Uint8Array(h.frames * p);
    let k = 0;
    for (let path = 0; path < p; path++) {
      let state = s.vis0[path] ? 1 : 0;
      let from = 0;
      let frame = 0;
      for (let j = 0; j < s.visCounts[path]; j++, k++) {
        frame += s.visFrames[k];
        if (frame <= from || frame >= h.frames) throw new Corrupt("a visibility change is out of order");
        for (let f = from; f < frame; f++) out[f * p + path] = state;
        state ^= 1;
        from = frame;
      }
      for (let f = from; f < h.frames; f++) out[f * p + path] = state;
    }
    return out;
  }

  function decode(block) {
    const { h, s, gouraud } = parse(block);
    const frames1 = h.frames + 1;
    const xy = expand(s.posCounts, s.posFrames, s.posValues, 2, frames1, h.scale, 0, Float32Array);
    if (s.head) { // positions are local to the head transform: to px, once
      const nv = h.vertices;
      for (let f = 0; f < frames1; f++) {
        const m = s.head.subarray(6 * f, 6 * f + 6);
        for (let i = 2 * f * nv, end = 2 * (f + 1) * nv; i < end; i += 2) {
          const x = xy[i], y = xy[i + 1];
          xy[i] = m[0] * x + m[1] * y + m[2];
          xy[i + 1] = m[3] * x + m[4] * y + m[5];
        }
      }
    }
    return {
      h, gouraud,
      pathVertices: s.pathVertices,
      xy,
      rgb: expand(s.colorCounts, s.colorFrames, s.colorValues, 3, frames1, 1, 256, Uint8ClampedArray),
      shown: visibility(h, s),
    };
  }

  // Renderers: frame(f, w) draws frame f + w (0 <= w <= 1) of the decoded animation.
  // WebGL 2 evaluates the animation on the GPU: the expanded tracks, colours and visibility are textures, each
  // corner's vertex shader interpolates its vertex and drops its triangle when hidden, so a frame costs the script
  // two uniforms. The other renderers take the corners from cpuFrames().
  // WebGL draws the triangles as they are, no seam stroke and no growing: its rasterisation of triangles that share
  // an edge is watertight (a pixel or sample is covered by exactly one of them), so no seam shows between
  // neighbours, multisampled or not, and the silhouette is three.js's.
  const GL2_VS = `#version 300 es
precision highp float;
precision highp int;
uniform highp sampler2D xy; // RG32F, texel f * vertices + v: px
uniform mediump sampler2D rgb; // RGB8, texel f * tracks + track
uniform mediump sampler2D shown; // R8, texel f * paths + path
uniform int f;
uniform float w;
uniform int nv;
uniform int nc;
uniform int np;
uniform bool gouraud;
uniform vec2 s;
in uint vid; // this corner's vertex
out vec4 v;
ivec2 at(int i, int width) { return ivec2(i % width, i / width); }
vec2 pos(uint id) {
  int width = textureSize(xy, 0).x;
  int i = f * nv + int(id);
  vec2 a = texelFetch(xy, at(i, width), 0).rg;
  return a + w * (texelFetch(xy, at(i + nv, width), 0).rg - a);
}
vec3 colour(int track) {
  int width = textureSize(rgb, 0).x;
  int i = f * nc + track;
  vec3 a = texelFetch(rgb, at(i, width), 0).rgb * 255.0;
  return floor(a + w * (texelFetch(rgb, at(i + nc, width), 0).rgb * 255.0 - a) + 0.5) / 255.0;
}
void main() {
  int path = gl_VertexID / 3;
  if (texelFetch(shown, at(f * np + path, textureSize(shown, 0).x), 0).r == 0.0) { // 1 (shown) reads 1/255
    gl_Position = vec4(2.0, 2.0, 2.0, 1.0); // outside the clip volume: the triangle is dropped
    v = vec4(0.0);
    return;
  }
  vec2 q = pos(vid);
  v = vec4(colour(gouraud ? int(vid) : path), 1.0);
  gl_Position = vec4(q.x * s.x - 1.0, 1.0 - q.y * s.y, 0.0, 1.0);
}`;
  const GL2_FS = `#version 300 es
precision mediump float;
in vec4 v;
out vec4 o;
void main() { o = v; }`;

  function program(gl, vs, fs) {
    const prog = gl.createProgram();
    for (const [type, src] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
      const sh = gl.createShader(type);
      gl.shaderSource(sh, src);
      gl.compileShader(sh);
      if (!gl.getShaderParameter(sh, gl.COMPILE_STATUS)) return null;
      gl.attachShader(prog, sh);
    }
    gl.linkProgram(prog);
    return gl.getProgramParameter(prog, gl.LINK_STATUS) ? prog : null;
  }

  // A WebGL context of the given type ("webgl2" or "webgl") on canvas cv, or null.
  function context(cv, type, antialias) {
    try {
      return cv.getContext(type, { antialias, alpha: true, premultipliedAlpha: true, depth: false });
    } catch (e) {
      return null;
    }
  }

  // WebGL 2 multisamples into its own renderbuffer, blitted to the canvas each frame, so that dropping
  // multisampling is a matter of drawing to the canvas directly: no new context, no second upload.
  // With a finite budgetMs, multisampling is kept only when the median of PROBES timed multisampled frames (each
  // drawn, resolved and waited for with a one-pixel read) takes at most budgetMs.
  function webgl2Renderer(cv, anim, antialias, budgetMs) {
    const gl = context(cv, "webgl2", false);
    if (!gl) return null;
    const { h, gouraud, pathVertices, xy, rgb, shown } = anim;
    const prog = program(gl, GL2_VS, GL2_FS);
    if (!prog) return null;
    const maxSize = gl.getParameter(gl.MAX_TEXTURE_SIZE);
    const width = Math.min(maxSize, 4096);
    // One texture of n texels (rows of `width`), unfiltered; null when it does not fit.
    function texture(unit, internal, format, type, data, channels) {
      const n = data.length / channels;
      const rows = Math.max(1, Math.ceil(n / width));
      if (rows > maxSize) return null;
      const tex = gl.createTexture();
      gl.activeTexture(gl.TEXTURE0 + unit);
      gl.bindTexture(gl.TEXTURE_2D, tex);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
      gl.texStorage2D(gl.TEXTURE_2D, 1, internal, width, rows);
      const full = Math.floor(n / width);
      if (full) gl.texSubImage2D(gl.TEXTURE_2D, 0, 0, 0, width, full, format, type, data.subarray(0, full * width * channels));
      if (n > full * width) {
        gl.texSubImage2D(gl.TEXTURE_2D, 0, 0, full, n - full * width, 1, format, type,
          data.subarray(full * width * channels));
      }
      return tex;
    }
    gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
    if (!texture(0, gl.RG32F, gl.RG, gl.FLOAT, xy, 2) || !texture(1, gl.RGB8, gl.RGB, gl.UNSIGNED_BYTE, rgb, 3) ||
        !texture(2, gl.R8, gl.RED, gl.UNSIGNED_BYTE, shown, 1)) {
      return null;
    }
    const p = h.paths;
    gl.useProgram(prog);
    const buf = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, buf);
    gl.bufferData(gl.ARRAY_BUFFER, pathVertices, gl.STATIC_DRAW); // per corner: its vertex
    const vLoc = gl.getAttribLocation(prog, "vid");
    gl.enableVertexAttribArray(vLoc);
    gl.vertexAttribIPointer(vLoc, 1, gl.UNSIGNED_INT, 0, 0);
    const u = (name) => gl.getUniformLocation(prog, name);
    gl.uniform1i(u("xy"), 0);
    gl.uniform1i(u("rgb"), 1);
    gl.uniform1i(u("shown"), 2);
    gl.uniform1i(u("nv"), h.vertices);
    gl.uniform1i(u("nc"), h.colorTracks);
    gl.uniform1i(u("np"), p);
    gl.uniform1i(u("gouraud"), gouraud ? 1 : 0);
    gl.uniform2f(u("s"), 2 / h.width, 2 / h.height);
    const fLoc = u("f");
    const wLoc = u("w");
    gl.disable(gl.DEPTH_TEST); // painter's order: later triangles cover earlier ones
    if (gl.getError() !== gl.NO_ERROR) return null;
    let msaa = null; // [framebuffer, renderbuffer] while multisampling
    // The multisampled framebuffer fb resolved onto the canvas.
    function resolve(fb) {
      gl.bindFramebuffer(gl.READ_FRAMEBUFFER, fb);
      gl.bindFramebuffer(gl.DRAW_FRAMEBUFFER, null);
      gl.blitFramebuffer(0, 0, cv.width, cv.height, 0, 0, cv.width, cv.height, gl.COLOR_BUFFER_BIT, gl.NEAREST);
    }
    const samples = Math.min(4, gl.getParameter(gl.MAX_SAMPLES));
    if (antialias && samples > 1) {
      const rb = gl.createRenderbuffer();
      gl.bindRenderbuffer(gl.RENDERBUFFER, rb);
      gl.renderbufferStorageMultisample(gl.RENDERBUFFER, samples, gl.RGBA8, cv.width, cv.height);
      const fb = gl.createFramebuffer();
      gl.bindFramebuffer(gl.FRAMEBUFFER, fb);
      gl.framebufferRenderbuffer(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.RENDERBUFFER, rb);
      if (gl.checkFramebufferStatus(gl.FRAMEBUFFER) === gl.FRAMEBUFFER_COMPLETE) {
        // One trial resolve: a browser whose canvas format differs from the renderbuffer's refuses the blit.
        resolve(fb);
        if (gl.getError() === gl.NO_ERROR) msaa = [fb, rb];
      }
      gl.bindFramebuffer(gl.FRAMEBUFFER, null);
      if (!msaa) {
        gl.deleteFramebuffer(fb);
        gl.deleteRenderbuffer(rb);
      }
    }
    if (gl.getError() !== gl.NO_ERROR) return null;
    // ms of one multisampled frame 0, drawn and finished: the median of PROBES after one that compiles.
    function probe() {
      const px = new Uint8Array(4);
      const times = [];
      for (let i = 0; i <= PROBES; i++) {
        const t0 = performance.now();
        frame(0, 0);
        gl.bindFramebuffer(gl.FRAMEBUFFER, null); // read the resolved canvas (a multisampled one cannot be read)
        gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
        if (i) times.push(performance.now() - t0);
      }
      return times.sort((a, b) => a - b)[PROBES >> 1];
    }
    function frame(f, w) {
      gl.bindFramebuffer(gl.FRAMEBUFFER, msaa ? msaa[0] : null);
      gl.viewport(0, 0, cv.width, cv.height);
      gl.clearColor(0, 0, 0, 0);
      gl.clear(gl.COLOR_BUFFER_BIT);
      gl.uniform1i(fLoc, f);
      gl.uniform1f(wLoc, w);
      gl.drawArrays(gl.TRIANGLES, 0, 3 * p);
      if (msaa) resolve(msaa[0]);
    }
    function dropMsaa() {
      if (!msaa) return;
      gl.bindFramebuffer(gl.FRAMEBUFFER, null);
      gl.deleteFramebuffer(msaa[0]);
      gl.deleteRenderbuffer(msaa[1]);
      msaa = null;
    }
    const probeMs = msaa && Number.isFinite(budgetMs) ? probe() : null;
    if (probeMs !== null && probeMs > budgetMs) dropMsaa();
    return {
      name: "webgl2",
      gl,
      antialias: msaa !== null,
      probeMs,
      frame,
      dropAntialias() {
        dropMsaa();
        this.antialias = false;
      },
    };
  }

  // draw(positions (x, y px per drawn corner), colours (r, g, b, 255 per corner), corners).
  function webglRenderer(cv, width, height, antialias) {
    const gl = context(cv, "webgl", antialias);
    if (!gl) return null;
    const vs = "attribute vec2 p;attribute vec4 c;uniform vec2 s;varying vec4 v;" +
      "void main(){gl_Position=vec4(p.x*s.x-1.0,1.0-p.y*s.y,0.0,1.0);v=c;}";
    const fs = "precision mediump float;varying vec4 v;void main(){gl_FragColor=v;}";
    const prog = program(gl, vs, fs);
    if (!prog) return null;
    gl.useProgram(prog);
    const posBuf = gl.createBuffer();
    const colBuf = gl.createBuffer();
    const pLoc = gl.getAttribLocation(prog, "p");
    const cLoc = gl.getAttribLocation(prog, "c");
    gl.enableVertexAttribArray(pLoc);
    gl.enableVertexAttribArray(cLoc);
    gl.uniform2f(gl.getUniformLocation(prog, "s"), 2 / width, 2 / height);
    gl.disable(gl.DEPTH_TEST); // painter's order: later triangles cover earlier ones
    return {
      name: "webgl",
      gl,
      draw(pos, col, corners) {
        gl.viewport(0, 0, cv.width, cv.height);
        gl.clearColor(0, 0, 0, 0);
        gl.clear(gl.COLOR_BUFFER_BIT);
        if (!corners) return;
        gl.bindBuffer(gl.ARRAY_BUFFER, posBuf);
        gl.bufferData(gl.ARRAY_BUFFER, pos.subarray(0, 2 * corners), gl.STREAM_DRAW);
        gl.vertexAttribPointer(pLoc, 2, gl.FLOAT, false, 0, 0);
        gl.bindBuffer(gl.ARRAY_BUFFER, colBuf);
        gl.bufferData(gl.ARRAY_BUFFER, col.subarray(0, 4 * corners), gl.STREAM_DRAW);
        gl.vertexAttribPointer(cLoc, 4, gl.UNSIGNED_BYTE, true, 0, 0);
        gl.drawArrays(gl.TRIANGLES, 0, corners);
      },
    };
  }

  // Per path edge (3 * path + i: corner i to i + 1) the same edge of the one other path that shares it, -1 on a
  // boundary or where three or more share it. Vertices that coincide in every frame (a mesh split along UV or
  // normal seams) are welded first: compared at the first, middle and last frame, as the player holds them.
  function edgePartners(anim) {
    const { h, pathVertices, xy } = anim;
    const nv = h.vertices;
    const weld = new Int32Array(nv);
    const seen = new Map();
    for (let v = 0; v < nv; v++) {
      let key = "";
      for (const f of [0, h.frames >> 1, h.frames]) key += xy[2 * (f * nv + v)] + "," + xy[2 * (f * nv + v) + 1] + ";";
      if (!seen.has(key)) seen.set(key, v);
      weld[v] = seen.get(key);
    }
    const partner = new Int32Array(3 * h.paths).fill(-1);
    const first = new Map();
    for (let k = 0; k < 3 * h.paths; k++) {
      const j = k - (k % 3);
      const a = weld[pathVertices[k]];
      const b = weld[pathVertices[j + ((k % 3) + 1) % 3]];
      const key = Math.min(a, b) * nv + Math.max(a, b);
      const other = first.get(key);
      if (other === undefined) {
        first.set(key, k);
      } else if (other >= 0) {
        const paired = partner[other] >= 0;
        partner[other] = paired ? -1 : k;
        if (!paired) partner[k] = other;
        else first.set(key, -1); // a third path on this edge
      }
    }
    for (let k = 0; k < partner.length; k++) {
      if (partner[k] >= 0 && partner[partner[k]] !== k) partner[k] = -1;
    }
    return partner;
  }

  // Canvas 2D anti-aliases each triangle on its own, so the page shows through the edge two triangles share: like
  // the SVG it strokes such edges with the fill colour (STROKE_PX, round caps and joins), but only where the
  // other path is drawn that frame, so the silhouette does not grow (seams.py's rule, by topology alone).
  // Gouraud falls back to each triangle's mean colour.
  function canvasRenderer(cv, anim) {
    const ctx = cv.getContext("2d");
    if (!ctx) return null;
    const { width, height } = anim.h;
    const partner = edgePartners(anim);
    const area2 = new Float64Array(anim.h.paths); // twice the area of each path drawn this frame
    const rim = new Uint8Array(anim.h.paths); // ... 1 when one of its edges is outline this frame
    return {
      name: "canvas2d",
      draw(pos, col, corners, paths, shownNow) {
        ctx.setTransform(cv.width / width, 0, 0, cv.height / height, 0, 0);
        ctx.clearRect(0, 0, width, height);
        ctx.lineWidth = STROKE_PX;
        ctx.lineJoin = "round";
        ctx.lineCap = "round";
        for (let i = 0; i < corners; i += 3) {
          const ex = pos[2 * i + 2] - pos[2 * i], ey = pos[2 * i + 3] - pos[2 * i + 1];
          const fx = pos[2 * i + 4] - pos[2 * i], fy = pos[2 * i + 5] - pos[2 * i + 1];
          const j = paths[i / 3];
          area2[j] = Math.abs(ex * fy - ey * fx);
          rim[j] = 0;
          for (let e = 0; e < 3; e++) {
            const o = partner[3 * j + e];
            if (o < 0 || !shownNow[(o - (o % 3)) / 3]) rim[j] = 1;
          }
        }
        for (let i = 0; i < corners; i += 3) {
          const a = 4 * i;
          const r = Math.round((col[a] + col[a + 4] + col[a + 8]) / 3);
          const g = Math.round((col[a + 1] + col[a + 5] + col[a + 9]) / 3);
          const b = Math.round((col[a + 2] + col[a + 6] + col[a + 10]) / 3);
          ctx.fillStyle = ctx.strokeStyle = "rgb(" + r + "," + g + "," + b + ")";
          ctx.beginPath();
          ctx.moveTo(pos[2 * i], pos[2 * i + 1]);
          ctx.lineTo(pos[2 * i + 2], pos[2 * i + 3]);
          ctx.lineTo(pos[2 * i + 4], pos[2 * i + 5]);
          ctx.closePath();
          ctx.fill();
          const j = paths[i / 3];
          let inner = 0; // bit e: edge e (corner e to e + 1) is shared with a path drawn now, neither a rim sliver
          for (let e = 0; e < 3; e++) {
            const o = partner[3 * j + e];
            const q = (o - (o % 3)) / 3;
            if (o < 0 || !shownNow[q]) continue;
            const c0 = i + e, c1 = i + (e + 1) % 3;
            const wide = SLIVER_PX * Math.hypot(pos[2 * c1] - pos[2 * c0], pos[2 * c1 + 1] - pos[2 * c0 + 1]);
            if ((rim[j] && area2[j] < wide) || (rim[q] && area2[q] < wide)) continue;
            inner |= 1 << e;
          }
          if (!inner) continue;
          ctx.beginPath();
          if (inner === 7) {
            ctx.moveTo(pos[2 * i], pos[2 * i + 1]);
            ctx.lineTo(pos[2 * i + 2], pos[2 * i + 3]);
            ctx.lineTo(pos[2 * i + 4], pos[2 * i + 5]);
            ctx.closePath();
          } else {
            let e = 0; // start after a left-out edge, so consecutive stroked edges join
            while (inner & (1 << e)) e++;
            let open = false;
            for (let step = 1; step <= 3; step++) {
              const s0 = (e + step) % 3;
              if (!(inner & (1 << s0))) {
                open = false;
                continue;
              }
              const c0 = i + s0, c1 = i + (s0 + 1) % 3;
              if (!open) ctx.moveTo(pos[2 * c0], pos[2 * c0 + 1]);
              ctx.lineTo(pos[2 * c1], pos[2 * c1 + 1]);
              open = true;
            }
          }
          ctx.stroke();
        }
      },
    };
  }

  // The CPU side of the WebGL 1 and canvas 2D renderers: each frame's corners, then draw(pos, col, corners,
  // paths (the path of each drawn triangle), shownNow (per path: drawn this frame)).
  function cpuFrames(anim, draw) {
    const { h, gouraud, pathVertices, xy, rgb, shown } = anim;
    const p = h.paths;
    const nv = h.vertices;
    const nc = h.colorTracks;
    const pos = new Float32Array(2 * 3 * p);
    const col = new Uint8Array(4 * 3 * p);
    const vxy = new Float32Array(2 * nv);
    const vrgb = new Float32Array(3 * nc);
    const paths = new Uint32Array(p);
    return (f, w) => {
      const a = f * nv * 2;
      const b = a + nv * 2;
      for (let i = 0; i < 2 * nv; i++) vxy[i] = xy[a + i] + w * (xy[b + i] - xy[a + i]);
      const ca = f * nc * 3;
      const cb = ca + nc * 3;
      for (let i = 0; i < 3 * nc; i++) vrgb[i] = rgb[ca + i] + w * (rgb[cb + i] - rgb[ca + i]);
      const vis = f * p;
      let n = 0;
      for (let j = 0; j < p; j++) {
        if (!shown[vis + j]) continue;
        paths[n / 3] = j;
        for (let c = 0; c < 3; c++) {
          const v = pathVertices[3 * j + c];
          pos[2 * n] = vxy[2 * v];
          pos[2 * n + 1] = vxy[2 * v + 1];
          const src = 3 * (gouraud ? v : j);
          col[4 * n] = Math.round(vrgb[src]);
          col[4 * n + 1] = Math.round(vrgb[src + 1]);
          col[4 * n + 2] = Math.round(vrgb[src + 2]);
          col[4 * n + 3] = 255;
          n++;
        }
      }
      draw(pos, col, n, paths, shown.subarray(vis, vis + p));
    };
  }

  // A new canvas in place of one a failed renderer has claimed (a canvas keeps its first context type).
  function freshCanvas() {
    const next = canvas.cloneNode(false);
    canvas.replaceWith(next);
    canvas = next;
    return next;
  }

  // The first renderer that works, from `wanted` ("webgl2", "webgl" or "canvas2d") down; WebGL multisampled when
  // antialias is set (WebGL 2: while a multisampled frame takes at most budgetMs, see webgl2Renderer).
  function pickRenderer(anim, wanted, antialias, budgetMs = Infinity) {
    const { h } = anim;
    const order = ["webgl2", "webgl", "canvas2d"];
    for (const name of order.slice(Math.max(0, order.indexOf(wanted)))) {
      let r = null;
      if (name === "webgl2") {
        r = webgl2Renderer(canvas, anim, antialias, budgetMs);
      } else if (name === "webgl") {
        const gl1 = webglRenderer(canvas, h.width, h.height, antialias);
        r = gl1 && { name, frame: cpuFrames(anim, gl1.draw), gl: gl1.gl };
      } else {
        const c2 = canvasRenderer(canvas, anim);
        r = c2 && { name, frame: cpuFrames(anim, c2.draw) };
      }
      if (r) return r;
      freshCanvas();
    }
    return null;
  }

  function start(anim) {
    const { h, xy } = anim;
    const nv = h.vertices;
    const duration = h.frames / h.fps;
    const dpr = Math.max(1, window.devicePixelRatio || 1);
    canvas.width = Math.round(h.width * dpr);
    canvas.height = Math.round(h.height * dpr);
    canvas.style.width = h.width + "px";
    // facesvgPlayerOptions (tests, comparisons): renderer ("webgl" or "canvas2d") starts lower down the list;
    // antialias true or false pins WebGL's multisampling, which is otherwise left out from the start when a
    // multisampled frame takes over msaaBudgetMs (WebGL 2) and dropped when frames come late.
    const options = window.facesvgPlayerOptions || {};
    const autoAA = options.antialias === undefined || options.antialias === "auto";
    let antialias = autoAA || options.antialias === true;
    const budgetMs = autoAA ? options.msaaBudgetMs ?? MSAA_BUDGET_MS : Infinity;
    let renderer = pickRenderer(anim, options.renderer, antialias, budgetMs);
    if (!renderer) throw new Corrupt("this browser can draw neither WebGL nor canvas 2D");
    if (renderer.antialias === false) antialias = false; // WebGL 2 without a multisampled renderbuffer
    const intervals = []; // ms between the last 2 * SLOW_WINDOW played frames
    let lastNow = null;

    let time = 0; // seconds into the animation
    let playing = !window.matchMedia("(prefers-reduced-motion: reduce)").matches;
    let clockStart = null; // rAF timestamp at which `time` was `clockTime`
    let clockTime = 0;
    let drawnTime = -1;

    function render(t) {
      const u = Math.min(Math.max(t, 0), duration) * h.fps; // frames
      let f = Math.floor(u);
      if (f >= h.frames) f = h.frames - 1;
      renderer.frame(f, u - f);
      drawnTime = t;
      scrub.value = String(t);
      timeLabel.textContent = t.toFixed(2) + " s";
    }

    function setPlaying(on) {
      playing = on;
      clockStart = null;
      clockTime = time;
      playButton.textContent = on ? "Pause" : "Play";
      playButton.setAttribute("aria-pressed", on ? "true" : "false");
    }

    // Multisampling costs a software-rendered or weak GPU most of its frame. WebGL 2 times it before the first
    // frame (webgl2Renderer's probe) and starts without it when it takes over half a 60 Hz frame. Later, the
    // player draws on without it (WebGL 2: straight to the canvas; WebGL 1: on a new canvas, as a context keeps
    // its attributes), once and for the rest of the page's life, when the median of
    // SLOW_WINDOW played frames misses SLOW_FPS, or as soon as frames come late while the median keeps the
    // display's pace: more than LATE_SHARE of 2 * SLOW_WINDOW intervals over 1.5 display frames (the shortest
    // interval seen), counted in the last 2 * SLOW_WINDOW. A device that plays 55 of 60 frames draws every frame
    // without it; one that plays 40 drops it within about 10 frames of the warm-up.
    const slowFps = options.slowFps || SLOW_FPS;
    const lateShare = options.lateShare ?? LATE_SHARE;
    let warm = 0;
    let shortest = Infinity;
    function watchPace(now) {
      if (!playing || !autoAA || !antialias || !renderer.gl) {
        lastNow = null;
        return;
      }
      const last = lastNow;
      lastNow = now;
      if (last === null || ++warm <= WARM_UP) return;
      const dt = now - last;
      shortest = Math.min(shortest, Math.max(dt, 4));
      intervals.push(dt);
      if (intervals.length > 2 * SLOW_WINDOW) intervals.shift();
      const late = intervals.reduce((n, d) => n + (d > 1.5 * shortest), 0) > lateShare * 2 * SLOW_WINDOW;
      const slow = intervals.length >= SLOW_WINDOW
        && intervals.slice(-SLOW_WINDOW).sort((a, b) => a - b)[SLOW_WINDOW >> 1] * slowFps > 1000;
      if (!late && !slow) return;
      antialias = false;
      drawnTime = -1;
      if (renderer.dropAntialias) {
        renderer.dropAntialias();
        return;
      }
      const before = renderer;
      const lose = before.gl.getExtension("WEBGL_lose_context");
      freshCanvas();
      const next = pickRenderer(anim, before.name, false);
      if (!next) return; // cannot happen for a renderer that worked; keep drawing nothing rather than fail
      renderer = next;
      api.renderer = next.name;
      if (lose) lose.loseContext();
    }

    function frame(now) {
      watchPace(now);
      if (playing) {
        if (clockStart === null) {
          clockStart = now;
          clockTime = time;
        }
        let t = clockTime + (now - clockStart) / 1000;
        if (t >= duration) {
          if (loopBox.checked) {
            t %= duration;
          } else {
            t = (h.frames - 1) / h.fps;
            setPlaying(false);
          }
        }
        time = t;
      }
      if (time !== drawnTime) render(time);
      requestAnimationFrame(frame);
    }

    function seek(t) {
      time = Math.min(Math.max(Number(t) || 0, 0), duration);
      if (time >= duration) time = loopBox.checked ? 0 : (h.frames - 1) / h.fps;
      clockStart = null;
      clockTime = time;
      render(time);
    }

    scrub.max = String(duration);
    scrub.step = String(1 / h.fps / 4);
    playButton.addEventListener("click", () => setPlaying(!playing));
    root.addEventListener("click", (e) => { // on the root: a new canvas may replace this one
      if (e.target === canvas) setPlaying(!playing);
    });
    document.addEventListener("keydown", (e) => {
      if (e.code === "Space" && e.target === document.body) {
        e.preventDefault();
        setPlaying(!playing);
      }
    });
    scrub.addEventListener("input", () => {
      setPlaying(false);
      seek(Number(scrub.value));
    });
    Object.assign(api, {
      state: "ready", renderer: renderer.name, frames: h.frames, fps: h.fps, duration,
      msaaProbeMs: renderer.probeMs ?? null, // the start-up probe's multisampled frame, ms (WebGL 2, auto)
      seek(t) { setPlaying(false); seek(t); },
      play() { setPlaying(true); },
      pause() { setPlaying(false); },
      positions(f) { return Array.from(xy.subarray(2 * nv * f, 2 * nv * (f + 1))); }, // frame f's px (tests)
    });
    Object.defineProperties(api, { // live values (Object.assign would copy a getter's value once)
      time: { get: () => time, enumerable: true },
      playing: { get: () => playing, enumerable: true },
      antialias: { get: () => antialias, enumerable: true }, // WebGL multisampling in use
    });
    setPlaying(playing);
    render(0);
    root.dataset.state = "ready";
    requestAnimationFrame(frame);
  }

  async function main() {
    try {
      if (new Uint8Array(new Uint16Array([1]).buffer)[0] !== 1) {
        throw new Corrupt("this device is big-endian, which the player does not support");
      }
      const node = $("facesvg-data");
      const expected = Number(node && node.dataset.bytes);
      if (!node || !(expected >= HEADER_BYTES && expected <= 1 << 30)) {
        throw new Corrupt("the page has no data block of a valid length");
      }
      const block = await inflate(base64Bytes(node.textContent), expected);
      start(decode(block));
    } catch (e) {
      const why = e instanceof Corrupt ? e.message : "an unexpected error (" + (e && e.message) + ")";
      fail("This animation cannot be played: " + why + ". Regenerate the file with facesvg.");
    }
  }

  main();
})();
