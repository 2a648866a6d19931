// texcook view: a baked scene against its source images, or one texture on
// planes, rendered by three.js. The server's /_texcook/site.json says what.
// Query: ?layout=side|baked|original (scenes), ?filter=...&level=N&diff=1
// (textures); window.texcook.state becomes "ready" (or "error") once drawn.
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { KTX2Loader } from 'three/addons/loaders/KTX2Loader.js';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { RoomEnvironment } from 'three/addons/environments/RoomEnvironment.js';
import { readLevels } from './probe.js';

const query = new URLSearchParams(location.search);
const $ = (id) => document.getElementById(id);
const api = window.texcook = { state: 'loading', textures: [], error: null, timings: {} };
const mark = (what) => { api.timings[what] = Math.round(performance.now()); };

const canvas = $('canvas');
const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(1);
// Basis Universal payloads (KHR_texture_basisu, vkFormat 0) go through three.js's transcoder
const ktx2 = new KTX2Loader().setTranscoderPath('/_texcook/three/examples/jsm/libs/basis/').detectSupport(renderer);
api.readLevels = (url) => readLevels(renderer, ktx2, missingExtensions, url);

let site = null;
let draw = () => {};

function size() {
  const w = canvas.clientWidth, h = canvas.clientHeight;
  if (canvas.width !== w || canvas.height !== h) renderer.setSize(w, h, false);
  return [w, h];
}

function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === 'class') node.className = v; else if (k.startsWith('on')) node.addEventListener(k.slice(2), v);
    else node.setAttribute(k, v);
  }
  for (const c of children) node.append(c);
  return node;
}

// Whether this browser can show a KTX2 file of vkFormat `vk`: three.js's
// KTX2Loader must take it, and the GPU must have its WebGL extension.
function missingExtensions(vk) {
  const facts = site.vk[vk];
  return facts ? facts.webgl.filter((e) => !renderer.extensions.has(e)) : [];
}

function support(vk) {
  const facts = site.vk[vk];
  if (!facts) return { ok: false, why: `vkFormat ${vk} is not a format texcook knows` };
  if (!facts.three) return { ok: false, why: `three.js r${site.three.split('.')[1]} KTX2Loader refuses vkFormat ${vk} (${facts.format}${facts.srgb ? ' sRGB' : ''})` };
  const missing = missingExtensions(vk);
  if (missing.length) return { ok: false, why: `this GPU lacks ${missing.join(', ')}` };
  if (facts.srgb_ignored) return { ok: true, why: 'three.js samples it without the sRGB curve (WebGL 2 has no sRGB R8/RG8): too bright' };
  return { ok: true, why: '' };
}

async function vkFormatOf(parser, image, base) {
  let bytes;
  if (image.bufferView !== undefined) bytes = await parser.getDependency('bufferView', image.bufferView);
  else bytes = await (await fetch(new URL(image.uri, base))).arrayBuffer();
  return new DataView(bytes, 0, 16).getUint32(12, true);
}

// A GLTFLoader plugin for texcook's KTX2 extension (and EXT_texture_astc,
// which has the same shape): the KTX2 image through KTX2Loader when this
// browser can show its format, else the texture's own source (the fallback).
class KTX2Extension {
  constructor(parser, name, base, records) {
    Object.assign(this, { parser, name, base, records });
  }

  loadTexture(index) {
    const parser = this.parser, json = parser.json, def = json.textures[index];
    const ext = def.extensions && def.extensions[this.name];
    if (!ext) return null;
    const image = json.images[ext.source];
    return vkFormatOf(parser, image, this.base).then((vk) => {
      const s = support(vk);
      const record = { texture: index, image: ext.source, name: image.name || image.uri || `image ${ext.source}`, vk, extension: this.name, ...s };
      this.records.push(record);
      if (s.ok) {
        return parser.loadTextureImage(index, ext.source, ktx2).then((t) => {
          record.shown = t.isCompressedTexture ? 'KTX2 (compressed)' : 'KTX2';
          record.compressed = !!t.isCompressedTexture;
          return t;
        });
      }
      if (def.source === undefined) { record.shown = 'nothing: no fallback image'; return null; }
      record.shown = 'fallback: ' + (json.images[def.source].uri || `image ${def.source}`);
      return parser.loadTextureImage(index, def.source, parser.textureLoader);
    });
  }
}

