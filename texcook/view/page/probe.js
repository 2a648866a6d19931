// Read back every texel of every level of a KTX2 file as the GPU samples it:
// texelFetch into a 32-bit float target (sRGB formats come back in linear
// light, as shaders see them), returned as base64 of little-endian float32 RGBA
// rows, row 0 first. What `texcook view`'s browser test compares with
// texcook's own decode.
import * as THREE from 'three';

const fetchShader = (level) => new THREE.RawShaderMaterial({
  glslVersion: THREE.GLSL3,
  uniforms: { tex: { value: null } },
  vertexShader: `precision highp float; in vec3 position;
    void main() { gl_Position = vec4(position.xy, 0.0, 1.0); }`,
  fragmentShader: `precision highp float; precision highp sampler2D; uniform sampler2D tex; out vec4 colour;
    void main() { colour = texelFetch(tex, ivec2(gl_FragCoord.xy), ${level | 0}); }`,
});

function base64(floats) {
  const bytes = new Uint8Array(floats.buffer);
  let text = '';
  for (let i = 0; i < bytes.length; i += 0x8000) text += String.fromCharCode.apply(null, bytes.subarray(i, i + 0x8000));
  return btoa(text);
}

// missing(vk): the WebGL extensions this GPU lacks for the format (three.js
// uploads a compressed texture the GPU cannot take as nothing, with a warning).
export async function readLevels(renderer, ktx2, missing, url) {
  const bytes = await (await fetch(url)).arrayBuffer();
  const vk = new DataView(bytes, 0, 16).getUint32(12, true);
  let texture;
  try {
    texture = await new Promise((ok, no) => ktx2.parse(bytes, ok, no));
  } catch (e) {
    return { loaded: false, vk, why: String(e && e.message || e) };
  }
  const lacks = missing(vk);
  if (lacks.length) return { loaded: false, vk, why: `this GPU lacks ${lacks.join(', ')}` };
  const gl = renderer.getContext();
  const scene = new THREE.Scene();
  const quad = new THREE.Mesh(new THREE.BufferGeometry(), null);
  quad.geometry.setAttribute('position', new THREE.Float32BufferAttribute([-1, -1, 0, 3, -1, 0, -1, 3, 0], 3));
  quad.frustumCulled = false;
  scene.add(quad);
  const camera = new THREE.Camera();
  const levels = [];
  const count = texture.mipmaps.length;
  for (let level = 0; level < count; level++) {
    const w = texture.mipmaps[level].width, h = texture.mipmaps[level].height;
    const target = new THREE.WebGLRenderTarget(w, h, { type: THREE.FloatType, format: THREE.RGBAFormat, depthBuffer: false });
    quad.material = fetchShader(level);
    quad.material.uniforms.tex.value = texture;
    renderer.setRenderTarget(target);
    renderer.render(scene, camera);
    const out = new Float32Array(w * h * 4);
    renderer.readRenderTargetPixels(target, 0, 0, w, h, out);
    renderer.setRenderTarget(null);
    target.dispose();
    quad.material.dispose();
    levels.push({ width: w, height: h, data: base64(out) });
  }
  const error = gl.getError();
  texture.dispose();
  return { loaded: true, vk, compressed: !!texture.isCompressedTexture, colorSpace: texture.colorSpace,
    format: texture.format, glError: error, levels };
}
