// The Khronos glTF validator (npm `gltf-validator`) on one .glb/.gltf file: prints its report's
// issue counts and messages as one JSON line. Used by `make corpus` (benchmarks/corpus.py).
const fs = require("fs");
const path = require("path");
const validator = require("gltf-validator");

const file = process.argv[2];
const bytes = new Uint8Array(fs.readFileSync(file));
validator.validateBytes(bytes, {
  uri: path.basename(file),
  maxIssues: 200,
  externalResourceFunction: (uri) => new Promise((resolve, reject) => {
    fs.readFile(path.join(path.dirname(file), decodeURIComponent(uri)), (err, data) =>
      err ? reject(err.toString()) : resolve(new Uint8Array(data)));
  }),
}).then((report) => {
  const messages = report.issues.messages.map((m) => ({ code: m.code, severity: m.severity, pointer: m.pointer }));
  console.log(JSON.stringify({ errors: report.issues.numErrors, warnings: report.issues.numWarnings,
                               infos: report.issues.numInfos, messages,
                               extensions: (report.info && report.info.extensionsUsed) || [] }));
}).catch((error) => { console.log(JSON.stringify({ errors: -1, fatal: String(error) })); process.exit(0); });