// The original look: every texture from its own source image.
class SourceOnly {
  constructor(parser) { this.parser = parser; this.name = 'texcook_source_only'; }
  loadTexture(index) {
    const def = this.parser.json.textures[index];
    if (def.source === undefined) return null;
    return this.parser.loadTextureImage(index, def.source, this.parser.textureLoader);
  }
}

async function loadModel(url, baked, records) {
  const loader = new GLTFLoader();
  const base = new URL(url, location.href);
  if (baked) {
    for (const name of ['TEXCOOK_texture_ktx2', 'EXT_texture_astc', 'KHR_texture_basisu']) {
      loader.register((parser) => new KTX2Extension(parser, name, base, records));
    }
  } else {
    loader.register((parser) => new SourceOnly(parser));
  }
  const scene = (await loader.loadAsync(url)).scene;
  mark(baked ? 'baked model' : 'source model');
  return scene;
}

// Put the whole model in view of the narrowest viewport (`aspect`), seen from the front, a little above and right.
function frame(camera, controls, object, aspect) {
  const box = new THREE.Box3().setFromObject(object);
  const centre = box.getCenter(new THREE.Vector3());
  const radius = Math.max(box.getSize(new THREE.Vector3()).length() / 2, 1e-3);
  // the bounding sphere inside the narrower of the two half-angles of view
  const vHalf = THREE.MathUtils.degToRad(camera.fov) / 2;
  const hHalf = Math.atan(Math.tan(vHalf) * aspect);
  const distance = radius / Math.sin(Math.min(vHalf, hHalf));
  camera.near = radius / 100; camera.far = radius * 100;
  camera.position.copy(centre).add(new THREE.Vector3(0.3, 0.2, 1).normalize().multiplyScalar(distance));
  camera.updateProjectionMatrix();
  controls.target.copy(centre);
  controls.update();
}

function fmtPsnr(p) {
  if (p === 'inf') return '∞';
  return typeof p === 'number' ? p.toFixed(2) + ' dB' : '—';
}

