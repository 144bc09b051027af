// facesvg fap2d player: plays a 2D MPEG-4 face package (zip) on a canvas by warping textured triangles.
// Three layers, bottom to top: the portrait, the mouth (teeth and tongue) image, the deformable face mesh
// textured by the portrait. Each frame moves the mesh vertices by the package's 2D FAT (piecewise linear per
// FAP) and draws every triangle with its own affine transform, clipped to the triangle.
// Zip entries are read with the browser's DecompressionStream ("deflate-raw"); no library is needed.
"use strict";

(function () {
  const N_FAPS = 68;
  const MITER_LIMIT = 4;

  async function inflateRaw(bytes) {
    const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream("deflate-raw"));
    return new Uint8Array(await new Response(stream).arrayBuffer());
  }

  // Entries of a zip archive by name, as Uint8Array (stored and deflated entries only).
  async function unzip(buffer) {
    const dv = new DataView(buffer);
    let eocd = -1;
    for (let i = buffer.byteLength - 22; i >= Math.max(0, buffer.byteLength - 22 - 65535); i--) {
      if (dv.getUint32(i, true) === 0x06054b50) { eocd = i; break; }
    }
    if (eocd < 0) throw new Error("not a zip file");
    const count = dv.getUint16(eocd + 10, true);
    let p = dv.getUint32(eocd + 16, true);
    const files = {};
    const names = new TextDecoder();
    for (let k = 0; k < count; k++) {
      if (dv.getUint32(p, true) !== 0x02014b50) throw new Error("corrupt zip directory");
      const method = dv.getUint16(p + 10, true);
      const size = dv.getUint32(p + 20, true);
      const nlen = dv.getUint16(p + 28, true), xlen = dv.getUint16(p + 30, true), clen = dv.getUint16(p + 32, true);
      const local = dv.getUint32(p + 42, true);
      const name = names.decode(new Uint8Array(buffer, p + 46, nlen));
      const start = local + 30 + dv.getUint16(local + 26, true) + dv.getUint16(local + 28, true);
      const raw = new Uint8Array(buffer, start, size);
      if (method === 0) files[name] = raw.slice();
      else if (method === 8) files[name] = await inflateRaw(raw);
      else throw new Error("zip entry " + name + " uses an unsupported compression method " + method);
      p += 46 + nlen + xlen + clen;
    }
    return files;
  }

  const TYPES = { u1: Uint8Array, i1: Int8Array, u2: Uint16Array, i2: Int16Array, u4: Uint32Array, i4: Int32Array, f4: Float32Array };

  function array(blob, ref) {
    const T = TYPES[ref.dtype];
    const n = ref.shape.reduce((a, b) => a * b, 1);
    const bytes = blob.slice(ref.offset, ref.offset + n * T.BYTES_PER_ELEMENT);  // copy: aligned
    if (bytes.length !== n * T.BYTES_PER_ELEMENT) throw new Error("data.bin is shorter than the manifest says");
    return new T(bytes.buffer);
  }

  // .fap text -> Float32Array (frames * 68) of low-level values (unset FAPs and FAP 1-2 are 0).
  function parseFap(text) {
    const lines = text.split(/\r?\n/).map((l) => l.trim()).filter((l) => l && !l.startsWith("#"));
    if (!lines.length) throw new Error("empty FAP stream");
    const head = lines[0].split(/\s+/);
    const fps = parseFloat(head[head.length - 2]);
    const frames = (lines.length - 1) >> 1;
    const values = new Float32Array(frames * N_FAPS);
    for (let t = 0; t < frames; t++) {
      const mask = lines[1 + 2 * t].split(/\s+/).slice(0, N_FAPS).map(Number);
      const vals = lines[2 + 2 * t].split(/\s+/).slice(1).map(Number);
      let nset = 0;
      for (const b of mask) nset += b ? 1 : 0;
      const extra = vals.length - nset;  // FAP 1 may carry 4 values and FAP 2 six
      let i = (mask[0] ? (extra === 3 || extra === 8 ? 4 : 1) : 0) + (mask[1] ? (extra === 5 || extra === 8 ? 6 : 1) : 0);
      for (let f = 2; f < N_FAPS; f++) if (mask[f]) values[t * N_FAPS + f] = vals[i++];
    }
    return { fps, frames, values };
  }

  async function loadImage(bytes) {
    return await createImageBitmap(new Blob([bytes], { type: "image/png" }));
  }

  async function loadPackage(buffer) {
    const files = await unzip(buffer);
    const m = JSON.parse(new TextDecoder().decode(files["manifest.json"]));
    if (m.format !== "facesvg-fap2d" || String(m.version).split(".")[0] !== "1") {
      throw new Error("not a facesvg-fap2d 1.x package");
    }
    const blob = files[m.data];
    const mesh = m.mesh;
    const q = array(blob, mesh.vertices);
    const xy0 = new Float32Array(q.length);
    for (let i = 0; i < q.length; i++) xy0[i] = q[i] * mesh.xy_step;
    const fat = m.fat2d.faps.map((e) => {
      // The stored rows skip amplitude 0, where the displacement is 0: put that row back in place.
      const qd = array(blob, e.displacements), row = e.displacements.shape[1] * 2;
      let at = 0;
      while (at < e.amplitudes.length && e.amplitudes[at] < 0) at++;
      const amps = e.amplitudes.slice(0, at).concat([0], e.amplitudes.slice(at));
      const d = new Float32Array(qd.length + row);
      for (let i = 0; i < qd.length; i++) d[i < at * row ? i : i + row] = qd[i] * e.step_px;
      return { fap: e.fap, amps, verts: array(blob, e.vertices), disp: d, m: e.displacements.shape[1] };
    });
    const layers = {};
    for (const l of m.layers) layers[l.name] = l;
    const stream = parseFap(new TextDecoder().decode(files[m.stream.file]));
    return {
      manifest: m, xy0, tris: array(blob, mesh.triangles), fat, stream, overdraw: mesh.overdraw_px || 0,
      dirtyCell: mesh.dirty_cell_px, mouthBox: layers.mouth.box || null,
      portrait: await loadImage(files[layers.portrait.image]),
      mouth: await loadImage(files[layers.mouth.image]),
      texture: await loadImage(files[layers.face.texture]),
    };
  }

  // Vertex positions for one row of 68 FAP values (same arithmetic as converter/fap2d_render.py).
  function positions(pkg, values, offset, out) {
    out.set(pkg.xy0);
    for (const e of pkg.fat) {
      const v = values[offset + e.fap - 1];
      if (v === 0) continue;
      const a = e.amps, k = a.length;
      let i = 0;
      while (i < k - 2 && v >= a[i + 1]) i++;
      const t = (v - a[i]) / (a[i + 1] - a[i]);
      const n2 = e.m * 2, d = e.disp, o0 = i * n2, o1 = (i + 1) * n2;
      const verts = e.verts;
      if (e.m === 1) {
        const dx = d[o0] + t * (d[o1] - d[o0]), dy = d[o0 + 1] + t * (d[o1 + 1] - d[o0 + 1]);
        for (let j = 0; j < verts.length; j++) { out[2 * verts[j]] += dx; out[2 * verts[j] + 1] += dy; }
      } else {
        for (let j = 0; j < verts.length; j++) {
          const s = 2 * j;
          out[2 * verts[j]] += d[o0 + s] + t * (d[o1 + s] - d[o0 + s]);
          out[2 * verts[j] + 1] += d[o0 + s + 1] + t * (d[o1 + s + 1] - d[o0 + s + 1]);
        }
      }
    }
    return out;
  }

  // Corners of a triangle whose edges are pushed d px outwards (mitre limited), written into out[0..5].
  function grown(x0, y0, x1, y1, x2, y2, d, out) {
    const P = [x0, y0, x1, y1, x2, y2];
    const nx = [0, 0, 0], ny = [0, 0, 0];
    for (let i = 0; i < 3; i++) {
      const a = 2 * i, b = 2 * ((i + 1) % 3), c = 2 * ((i + 2) % 3);
      let ex = P[b] - P[a], ey = P[b + 1] - P[a + 1];
      let mx = ey, my = -ex;
      const l = Math.hypot(mx, my);
      if (l > 1e-12) { mx /= l; my /= l; }
      if (mx * (P[c] - P[a]) + my * (P[c + 1] - P[a + 1]) > 0) { mx = -mx; my = -my; }
      nx[i] = mx; ny[i] = my;
    }
    for (let i = 0; i < 3; i++) {
      const j = (i + 2) % 3;  // the other edge at corner i
      let den = 1 + nx[j] * nx[i] + ny[j] * ny[i];
      if (!(den > 1e-6)) den = 1e-6;
      let mx = (nx[j] + nx[i]) / den, my = (ny[j] + ny[i]) / den;
      const l = Math.hypot(mx, my);
      if (l > MITER_LIMIT) { mx *= MITER_LIMIT / l; my *= MITER_LIMIT / l; }
      out[2 * i] = P[2 * i] + d * mx;
      out[2 * i + 1] = P[2 * i + 1] + d * my;
    }
    return out;
  }

  // Draw the three layers. Consecutive triangles (in drawing order) that share one affine texture transform,
  // such as every triangle no FAP moves this frame, are clipped and drawn together: one clip and one drawImage
  // per run instead of per triangle, with the drawing order (and so the occlusion) unchanged.
  function drawFrame(ctx, pkg, pos) {
    const W = ctx.canvas.width, H = ctx.canvas.height;
    const uv = pkg.xy0, tris = pkg.tris, grow = pkg.overdraw, tex = pkg.texture;
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.clearRect(0, 0, W, H);
    ctx.drawImage(pkg.portrait, 0, 0);
    ctx.drawImage(pkg.mouth, 0, 0);
    // Triangles no FAP moves, away from every moved triangle (old and new place) and from the mouth layer,
    // would draw the portrait's own pixels: skip them (same rule as converter/fap2d_render.py).
    const C = pkg.dirtyCell, gw = Math.ceil(W / C), gh = Math.ceil(H / C), M = 2;
    const nT = tris.length / 3;
    if (!pkg.dirty) { pkg.dirty = new Uint8Array(gw * gh); pkg.moving = new Uint8Array(nT); }
    const dirty = pkg.dirty, moving = pkg.moving;
    dirty.fill(0);
    const mark = (x0, y0, x1, y1) => {
      const cx0 = Math.max(0, Math.floor((x0 - M) / C)), cy0 = Math.max(0, Math.floor((y0 - M) / C));
      const cx1 = Math.min(gw - 1, Math.floor((x1 + M) / C)), cy1 = Math.min(gh - 1, Math.floor((y1 + M) / C));
      for (let y = cy0; y <= cy1; y++) for (let x = cx0; x <= cx1; x++) dirty[y * gw + x] = 1;
    };
    if (pkg.mouthBox) mark(...pkg.mouthBox);
    for (let t = 0; t < nT; t++) {
      const i0 = 2 * tris[3 * t], i1 = 2 * tris[3 * t + 1], i2 = 2 * tris[3 * t + 2];
      const m = pos[i0] !== uv[i0] || pos[i0 + 1] !== uv[i0 + 1] || pos[i1] !== uv[i1] || pos[i1 + 1] !== uv[i1 + 1]
        || pos[i2] !== uv[i2] || pos[i2 + 1] !== uv[i2 + 1];
      moving[t] = m ? 1 : 0;
      if (m) {
        mark(Math.min(pos[i0], pos[i1], pos[i2], uv[i0], uv[i1], uv[i2]),
             Math.min(pos[i0 + 1], pos[i1 + 1], pos[i2 + 1], uv[i0 + 1], uv[i1 + 1], uv[i2 + 1]),
             Math.max(pos[i0], pos[i1], pos[i2], uv[i0], uv[i1], uv[i2]),
             Math.max(pos[i0 + 1], pos[i1 + 1], pos[i2 + 1], uv[i0 + 1], uv[i1 + 1], uv[i2 + 1]));
      }
    }
    const touched = (i0, i1, i2) => {
      const cx0 = Math.max(0, Math.floor((Math.min(uv[i0], uv[i1], uv[i2]) - M) / C));
      const cy0 = Math.max(0, Math.floor((Math.min(uv[i0 + 1], uv[i1 + 1], uv[i2 + 1]) - M) / C));
      const cx1 = Math.min(gw - 1, Math.floor((Math.max(uv[i0], uv[i1], uv[i2]) + M) / C));
      const cy1 = Math.min(gh - 1, Math.floor((Math.max(uv[i0 + 1], uv[i1 + 1], uv[i2 + 1]) + M) / C));
      for (let y = cy0; y <= cy1; y++) for (let x = cx0; x <= cx1; x++) if (dirty[y * gw + x]) return true;
      return false;
    };
    let open = false, ra = 0, rb = 0, rc = 0, rd = 0, re = 0, rf = 0;
    let sx0 = 0, sy0 = 0, sx1 = 0, sy1 = 0;
    const flush = () => {
      if (!open) return;
      ctx.save();
      ctx.clip();
      ctx.setTransform(ra, rb, rc, rd, re, rf);
      const sx = Math.max(0, Math.floor(sx0) - 2), sy = Math.max(0, Math.floor(sy0) - 2);
      const sw = Math.min(W, Math.ceil(sx1) + 2) - sx, sh = Math.min(H, Math.ceil(sy1) + 2) - sy;
      if (sw > 0 && sh > 0) ctx.drawImage(tex, sx, sy, sw, sh, sx, sy, sw, sh);
      ctx.restore();
      open = false;
    };
    const EPS = 1e-6, corners = new Float64Array(6);
    for (let f = 0; f < tris.length; f += 3) {
      const i0 = 2 * tris[f], i1 = 2 * tris[f + 1], i2 = 2 * tris[f + 2];
      if (!moving[f / 3] && !touched(i0, i1, i2)) continue;
      const x0 = pos[i0], y0 = pos[i0 + 1], x1 = pos[i1], y1 = pos[i1 + 1], x2 = pos[i2], y2 = pos[i2 + 1];
      const u0 = uv[i0], v0 = uv[i0 + 1], u1 = uv[i1], v1 = uv[i1 + 1], u2 = uv[i2], v2 = uv[i2 + 1];
      const du1 = u1 - u0, dv1 = v1 - v0, du2 = u2 - u0, dv2 = v2 - v0;
      const den = du1 * dv2 - du2 * dv1;
      const dx1 = x1 - x0, dy1 = y1 - y0, dx2 = x2 - x0, dy2 = y2 - y0;
      const area = dx1 * dy2 - dx2 * dy1;
      if (Math.abs(den) < 1e-9 || Math.abs(area) < 1e-9) continue;
      // Affine texture -> screen: [a c e; b d g].
      const a = (dx1 * dv2 - dx2 * dv1) / den, c = (dx2 * du1 - dx1 * du2) / den;
      const b = (dy1 * dv2 - dy2 * dv1) / den, d = (dy2 * du1 - dy1 * du2) / den;
      const e = x0 - a * u0 - c * v0, g = y0 - b * u0 - d * v0;
      if (open && !(Math.abs(a - ra) < EPS && Math.abs(b - rb) < EPS && Math.abs(c - rc) < EPS && Math.abs(d - rd) < EPS
                    && Math.abs(e - re) < 1e-3 && Math.abs(g - rf) < 1e-3)) flush();
      if (!open) {
        ctx.beginPath();
        open = true; ra = a; rb = b; rc = c; rd = d; re = e; rf = g;
        sx0 = Infinity; sy0 = Infinity; sx1 = -Infinity; sy1 = -Infinity;
      }
      sx0 = Math.min(sx0, u0, u1, u2); sy0 = Math.min(sy0, v0, v1, v2);
      sx1 = Math.max(sx1, u0, u1, u2); sy1 = Math.max(sy1, v0, v1, v2);
      // The triangle with every edge pushed `grow` px outwards (mitred corners, limited to 4 x grow), always
      // wound the same way so the nonzero rule unites overlapping triangles of a run. Same as fap2d_render.py.
      const q = grown(x0, y0, x1, y1, x2, y2, grow, corners);
      const p0x = q[0], p0y = q[1], p1x = q[2], p1y = q[3], p2x = q[4], p2y = q[5];
      ctx.moveTo(p0x, p0y);
      if (area > 0) { ctx.lineTo(p1x, p1y); ctx.lineTo(p2x, p2y); }
      else { ctx.lineTo(p2x, p2y); ctx.lineTo(p1x, p1y); }
      ctx.closePath();
    }
    flush();
  }

  class Player {
    constructor(canvas, pkg, ui) {
      this.canvas = canvas;
      this.ctx = canvas.getContext("2d");
      this.pkg = pkg;
      this.ui = ui || {};
      this.frame = 0;
      this.playing = false;
      this.pos = new Float32Array(pkg.xy0.length);
      canvas.width = pkg.manifest.size[0];
      canvas.height = pkg.manifest.size[1];
      this.nFrames = pkg.stream.frames;
      this.fps = pkg.stream.fps;
    }

    renderFrame(k) {
      this.frame = Math.max(0, Math.min(this.nFrames - 1, k | 0));
      positions(this.pkg, this.pkg.stream.values, this.frame * N_FAPS, this.pos);
      drawFrame(this.ctx, this.pkg, this.pos);
      if (this.ui.seek) this.ui.seek.value = String(this.frame);
      if (this.ui.label) this.ui.label.textContent = `${this.frame + 1} / ${this.nFrames}`;
    }

    renderValues(values) {
      positions(this.pkg, values, 0, this.pos);
      drawFrame(this.ctx, this.pkg, this.pos);
    }

    play() {
      if (this.playing) return;
      this.playing = true;
      const start = performance.now() - (this.frame / this.fps) * 1000;
      const tick = (now) => {
        if (!this.playing) return;
        const k = Math.floor(((now - start) / 1000) * this.fps) % this.nFrames;
        if (k !== this.frame || !this.drawn) { this.renderFrame(k); this.drawn = true; }
        requestAnimationFrame(tick);
      };
      this.drawn = false;
      requestAnimationFrame(tick);
      if (this.ui.button) this.ui.button.textContent = "Pause";
    }

    pause() {
      this.playing = false;
      if (this.ui.button) this.ui.button.textContent = "Play";
    }

    // Mean milliseconds to compute and rasterise one frame, forcing rasterisation with a 1-pixel readback.
    timeFrames(n) {
      const t0 = performance.now();
      for (let i = 0; i < n; i++) {
        this.renderFrame(i % this.nFrames);
        this.ctx.getImageData(0, 0, 1, 1);
      }
      return (performance.now() - t0) / n;
    }

    // Frames per second actually shown when a new frame is drawn on every animation frame for `ms`.
    measureFps(ms) {
      return new Promise((resolve) => {
        let shown = 0, start = null;
        const tick = (now) => {
          if (start === null) start = now;
          this.renderFrame(shown % this.nFrames);
          shown++;
          if (now - start < ms) requestAnimationFrame(tick);
          else resolve((shown - 1) / ((now - start) / 1000));
        };
        requestAnimationFrame(tick);
      });
    }
  }

  async function open(src, canvas, ui) {
    const res = await fetch(src);
    if (!res.ok) throw new Error(`cannot load ${src}: HTTP ${res.status}`);
    return new Player(canvas, await loadPackage(await res.arrayBuffer()), ui);
  }

  window.Fap2d = { unzip, parseFap, loadPackage, positions, Player, open };
})();
