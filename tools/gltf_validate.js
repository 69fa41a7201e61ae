// Validate a .glb/.gltf with the Khronos glTF-Validator (npm package gltf-validator); prints its JSON report.
// usage: node tools/gltf_validate.js NODE_MODULES/gltf-validator FILE
const fs = require("fs");
const path = require("path");

const validator = require(process.argv[2]);
const file = process.argv[3];
const bytes = new Uint8Array(fs.readFileSync(file));
validator.validateBytes(bytes, {
  uri: path.basename(file),
  maxIssues: 200,
  externalResourceFunction: (uri) => new Promise((resolve, reject) => {
    fs.readFile(path.join(path.dirname(file), decodeURIComponent(uri)),
      (err, data) => (err ? reject(err.toString()) : resolve(new Uint8Array(data))));
  }),
}).then((report) => console.log(JSON.stringify(report)))
  .catch((error) => { console.error(error); process.exit(1); });