async function showScene() {
  const records = [];
  // Image-based lighting costs seconds on SwiftShader (headless Chromium's CPU
  // WebGL): there, and with ?env=0, lights alone; both sides are lit alike.
  const gpu = renderer.getContext().getExtension('WEBGL_debug_renderer_info');
  const software = gpu && /SwiftShader/i.test(renderer.getContext().getParameter(gpu.UNMASKED_RENDERER_WEBGL));
  const ibl = query.get('env') !== '0' && !software;
  const env = ibl ? new THREE.PMREMGenerator(renderer).fromScene(new RoomEnvironment(), 0.04).texture : null;
  const makeScene = (root) => {
    const s = new THREE.Scene();
    s.environment = env;
    s.background = new THREE.Color(0x30333a);
    if (!ibl) {
      s.add(new THREE.HemisphereLight(0xffffff, 0x444450, 3));
      const sun = new THREE.DirectionalLight(0xffffff, 1.6);
      sun.position.set(1, 2, 3);
      s.add(sun);
    }
    s.add(root);
    return s;
  };
  mark('environment');
  const original = site.original;
  const [bakedRoot, originalRoot] = await Promise.all([
    loadModel(site.model, true, records),
    original.how === 'none' ? Promise.resolve(null)
      : loadModel(original.how === 'model' ? original.url : site.model, false, []),
  ]);
  mark('models');
  const scenes = { baked: makeScene(bakedRoot), original: originalRoot && makeScene(originalRoot) };
  const camera = new THREE.PerspectiveCamera(40, 1, 0.01, 100);
  const controls = new OrbitControls(camera, canvas);
  let layout = query.get('layout') || 'side';
  if (!scenes.original) layout = 'baked';
  const [w0, h0] = size();
  frame(camera, controls, bakedRoot, (layout === 'side' ? w0 / 2 : w0) / h0);

  const labels = $('labels');
  draw = () => {
    const [w, h] = size();
    const views = layout === 'side' ? [['baked', 0, w / 2], ['original', w / 2, w / 2]] : [[layout, 0, w]];
    labels.replaceChildren();
    renderer.setScissorTest(true);
    for (const [which, x, vw] of views) {
      renderer.setViewport(x, 0, vw, h);
      renderer.setScissor(x, 0, vw, h);
      camera.aspect = vw / h;
      camera.updateProjectionMatrix();
      renderer.render(scenes[which], camera);
      const text = which === 'baked' ? 'baked (texcook KTX2)' : `source images (${original.how === 'model' ? 'original model' : 'fallback images'})`;
      labels.append(el('div', { style: `left:${x + 8}px` }, text));
    }
    renderer.setScissorTest(false);
  };
  controls.addEventListener('change', () => draw());

  const buttons = el('div');
  for (const name of ['side', 'baked', 'original']) {
    const b = el('button', { class: name === layout ? 'on' : '', onclick: () => {
      layout = name; for (const o of buttons.children) o.className = o.textContent.startsWith(name) ? 'on' : '';
      draw();
    } }, name === 'side' ? 'side by side' : name);
    if (name !== 'baked' && !scenes.original) b.disabled = true;
    buttons.append(b);
  }
  $('controls').append(buttons, el('p', { class: 'small' }, `source: ${original.why}; lighting: ${ibl ? 'room environment' : 'lights only'}`));

  // the panel: scene.json's figures beside what this browser made of each file
  const rows = [];
  const listed = site.textures.length ? site.textures : records.map((r) => ({ name: r.name, image: r.image, vk: r.vk }));
  for (const t of listed) {
    const r = records.find((x) => x.image === t.image) || {};
    const facts = site.vk[t.vk || r.vk] || {};
    const status = r.ok === undefined ? el('span', { class: 'small' }, t.extension === 'MSFT_texture_dds' ? 'DDS: shown as its fallback (no DDS reader here)' : 'not read')
      : el('span', { class: r.ok && !r.why ? 'ok' : 'refused' }, r.ok ? `loaded: ${r.shown}${r.why ? '; ' + r.why : ''}` : `refused (${r.why}); shows ${r.shown}`);
    rows.push(el('tr', {},
      el('td', {}, t.name, el('div', { class: 'small' }, (t.slots || []).join(', '))),
      el('td', {}, `${t.format || facts.format || '?'}${(t.colour_space || (facts.srgb ? 'srgb' : '')) === 'srgb' ? ' sRGB' : ''}`,
        el('div', { class: 'small' }, t.width ? `${t.width}×${t.height}, ${t.levels} lv` : '')),
      el('td', {}, fmtPsnr(t.psnr), el('div', { class: 'small' }, t.psnr_channels || '')),
      el('td', {}, status)));
  }
  $('info').append(el('table', {}, el('tr', {}, ...['texture', 'format, size', 'PSNR', 'this browser'].map((h) => el('th', {}, h))), ...rows));
  api.textures = records;
  return [`${records.length} KTX2 texture(s) in the model`];
}

// --- one texture on a facing plane and a tilted one ----------------------------

const FILTERS = {
  nearest: [THREE.NearestFilter, THREE.NearestFilter, THREE.NearestMipmapNearestFilter],
  linear: [THREE.LinearFilter, THREE.LinearFilter, THREE.LinearMipmapNearestFilter],
  trilinear: [THREE.LinearFilter, THREE.LinearMipmapLinearFilter, THREE.LinearMipmapLinearFilter],
  anisotropic: [THREE.LinearFilter, THREE.LinearMipmapLinearFilter, THREE.LinearMipmapLinearFilter],
};

