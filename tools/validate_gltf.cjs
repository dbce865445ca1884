// Validates a .glb/.gltf with the Khronos glTF-Validator (npm package gltf-validator) and
// prints its issue counts and messages. Exit 0 only with 0 errors and 0 warnings.
// Usage: node tools/validate_gltf.cjs FILE
const fs = require("fs");
const path = require("path");
const validator = require("gltf-validator");

const file = process.argv[2];
if (!file) {
  console.error("usage: node tools/validate_gltf.cjs FILE");
  process.exit(2);
}
const bytes = new Uint8Array(fs.readFileSync(file));
validator
  .validateBytes(bytes, {
    uri: path.basename(file),
    maxIssues: 100,
    externalResourceFunction: (uri) =>
      new Promise((resolve, reject) => {
        fs.readFile(path.join(path.dirname(file), decodeURIComponent(uri)), (err, data) =>
          err ? reject(err.toString()) : resolve(new Uint8Array(data))
        );
      }),
  })
  .then((report) => {
    const i = report.issues;
    console.log(
      `errors ${i.numErrors} warnings ${i.numWarnings} infos ${i.numInfos} hints ${i.numHints}`
    );
    for (const m of i.messages) {
      console.log(`${m.severity} ${m.code} ${m.pointer || ""} ${m.message}`);
    }
    process.exit(i.numErrors === 0 && i.numWarnings === 0 ? 0 : 1);
  })
  .catch((e) => {
    console.error(`validation failed: ${e}`);
    process.exit(2);
  });
