// Independent decoding of ETC1S/BasisLZ KTX2 files with the Basis Universal
// transcoder three.js ships (examples/jsm/libs/basis), for tests/test_basislz.py.
//
//   node basis_decode.mjs TRANSCODER_DIR FILE...
//
// One JSON object per line and file: its size, whether the transcoder sees
// alpha, and every level transcoded to RGBA32 (base64, origWidth x origHeight
// texels, row-major), or {error} when the transcoder refuses the file.
import { readFileSync } from 'node:fs';
import { join } from 'node:path';
import vm from 'node:vm';

const RGBA32 = 13; // transcoder_texture_format::cTFRGBA32

async function loadTranscoder(dir) {
  // the transcoder is a classic script defining BASIS (an Emscripten factory)
  const code = readFileSync(join(dir, 'basis_transcoder.js'), 'utf8');
  const context = { console, WebAssembly, TextDecoder, URL, setTimeout, clearTimeout, performance };
  vm.createContext(context);
  vm.runInContext(code + '\n;globalThis.BASIS = BASIS;', context);
  const wasmBinary = readFileSync(join(dir, 'basis_transcoder.wasm'));
  const module = await context.BASIS({ wasmBinary });
  module.initializeBasis();
  return module;
}

function decode(module, path) {
  const file = new module.KTX2File(new Uint8Array(readFileSync(path)));
  try {
    if (!file.isValid()) return { file: path, error: 'KTX2File.isValid() is false' };
    if (!file.isETC1S()) return { file: path, error: 'not ETC1S' };
    if (!file.startTranscoding()) return { file: path, error: 'startTranscoding failed' };
    const levels = [];
    for (let level = 0; level < file.getLevels(); level++) {
      const info = file.getImageLevelInfo(level, 0, 0);
      const dst = new Uint8Array(file.getImageTranscodedSizeInBytes(level, 0, 0, RGBA32));
      if (!file.transcodeImage(dst, level, 0, 0, RGBA32, 0, -1, -1)) {
        return { file: path, error: `transcodeImage failed on level ${level}` };
      }
      levels.push({ width: info.origWidth, height: info.origHeight, rgba: Buffer.from(dst).toString('base64') });
    }
    return { file: path, width: file.getWidth(), height: file.getHeight(), hasAlpha: !!file.getHasAlpha(), levels };
  } finally {
    file.close();
    file.delete();
  }
}

const [dir, ...paths] = process.argv.slice(2);
const module = await loadTranscoder(dir);
for (const path of paths) {
  let record;
  try {
    record = decode(module, path);
  } catch (err) {
    record = { file: path, error: String(err && err.message ? err.message : err) };
  }
  process.stdout.write(JSON.stringify(record) + '\n');
}
