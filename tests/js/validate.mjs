// The Khronos glTF validator (npm gltf-validator) on a .gltf or .glb, for tests/test_scene.py.
//
//   node validate.mjs MODEL    prints the validator's JSON report on one line
//
// External buffers and images are read relative to the model, so the report covers
// them too (image headers, buffer lengths). Exit 0 whenever a report was made; the
// caller judges report.issues.numErrors.
import { readFileSync } from 'node:fs';
import path from 'node:path';
import validator from 'gltf-validator';

const file = process.argv[2];
if (!file) {
  process.stderr.write('usage: node validate.mjs MODEL.gltf|MODEL.glb\n');
  process.exit(2);
}
const full = path.resolve(file);

const report = await validator.validateBytes(new Uint8Array(readFileSync(full)), {
  uri: path.basename(full),
  maxIssues: 0, // all of them
  externalResourceFunction: async (uri) =>
    new Uint8Array(readFileSync(path.resolve(path.dirname(full), decodeURIComponent(uri)))),
});
process.stdout.write(JSON.stringify(report) + '\n');