const planeShader = {
  vertexShader: `varying vec2 vUv; void main() { vUv = vec2(uv.x, 1.0 - uv.y);
    gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0); }`,
  // level < 0: the sampler chooses; diff: |texture - source| times gain
  fragmentShader: `varying vec2 vUv; uniform sampler2D tex; uniform sampler2D src;
    uniform float level; uniform bool diff; uniform bool hasSrc; uniform float gain; uniform bool srgb;
    vec3 enc(vec3 x) { return srgb ? mix(12.92 * x, 1.055 * pow(x, vec3(1.0 / 2.4)) - 0.055, step(0.0031308, x)) : x; }
    vec3 dec(vec3 x) { return mix(x / 12.92, pow((x + 0.055) / 1.055, vec3(2.4)), step(0.04045, x)); }
    void main() {
      vec4 t = level < 0.0 ? texture(tex, vUv) : textureLod(tex, vUv, level);
      vec4 c = t;
      if (diff && hasSrc) {
        vec4 s = level < 0.0 ? texture(src, vUv) : textureLod(src, vUv, level);
        // the difference of the stored (encoded) values, shown as such: dec() undoes the output's sRGB curve
        c = vec4(dec(clamp(abs(enc(t.rgb) - enc(s.rgb)) * gain, 0.0, 1.0)), 1.0);
      }
      gl_FragColor = vec4(c.rgb, 1.0);
      #include <colorspace_fragment>
    }`,
};

