// Plays a glTF with three.js (GLTFLoader + AnimationMixer) and renders chosen times with a given camera.
// window.referencePlayer.render(request) resolves to one base64 RGBA buffer (rows bottom-up) per time.
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { MeshoptDecoder } from 'three/addons/libs/meshopt_decoder.module.js';

// facesvg's one light rig (converter/lighting.py): a key light fixed in eye space plus ambient, Lambert only.
const LIGHT_EYE = new THREE.Vector3(-0.35, 0.45, 0.82).normalize();

function rowMajor(rows) {
  return new THREE.Matrix4().set(...rows.flat());
}

function pickClips(animations, clips) {
  if (clips === 'all') return animations;
  return clips.map((c) => {
    const clip = typeof c === 'number' ? animations[c] : animations.find((a) => a.name === c);
    if (!clip) throw new Error(`no animation ${JSON.stringify(c)} among ${animations.length}`);
    return clip;
  });
}

// Every mesh drawn opaque with its own colour (factor and vertex colours) and side, flat Lambert. No texture:
// its alpha would leak into the mask alpha (OPAQUE materials must ignore it), and its colours are not compared.
function restyle(scene) {
  scene.traverse((obj) => {
    obj.frustumCulled = false;  // skinned and morphed meshes leave their rest-pose bounds
    if (!obj.isMesh) return;
    const mats = Array.isArray(obj.material) ? obj.material : [obj.material];
    const flat = mats.map((m) => new THREE.MeshLambertMaterial({
      color: m.color ? m.color.clone() : new THREE.Color(1, 1, 1),
      vertexColors: !!m.vertexColors, side: m.side, flatShading: true,
    }));
    obj.material = Array.isArray(obj.material) ? flat : flat[0];
  });
}

function base64(bytes) {
  let s = '';
  for (let i = 0; i < bytes.length; i += 0x8000) s += String.fromCharCode.apply(null, bytes.subarray(i, i + 0x8000));
  return btoa(s);
}

async function render(req) {
  const gltf = await new GLTFLoader().setMeshoptDecoder(MeshoptDecoder).loadAsync(req.url);
  const scene = new THREE.Scene();
  scene.add(gltf.scene);
  restyle(gltf.scene);

  const view = rowMajor(req.view);
  const camera = new THREE.Camera();  // the base class: nothing recomputes its projection
  camera.projectionMatrix.copy(rowMajor(req.projection));
  camera.projectionMatrixInverse.copy(camera.projectionMatrix).invert();
  camera.matrixAutoUpdate = false;
  camera.matrix.copy(view).invert();
  camera.matrixWorld.copy(camera.matrix);
  camera.matrixWorldInverse.copy(view);

  // Light intensities times pi: three.js's Lambert BRDF divides by pi.
  scene.add(new THREE.AmbientLight(0xffffff, 0.30 * Math.PI));
  const key = new THREE.DirectionalLight(0xffffff, 0.75 * Math.PI);
  key.position.copy(LIGHT_EYE).applyMatrix3(new THREE.Matrix3().setFromMatrix4(view).transpose());
  scene.add(key, key.target);

  const [w, h] = req.viewport;
  const renderer = new THREE.WebGLRenderer({ antialias: false, alpha: true, preserveDrawingBuffer: true });
  renderer.setPixelRatio(1);
  renderer.setSize(w, h, false);
  renderer.setClearColor(0x000000, 0);
  renderer.outputColorSpace = req.linear ? THREE.LinearSRGBColorSpace : THREE.SRGBColorSpace;
  document.body.appendChild(renderer.domElement);

  const mixer = new THREE.AnimationMixer(gltf.scene);
  const actions = pickClips(gltf.animations, req.clips).map((clip) => {
    const a = mixer.clipAction(clip);
    a.setLoop(THREE.LoopOnce, 1);
    a.clampWhenFinished = true;  // past a clip's end it holds its last pose, as glTF samplers do
    return a.play();
  });

  const gl = renderer.getContext();
  const out = [];
  for (const t of req.times) {
    actions.forEach((a) => a.reset());
    mixer.setTime(t);
    renderer.render(scene, camera);
    const px = new Uint8Array(w * h * 4);
    gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, px);
    out.push(base64(px));
  }
  renderer.dispose();
  return { frames: out, revision: THREE.REVISION, clips: gltf.animations.map((a) => a.name), played: actions.map((a) => a.getClip().name) };
}

window.referencePlayer = { render, revision: THREE.REVISION };
