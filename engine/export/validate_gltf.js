// Validate a glTF/glb with the Khronos glTF-Validator and print its JSON report.
// usage: node validate_gltf.js NODE_MODULES_DIR FILE
const path = require("path");
const fs = require("fs");
const validator = require(path.join(process.argv[2], "gltf-validator"));
const file = process.argv[3];
const data = new Uint8Array(fs.readFileSync(file));
validator.validateBytes(data, {
  uri: path.basename(file),
  externalResourceFunction: (uri) => new Promise((resolve, reject) => {
    fs.readFile(path.join(path.dirname(file), decodeURIComponent(uri)), (err, d) => (err ? reject(err.toString()) : resolve(new Uint8Array(d))));
  }),
}).then((report) => { console.log(JSON.stringify(report)); })
  .catch((err) => { console.error(String(err)); process.exit(1); });
