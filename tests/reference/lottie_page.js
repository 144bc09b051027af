// The Lottie reference players, driven by tests/reference/lottie.py: window.lottieReference.open(req) loads one
// animation in one player ("lottie-svg", "lottie-canvas" or "thorvg"), then seek(frame) / pixels() read frames.
// With ?play=<player>&src=<file> the page instead loads src and plays it in a loop (lottie_fps), counting the
// frames the player drew in window.lottiePlayed.
import { DotLottie } from './node_modules/@lottiefiles/dotlottie-web/dist/index.js';

// ThorVG's WASM from the package on disk, never from the CDN the library defaults to.
DotLottie.setWasmUrl(new URL('./node_modules/@lottiefiles/dotlottie-web/dist/dotlottie-player.wasm',
                             import.meta.url).href);

let current = null;

function stage(width, height) {
  const div = document.getElementById('stage');
  div.innerHTML = '';
  div.style.width = `${width}px`;
  div.style.height = `${height}px`;
  return div;
}

function fromBase64(text) {
  const raw = atob(text);
  const bytes = new Uint8Array(raw.length);
  for (let i = 0; i < raw.length; i++) bytes[i] = raw.charCodeAt(i);
  return bytes.buffer;
}

function toBase64(bytes) {
  let s = '';
  for (let i = 0; i < bytes.length; i += 0x8000) s += String.fromCharCode.apply(null, bytes.subarray(i, i + 0x8000));
  return btoa(s);
}

function lottieWeb(container, renderer, doc, play) {
  const settings = renderer === 'canvas'
    ? { dpr: 1, clearCanvas: true, preserveAspectRatio: 'xMidYMid meet' }
    : { preserveAspectRatio: 'xMidYMid meet', progressiveLoad: false };
  const anim = window.lottie.loadAnimation({ container, renderer, loop: play, autoplay: play,
                                             animationData: doc, rendererSettings: settings });
  return new Promise((resolve, reject) => {
    if (anim.isLoaded) { resolve(anim); return; }
    anim.addEventListener('DOMLoaded', () => resolve(anim));
    anim.addEventListener('data_failed', () => reject(new Error('lottie-web could not read the animation')));
    anim.addEventListener('error', (e) => reject(new Error(`lottie-web: ${e && e.nativeError}`)));
  });
}

function thorvg(container, width, height, data, play) {
  const canvas = document.createElement('canvas');
  canvas.width = width;
  canvas.height = height;
  canvas.style.width = `${width}px`;
  canvas.style.height = `${height}px`;
  canvas.style.display = 'block';
  container.appendChild(canvas);
  const player = new DotLottie({ canvas, data, autoplay: play, loop: play, useFrameInterpolation: true,
                                 layout: { fit: 'contain', align: [0.5, 0.5] },
                                 renderConfig: { devicePixelRatio: 1, autoResize: false, freezeOnOffscreen: false } });
  return new Promise((resolve, reject) => {
    player.addEventListener('load', () => resolve({ player, canvas }));
    player.addEventListener('loadError', (e) => reject(new Error(`ThorVG could not load the animation: ${e.error}`)));
  });
}

async function open(req) {
  if (current && current.kind === 'thorvg') current.player.destroy();
  current = null;
  const container = stage(req.width, req.height);
  if (req.player === 'thorvg') {
    const data = req.zip ? fromBase64(req.zip) : req.json;
    const { player, canvas } = await thorvg(container, req.width, req.height, data, false);
    current = { kind: 'thorvg', player, canvas, ip: req.ip };
    return { total: player.totalFrames };
  }
  const renderer = { 'lottie-svg': 'svg', 'lottie-canvas': 'canvas' }[req.player];
  if (!renderer) throw new Error(`unknown player ${req.player}`);
  const anim = await lottieWeb(container, renderer, JSON.parse(req.json), false);
  current = { kind: req.player, anim, ip: req.ip };
  return { total: anim.totalFrames, version: window.lottie.version };
}

// Seek to the Lottie frame (of the composition: ip..op) and draw it.
function seek(frame) {
  if (current.kind === 'thorvg') {
    current.player.setFrame(frame - current.ip);
    return current.player.currentFrame + current.ip;
  }
  current.anim.goToAndStop(frame - current.ip, true);
  return current.anim.currentFrame + current.ip;
}

// The canvas's RGBA, base64 (the canvas players only; the svg player is read by a screenshot).
function pixels() {
  const canvas = current.kind === 'thorvg' ? current.canvas : current.anim.renderer.canvasContext.canvas;
  const ctx = canvas.getContext('2d');
  const img = ctx.getImageData(0, 0, canvas.width, canvas.height);
  return { width: canvas.width, height: canvas.height, rgba: toBase64(new Uint8Array(img.data.buffer)) };
}

async function frames(list) {
  const out = [];
  for (const f of list) {
    seek(f);
    out.push(pixels().rgba);
  }
  return out;
}

async function playFromUrl(params) {
  window.lottiePlayed = { frames: 0, error: null, player: params.get('play') };
  try {
    const src = params.get('src');
    const w = Number(params.get('w')), h = Number(params.get('h'));
    const body = await fetch(src);
    const container = stage(w, h);
    if (params.get('play') === 'thorvg') {
      const data = src.endsWith('.lottie') ? await body.arrayBuffer() : await body.text();
      const { player } = await thorvg(container, w, h, data, true);
      player.addEventListener('frame', () => { window.lottiePlayed.frames++; });
    } else {
      const renderer = { 'lottie-svg': 'svg', 'lottie-canvas': 'canvas' }[params.get('play')];
      const anim = await lottieWeb(container, renderer, await body.json(), true);
      anim.addEventListener('enterFrame', () => { window.lottiePlayed.frames++; });
    }
  } catch (e) {
    window.lottiePlayed.error = String(e);
  }
}

window.lottieReference = { open, seek, pixels, frames };
const params = new URLSearchParams(location.search);
if (params.get('play')) playFromUrl(params);
