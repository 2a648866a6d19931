// Independent reading of KTX2 files with npm's ktx-parse, for tests/test_ktx2.py.
//
//   node ktxparse.mjs FILE...       one JSON object per line and file
//   node ktxparse.mjs --constants   the VK_FORMAT_* constants ktx-parse exports
//
// Level data is printed as base64 exactly as stored (still supercompressed), so the
// Python side can inflate it with its own zstd and compare with what it wrote.
import { readFileSync } from 'node:fs';
import * as ktx from 'ktx-parse';

const decoder = new TextDecoder('utf-8', { fatal: false });

function text(value) {
  if (typeof value === 'string') return value;
  let bytes = value;
  if (bytes.length && bytes[bytes.length - 1] === 0) bytes = bytes.subarray(0, bytes.length - 1);
  return decoder.decode(bytes);
}

function describe(path) {
  const container = ktx.read(new Uint8Array(readFileSync(path)));
  const dfd = container.dataFormatDescriptor[0];
  const keyValue = {};
  for (const [key, value] of Object.entries(container.keyValue)) keyValue[key] = text(value);
  return {
    file: path,
    vkFormat: container.vkFormat,
    typeSize: container.typeSize,
    pixelWidth: container.pixelWidth,
    pixelHeight: container.pixelHeight,
    pixelDepth: container.pixelDepth,
    layerCount: container.layerCount,
    faceCount: container.faceCount,
    levelCount: container.levels.length,
    supercompressionScheme: container.supercompressionScheme,
    colorModel: dfd.colorModel,
    colorPrimaries: dfd.colorPrimaries,
    transferFunction: dfd.transferFunction,
    flags: dfd.flags,
    texelBlockDimension: dfd.texelBlockDimension,
    bytesPlane: dfd.bytesPlane,
    samples: dfd.samples.map((s) => ({
      bitOffset: s.bitOffset,
      bitLength: s.bitLength,
      channelType: s.channelType,
      sampleLower: s.sampleLower,
      sampleUpper: s.sampleUpper,
    })),
    keyValue,
    levels: container.levels.map((level) => ({
      byteLength: level.levelData.byteLength,
      uncompressedByteLength: level.uncompressedByteLength,
      data: Buffer.from(level.levelData.buffer, level.levelData.byteOffset, level.levelData.byteLength).toString('base64'),
    })),
  };
}

const args = process.argv.slice(2);
if (args[0] === '--constants') {
  const out = {};
  for (const [name, value] of Object.entries(ktx)) if (name.startsWith('VK_FORMAT_')) out[name] = value;
  process.stdout.write(JSON.stringify(out) + '\n');
} else {
  for (const path of args) {
    let record;
    try {
      record = describe(path);
    } catch (err) {
      record = { file: path, error: String(err && err.message ? err.message : err) };
    }
    process.stdout.write(JSON.stringify(record) + '\n');
  }
}