async function showTexture() {
  const info = site.texture;
  const s = support(info.vk);
  const uniforms = { tex: { value: null }, src: { value: null }, level: { value: -1 }, diff: { value: false },
    hasSrc: { value: false }, gain: { value: 8 }, srgb: { value: !!info.srgb } };
  let texture = null, failure = null;
  if (s.ok) {
    try { texture = await ktx2.loadAsync(info.url); } catch (e) { failure = String(e.message || e); }
  } else failure = s.why;
  let source = null;
  if (site.source.url) {
    source = await new THREE.TextureLoader().loadAsync(site.source.url);
    source.flipY = false; // the KTX2 file's row 0 is the top row; sample both alike
    source.colorSpace = info.srgb ? THREE.SRGBColorSpace : THREE.NoColorSpace;
    source.wrapS = source.wrapT = THREE.RepeatWrapping;
    source.minFilter = THREE.LinearMipmapLinearFilter;
    source.needsUpdate = true;
    uniforms.src.value = source;
    uniforms.hasSrc.value = true;
  }
  uniforms.tex.value = texture || source; // a refused texture shows its source, labelled
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0x30333a);
  const material = new THREE.ShaderMaterial({ ...planeShader, uniforms });
  const flat = new THREE.Mesh(new THREE.PlaneGeometry(1, 1), material);
  flat.position.set(-0.62, 0, 0);
  const tilted = new THREE.Mesh(new THREE.PlaneGeometry(1, 4, 1, 1), material);
  tilted.rotation.x = -1.35;
  tilted.position.set(0.62, -0.35, -1.6);
  scene.add(flat, tilted);
  const camera = new THREE.PerspectiveCamera(40, 1, 0.01, 100);
  const [w0, h0] = size();
  const half = Math.tan(THREE.MathUtils.degToRad(20));
  camera.position.set(0, 0, Math.max(0.65 / half, 1.3 / (half * w0 / h0))); // both planes in view
  const controls = new OrbitControls(camera, canvas);

  const state = { filter: query.get('filter') || 'trilinear', level: Number(query.get('level') ?? -1), diff: query.get('diff') === '1' };
  const apply = () => {
    const t = uniforms.tex.value;
    if (!t) return;
    const [mag, min, forced] = FILTERS[state.filter];
    t.magFilter = mag;
    t.minFilter = state.level >= 0 ? forced : min;
    t.anisotropy = state.filter === 'anisotropic' ? renderer.capabilities.getMaxAnisotropy() : 1;
    t.wrapS = t.wrapT = THREE.RepeatWrapping;
    t.needsUpdate = true;
    uniforms.level.value = state.level;
    uniforms.diff.value = state.diff;
  };
  apply();
  const labels = $('labels');
  draw = () => {
    const [w, h] = size();
    renderer.setViewport(0, 0, w, h);
    camera.aspect = w / h;
    camera.updateProjectionMatrix();
    renderer.render(scene, camera);
    const what = texture ? `${info.name} (${info.format}${info.srgb ? ' sRGB' : ''})` : `${site.source.name || 'nothing'}: the source image (the texture was refused)`;
    labels.replaceChildren(el('div', { style: 'left:8px' },
      `${what}, ${state.filter}, ${state.level < 0 ? 'mip level by the sampler' : 'mip level ' + state.level}${state.diff ? `, |texture - source| x${uniforms.gain.value}` : ''}`));
  };
  controls.addEventListener('change', () => draw());

  const select = el('select', { onchange: (e) => { state.filter = e.target.value; apply(); draw(); } },
    ...Object.keys(FILTERS).map((f) => { const o = el('option', { value: f }, f); o.selected = f === state.filter; return o; }));
  const levels = el('select', { onchange: (e) => { state.level = Number(e.target.value); apply(); draw(); } },
    el('option', { value: -1 }, 'by the sampler'),
    ...Array.from({ length: info.levels }, (_, i) => { const o = el('option', { value: i }, `level ${i}`); o.selected = i === state.level; return o; }));
  const diff = el('input', { type: 'checkbox', onchange: (e) => { state.diff = e.target.checked; apply(); draw(); } });
  diff.checked = state.diff;
  if (!source) diff.disabled = true;
  $('controls').append(el('label', {}, 'filter ', select), el('label', {}, 'mip level ', levels),
    el('label', {}, diff, ' difference against the source', source ? '' : el('span', { class: 'small' }, ' (no source image: --source)')));
  const status = texture ? el('span', { class: s.why ? 'refused' : 'ok' }, 'loaded by KTX2Loader' + (s.why ? '; ' + s.why : ''))
    : el('span', { class: 'refused' }, `refused: ${failure}`);
  $('info').append(el('table', {},
    el('tr', {}, el('th', {}, 'format'), el('td', {}, `${info.format}${info.srgb ? ' sRGB' : ''} (vkFormat ${info.vk}) in ${info.container}`)),
    el('tr', {}, el('th', {}, 'size'), el('td', {}, `${info.width}×${info.height}, ${info.levels} level(s)`)),
    el('tr', {}, el('th', {}, 'source'), el('td', {}, site.source.name || '—')),
    el('tr', {}, el('th', {}, 'this browser'), el('td', {}, status))));
  api.textures = [{ name: info.name, vk: info.vk, ok: !!texture, why: failure, compressed: !!(texture && texture.isCompressedTexture) }];
  return [texture ? 'texture loaded' : 'texture refused'];
}

async function main() {
  site = await (await fetch('/_texcook/site.json')).json();
  // a probe page only reads textures back (texcook.readLevels), for the browser test
  if (site.kind === 'probe') { api.state = 'ready'; $('status').textContent = 'probe'; return; }
  $('title').textContent = site.kind === 'texture' ? site.texture.name : site.model.split('/').pop();
  const notes = site.kind === 'texture' ? await showTexture() : await showScene();
  window.addEventListener('resize', () => draw());
  draw();
  mark('drawn');
  $('status').textContent = `three.js ${site.three}; ${notes.join('; ')}`;
  api.state = 'ready';
}

main().catch((e) => {
  api.state = 'error';
  api.error = String(e && e.stack || e);
  $('status').className = 'error';
  $('status').textContent = String(e && e.message || e);
  console.error(e);
});
