// Validate a .glb / .gltf with the Khronos glTF-Validator (npm package gltf-validator,
// installed by scripts/setup.sh into .tools/ at the top of the repository) and print its JSON report on stdout.
// Usage: node tests/helpers/validate_gltf.js FILE
"use strict";
const fs = require("fs");
const path = require("path");
const validator = require(path.join(__dirname, "..", "..", ".tools", "node_modules", "gltf-validator"));

const file = process.argv[2];
if (!file) {
  console.error("usage: node tests/helpers/validate_gltf.js FILE.glb|FILE.gltf");
  process.exit(2);
}
const dir = path.dirname(file);
validator
  .validateBytes(new Uint8Array(fs.readFileSync(file)), {
    uri: path.basename(file),
    maxIssues: 1000,
    externalResourceFunction: (uri) =>
      new Promise((resolve, reject) => {
        fs.readFile(path.join(dir, decodeURIComponent(uri)), (err, data) => (err ? reject(err.toString()) : resolve(new Uint8Array(data))));
      }),
  })
  .then((report) => {
    console.log(JSON.stringify(report, null, 1));
  })
  .catch((err) => {
    console.error("glTF-Validator failed: " + err);
    process.exit(1);
  });
